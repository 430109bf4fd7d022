//! Area lights laid out for the packet kernel (`integrator::packet`): each triangle's
//! vertices, normal, area and emission, and each sphere's centre, radius and emission, in
//! one record of four 16-byte rows, so that eight lanes' light samples load a row a lane
//! and transpose (`F8::gather_rows`) instead of taking eight trips through
//! [`Light::sample`]; and the alias table of selection by power, so
//! that eight lanes choose their lights at once. A lane's sample is the scalar code's to
//! the bit: [`AreaLights::sample`] performs `Light::sample`'s and
//! `integrator::estimator::sample_chosen_light`'s operations in their order, and
//! [`PowerSelection::select`] `LightSet::select`'s.
//!
//! Built once per render, the first time the packet kernel runs (see
//! `World::area_lights`), and only then: 80 bytes a light.

use super::solid_angle::SPHERE_CONE_SMALL;
use super::{Light, LightSet};
use crate::geometry::frame::frame_from_normal_lanes;
use crate::geometry::ray::offset_ray_origin_lanes;
use crate::sampling::distribution::AliasTable;
use crate::simd::{F8, M8, U8, V3};
use glam::Vec3;
use std::f32::consts::PI;

/// Floats a record holds, in [`ROWS`] rows of four. A triangle: vertices 0, 1, 2 (three
/// each), the unit front normal, the area, the emitted radiance. A sphere: the centre, the
/// radius, the emitted radiance.
const RECORD: usize = 16;
const ROWS: usize = RECORD / 4;
const NORMAL: usize = 9;
const AREA: usize = 12;
const CENTRE: usize = 0;
const RADIUS: usize = 3;
const EMISSION: usize = 13;
/// The rows (as a mask) that hold a triangle's fields, and a sphere's.
const TRIANGLE_ROWS: u32 = (1 << ROWS) - 1;
const SPHERE_ROWS: u32 = row_of(CENTRE) | row_of(RADIUS) | row_of(EMISSION) | row_of(EMISSION + 2);

/// The mask bit of the row that holds field `f`.
const fn row_of(f: usize) -> u32 {
    1 << (f / 4)
}

/// Which lights the lanes sample, as [`AreaLights::lanes_sample`] takes them: triangles of
/// untextured emission by area, spheres of untextured emission in the cone they subtend.
pub const TRIANGLES: u32 = 1;
pub const SPHERES: u32 = 4;
/// Flag bit: the light emits from both sides.
const TWO_SIDED: u32 = 2;

/// The records of a scene's lights, by light index (zero records for the lights the lanes
/// leave to the scalar code).
pub struct AreaLights {
    records: Vec<[f32; 4]>,
    /// The light's kind ([`TRIANGLES`] or [`SPHERES`], 0 for the scalar code's) and
    /// [`TWO_SIDED`].
    flags: Vec<u32>,
    /// The kinds of light present.
    kinds: u32,
    /// Selection by power in lanes, where the lights are selected by power.
    selection: Option<PowerSelection>,
}

/// The alias table of selection by power laid out for lanes: per light, the probability
/// of keeping its bin, the light taken otherwise, and its probability.
pub struct PowerSelection {
    keep: Vec<f32>,
    alias: Vec<u32>,
    pmf: Vec<f32>,
}

impl PowerSelection {
    fn new(table: &AliasTable) -> Self {
        let (mut keep, mut alias, mut pmf) = (Vec::new(), Vec::new(), Vec::new());
        for (k, a, p) in table.bins() {
            keep.push(k);
            alias.push(a);
            pmf.push(p);
        }
        Self { keep, alias, pmf }
    }

    /// The lights chosen with numbers `u` in [0, 1), and their probabilities:
    /// `AliasTable::sample` lane by lane, to the bit.
    #[inline(always)]
    pub fn select(&self, u: F8) -> (U8, F8) {
        let (bin, fraction) = u.bin_and_fraction(self.keep.len() as u32);
        let keep = fraction.lt(F8::gather(&self.keep, bin));
        let chosen = U8::select(keep, bin, bin.gather(&self.alias));
        (chosen, F8::gather(&self.pmf, chosen))
    }
}

