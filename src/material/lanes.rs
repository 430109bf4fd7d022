//! The BSDFs of eight shading points at once, for the packet kernel
//! (`integrator::packet`): Lambert and the uncoated glTF BRDF in SIMD lanes, every other
//! BSDF (Phong, a clear-coated glTF surface) through its scalar code lane by lane. Each lane
//! performs the scalar BSDF's operations in the same order (no fused multiply-adds, the
//! same sine and cosine), so it returns the same bits: the packet kernel's paths are the
//! scalar kernel's. `tests` checks that over random directions.

use super::{Bsdf, Lobe};
use crate::geometry::triangle::Lanes;
use crate::simd::{F8, LANES, M8, V3};
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, FRAC_PI_2, FRAC_PI_4, PI};

/// Eight BSDFs (one a lane) in local shading frames (+z = shading normal).
pub struct BsdfLanes<'a> {
    /// Lanes whose BSDF is Lambert.
    lambert: M8,
    /// Lanes whose BSDF is the glTF BRDF without a clear coat.
    pbr: M8,
    /// Lanes of the uncoated glTF BRDF whose specular lobe is a perfect mirror.
    smooth: M8,
    /// Lanes evaluated by the scalar code (bit i: lane i).
    scalar: u32,
    /// Lambert albedo or glTF base colour.
    base: V3,
    metallic: F8,
    alpha: F8,
    f0: V3,
    /// Each lane's scalar BSDF (borrowed: eight of them are too large to copy a bounce).
    bsdfs: &'a [Bsdf<'a>; LANES],
}

/// Directions sampled in eight lanes.
pub struct SampleLanes {
    /// Local direction.
    pub wi: V3,
    /// f · cos θi / pdf.
    pub weight: V3,
    /// Solid-angle density, or the lobe's discrete probability for a delta lobe.
    pub pdf: F8,
    /// Lanes whose sample came from a delta lobe.
    pub delta: M8,
    /// Lanes with a sample (the scalar `sample` returned one).
    pub valid: M8,
}

/// Schlick's Fresnel with reflectance `f0` at normal incidence, at `cos`.
#[inline(always)]
fn schlick(f0: V3, cos: F8) -> V3 {
    let m = (F8::ONE - cos.abs()).max(F8::ZERO).min(F8::ONE);
    let m2 = m * m;
    let w = m2 * m2 * m;
    f0 + (V3::broadcast(F8::ONE) - f0) * w
}

/// `square_to_cosine_hemisphere` (concentric disk, lifted to the hemisphere) in lanes.
#[inline(always)]
fn cosine_hemisphere(u: [F8; 2]) -> V3 {
    let ox = u[0] * 2.0 - 1.0;
    let oy = u[1] * 2.0 - 1.0;
    let x_major = ox.abs().gt(oy.abs());
    let r = F8::select(x_major, ox, oy);
    let theta = F8::select(
        x_major,
        (oy / ox) * FRAC_PI_4,
        F8::splat(FRAC_PI_2) - (ox / oy) * FRAC_PI_4,
    );
    let (sin, cos) = theta.sin_cos();
    let centre = ox.eq(F8::ZERO) & oy.eq(F8::ZERO);
    let dx = F8::select(centre, F8::ZERO, r * cos);
    let dy = F8::select(centre, F8::ZERO, r * sin);
    let z = (F8::ONE - (dx * dx + dy * dy)).max(F8::ZERO).sqrt();
    V3::new(dx, dy, z)
}

/// The GGX quantities of `microfacet::Ggx` for a roughness `alpha` a lane.
struct GgxLanes {
    alpha: F8,
}

impl GgxLanes {
    #[inline(always)]
    fn d(&self, h: V3) -> F8 {
        let a2 = self.alpha * self.alpha;
        let t = h.z * h.z * (a2 - 1.0) + 1.0;
        let d = a2 / (F8::splat(PI) * t * t);
        F8::select(h.z.le(F8::ZERO), F8::ZERO, d)
    }

