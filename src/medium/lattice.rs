//! A voxel lattice in render space, walked by majorants: the values of a grid (density,
//! temperature) interpolated trilinearly between voxel centres, the largest value over
//! each coarse cell of [`CELL`]³ voxels, and the tentative collisions of a ray with it: a
//! Poisson process whose rate is a multiple of the cell's largest value, cell by cell
//! (Amanatides and Woo's 3D DDA over the cells; exponential steps inside each). The media
//! (`grid`) build delta tracking, ratio tracking and emission estimates on these collisions.

use crate::sampling::pcg::{Pcg32, mix_u64};
use crate::scene::DensityGrid;
use glam::{Affine3A, DMat4, DVec3, Vec3};
use std::sync::Arc;

/// Voxels along a side of a majorant cell.
pub const CELL: usize = 8;

/// The most tentative collisions of one walk: a grid whose majorant far exceeds its
/// densities along a ray (one voxel of 1e28 among thin ones) would otherwise step for
/// hours; a walk that reaches it counts as blocked. A walk of real media reaches it only
/// where the majorant's optical depth along the ray exceeds the real one some 20 000-fold
/// (past a real optical depth of about 3, ratio tracking's roulette ends it); 2^16 steps
/// take about a millisecond.
const MAX_COLLISIONS: u32 = 1 << 16;

/// A grid's values placed in render space, with majorants over its cells.
#[derive(Clone, Debug)]
pub(super) struct Lattice {
    values: Arc<[f32]>,
    resolution: [usize; 3],
    /// Render space to voxel space (the grid's box is [0, n] along each axis).
    to_voxel: Affine3A,
    majorants: MajorantGrid,
}

impl Lattice {
    /// `grid` (its unit cube to world space) in a render space that `world_to_render` maps
    /// world space to.
    pub(super) fn new(grid: &DensityGrid, world_to_render: DMat4) -> Self {
        let resolution = grid.resolution.map(|r| r as usize);
        let to_voxel = DMat4::from_scale(DVec3::from(grid.resolution.map(f64::from)))
            * grid.to_world.inverse()
            * world_to_render.inverse();
        Self {
            majorants: MajorantGrid::new(&grid.values, resolution),
            values: grid.values.clone(),
            resolution,
            to_voxel: Affine3A::from_mat4(to_voxel.as_mat4()),
        }
    }

    /// One over the shortest side of a voxel in render space (the longest row of the linear
    /// map to voxel space).
    pub(super) fn voxels_per_unit(&self) -> f32 {
        let rows = self.to_voxel.matrix3.transpose();
        rows.x_axis
            .length()
            .max(rows.y_axis.length())
            .max(rows.z_axis.length())
    }

    /// Replaces each cell's majorant `m` by `f(m)`: a majorant of a function of the values
    /// where `f` is non-decreasing (emission by temperature).
    pub(super) fn map_majorants(&mut self, f: impl Fn(f32) -> f32) {
        self.majorants.max.iter_mut().for_each(|m| *m = f(*m));
    }

    /// Render-space point `p` in voxel space.
    #[cfg(test)]
    pub(super) fn to_voxel(&self, p: Vec3) -> Vec3 {
        self.to_voxel.transform_point3(p)
    }

    /// The value at render-space point `p` (the edge voxels' beyond the grid's box).
    #[inline]
    pub(super) fn value_at(&self, p: Vec3) -> f32 {
        self.value(self.to_voxel.transform_point3(p))
    }

    /// The largest majorant of any cell.
    pub(super) fn largest_majorant(&self) -> f32 {
        self.majorants.max.iter().copied().fold(0.0, f32::max)
    }