/// Eight lanes' light samples.
pub struct AreaSamples {
    /// Unit direction towards the sampled point.
    pub wi: V3,
    /// Where the shadow ray ends (offset off the light).
    pub target: V3,
    pub radiance: V3,
    /// Solid-angle density, without the selection probability.
    pub pdf: F8,
    /// Lanes whose sample counts (the scalar code's `Some`, and not useless).
    pub valid: u32,
    /// Lanes the scalar code must sample: points inside a sphere, or on it, which sample
    /// its whole area instead of a cone.
    pub scalar: u32,
}

impl AreaLights {
    /// The records of the lights of `set`, and its selection by power; `emission(prim)` is
    /// the emitted radiance of a primitive whose emission is untextured, `None` otherwise.
    pub fn new(set: &LightSet, emission: impl Fn(u32) -> Option<Vec3>) -> Self {
        let lights = &set.lights;
        let mut records = vec![[0.0; 4]; lights.len() * ROWS];
        let mut flags = vec![0; lights.len()];
        for (i, light) in lights.iter().enumerate() {
            let record = records[i * ROWS..(i + 1) * ROWS].as_flattened_mut();
            let (kind, prim, two_sided) = match light {
                Light::Triangle(t) => {
                    for (v, p) in t.p.iter().enumerate() {
                        record[3 * v..3 * v + 3].copy_from_slice(&p.to_array());
                    }
                    record[NORMAL..NORMAL + 3].copy_from_slice(&t.n.to_array());
                    record[AREA] = t.area;
                    (TRIANGLES, t.prim, t.two_sided)
                }
                Light::Sphere(sp) => {
                    record[CENTRE..CENTRE + 3].copy_from_slice(&sp.centre.to_array());
                    record[RADIUS] = sp.radius;
                    (SPHERES, sp.prim, sp.two_sided)
                }
                _ => continue,
            };
            let Some(e) = emission(prim) else { continue };
            record[EMISSION..EMISSION + 3].copy_from_slice(&e.to_array());
            flags[i] = kind | if two_sided { TWO_SIDED } else { 0 };
        }
        let kinds = flags.iter().fold(0, |k, f| k | f) & (TRIANGLES | SPHERES);
        Self {
            records,
            flags,
            kinds,
            selection: set.power_table().map(PowerSelection::new),
        }
    }

    /// Selection by power in lanes; `None` under the other strategies.
    pub fn selection(&self) -> Option<&PowerSelection> {
        self.selection.as_ref()
    }

    /// Whether the lanes sample any light of `kinds` ([`TRIANGLES`], [`SPHERES`]).
    pub fn any(&self, kinds: u32) -> bool {
        self.kinds & kinds != 0
    }

    /// The lanes whose light `light` the lanes sample when they take the lights of `kinds`
    /// (the scalar code samples the others).
    #[inline(always)]
    pub fn lanes_sample(&self, light: U8, kinds: u32) -> u32 {
        let kinds = U8::splat(kinds);
        !(light.gather(&self.flags) & kinds).eq(U8::splat(0)).bits() & 0xff
    }

    /// Samples of lights `light` (each one the lanes sample) from points `p` with geometric
    /// normals `ng`, at numbers `u`, for the lanes of `mask`: per lane, `Light::sample`
    /// (triangles by area, spheres by cone) and `sample_chosen_light`'s emission and checks.
    #[inline(always)]
    pub fn sample(&self, light: U8, p: V3, ng: V3, u: [F8; 2], mask: u32) -> AreaSamples {
        let base = light.wrapping_mul(U8::splat(ROWS as u32));
        let flags = light.gather(&self.flags);
        let two = U8::splat(TWO_SIDED);
        let two_sided = (flags & two).eq(two);
        let spheres = if self.kinds & SPHERES != 0 {
            (flags & U8::splat(SPHERES)).eq(U8::splat(SPHERES)).bits() & mask
        } else {
            0
        };
        let triangles = mask & !spheres;
        let rows = if triangles != 0 {
            TRIANGLE_ROWS
        } else {
            SPHERE_ROWS
        };
        let record = record_fields(&self.records, base, rows);
        let (mut y, mut n, mut cone_pdf, mut scalar) = (V3::ZERO, V3::ZERO, F8::ZERO, 0);
        if triangles != 0 {
            (y, n) = triangle_points(&record, u);
        }
        if spheres != 0 {
            let s = sphere_points(&record, p, u);
            let m = M8::from_bits(spheres);
            (y, n) = (V3::select(m, s.y, y), V3::select(m, s.n, n));
            cone_pdf = s.pdf;
            scalar = spheres & !s.cone;
        }
        // area_sample.
        let to_light = y - p;
        let d2 = to_light.length_squared();
        let wi = to_light / d2.sqrt();
        let cos_light = -n.dot(wi);
        let zero = F8::ZERO;
        let facing_away = cos_light.le(zero) & !two_sided;
        let sampled = d2.gt(zero) & !(facing_away | cos_light.eq(zero));
        let target = offset_ray_origin_lanes(y, V3::select(cos_light.gt(zero), n, -n));
        let mut pdf = d2 / cos_light.abs() / record[AREA];
        if spheres != 0 {
            pdf = F8::select(M8::from_bits(spheres), cone_pdf, pdf);
        }
        // sample_chosen_light: a zero emission or a point behind the shading point is useless.
        let radiance = vector(&record, EMISSION);
        let black = radiance.x.eq(zero) & radiance.y.eq(zero) & radiance.z.eq(zero);
        let useless: M8 = black | wi.dot(ng).le(zero);
        AreaSamples {
            wi,
            target,
            radiance,
            pdf,
            valid: sampled.and_not(useless).bits() & mask & !scalar,
            scalar,
        }
    }
}

