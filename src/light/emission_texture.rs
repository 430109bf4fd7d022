//! Emissive textures as lights: how much each emitting triangle gives off, from the texels
//! of its emissive texture that its surface shows.
//!
//! Every emissive triangle is a light whose probability of being chosen for a light sample
//! follows its power (`Light::power`): its area times the luminance of its mean emission.
//! With an emissive texture that mean is over the texels the triangle's UV footprint reads,
//! so a screen's lit pixels and a helmet's glowing trim get the light samples and the dark
//! parts of the texture none (a footprint whose texels are all black is a light of zero
//! power, never chosen, which is exact: its surface emits nothing). A whole-texture mean per
//! triangle, besides losing that, costs time proportional to triangles × texels.
//!
//! [`EmissionPyramid`] is built once per emissive texture (and emission factor) in time
//! linear in its texels: level 0 holds each texel's emitted luminance, each level above the
//! mean of 2 × 2 below. A triangle's mean is read at the finest level where its footprint's
//! bounding box, grown by the texel a bilinear lookup reaches beyond it, spans at most
//! [`FOOTPRINT_TEXELS`] texels a side, following the texture's wrap modes; so the whole
//! preparation is linear in texels plus triangles. All values are non-negative sums, so a
//! footprint averages to zero exactly when every texel it can read is black.
//!
//! Within a triangle whose footprint covers many texels, light samples follow the texture
//! too ([`TriangleEmission`]): the triangle is split by midpoint subdivision into 4^d
//! sub-triangles of equal area (d up to [`MAX_DEPTH`], each covering about
//! [`LEAF_TEXELS`] texels or more), each weighted by its footprint's mean from the pyramid,
//! and the weights are kept as a tree of sums. A sample descends the tree to a sub-triangle
//! with probability proportional to its weight and takes a uniform point in it; the density
//! at a point descends the same tree by the point's barycentrics. A sub-triangle of weight
//! zero is never sampled, which is exact for the same reason as above. So a screen of two
//! triangles showing a small bright logo sends its light samples to the logo, not across
//! the black around it. Triangles whose sub-triangles differ little keep uniform sampling
//! (no tree, no memory).

use crate::color::luminance;
use crate::sampling::warp::square_to_uniform_triangle;
use crate::scene::{Texture, Wrap};
use glam::{Vec2, Vec3};

/// The widest a footprint is read, in texels of the level it is read at.
const FOOTPRINT_TEXELS: usize = 16;

/// The deepest subdivision of an emitting triangle: 4^5 = 1024 sub-triangles, a tree of
/// 1365 sums (5.3 kB).
pub const MAX_DEPTH: u32 = 5;
/// The texels a sub-triangle's footprint covers at least (by area).
const LEAF_TEXELS: f32 = 16.0;
/// Sub-triangles whose weights all lie within this factor of each other are sampled
/// uniformly: the tree would gain little.
const UNIFORM_SPREAD: f32 = 1.25;

/// One level of the pyramid.
struct Level {
    width: usize,
    height: usize,
    values: Vec<f32>,
}

/// Emitted luminance of a texture's texels, with coarser levels of block means.
pub struct EmissionPyramid {
    levels: Vec<Level>,
    wrap: (Wrap, Wrap),
}

