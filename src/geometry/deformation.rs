//! Meshes that change shape over the shutter (deformation blur): the vertex positions, and
//! the shading normals where the mesh has them, at keys evenly spaced over the shutter,
//! interpolated linearly at a ray's time, as Cycles' motion steps and Embree's linear
//! motion blur of triangles do. The topology is the same at every key.
//!
//! A deforming triangle lies, at any time, inside the box of its corners at all keys (a
//! linear interpolation stays inside the hull of its ends), so the BVH bounds it by that
//! box and intersects the triangle at the ray's time (`geometry::bvh`).
//!
//! Times are fractions of the shutter: 0 at its opening, 1 at its closing.

use super::motion::MAX_KEYS;
use glam::{DMat3, DMat4, Vec3};

/// A mesh's vertex keys over the shutter.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Deformation {
    /// Per key, every vertex's position (keys evenly spaced from the shutter's opening to
    /// its closing).
    pub positions: Vec<Vec<Vec3>>,
    /// Per key, every vertex's shading normal, where the mesh has normals.
    pub normals: Option<Vec<Vec<Vec3>>>,
}

impl Deformation {
    /// Why these keys cannot deform a mesh of `vertices` vertices (with normals if
    /// `normals`), if they cannot: 2 to [`MAX_KEYS`] keys, each of every vertex, finite.
    pub fn check(&self, vertices: usize, normals: bool) -> Result<(), String> {
        let keys = self.positions.len();
        if !(2..=MAX_KEYS).contains(&keys) {
            return Err(format!(
                "{keys} position keys; a deformation has 2 to {MAX_KEYS}"
            ));
        }
        if let Some(k) = self.positions.iter().position(|k| k.len() != vertices) {
            return Err(format!(
                "position key {k} has {} points for {vertices} vertices",
                self.positions[k].len()
            ));
        }
        if self.positions.iter().flatten().any(|p| !p.is_finite()) {
            return Err("a position key is not finite".into());
        }
        match &self.normals {
            Some(_) if !normals => Err("normal keys for a mesh without normals".into()),
            Some(n) if n.len() != keys => {
                Err(format!("{} normal keys for {keys} position keys", n.len()))
            }
            Some(n) if n.iter().any(|k| k.len() != vertices) => {
                Err(format!("a normal key is not of {vertices} vertices"))
            }
            Some(n) if n.iter().flatten().any(|v| !v.is_finite()) => {
                Err("a normal key is not finite".into())
            }
            _ => Ok(()),
        }
    }

    /// True if some vertex is somewhere else at some key: the mesh deforms.
    pub fn moves(&self) -> bool {
        self.positions.windows(2).any(|w| w[0] != w[1])
    }

    /// How many keys.
    pub fn keys(&self) -> usize {
        self.positions.len()
    }

    /// Bytes its keys hold.
    pub fn bytes(&self) -> u64 {
        let keys = |k: &Vec<Vec<Vec3>>| {
            k.iter()
                .map(|k| std::mem::size_of_val(k.as_slice()))
                .sum::<usize>()
        };
        (keys(&self.positions) + self.normals.as_ref().map_or(0, keys)) as u64
    }

    /// Moves every key by `to_render` (normals by `normal_matrix`, its inverse transpose).
    pub fn transform(&mut self, to_render: &DMat4, normal_matrix: &DMat3) {
        for p in self.positions.iter_mut().flatten() {
            *p = to_render.transform_point3(p.as_dvec3()).as_vec3();
        }
        for n in self.normals.iter_mut().flatten().flatten() {
            *n = (*normal_matrix * n.as_dvec3())
                .normalize_or_zero()
                .as_vec3();
        }
    }

    /// Vertex `v`'s position at shutter time `time`.
    #[inline]
    pub fn position(&self, v: usize, time: f32) -> Vec3 {
        let (i, u) = segment(self.positions.len(), time);
        self.positions[i][v].lerp(self.positions[i + 1][v], u)
    }

    /// The corners `tri` at shutter time `time`, and their shading normals (not normalised)
    /// where the mesh has normals: one key interval found for all six.
    #[inline]
    pub fn triangle(&self, tri: [u32; 3], time: f32) -> ([Vec3; 3], Option<[Vec3; 3]>) {
        let (i, u) = segment(self.positions.len(), time);
        let lerp =
            |keys: &[Vec<Vec3>]| tri.map(|v| keys[i][v as usize].lerp(keys[i + 1][v as usize], u));
        (lerp(&self.positions), self.normals.as_deref().map(lerp))
    }