    /// The value at voxel-space point `q` (inside the grid's box), interpolated
    /// trilinearly between voxel centres.
    #[inline]
    pub(super) fn value(&self, q: Vec3) -> f32 {
        let [nx, ny, nz] = self.resolution;
        let axis = |v: f32, n: usize| {
            let x = (v - 0.5).clamp(0.0, (n - 1) as f32);
            let i = (x as usize).min(n - 1);
            (i, (i + 1).min(n - 1), x - i as f32)
        };
        let (x0, x1, fx) = axis(q.x, nx);
        let (y0, y1, fy) = axis(q.y, ny);
        let (z0, z1, fz) = axis(q.z, nz);
        let d = &self.values;
        let at = |x: usize, y: usize, z: usize| d[(z * ny + y) * nx + x];
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let plane = |z: usize| {
            lerp(
                lerp(at(x0, y0, z), at(x1, y0, z), fx),
                lerp(at(x0, y1, z), at(x1, y1, z), fx),
                fy,
            )
        };
        lerp(plane(z0), plane(z1), fz)
    }

    /// The tentative collisions along the ray from `origin` in unit direction `dir` up to
    /// `length` (render space), at `rate` per unit length and unit value of the majorant
    /// grid; `None` where it misses the lattice.
    #[inline]
    pub(super) fn walk(&self, origin: Vec3, dir: Vec3, length: f32, rate: f32) -> Option<Walk<'_>> {
        let o = self.to_voxel.transform_point3(origin);
        let d = self.to_voxel.transform_vector3(dir);
        // A ray with a NaN or infinite component (corrupt geometry upstream) crosses nothing,
        // as it hits nothing (`geometry::bvh`).
        if !(o.is_finite() && d.is_finite()) {
            return None;
        }
        let hi = Vec3::from(self.resolution.map(|n| n as f32));
        let inv = d.recip();
        let (a, b) = ((Vec3::ZERO - o) * inv, (hi - o) * inv);
        // NaN (a ray along a face) drops out of min/max.
        let t0 = a.min(b).max_element().max(0.0);
        let t1 = a.max(b).min_element().min(length);
        if !(t0 < t1) {
            return None;
        }
        let g = &self.majorants;
        let p = (o + d * t0) / CELL as f32;
        let mut cell = [0i64; 3];
        let mut step = [0i64; 3];
        let mut t_next = [f32::INFINITY; 3];
        let mut t_delta = [f32::INFINITY; 3];
        for k in 0..3 {
            cell[k] = (p[k].floor() as i64).clamp(0, g.cells[k] as i64 - 1);
            if d[k] > 0.0 {
                step[k] = 1;
                t_delta[k] = CELL as f32 / d[k];
                t_next[k] = t0 + ((cell[k] + 1) as f32 - p[k]) * t_delta[k];
            } else if d[k] < 0.0 {
                step[k] = -1;
                t_delta[k] = -(CELL as f32) / d[k];
                t_next[k] = t0 + (p[k] - cell[k] as f32) * t_delta[k];
            }
        }
        let cells = Cells {
            grid: g,
            cell,
            step,
            t_next,
            t_delta,
            t: t0,
            t_end: t1,
        };
        Some(Walk {
            lattice: self,
            cells,
            o,
            d,
            t: t0,
            leave: t0,
            rate,
            majorant: 0.0,
            collisions: 0,
        })
    }
}

/// The largest value over each cell of [`CELL`]³ voxels, taken over every voxel that
/// trilinear interpolation inside the cell reads.
#[derive(Clone, Debug)]
struct MajorantGrid {
    cells: [usize; 3],
    max: Vec<f32>,
}

impl MajorantGrid {
    fn new(values: &[f32], res: [usize; 3]) -> Self {
        let cells = res.map(|n| n.div_ceil(CELL));
        let mut max = vec![0.0f32; cells[0] * cells[1] * cells[2]];
        // Voxels a cell's lookups read: one beyond each face (clamped).
        let span = |c: usize, n: usize| (c * CELL).saturating_sub(1)..((c + 1) * CELL + 1).min(n);
        for cz in 0..cells[2] {
            for cy in 0..cells[1] {
                for cx in 0..cells[0] {
                    let mut m = 0.0f32;
                    for z in span(cz, res[2]) {
                        for y in span(cy, res[1]) {
                            let row = (z * res[1] + y) * res[0];
                            for x in span(cx, res[0]) {
                                m = m.max(values[row + x]);
                            }
                        }
                    }
                    max[(cz * cells[1] + cy) * cells[0] + cx] = m;
                }
            }
        }
        Self { cells, max }
    }