/// Points on triangle lights at `u` (`warp::square_to_uniform_triangle`, both branches and
/// a select) and their normals.
#[inline(always)]
fn triangle_points(record: &[F8; RECORD], u: [F8; 2]) -> (V3, V3) {
    let (p0, p1, p2) = (vector(record, 0), vector(record, 3), vector(record, 6));
    let half = F8::splat(2.0);
    let first = u[0].lt(u[1]);
    let (b0_first, b1_second) = (u[0] / half, u[1] / half);
    let b0 = F8::select(first, b0_first, u[0] - b1_second);
    let b1 = F8::select(first, u[1] - b0_first, b1_second);
    let (bx, by) = (b1, F8::ONE - b0 - b1);
    let y = p0 * (F8::ONE - bx - by) + p1 * bx + p2 * by;
    (y, vector(record, NORMAL))
}

/// Points on sphere lights sampled in their cones from `p`.
struct SpherePoints {
    y: V3,
    n: V3,
    /// The cone's solid-angle density.
    pdf: F8,
    /// Lanes where `p` sees a cone (outside the sphere); the others sample by area.
    cone: u32,
}

/// `solid_angle::sphere_cone`, `sample_sphere_cone` and `sphere_cone_pdf` lane by lane.
#[inline(always)]
fn sphere_points(record: &[F8; RECORD], p: V3, u: [F8; 2]) -> SpherePoints {
    let (c, r) = (vector(record, CENTRE), record[RADIUS]);
    let one = F8::ONE;
    let zero = F8::ZERO;
    // sphere_cone.
    let axis = c - p;
    let d2 = axis.length_squared();
    let sin2 = r * r / d2;
    let small = F8::splat(0.5) * sin2 + F8::splat(0.125) * sin2 * sin2;
    let large = one - (one - sin2).sqrt();
    let omc_max = F8::select(sin2.lt(F8::splat(SPHERE_CONE_SMALL)), small, large);
    let cone = sin2.lt(one) & omc_max.gt(zero);
    // sample_sphere_cone.
    let dc = d2.sqrt();
    let sin2_max = (r / dc) * (r / dc);
    let sin_max = sin2_max.sqrt();
    let omc = u[0] * omc_max;
    let cos_theta = one - omc;
    let sin2_theta = (omc * (F8::splat(2.0) - omc)).max(zero);
    let cos_alpha =
        sin2_theta / sin_max + cos_theta * (one - sin2_theta / sin2_max).max(zero).sqrt();
    let sin_alpha = (one - cos_alpha * cos_alpha).max(zero).sqrt();
    let (sin_phi, cos_phi) = (F8::splat(2.0 * PI) * u[1]).sin_cos();
    let [s, t, w] = frame_from_normal_lanes((axis / dc).normalize());
    let n = -(s * (sin_alpha * cos_phi) + t * (sin_alpha * sin_phi) + w * cos_alpha);
    SpherePoints {
        y: c + n * r,
        n,
        pdf: one / (F8::splat(2.0 * PI) * omc_max),
        cone: cone.bits(),
    }
}