    #[inline(always)]
    fn g1(&self, w: V3) -> F8 {
        let cos2 = w.z * w.z;
        let tan2 = ((F8::ONE - cos2) / cos2).max(F8::ZERO);
        let lambda = ((F8::ONE + self.alpha * self.alpha * tan2).sqrt() - 1.0) * 0.5;
        let lambda = F8::select(cos2.le(F8::ZERO), F8::splat(f32::INFINITY), lambda);
        F8::ONE / (F8::ONE + lambda)
    }

    #[inline(always)]
    fn visibility(&self, n_dot_l: F8, n_dot_v: F8) -> F8 {
        let a2 = self.alpha * self.alpha;
        let one_minus = F8::ONE - a2;
        let gv = n_dot_l * (n_dot_v * n_dot_v * one_minus + a2).sqrt();
        let gl = n_dot_v * (n_dot_l * n_dot_l * one_minus + a2).sqrt();
        let s = gv + gl;
        F8::select(s.gt(F8::ZERO), F8::splat(0.5) / s, F8::ZERO)
    }

    #[inline(always)]
    fn reflection_pdf(&self, wo: V3, h: V3) -> F8 {
        let wo_h = wo.dot(h);
        let visible = self.g1(wo) * wo_h.max(F8::ZERO) * self.d(h) / wo.z;
        let visible = F8::select(wo.z.le(F8::ZERO), F8::ZERO, visible);
        F8::select(wo_h.le(F8::ZERO), F8::ZERO, visible / (wo_h * 4.0))
    }

    #[inline(always)]
    fn sample_visible_normal(&self, wo: V3, u: [F8; 2]) -> V3 {
        let a = self.alpha;
        let wo_std = V3::new(wo.x * a, wo.y * a, wo.z).normalize();
        let (sin_phi, cos_phi) = (u[0] * (2.0 * PI)).sin_cos();
        let z = (F8::ONE - u[1]) * (F8::ONE + wo_std.z) - wo_std.z;
        let sin_theta = (F8::ONE - z * z).max(F8::ZERO).min(F8::ONE).sqrt();
        let h_std = V3::new(sin_theta * cos_phi, sin_theta * sin_phi, z) + wo_std;
        V3::new(h_std.x * a, h_std.y * a, h_std.z.max(F8::ZERO)).normalize()
    }
}