impl EmissionPyramid {
    /// The pyramid of `texture` as an emissive texture of `factor` (sRGB-decoded colour
    /// times the factor, to luminance).
    pub fn new(texture: &Texture, factor: Vec3) -> Self {
        let (width, height) = (
            texture.width.max(1) as usize,
            texture.height.max(1) as usize,
        );
        let mut values = Vec::with_capacity(width * height);
        for y in 0..height as u32 {
            for x in 0..width as u32 {
                let texel = texture.texel_linear(x, y, true).truncate();
                values.push(luminance(texel * factor).max(0.0));
            }
        }
        let mut levels = vec![Level {
            width,
            height,
            values,
        }];
        while let Some(last) = levels.last()
            && (last.width > 1 || last.height > 1)
        {
            let (w, h) = (last.width.div_ceil(2), last.height.div_ceil(2));
            let at = |x: usize, y: usize| {
                last.values[y.min(last.height - 1) * last.width + x.min(last.width - 1)]
            };
            let values = (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .map(|(x, y)| {
                    let (x, y) = (2 * x, 2 * y);
                    0.25 * (at(x, y) + at(x + 1, y) + at(x, y + 1) + at(x + 1, y + 1))
                })
                .collect();
            levels.push(Level {
                width: w,
                height: h,
                values,
            });
        }
        Self {
            levels,
            wrap: (texture.wrap_u, texture.wrap_v),
        }
    }

    /// Width and height of the texture in texels.
    pub fn size(&self) -> (usize, usize) {
        (self.levels[0].width, self.levels[0].height)
    }

    /// Mean emitted luminance over the texels that lookups at texture coordinates inside
    /// the box `lo`..`hi` can read (bilinear reach included).
    pub fn mean_over(&self, lo: Vec2, hi: Vec2) -> f32 {
        let base = &self.levels[0];
        if !(lo.is_finite() && hi.is_finite()) {
            return self.levels.last().map_or(0.0, |l| l.values[0]);
        }
        // Texel indices of level 0 the box reaches, one beyond for bilinear filtering.
        let range = |lo: f32, hi: f32, n: usize| {
            let a = (lo as f64 * n as f64 - 0.5).floor() as i64;
            let b = ((hi as f64 * n as f64 - 0.5).floor() as i64).saturating_add(1);
            (a, b)
        };
        let (x0, x1) = range(lo.x, hi.x, base.width);
        let (y0, y1) = range(lo.y, hi.y, base.height);
        let xs = axis_segments(x0, x1, base.width, self.wrap.0);
        let ys = axis_segments(y0, y1, base.height, self.wrap.1);
        let span = |segs: &[(usize, usize)]| segs.iter().map(|(a, b)| b - a + 1).sum::<usize>();
        // The finest level at which the footprint spans at most FOOTPRINT_TEXELS a side.
        let mut level = 0;
        while level + 1 < self.levels.len()
            && (span(&xs) >> level > FOOTPRINT_TEXELS || span(&ys) >> level > FOOTPRINT_TEXELS)
        {
            level += 1;
        }
        let l = &self.levels[level];
        let (mut sum, mut count) = (0.0f64, 0usize);
        for &(ya, yb) in &ys {
            for y in (ya >> level)..=(yb >> level).min(l.height - 1) {
                for &(xa, xb) in &xs {
                    for x in (xa >> level)..=(xb >> level).min(l.width - 1) {
                        sum += l.values[y * l.width + x] as f64;
                        count += 1;
                    }
                }
            }
        }
        if count == 0 {
            0.0
        } else {
            (sum / count as f64) as f32
        }
    }
}

/// Light samples on one emitting triangle that follow its emissive texture (see the module
/// doc). Positions are barycentrics (b1, b2): the point is p0 (1 - b1 - b2) + p1 b1 + p2 b2,
/// and (b1, b2) are also coordinates in the triangle (0, 0), (1, 0), (0, 1), which the
/// subdivision splits: child 0 at corner 0, child 1 at corner 1, child 2 at corner 2, child
/// 3 the middle one, turned over.
#[derive(Clone, Debug)]
pub struct TriangleEmission {
    depth: u32,
    /// The sub-triangles' weights and their sums, level by level from the root: level l
    /// starts at (4^l - 1) / 3, and node i of level l has children 4i..4i+3 of level l + 1.
    sums: Vec<f32>,
}

/// Index of the first node of level `l` in [`TriangleEmission::sums`].
#[inline]
fn level_start(l: u32) -> usize {
    ((1usize << (2 * l)) - 1) / 3
}

/// The child of a subdivided triangle holding local point `b`, and `b` in the child's own
/// coordinates.
#[inline]
fn child_at(b: Vec2) -> (usize, Vec2) {
    if b.x + b.y < 0.5 {
        (0, 2.0 * b)
    } else if b.x >= 0.5 {
        (1, Vec2::new(2.0 * b.x - 1.0, 2.0 * b.y))
    } else if b.y >= 0.5 {
        (2, Vec2::new(2.0 * b.x, 2.0 * b.y - 1.0))
    } else {
        (3, Vec2::ONE - 2.0 * b)
    }
}

/// Point `b` of child `c`, in the parent's coordinates ([`child_at`] undone).
#[inline]
fn from_child(c: usize, b: Vec2) -> Vec2 {
    match c {
        0 => 0.5 * b,
        1 => Vec2::new(0.5 * (b.x + 1.0), 0.5 * b.y),
        2 => Vec2::new(0.5 * b.x, 0.5 * (b.y + 1.0)),
        _ => 0.5 * (Vec2::ONE - b),
    }
}

impl TriangleEmission {
    /// The sampling tree of a triangle whose vertices have texture coordinates `uvs` (the
    /// texture transform applied) on `pyramid`'s texture, with subdivision at most
    /// `max_depth`; `None` where uniform sampling is as good (a footprint of few texels,
    /// or nearly even emission) or nothing is emitted.
    pub fn new(pyramid: &EmissionPyramid, uvs: [Vec2; 3], max_depth: u32) -> Option<Self> {
        let depth = Self::depth_for(pyramid, uvs).min(max_depth);
        if depth == 0 {
            return None;
        }
        let leaves = 1usize << (2 * depth);
        let mut sums = vec![0.0f32; level_start(depth + 1)];
        // Leaves in tree order: a leaf's index holds, two bits a level, the child taken at
        // each level, the root's child in the highest bits.
        let uv_at = |b: Vec2| uvs[0] * (1.0 - b.x - b.y) + uvs[1] * b.x + uvs[2] * b.y;
        let first_leaf = level_start(depth);
        for leaf in 0..leaves {
            let corners = [Vec2::ZERO, Vec2::X, Vec2::Y].map(|mut b| {
                for l in (0..depth).rev() {
                    let c = (leaf >> (2 * (depth - 1 - l))) & 3;
                    b = from_child(c, b);
                }
                uv_at(b)
            });
            let lo = corners[0].min(corners[1]).min(corners[2]);
            let hi = corners[0].max(corners[1]).max(corners[2]);
            sums[first_leaf + leaf] = pyramid.mean_over(lo, hi);
        }
        let weights = &sums[first_leaf..];
        let (min, max) = weights
            .iter()
            .fold((f32::INFINITY, 0.0f32), |(lo, hi), &w| {
                (lo.min(w), hi.max(w))
            });
        if !(max > 0.0) || (min > 0.0 && max <= UNIFORM_SPREAD * min) {
            return None;
        }
        for l in (0..depth).rev() {
            let (start, below) = (level_start(l), level_start(l + 1));
            for i in 0..(1usize << (2 * l)) {
                let c = below + 4 * i;
                sums[start + i] = sums[c] + sums[c + 1] + sums[c + 2] + sums[c + 3];
            }
        }
        Some(Self { depth, sums })
    }