/// The fields of each lane's record (of rows `base` to `base + ROWS`) in the rows of mask
/// `rows`, zero in the others. A function, not a closure: closures compile outside the
/// packet kernel's AVX2 code, where the intrinsics become calls.
#[inline(always)]
fn record_fields(records: &[[f32; 4]], base: U8, rows: u32) -> [F8; RECORD] {
    let mut fields = [F8::ZERO; RECORD];
    for (row, out) in fields.chunks_exact_mut(4).enumerate() {
        if rows & (1 << row) != 0 {
            out.copy_from_slice(&F8::gather_rows(records, base + U8::splat(row as u32)));
        }
    }
    fields
}

/// Fields `f`, `f + 1` and `f + 2` as a vector.
#[inline(always)]
fn vector(record: &[F8; RECORD], f: usize) -> V3 {
    V3::new(record[f], record[f + 1], record[f + 2])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::{
        LightSampling, LightSelect, PointLight, SphereLight, TriangleLight, solid_angle,
    };
    use crate::sampling::distribution::AliasTable;
    use crate::sampling::pcg::Pcg32;

    /// The lanes choose the alias table's lights with its probabilities, to the bit: tables
    /// of 1 to 40 random weights (some zero), numbers at random and just below and at each
    /// bin's edge, where the product's rounding in f32 would take the next bin.
    #[test]
    fn lane_selection_is_the_alias_tables() {
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let mut rng = Pcg32::new(3, 7);
        let mut below_edge = 0;
        for n in 1..=40u32 {
            let weights: Vec<f32> = (0..n)
                .map(|i| {
                    if i % 7 == 3 {
                        0.0
                    } else {
                        rng.next_f32() * 10.0
                    }
                })
                .collect();
            let Some(table) = AliasTable::new(&weights) else {
                continue;
            };
            let selection = PowerSelection::new(&table);
            let mut us: Vec<f32> = (0..200).map(|_| rng.next_f32()).collect();
            for k in 1..n {
                let edge = k as f32 / n as f32;
                us.extend([edge, f32::from_bits(edge.to_bits() - 1)]);
                below_edge += usize::from((edge.next_down() * n as f32) as u32 == k);
            }
            us.resize(us.len().next_multiple_of(8), 0.0);
            for chunk in us.chunks_exact(8) {
                let u: [f32; 8] = chunk.try_into().expect("eight numbers");
                let (light, p) = selection.select(F8::from_array(u));
                let (light, p) = (light.to_array(), p.to_array());
                for l in 0..8 {
                    let (index, pmf) = table.sample(u[l]);
                    assert_eq!(
                        (light[l] as usize, p[l].to_bits()),
                        (index, pmf.to_bits()),
                        "n {n}, u {}",
                        u[l]
                    );
                }
            }
        }
        // Numbers whose product rounds up to the bin edge in f32 occur.
        assert!(below_edge > 10, "{below_edge}");
    }

    /// Every lane's sample is the scalar code's to the bit: `Light::sample` (triangles by
    /// area, spheres by cone), the emission, and `sample_chosen_light`'s checks, for one-
    /// and two-sided lights seen from both sides, grazing and from their own plane, a light
    /// of zero emission, a sphere small enough for the cone's series; lanes inside or on a
    /// sphere are left to the scalar code, which samples its area.
    #[test]
    fn lanes_are_the_scalar_light_samples() {
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let triangle = |p: [Vec3; 3], two_sided: bool, prim: u32| {
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            Light::Triangle(TriangleLight {
                prim,
                p,
                n: n.normalize(),
                area: 0.5 * n.length(),
                two_sided,
                mean_radiance: Vec3::ONE,
                emission: None,
            })
        };
        let sphere = |centre: Vec3, radius: f32, two_sided: bool, prim: u32| {
            Light::Sphere(SphereLight {
                prim,
                centre,
                radius,
                two_sided,
                textured: false,
                mean_radiance: Vec3::ONE,
            })
        };
        let lights = [
            triangle([Vec3::ZERO, Vec3::X, Vec3::Y], false, 0),
            triangle(
                [
                    Vec3::new(0.2, 1.0, -0.3),
                    Vec3::new(1.5, 0.9, 0.1),
                    Vec3::new(0.4, 1.2, 1.0),
                ],
                true,
                1,
            ),
            triangle(
                [
                    Vec3::new(-1.0, 0.0, 2.0),
                    Vec3::new(1.0, 0.0, 2.0),
                    Vec3::new(0.0, 3.0, 2.0),
                ],
                false,
                2,
            ),
            Light::Point(PointLight {
                position: Vec3::ONE,
                intensity: Vec3::ONE,
            }),
            sphere(Vec3::new(0.5, 0.5, 1.5), 0.6, false, 4),
            sphere(Vec3::new(-1.0, 1.0, 0.0), 0.01, true, 5),
        ];
        let emission = |prim: u32| match prim {
            0 => Some(Vec3::new(3.0, 2.0, 1.0)),
            1 | 5 => Some(Vec3::splat(0.7)),
            4 => Some(Vec3::new(0.5, 1.0, 2.0)),
            _ => Some(Vec3::ZERO),
        };
        let set = LightSet::new(lights.to_vec(), None, 10.0, LightSelect::Power);
        let table = AreaLights::new(&set, emission);
        let kinds = TRIANGLES | SPHERES;
        assert!(table.any(SPHERES) && table.any(TRIANGLES) && table.selection().is_some());
        let every_light = U8::from_array([0, 1, 2, 3, 4, 5, 0, 0]);
        assert_eq!(table.lanes_sample(every_light, kinds), 0xff & !(1 << 3));
        assert_eq!(table.lanes_sample(every_light, SPHERES), 0b11_0000);
        let sampled_by_lanes = [0, 1, 2, 4, 5];
        let mut rng = Pcg32::new(9, 9);
        // Lanes whose sample counted, that did not, and that the scalar code took.
        let mut checked = [0usize; 3];
        for round in 0..5_000 {
            let pick: [u32; 8] =
                std::array::from_fn(|_| sampled_by_lanes[rng.next_u32() as usize % 5]);
            let ps: [Vec3; 8] = std::array::from_fn(|l| match (round + l) % 7 {
                // In the first light's plane.
                0 => Vec3::new(rng.next_f32() * 2.0 - 0.5, rng.next_f32() * 2.0 - 0.5, 0.0),
                // Inside the first sphere, or on it.
                1 => {
                    let d = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5;
                    let r = if rng.next_f32() < 0.5 { 0.6 } else { 0.3 };
                    Vec3::new(0.5, 0.5, 1.5) + d.normalize_or(Vec3::Z) * r
                }
                _ => Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0,
            });
            let ngs: [Vec3; 8] = std::array::from_fn(|_| {
                let v = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5;
                v.normalize_or(Vec3::Z)
            });
            let us: [[f32; 2]; 8] = std::array::from_fn(|_| [rng.next_f32(), rng.next_f32()]);
            let lane = |i: usize| F8::from_array(std::array::from_fn(|l| us[l][i]));
            let s = table.sample(
                U8::from_array(pick),
                V3::from_lanes(&ps),
                V3::from_lanes(&ngs),
                [lane(0), lane(1)],
                0xff,
            );
            for l in 0..8 {
                if s.scalar & (1 << l) != 0 {
                    let Light::Sphere(sp) = &lights[pick[l] as usize] else {
                        panic!("lane {l}: only spheres are left to the scalar code");
                    };
                    assert!(solid_angle::sphere_cone(ps[l], sp.centre, sp.radius).is_none());
                    assert_eq!(s.valid & (1 << l), 0);
                    checked[2] += 1;
                    continue;
                }
                let u = glam::Vec2::new(us[l][0], us[l][1]);
                let scalar = lights[pick[l] as usize]
                    .sample(ps[l], None, LightSampling::Auto, u)
                    .map(|mut ls| {
                        let (prim, _) = ls.area_point.expect("an area sample");
                        ls.radiance *= emission(prim).expect("untextured");
                        ls
                    })
                    .filter(|ls| !(ls.radiance == Vec3::ZERO || ls.wi.dot(ngs[l]) <= 0.0));
                let valid = s.valid & (1 << l) != 0;
                assert_eq!(
                    valid,
                    scalar.is_some(),
                    "lane {l}, light {}, p {}",
                    pick[l],
                    ps[l]
                );
                checked[valid as usize] += 1;
                let Some(ls) = scalar else { continue };
                let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                assert_eq!(bits(s.wi.lane(l)), bits(ls.wi));
                assert_eq!(bits(s.target.lane(l)), bits(ls.target.expect("a target")));
                assert_eq!(bits(s.radiance.lane(l)), bits(ls.radiance));
                assert_eq!(s.pdf.to_array()[l].to_bits(), ls.pdf.to_bits());
            }
        }
        // Every outcome occurs often.
        assert!(
            checked[0] > 5_000 && checked[1] > 5_000 && checked[2] > 500,
            "{checked:?}"
        );
    }
}
