//! UDIM texture sets: one texture made of many images ("tiles"), each covering one unit
//! square of texture space, as Mari, Substance Painter and Houdini paint production assets
//! and as OpenImageIO, RenderMan, Arnold, Karma and Cycles look them up.
//!
//! Tile number `1001 + u + 10 v` holds the square `[u, u + 1) × [v, v + 1)` of USD's
//! texture coordinates `st` (v up, u in 0..10, v ≥ 0). lucerna's coordinates are glTF's
//! (v down: `uv = (s, 1 - t)`), in which tile (u, v) is `[u, u + 1) × (-v, 1 - v]`; a point
//! of it is read from the tile's image at `uv - (u, -v)`, a translation, so footprints of
//! filtered lookups pass through unchanged. Each tile is filtered on its own and clamped at
//! its edges (a lookup never blends two tiles), and coordinates where the set has no tile
//! read the set's fallback image, which is the texture's own image (see
//! [`crate::scene::Texture::udim`]).

use glam::Vec2;

/// Columns of the UDIM grid: tile numbers run 1001..=1010 along u, then the next row.
pub const COLUMNS: u32 = 10;
/// The first tile's number.
pub const FIRST: u32 = 1001;
/// The last tile number accepted (row 899): four-digit numbers, as file names spell them.
pub const LAST: u32 = 9999;

/// The tiles of a UDIM texture, each an image `T` (a [`crate::scene::Texture`]).
#[derive(Clone, Debug)]
pub struct Udim<T> {
    /// Tile numbers and the indices of the scene textures holding their images, as the
    /// scene file names them.
    pub tiles: Vec<(u32, u32)>,
    /// For column `c` and row `r`, `COLUMNS * r + c`: one more than the index into
    /// `images` of the tile there, 0 where the set has none.
    grid: Vec<u32>,
    /// The tiles' images, in the order of `tiles`.
    images: Vec<T>,
}

impl<T> Udim<T> {
    /// The set of `tiles` (number, texture index), whose images are `image(index)`.
    /// Errors name the problem: a number outside 1001..=9999, a number given twice, or
    /// what `image` says of an index.
    pub fn new(
        tiles: Vec<(u32, u32)>,
        mut image: impl FnMut(u32) -> Result<T, String>,
    ) -> Result<Self, String> {
        // Numbers are checked before the grid is sized by them.
        if let Some(&(number, _)) = tiles.iter().find(|(n, _)| !(FIRST..=LAST).contains(n)) {
            return Err(format!("tile number {number} is outside {FIRST}..={LAST}"));
        }
        let rows = tiles
            .iter()
            .map(|&(n, _)| (n - FIRST) / COLUMNS + 1)
            .max()
            .unwrap_or(0);
        let mut grid = vec![0u32; (COLUMNS * rows) as usize];
        let mut images = Vec::with_capacity(tiles.len());
        for (k, &(number, index)) in tiles.iter().enumerate() {
            let image = image(index).map_err(|e| format!("tile {number}: {e}"))?;
            let cell = &mut grid[(number - FIRST) as usize];
            if *cell != 0 {
                return Err(format!("tile {number} is given twice"));
            }
            *cell = k as u32 + 1;
            images.push(image);
        }
        Ok(Self {
            tiles,
            grid,
            images,
        })
    }

    /// The image of the tile at `uv` and the coordinates in it, or `None` where the set has
    /// no tile (the fallback is read there).
    #[inline]
    pub fn tile(&self, uv: Vec2) -> Option<(&T, Vec2)> {
        let cell = number_at(uv)? - FIRST;
        let slot = *self.grid.get(cell as usize)?;
        let image = self.images.get(slot.checked_sub(1)? as usize)?;
        let (column, row) = ((cell % COLUMNS) as f32, (cell / COLUMNS) as f32);
        Some((image, uv - Vec2::new(column, -row)))
    }

    /// The tiles' images.
    pub fn images(&self) -> &[T] {
        &self.images
    }

    /// The same set with its images replaced by `f` of each.
    pub fn map_images<U>(&self, f: impl FnMut(&T) -> U) -> Udim<U> {
        Udim {
            tiles: self.tiles.clone(),
            grid: self.grid.clone(),
            images: self.images.iter().map(f).collect(),
        }
    }

    /// Whether the set has tile `number`.
    pub fn has(&self, number: u32) -> bool {
        self.tiles.iter().any(|&(n, _)| n == number)
    }
}

/// The UDIM tile number at `uv` (lucerna's convention), whether or not a set has it;
/// `None` outside the numbered range (u outside [0, 10), v below 0 in USD's terms).
pub fn number_at(uv: Vec2) -> Option<u32> {
    let (column, row) = (uv.x.floor(), (1.0 - uv.y).floor());
    let in_range = (0.0..COLUMNS as f32).contains(&column)
        && (0.0..=((LAST - FIRST) / COLUMNS) as f32).contains(&row);
    in_range.then(|| FIRST + column as u32 + COLUMNS * row as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tiles that are their texture indices' names.
    fn named(index: u32) -> Result<String, String> {
        (index < 3)
            .then(|| format!("image {index}"))
            .ok_or_else(|| format!("texture index {index} out of range"))
    }

    #[test]
    fn tiles_are_found_by_usd_st_and_read_at_the_offset_coordinates() {
        let set = Udim::new(vec![(1001, 0), (1002, 1), (1011, 2)], named).unwrap();
        // uv = (s, 1 - t): st (1.25, 0.5) is tile 1002, st (0.5, 1.75) tile 1011.
        let (image, local) = set.tile(Vec2::new(1.25, 0.5)).unwrap();
        assert_eq!(image, "image 1");
        assert!((local - Vec2::new(0.25, 0.5)).length() < 1e-6);
        let (image, local) = set.tile(Vec2::new(0.5, 1.0 - 1.75)).unwrap();
        assert_eq!(image, "image 2");
        assert!((local - Vec2::new(0.5, 0.25)).length() < 1e-6, "{local}");
        assert_eq!(number_at(Vec2::new(0.5, 1.0 - 1.75)), Some(1011));
        // No tile 1012, nothing left of u = 0 or below t = 0, nothing at u ≥ 10.
        for uv in [
            Vec2::new(1.5, -0.5),
            Vec2::new(-0.5, 0.5),
            Vec2::new(0.5, 1.5),
            Vec2::new(10.5, 0.5),
            Vec2::NAN,
        ] {
            assert!(set.tile(uv).is_none(), "{uv}");
        }
        assert_eq!(number_at(Vec2::new(10.5, 0.5)), None);
    }

    #[test]
    fn bad_sets_are_refused_with_the_reason() {
        let err = |tiles| Udim::new(tiles, named).unwrap_err();
        assert!(err(vec![(1000, 0)]).contains("outside"));
        assert!(err(vec![(10000, 0)]).contains("outside"));
        assert!(err(vec![(1001, 0), (u32::MAX, 1)]).contains("outside"));
        assert!(err(vec![(1001, 0), (1001, 0)]).contains("twice"));
        assert_eq!(
            err(vec![(1001, 5)]),
            "tile 1001: texture index 5 out of range"
        );
    }
}