    /// The subdivision depth a triangle's footprint asks for: sub-triangles of at least
    /// [`LEAF_TEXELS`] texels, at most [`MAX_DEPTH`] levels.
    pub fn depth_for(pyramid: &EmissionPyramid, uvs: [Vec2; 3]) -> u32 {
        let (w, h) = pyramid.size();
        let texels = 0.5 * (uvs[1] - uvs[0]).perp_dot(uvs[2] - uvs[0]).abs() * (w * h) as f32;
        if !(texels >= 4.0 * LEAF_TEXELS) {
            return 0;
        }
        ((texels / LEAF_TEXELS).log2() / 2.0)
            .floor()
            .min(MAX_DEPTH as f32) as u32
    }

    /// A point (barycentrics) and its density relative to uniform sampling by area.
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let mut ux = u.x;
        let mut node = 0usize;
        let mut path = [0usize; MAX_DEPTH as usize];
        for (l, step) in path.iter_mut().enumerate().take(self.depth as usize) {
            let first = level_start(l as u32 + 1) + 4 * node;
            let children = &self.sums[first..first + 4];
            let total: f32 = children.iter().sum();
            let mut target = ux * total;
            let mut chosen = None;
            for (c, &w) in children.iter().enumerate() {
                if w > 0.0 {
                    chosen = Some(c);
                    if target < w {
                        break;
                    }
                    target -= w;
                }
            }
            // Rounding can leave the target past the last child of weight: it is taken.
            let c = chosen.unwrap_or(0);
            ux = (target / children[c]).clamp(0.0, 1.0 - f32::EPSILON / 2.0);
            *step = c;
            node = 4 * node + c;
        }
        let mut b = square_to_uniform_triangle(Vec2::new(ux, u.y));
        for &c in path[..self.depth as usize].iter().rev() {
            b = from_child(c, b);
        }
        (b, self.relative_density(node))
    }

    /// Density at barycentrics `b` relative to uniform sampling by area.
    pub fn density(&self, b: Vec2) -> f32 {
        let mut local = b;
        let mut node = 0usize;
        for _ in 0..self.depth {
            let (c, inner) = child_at(local);
            local = inner;
            node = 4 * node + c;
        }
        self.relative_density(node)
    }

    #[inline]
    fn relative_density(&self, leaf: usize) -> f32 {
        self.sums[level_start(self.depth) + leaf] / self.sums[0]
            * (1usize << (2 * self.depth)) as f32
    }
}

