//! Fresnel reflectance of dielectric interfaces and refraction (Snell's law), in the
//! conventions of pbrt-v4 and Mitsuba 3: `eta` is the relative index of refraction, the
//! index on the transmitted side over the index on the incident side, and directions point
//! away from the surface.

use glam::Vec3;

/// Unpolarised Fresnel reflectance of a smooth dielectric interface for light arriving at
/// `cos_i` (the cosine to the normal on the incident side, positive) with relative index
/// `eta`: exact, including total internal reflection (1 past the critical angle).
#[inline]
pub fn dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let r_parallel = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perpendicular = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parallel * r_parallel + r_perpendicular * r_perpendicular)
}

/// Reflectance at normal incidence of an interface of relative index `eta`.
#[inline]
pub fn normal_reflectance(eta: f32) -> f32 {
    ((eta - 1.0) / (eta + 1.0)).powi(2)
}

/// The relative IOR whose reflectance at normal incidence is `weight` times `eta`'s, on the
/// same side of 1 (OpenPBR's modulation of a dielectric by its specular weight: weight 0 is
/// an interface that neither reflects nor bends light). Weights that would make the
/// reflectance reach 1 are held just below it.
#[inline]
pub fn weighted_ior(eta: f32, weight: f32) -> f32 {
    let s = (weight.max(0.0) * normal_reflectance(eta))
        .sqrt()
        .min(0.999);
    if eta >= 1.0 {
        (1.0 + s) / (1.0 - s)
    } else {
        (1.0 - s) / (1.0 + s)
    }
}

/// Reflectance and transmittance of a thin slab whose two faces each reflect `r` (light
/// bouncing inside it any number of times, none absorbed): R = r + (1-r)² r / (1 - r²) =
/// 2r / (1 + r), T = 1 - R, as Mitsuba 3's `thindielectric` computes them.
#[inline]
pub fn thin_slab(r: f32) -> (f32, f32) {
    if r >= 1.0 {
        return (1.0, 0.0);
    }
    let reflected = 2.0 * r / (1.0 + r);
    (reflected, 1.0 - reflected)
}

/// The direction `wo` (unit, on the side `n` points to) refracts into through an interface
/// of relative index `eta` (transmitted over incident side) with normal `n`; `None` under
/// total internal reflection.
#[inline]
pub fn refract(wo: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = wo.dot(n);
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = sin2_i / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((-wo / eta + n * (cos_i / eta - cos_t)).normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_incidence_and_total_internal_reflection() {
        assert!((dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!((dielectric(1.0, 1.0 / 1.5) - 0.04).abs() < 1e-6);
        assert_eq!(dielectric(1.0, 1.0), 0.0);
        // Critical angle from glass into air: sin θc = 1/1.5.
        let critical = (1.0f32 / 1.5).asin();
        assert_eq!(dielectric((critical + 0.01).cos(), 1.0 / 1.5), 1.0);
        assert!(dielectric((critical - 0.01).cos(), 1.0 / 1.5) < 1.0);
        // Grazing incidence reflects everything.
        assert!(dielectric(1e-4, 1.5) > 0.99);
        assert!((normal_reflectance(1.5) - 0.04).abs() < 1e-6);
    }

    #[test]
    fn fresnel_is_the_same_from_both_sides_of_snells_law() {
        // A ray refracted into glass and the reverse ray see the same reflectance.
        for theta in [0.1f32, 0.5, 0.9, 1.3] {
            let wo = Vec3::new(theta.sin(), 0.0, theta.cos());
            let wt = refract(wo, Vec3::Z, 1.5).unwrap();
            let inside = dielectric(-wt.z, 1.0 / 1.5);
            let outside = dielectric(wo.z, 1.5);
            assert!(
                (inside - outside).abs() < 1e-5,
                "{theta}: {inside} {outside}"
            );
        }
    }

    #[test]
    fn refraction_obeys_snells_law_and_reverses() {
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let wt = refract(wo, Vec3::Z, 1.33).unwrap();
        assert!(wt.z < 0.0);
        // sin θo = 1.33 sin θt.
        assert!((0.6 - 1.33 * wt.x.abs()).abs() < 1e-5);
        // The reverse path: from inside the glass along wt's reverse, out along wo.
        let back = refract(wt, -Vec3::Z, 1.0 / 1.33).unwrap();
        assert!((back - wo).length() < 1e-5, "{back}");
        assert!(refract(Vec3::new(0.9, 0.0, 0.436).normalize(), Vec3::Z, 1.0 / 1.5).is_none());
    }

    #[test]
    fn thin_slab_sums_the_internal_reflections() {
        let r = 0.04;
        let (reflected, transmitted) = thin_slab(r);
        let mut series = r;
        let mut inside = (1.0 - r) * (1.0 - r);
        for _ in 0..50 {
            series += inside * r;
            inside *= r * r;
        }
        assert!((reflected - series).abs() < 1e-6);
        assert!((reflected + transmitted - 1.0).abs() < 1e-6);
        assert_eq!(thin_slab(1.0), (1.0, 0.0));
    }

    #[test]
    fn weighted_ior_scales_the_normal_reflectance() {
        for eta in [1.584f32, 1.33, 1.0 / 1.5, 2.4] {
            for w in [0.0f32, 0.383, 0.7, 1.0] {
                let e = weighted_ior(eta, w);
                let want = w * normal_reflectance(eta);
                assert!(
                    (normal_reflectance(e) - want).abs() < 1e-6,
                    "{eta} {w}: {e}"
                );
                assert!(w == 0.0 || (e > 1.0) == (eta > 1.0), "{eta} {w}: {e}");
            }
        }
        assert_eq!(weighted_ior(1.5, 0.0), 1.0);
        assert!((weighted_ior(1.5, 1.0) - 1.5).abs() < 1e-5);
    }
}