impl<'a> BsdfLanes<'a> {
    /// The lanes of `bsdfs`; only lanes set in `used` are ever read.
    #[inline(always)]
    pub fn new(bsdfs: &'a [Bsdf<'a>; LANES], used: u32) -> Self {
        let mut base = [Vec3::ZERO; LANES];
        let mut f0 = [Vec3::ZERO; LANES];
        let (mut metallic, mut alpha) = ([0.0; LANES], [1.0; LANES]);
        let (mut lambert, mut pbr, mut scalar) = (0, 0, 0);
        for (lane, bsdf) in bsdfs.iter().enumerate() {
            if used & (1 << lane) == 0 {
                continue;
            }
            match bsdf {
                Bsdf::Lambert(l) => {
                    base[lane] = l.albedo;
                    lambert |= 1 << lane;
                }
                Bsdf::GltfPbr(p) => match p.uncoated() {
                    Some(parts) => {
                        (base[lane], metallic[lane]) = (parts.base, parts.metallic);
                        (alpha[lane], f0[lane]) = (parts.alpha, parts.f0);
                        pbr |= 1 << lane;
                    }
                    None => scalar |= 1 << lane,
                },
                Bsdf::Phong(_)
                | Bsdf::Dielectric(_)
                | Bsdf::ThinDielectric(_)
                | Bsdf::Layered(_) => scalar |= 1 << lane,
            }
        }
        let alpha = F8::from_array(alpha);
        Self {
            lambert: M8::from_bits(lambert),
            pbr: M8::from_bits(pbr),
            smooth: M8::from_bits(pbr) & alpha.lt(F8::splat(super::microfacet::SMOOTH_ALPHA)),
            scalar,
            base: V3::from_lanes(&base),
            metallic: F8::from_array(metallic),
            alpha,
            f0: V3::from_lanes(&f0),
            bsdfs,
        }
    }

    /// The lanes of `mask` whose BSDF has a lobe that is not a delta
    /// ([`Bsdf::has_non_delta`]): from the lanes' parameters for Lambert and the uncoated
    /// glTF BRDF (not a smooth pure metal), lane by lane for the others.
    #[inline(always)]
    pub fn non_delta(&self, mask: u32) -> u32 {
        let rough_or_dielectric = !self.smooth | self.metallic.lt(F8::ONE);
        let mut non_delta = (self.lambert | (self.pbr & rough_or_dielectric)).bits() & mask;
        for lane in Lanes::new(mask & self.scalar) {
            if self.bsdfs[lane].has_non_delta() {
                non_delta |= 1 << lane;
            }
        }
        non_delta
    }

    /// The glTF specular reflectance (dielectric and metal Fresnel mixed by metallic).
    #[inline(always)]
    fn specular_fresnel(&self, cos: F8) -> V3 {
        let fd = schlick(self.f0, cos);
        let fm = schlick(self.base, cos);
        fd * (F8::ONE - self.metallic) + fm * self.metallic
    }

    /// The glTF diffuse weight (1 - metallic)(1 - F_d(cos)) base.
    #[inline(always)]
    fn diffuse_weight(&self, cos: F8) -> V3 {
        let fd = schlick(self.f0, cos);
        self.base * (F8::ONE - self.metallic) * (V3::broadcast(F8::ONE) - fd)
    }

    /// The energy compensation's scale of each rough glTF lane's specular lobe at `wo`,
    /// from the lane's scalar BRDF (one in the other lanes, whose glossy term is zero).
    #[inline(always)]
    fn specular_energy(&self, wo: V3) -> V3 {
        let mut scale = [Vec3::ONE; LANES];
        for lane in Lanes::new(self.pbr.bits() & !self.smooth.bits()) {
            if let Bsdf::GltfPbr(p) = &self.bsdfs[lane] {
                scale[lane] = p.specular_energy(wo.lane(lane).z);
            }
        }
        V3::from_lanes(&scale)
    }

    /// The glTF lobe probabilities (specular, diffuse) at `wo`.
    #[inline(always)]
    fn lobe_probabilities(&self, wo: V3) -> (F8, F8) {
        let s = self.specular_fresnel(wo.z).luminance();
        let d = self.diffuse_weight(wo.z).luminance();
        let total = s + d;
        let positive = total.gt(F8::ZERO);
        (
            F8::select(positive, s / total, F8::ONE),
            F8::select(positive, d / total, F8::ZERO),
        )
    }

    /// The glTF f · cos θi and density for directions above the surface with half vector
    /// `h`, given the lobe probabilities and the specular energy scale at `wo`.
    #[inline(always)]
    fn pbr_eval_pdf_at(&self, wo: V3, wi: V3, h: V3, (ps, pd): (F8, F8), energy: V3) -> (V3, F8) {
        let ggx = GgxLanes { alpha: self.alpha };
        let v_h = wo.dot(h);
        let diffuse = self.diffuse_weight(v_h) * F8::splat(FRAC_1_PI);
        let vd = ggx.visibility(wi.z, wo.z) * ggx.d(h);
        let glossy = self.specular_fresnel(v_h) * F8::select(self.smooth, F8::ZERO, vd) * energy;
        let f = diffuse * wi.z + glossy * wi.z;
        let cosine = wi.z.max(F8::ZERO) / F8::splat(PI);
        let specular = F8::select(self.smooth, F8::ZERO, ps * ggx.reflection_pdf(wo, h));
        (f, pd * cosine + specular)
    }

    /// f · cos θi and the density of `sample` for the pair (`wo`, `wi`) of each lane in
    /// `lanes` (as the scalar `eval` and `pdf`).
    #[target_feature(enable = "avx2,fma")]
    pub fn eval_pdf(&self, wo: V3, wi: V3, lanes: u32) -> (V3, F8) {
        let above = wo.z.gt(F8::ZERO) & wi.z.gt(F8::ZERO);
        let cosine = wi.z.max(F8::ZERO) / F8::splat(PI);
        let mut f = self.base * (wi.z * FRAC_1_PI);
        let mut pdf = F8::select(wo.z.gt(F8::ZERO), cosine, F8::ZERO);
        if (self.pbr & M8::from_bits(lanes)).any() {
            let h = (wo + wi).normalize();
            let (pf, ppdf) = self.pbr_eval_pdf_at(
                wo,
                wi,
                h,
                self.lobe_probabilities(wo),
                self.specular_energy(wo),
            );
            f = V3::select(self.pbr, pf, f);
            pdf = F8::select(self.pbr, ppdf, pdf);
        }
        let f = V3::select(above, f, V3::ZERO);
        let pdf = F8::select(self.pbr.and_not(above), F8::ZERO, pdf);
        let scalar = self.scalar & lanes;
        if scalar == 0 {
            return (f, pdf);
        }
        let (mut fx, mut fy, mut fz, mut p) = (
            f.x.to_array(),
            f.y.to_array(),
            f.z.to_array(),
            pdf.to_array(),
        );
        for lane in Lanes::new(scalar) {
            let (o, i) = (wo.lane(lane), wi.lane(lane));
            let v = self.bsdfs[lane].eval(o, i);
            (fx[lane], fy[lane], fz[lane]) = (v.x, v.y, v.z);
            p[lane] = self.bsdfs[lane].pdf(o, i);
        }
        (
            V3::new(F8::from_array(fx), F8::from_array(fy), F8::from_array(fz)),
            F8::from_array(p),
        )
    }

    /// Samples a direction in each lane of `lanes`: `u_lobe` picks the lobe, `u` the
    /// direction in it (as the scalar `sample`).
    #[target_feature(enable = "avx2,fma")]
    pub fn sample(&self, wo: V3, u_lobe: F8, u: [F8; 2], lanes: u32) -> SampleLanes {
        let wo_above = wo.z.gt(F8::ZERO);
        let cosine_wi = cosine_hemisphere(u);
        let cosine_pdf = cosine_wi.z.max(F8::ZERO) / F8::splat(PI);
        let lambert = SampleLanes {
            wi: cosine_wi,
            weight: self.base,
            pdf: cosine_pdf,
            delta: M8::none(),
            valid: self.lambert & wo_above & cosine_pdf.gt(F8::ZERO),
        };
        // A new value, not the Lambert lanes' overwritten: selects back into them compile to
        // masked stores (see `F8::merge`).
        let s = if (self.pbr & M8::from_bits(lanes)).any() {
            let probabilities = self.lobe_probabilities(wo);
            let specular = u_lobe.lt(probabilities.0);
            let mirror = specular & self.smooth;
            let ggx = GgxLanes { alpha: self.alpha };
            let h = ggx.sample_visible_normal(wo, u);
            let reflected = h * (wo.dot(h) * 2.0) - wo;
            let wi = V3::select(specular, reflected, cosine_wi);
            let hw = (wo + wi).normalize();
            let (f, pdf) =
                self.pbr_eval_pdf_at(wo, wi, hw, probabilities, self.specular_energy(wo));
            let glossy_valid = wi.z.gt(F8::ZERO) & pdf.gt(F8::ZERO);
            // A perfect mirror: the specular reflectance over its probability.
            let mirror_wi = V3::new(-wo.x, -wo.y, wo.z);
            let mirror_weight = self.specular_fresnel(wo.z) / probabilities.0;
            let pbr = SampleLanes {
                wi: V3::select(mirror, mirror_wi, wi),
                weight: V3::select(mirror, mirror_weight, f / pdf),
                pdf: F8::select(mirror, probabilities.0, pdf),
                delta: mirror,
                valid: wo_above & (mirror | glossy_valid),
            };
            SampleLanes {
                wi: V3::select(self.pbr, pbr.wi, lambert.wi),
                weight: V3::select(self.pbr, pbr.weight, lambert.weight),
                pdf: F8::select(self.pbr, pbr.pdf, lambert.pdf),
                delta: self.pbr & pbr.delta,
                valid: self.pbr & pbr.valid | lambert.valid,
            }
        } else {
            lambert
        };
        let scalar = self.scalar & lanes;
        if scalar == 0 {
            return s;
        }
        let mut arrays = [
            s.wi.x.to_array(),
            s.wi.y.to_array(),
            s.wi.z.to_array(),
            s.weight.x.to_array(),
            s.weight.y.to_array(),
            s.weight.z.to_array(),
            s.pdf.to_array(),
        ];
        let (mut delta, mut valid) = (s.delta.bits(), s.valid.bits());
        let (ul, u0, u1) = (u_lobe.to_array(), u[0].to_array(), u[1].to_array());
        for lane in Lanes::new(scalar) {
            let bit = 1 << lane;
            match self.bsdfs[lane].sample(wo.lane(lane), ul[lane], Vec2::new(u0[lane], u1[lane])) {
                Some(b) => {
                    let values = [
                        b.wi.x, b.wi.y, b.wi.z, b.weight.x, b.weight.y, b.weight.z, b.pdf,
                    ];
                    for (array, v) in arrays.iter_mut().zip(values) {
                        array[lane] = v;
                    }
                    valid |= bit;
                    if b.lobe == Lobe::Specular {
                        delta |= bit;
                    } else {
                        delta &= !bit;
                    }
                }
                None => valid &= !bit,
            }
        }
        let [wx, wy, wz, gx, gy, gz, pdf] = arrays;
        let f = F8::from_array;
        SampleLanes {
            wi: V3::new(f(wx), f(wy), f(wz)),
            weight: V3::new(f(gx), f(gy), f(gz)),
            pdf: f(pdf),
            delta: M8::from_bits(delta),
            valid: M8::from_bits(valid),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::gltf_pbr::GltfPbr;
    use super::super::lambert::Lambert;
    use super::super::phong::Phong;
    use super::*;
    use crate::sampling::pcg::Pcg32;

    /// A direction on the sphere from two uniform numbers, mostly in the upper hemisphere.
    fn direction(rng: &mut Pcg32) -> Vec3 {
        let z = rng.next_f32() * 1.2 - 0.2;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = 2.0 * PI * rng.next_f32();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    fn same(a: f32, b: f32, what: &str) {
        assert_eq!(a.to_bits(), b.to_bits(), "{what}: lanes {a}, scalar {b}");
    }

    /// Every lane returns its scalar BSDF's bits: f · cos θi, the density, and the sampled
    /// direction, weight, density and lobe, for Lambert, glTF metals and dielectrics
    /// (rough and mirror-smooth), and the lanes handed to the scalar code (Phong, a coated
    /// glTF surface); and `non_delta` picks the lanes `Bsdf::has_non_delta` picks.
    #[test]
    fn lanes_agree_with_the_scalar_bsdfs() {
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let kinds = [
            Bsdf::Lambert(Lambert {
                albedo: Vec3::new(0.8, 0.5, 0.2),
            }),
            Bsdf::GltfPbr(GltfPbr::new(Vec3::ONE, 1.0, 0.3, 1.5)),
            Bsdf::GltfPbr(GltfPbr::new(Vec3::new(0.9, 0.6, 0.3), 0.0, 0.7, 1.5)),
            Bsdf::GltfPbr(GltfPbr::new(Vec3::new(0.5, 0.5, 0.9), 0.4, 0.0, 1.33)),
            Bsdf::GltfPbr(GltfPbr::new(Vec3::ONE, 1.0, 0.01, 1.5)),
            Bsdf::Phong(Phong {
                kd: Vec3::splat(0.3),
                ks: Vec3::splat(0.4),
                exponent: 30.0,
            }),
            Bsdf::GltfPbr(GltfPbr::new(Vec3::splat(0.4), 0.0, 0.5, 1.5).with_clearcoat(0.8, 0.2)),
            Bsdf::GltfPbr(GltfPbr::new(Vec3::splat(0.7), 1.0, 0.9, 1.5)),
        ];
        let lanes = BsdfLanes::new(&kinds, 0xff);
        // The smooth pure metal (lane 4) alone has only a delta lobe.
        assert_eq!(lanes.non_delta(0xff), 0xff & !(1 << 4));
        for mask in 0..=0xffu32 {
            let expected = (0..LANES)
                .filter(|&l| mask & (1 << l) != 0 && kinds[l].has_non_delta())
                .fold(0, |m, l| m | 1 << l);
            assert_eq!(lanes.non_delta(mask), expected, "mask {mask:#x}");
        }
        let mut rng = Pcg32::new(7, 3);
        let mut checked = [0usize; 2];
        for _ in 0..4000 {
            let wo: [Vec3; 8] = std::array::from_fn(|_| direction(&mut rng));
            let wi: [Vec3; 8] = std::array::from_fn(|_| direction(&mut rng));
            let u: [[f32; 3]; 8] = std::array::from_fn(|_| std::array::from_fn(|_| rng.next_f32()));
            // SAFETY: AVX2 and FMA were detected above.
            let (f, pdf) =
                unsafe { lanes.eval_pdf(V3::from_lanes(&wo), V3::from_lanes(&wi), 0xff) };
            let ul = F8::from_array(u.map(|u| u[0]));
            let uv = [
                F8::from_array(u.map(|u| u[1])),
                F8::from_array(u.map(|u| u[2])),
            ];
            // SAFETY: as above.
            let s = unsafe { lanes.sample(V3::from_lanes(&wo), ul, uv, 0xff) };
            for (lane, bsdf) in kinds.iter().enumerate() {
                let (f_s, pdf_s) = (bsdf.eval(wo[lane], wi[lane]), bsdf.pdf(wo[lane], wi[lane]));
                let f_l = f.lane(lane);
                for c in 0..3 {
                    same(f_l[c], f_s[c], &format!("lane {lane} f"));
                }
                same(pdf.to_array()[lane], pdf_s, &format!("lane {lane} pdf"));
                checked[0] += 1;
                let scalar = bsdf.sample(wo[lane], u[lane][0], Vec2::new(u[lane][1], u[lane][2]));
                assert_eq!(
                    s.valid.bits() & (1 << lane) != 0,
                    scalar.is_some(),
                    "lane {lane} sample validity"
                );
                let Some(b) = scalar else { continue };
                checked[1] += 1;
                assert_eq!(
                    s.delta.bits() & (1 << lane) != 0,
                    b.is_delta(),
                    "lane {lane} delta"
                );
                let (wi_l, weight_l) = (s.wi.lane(lane), s.weight.lane(lane));
                for c in 0..3 {
                    same(wi_l[c], b.wi[c], &format!("lane {lane} wi"));
                    same(weight_l[c], b.weight[c], &format!("lane {lane} weight"));
                }
                same(
                    s.pdf.to_array()[lane],
                    b.pdf,
                    &format!("lane {lane} sample pdf"),
                );
            }
        }
        assert!(checked.iter().all(|&n| n > 10_000), "{checked:?}");
    }
}