    #[inline]
    fn at(&self, c: [usize; 3]) -> f32 {
        self.max[(c[2] * self.cells[1] + c[1]) * self.cells[0] + c[0]]
    }
}

/// The cells a ray crosses, in order: `(t_enter, t_leave, majorant value)` (3D DDA,
/// Amanatides and Woo).
pub(super) struct Cells<'g> {
    grid: &'g MajorantGrid,
    cell: [i64; 3],
    step: [i64; 3],
    t_next: [f32; 3],
    t_delta: [f32; 3],
    pub(super) t: f32,
    pub(super) t_end: f32,
}

impl Iterator for Cells<'_> {
    type Item = (f32, f32, f32);

    #[inline]
    fn next(&mut self) -> Option<Self::Item> {
        if self.t >= self.t_end {
            return None;
        }
        let axis = if self.t_next[0] < self.t_next[1] {
            if self.t_next[0] < self.t_next[2] {
                0
            } else {
                2
            }
        } else if self.t_next[1] < self.t_next[2] {
            1
        } else {
            2
        };
        let leave = self.t_next[axis].min(self.t_end);
        let c = self.cell.map(|c| c as usize);
        let item = (self.t, leave, self.grid.at(c));
        self.t = leave;
        self.cell[axis] += self.step[axis];
        self.t_next[axis] += self.t_delta[axis];
        if self.cell[axis] < 0 || self.cell[axis] >= self.grid.cells[axis] as i64 {
            self.t_end = self.t;
        }
        Some(item)
    }
}

/// A tentative collision of a walk.
pub(super) enum Collision {
    /// At distance `t`, where the lattice's value is `value`, under majorant `majorant`
    /// (collisions per unit length there).
    At { t: f32, value: f32, majorant: f32 },
    /// The walk reached [`MAX_COLLISIONS`]: it counts as blocked.
    Capped,
}

/// The tentative collisions along a ray in voxel space: exponential steps under each
/// majorant cell's extinction in turn (memoryless, so a step cut at a cell's far side starts
/// afresh in the next cell).
pub(super) struct Walk<'m> {
    lattice: &'m Lattice,
    pub(super) cells: Cells<'m>,
    pub(super) o: Vec3,
    pub(super) d: Vec3,
    t: f32,
    /// Tentative collisions per unit length and unit value of the majorant grid.
    rate: f32,
    /// The far side of the current cell, and its majorant extinction.
    leave: f32,
    majorant: f32,
    collisions: u32,
}

impl Walk<'_> {
    /// The next tentative collision, from `rng`; `None` past the end of the ray.
    #[inline(always)]
    pub(super) fn next(&mut self, rng: &mut Pcg32) -> Option<Collision> {
        loop {
            if self.majorant > 0.0 {
                self.collisions += 1;
                if self.collisions > MAX_COLLISIONS {
                    return Some(Collision::Capped);
                }
                self.t -= (1.0 - rng.next_f32()).ln() / self.majorant;
                if self.t < self.leave {
                    return Some(Collision::At {
                        t: self.t,
                        value: self.lattice.value(self.o + self.d * self.t),
                        majorant: self.majorant,
                    });
                }
            }
            let (enter, leave, max) = self.cells.next()?;
            self.t = enter;
            self.leave = leave;
            self.majorant = max * self.rate;
        }
    }
}

/// The generator of a walk along the ray from `origin` along `dir`, driven by `bits`.
#[inline]
pub(super) fn walk_rng(origin: Vec3, dir: Vec3, bits: u32) -> Pcg32 {
    let a = u64::from(origin.x.to_bits()) << 32 | u64::from(origin.y.to_bits());
    let b = u64::from(origin.z.to_bits()) << 32 | u64::from(dir.x.to_bits());
    let c = u64::from(dir.y.to_bits()) << 32 | u64::from(dir.z.to_bits());
    let seed = mix_u64(a ^ mix_u64(b ^ mix_u64(c ^ u64::from(bits))));
    Pcg32::new(seed, mix_u64(seed))
}