/// The texel indices (inclusive segments of `0..n`) that the indices `a..=b` wrap to.
fn axis_segments(a: i64, b: i64, n: usize, mode: Wrap) -> Vec<(usize, usize)> {
    let n = n as i64;
    if b - a + 1 >= n && mode != Wrap::ClampToEdge {
        return vec![(0, n as usize - 1)];
    }
    match mode {
        Wrap::ClampToEdge => vec![(a.clamp(0, n - 1) as usize, b.clamp(0, n - 1) as usize)],
        Wrap::Repeat => {
            let (a, len) = (a.rem_euclid(n), b - a);
            if a + len < n {
                vec![(a as usize, (a + len) as usize)]
            } else {
                vec![(a as usize, n as usize - 1), (0, (a + len - n) as usize)]
            }
        }
        Wrap::MirroredRepeat => {
            // Each index maps to one texel; a range shorter than n crosses at most one fold.
            let texel = |i: i64| {
                let p = i.rem_euclid(2 * n);
                if p < n { p } else { 2 * n - 1 - p }
            };
            let mut segments: Vec<(usize, usize)> = Vec::new();
            let (mut start, mut prev) = (texel(a), texel(a));
            for i in a + 1..=b {
                let t = texel(i);
                if (t - prev).abs() != 1 {
                    segments.push((start.min(prev) as usize, start.max(prev) as usize));
                    start = t;
                }
                prev = t;
            }
            segments.push((start.min(prev) as usize, start.max(prev) as usize));
            segments
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Texels;
    use std::sync::Arc;

    fn texture(width: u32, height: u32, lit: &[(u32, u32)], wrap: Wrap) -> Texture {
        let mut texels = vec![[0u8, 0, 0, 255]; (width * height) as usize];
        for &(x, y) in lit {
            texels[(y * width + x) as usize] = [255, 255, 255, 255];
        }
        Texture {
            name: "t".into(),
            width,
            height,
            texels: Arc::new(Texels::Rgba8(texels)),
            mips: Default::default(),
            wrap_u: wrap,
            wrap_v: wrap,
            nearest: false,
            mipmaps: true,
            udim: None,
        }
    }

    /// A footprint that can read a lit texel has a positive mean, one that cannot has none,
    /// at every level the footprint size selects.
    #[test]
    fn zero_exactly_where_no_readable_texel_emits() {
        let t = texture(64, 32, &[(40, 20)], Wrap::ClampToEdge);
        let p = EmissionPyramid::new(&t, Vec3::ONE);
        let (u, v) = ((40.5) / 64.0, (20.5) / 32.0);
        // A point on the lit texel (its bilinear reach: the lit texel of four), one 0.9
        // texels away (still reading it), one far.
        assert!((p.mean_over(Vec2::new(u, v), Vec2::new(u, v)) - 0.25).abs() < 1e-6);
        let near = Vec2::new(u + 0.9 / 64.0, v);
        assert!(p.mean_over(near, near) > 0.0, "bilinear reach");
        let far = Vec2::new(u - 10.0 / 64.0, v);
        assert_eq!(p.mean_over(far, far), 0.0);
        // Large boxes read coarse levels, still positive over the texel, zero away from it.
        assert!(p.mean_over(Vec2::new(0.5, 0.5), Vec2::new(0.75, 0.75)) > 0.0);
        assert_eq!(p.mean_over(Vec2::new(0.0, 0.0), Vec2::new(0.4, 0.4)), 0.0);
        // The whole texture: one lit texel of 2048.
        let whole = p.mean_over(Vec2::ZERO, Vec2::ONE);
        assert!((whole - 1.0 / 2048.0).abs() < 1e-4, "{whole}");
    }

    #[test]
    fn footprints_wrap_as_lookups_do() {
        // The lit texels are at the left edge: a box just right of u = 1 reaches them under
        // repeat, not under clamp; under mirrored repeat, a box just left of u = 0 does.
        for (wrap, box_lo, lit) in [
            (Wrap::Repeat, 1.005f32, true),
            (Wrap::ClampToEdge, 1.005, false),
            (Wrap::MirroredRepeat, -0.002, true),
            (Wrap::Repeat, -0.05, false),
        ] {
            let t = texture(32, 8, &[(0, 4), (0, 3)], wrap);
            let p = EmissionPyramid::new(&t, Vec3::ONE);
            let lo = Vec2::new(box_lo, 0.5);
            let hi = Vec2::new(box_lo + 0.002, 0.5);
            assert_eq!(p.mean_over(lo, hi) > 0.0, lit, "{wrap:?} at u = {box_lo}");
        }
        assert_eq!(axis_segments(-2, 1, 8, Wrap::Repeat), vec![(6, 7), (0, 1)]);
        assert_eq!(
            axis_segments(-2, 1, 8, Wrap::MirroredRepeat),
            vec![(0, 1), (0, 1)]
        );
        assert_eq!(
            axis_segments(6, 9, 8, Wrap::MirroredRepeat),
            vec![(6, 7), (6, 7)]
        );
        assert_eq!(axis_segments(-3, 20, 8, Wrap::Repeat), vec![(0, 7)]);
    }
}
