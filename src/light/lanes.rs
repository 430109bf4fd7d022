//! Triangle lights laid out for the packet kernel (`integrator::packet`): each light's
//! vertices, normal, area and emission in one record, so that eight lanes' area samples are
//! eight gathers a field instead of eight trips through [`Light::sample`]. A lane's sample
//! is the scalar code's to the bit: [`TriangleLights::sample`] performs `Light::sample`'s
//! and `integrator::path::sample_light`'s operations in their order.
//!
//! Built once per render, the first time the packet kernel runs (see
//! `World::triangle_lights`), and only then: 68 bytes a light.

use super::Light;
use crate::geometry::ray::offset_ray_origin_lanes;
use crate::simd::{F8, M8, U8, V3};
use glam::Vec3;

/// Floats a record holds: vertices 0, 1, 2 (three each), the unit front normal, the area,
/// the emitted radiance.
const RECORD: u32 = 16;
const NORMAL: u32 = 9;
const AREA: u32 = 12;
const EMISSION: u32 = 13;

/// Flag bits: the lanes sample the light (a triangle of untextured emission); it emits
/// from both sides.
const LANES_SAMPLE: u32 = 1;
const TWO_SIDED: u32 = 2;

/// The records of a scene's lights, by light index (zero records for the lights the lanes
/// leave to the scalar code).
pub struct TriangleLights {
    records: Vec<f32>,
    flags: Vec<u32>,
    /// Whether the lanes sample any light.
    any: bool,
}

/// Eight lanes' area samples.
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
}

impl TriangleLights {
    /// The records of `lights`; `emission(prim)` is the emitted radiance of a primitive
    /// whose emission is untextured, `None` otherwise.
    pub fn new(lights: &[Light], emission: impl Fn(u32) -> Option<Vec3>) -> Self {
        let mut records = vec![0.0; lights.len() * RECORD as usize];
        let mut flags = vec![0; lights.len()];
        for (i, light) in lights.iter().enumerate() {
            let Light::Triangle(t) = light else { continue };
            let Some(e) = emission(t.prim) else { continue };
            let record = &mut records[i * RECORD as usize..(i + 1) * RECORD as usize];
            for (v, p) in t.p.iter().enumerate() {
                record[3 * v..3 * v + 3].copy_from_slice(&p.to_array());
            }
            record[NORMAL as usize..NORMAL as usize + 3].copy_from_slice(&t.n.to_array());
            record[AREA as usize] = t.area;
            record[EMISSION as usize..EMISSION as usize + 3].copy_from_slice(&e.to_array());
            flags[i] = LANES_SAMPLE | if t.two_sided { TWO_SIDED } else { 0 };
        }
        let any = flags.iter().any(|&f| f & LANES_SAMPLE != 0);
        Self {
            records,
            flags,
            any,
        }
    }

    /// Whether the lanes sample any light.
    pub fn any(&self) -> bool {
        self.any
    }

    /// Whether the lanes sample light `light` (otherwise the scalar code does).
    #[inline(always)]
    pub fn lanes_sample(&self, light: usize) -> bool {
        self.flags[light] & LANES_SAMPLE != 0
    }

    /// Area samples of lights `light` (each one the lanes sample) from points `p` with
    /// geometric normals `ng`, at numbers `u`, for the lanes of `mask`: per lane,
    /// `Light::sample` by area and `sample_light`'s emission and checks.
    #[inline(always)]
    pub fn sample(&self, light: U8, p: V3, ng: V3, u: [F8; 2], mask: u32) -> AreaSamples {
        let base = light.wrapping_mul(U8::splat(RECORD));
        let records = &self.records[..];
        let (p0, p1, p2) = (
            vector(records, base, 0),
            vector(records, base, 3),
            vector(records, base, 6),
        );
        let n = vector(records, base, NORMAL);
        let two = U8::splat(TWO_SIDED);
        let two_sided = (light.gather(&self.flags) & two).eq(two);
        // warp::square_to_uniform_triangle, both branches and a select.
        let half = F8::splat(2.0);
        let first = u[0].lt(u[1]);
        let (b0_first, b1_second) = (u[0] / half, u[1] / half);
        let b0 = F8::select(first, b0_first, u[0] - b1_second);
        let b1 = F8::select(first, u[1] - b0_first, b1_second);
        let (bx, by) = (b1, F8::ONE - b0 - b1);
        let y = p0 * (F8::ONE - bx - by) + p1 * bx + p2 * by;
        // area_sample.
        let to_light = y - p;
        let d2 = to_light.length_squared();
        let wi = to_light / d2.sqrt();
        let cos_light = -n.dot(wi);
        let zero = F8::ZERO;
        let facing_away = cos_light.le(zero) & !two_sided;
        let sampled = d2.gt(zero) & !(facing_away | cos_light.eq(zero));
        let target = offset_ray_origin_lanes(y, V3::select(cos_light.gt(zero), n, -n));
        let pdf = d2 / cos_light.abs() / field(records, base, AREA);
        // sample_light: a zero emission or a point behind the shading point is useless.
        let radiance = vector(records, base, EMISSION);
        let black = radiance.x.eq(zero) & radiance.y.eq(zero) & radiance.z.eq(zero);
        let useless: M8 = black | wi.dot(ng).le(zero);
        AreaSamples {
            wi,
            target,
            radiance,
            pdf,
            valid: sampled.and_not(useless).bits() & mask,
        }
    }
}

/// Field `f` of the records from `base` in each lane. A function, not a closure: closures
/// compile outside the packet kernel's AVX2 code, where the intrinsics become calls.
#[inline(always)]
fn field(records: &[f32], base: U8, f: u32) -> F8 {
    F8::gather(records, base + U8::splat(f))
}

/// Fields `f`, `f + 1` and `f + 2` as a vector.
#[inline(always)]
fn vector(records: &[f32], base: U8, f: u32) -> V3 {
    V3::new(
        field(records, base, f),
        field(records, base, f + 1),
        field(records, base, f + 2),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrator::LightSampling;
    use crate::light::TriangleLight;
    use crate::sampling::pcg::Pcg32;

    /// Every lane's sample is the scalar code's to the bit: `Light::sample` by area, the
    /// emission, and `sample_light`'s checks, for one- and two-sided lights seen from both
    /// sides, grazing and from their own plane, and a light of zero emission.
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
            Light::Point {
                position: Vec3::ONE,
                intensity: Vec3::ONE,
            },
        ];
        let emission = |prim: u32| match prim {
            0 => Some(Vec3::new(3.0, 2.0, 1.0)),
            1 => Some(Vec3::splat(0.7)),
            _ => Some(Vec3::ZERO),
        };
        let table = TriangleLights::new(&lights, emission);
        assert!(table.any() && !table.lanes_sample(3));
        let mut rng = Pcg32::new(9, 9);
        let mut checked = [0usize; 2];
        for round in 0..5_000 {
            let pick: [u32; 8] = std::array::from_fn(|_| rng.next_u32() % 3);
            let ps: [Vec3; 8] = std::array::from_fn(|l| match (round + l) % 5 {
                // In the first light's plane.
                0 => Vec3::new(rng.next_f32() * 2.0 - 0.5, rng.next_f32() * 2.0 - 0.5, 0.0),
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
        // Both outcomes occur often.
        assert!(checked.iter().all(|&c| c > 5_000), "{checked:?}");
    }
}