    /// Vertex `v`'s shading normal at shutter time `time` (not normalised), if the mesh has
    /// normals.
    #[inline]
    pub fn normal(&self, v: usize, time: f32) -> Option<Vec3> {
        let normals = self.normals.as_ref()?;
        let (i, u) = segment(normals.len(), time);
        Some(normals[i][v].lerp(normals[i + 1][v], u))
    }
}

/// The key interval of `time` among `keys` evenly spaced keys, and the fraction of it.
#[inline(always)]
pub fn segment(keys: usize, time: f32) -> (usize, f32) {
    let intervals = keys - 1;
    let x = time.clamp(0.0, 1.0) * intervals as f32;
    let i = (x as usize).min(intervals - 1);
    (i, x - i as f32)
}

/// A triangle at shutter time `time` from its corners at `keys` evenly spaced keys.
#[inline(always)]
pub fn triangle_at(keys: &[[Vec3; 3]], time: f32) -> [Vec3; 3] {
    let (i, u) = segment(keys.len(), time);
    let (a, b) = (keys[i], keys[i + 1]);
    [a[0].lerp(b[0], u), a[1].lerp(b[1], u), a[2].lerp(b[2], u)]
}

/// The box of a triangle over the whole shutter: of its corners at every key.
pub fn swept_bounds(keys: &[[Vec3; 3]]) -> (Vec3, Vec3) {
    keys.iter()
        .flatten()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
            (lo.min(p), hi.max(p))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn deformation(keys: &[f32]) -> Deformation {
        Deformation {
            positions: keys
                .iter()
                .map(|&x| vec![Vec3::new(x, 0.0, 0.0), Vec3::Y])
                .collect(),
            normals: None,
        }
    }

    #[test]
    fn positions_are_interpolated_linearly_between_evenly_spaced_keys() {
        let d = deformation(&[0.0, 1.0, 3.0]);
        for (time, x) in [(0.0, 0.0), (0.25, 0.5), (0.5, 1.0), (0.75, 2.0), (1.0, 3.0)] {
            assert!((d.position(0, time).x - x).abs() < 1e-6, "{time}");
        }
        // Outside the shutter: its ends.
        assert_eq!(d.position(0, -1.0).x, 0.0);
        assert_eq!(d.position(0, 2.0).x, 3.0);
        assert!(d.moves());
        assert!(!deformation(&[1.0, 1.0]).moves());
    }

    #[test]
    fn bad_keys_are_named() {
        let mut d = deformation(&[0.0]);
        assert!(d.check(2, false).unwrap_err().contains("1 position keys"));
        d = deformation(&[0.0, 1.0]);
        assert!(d.check(3, false).unwrap_err().contains("for 3 vertices"));
        d.positions[1][0].x = f32::NAN;
        assert!(d.check(2, false).unwrap_err().contains("not finite"));
        d = deformation(&[0.0, 1.0]);
        d.normals = Some(vec![vec![Vec3::Z; 2]]);
        assert!(d.check(2, true).unwrap_err().contains("1 normal keys"));
        assert!(d.check(2, false).is_err());
        d.normals = Some(vec![vec![Vec3::Z; 2]; 2]);
        assert_eq!(d.check(2, true), Ok(()));
    }

    #[test]
    fn a_triangle_stays_inside_its_swept_box() {
        let keys = [
            [Vec3::ZERO, Vec3::X, Vec3::Y],
            [Vec3::new(2.0, 1.0, 0.0), Vec3::new(3.0, -1.0, 1.0), Vec3::Z],
            [Vec3::splat(-1.0), Vec3::ONE, Vec3::new(0.0, 4.0, 0.0)],
        ];
        let (lo, hi) = swept_bounds(&keys);
        for s in 0..=100 {
            for p in triangle_at(&keys, s as f32 / 100.0) {
                assert!(p.cmpge(lo).all() && p.cmple(hi).all());
            }
        }
        assert_eq!(triangle_at(&keys, 0.5), keys[1]);
    }
}
