//! Thin-film interference (KHR_materials_iridescence): the reflectance of a base under a
//! film of index `film_ior` and thickness `thickness` nanometres, in RGB, by Belcour &
//! Barla 2017's Airy summation with the spectral integration done analytically against
//! Gaussian fits of the colour matching functions, as the extension specifies it (Schlick
//! Fresnel at both interfaces, phase shifts of 0 or π, two orders of interference).

use glam::{Mat3, Vec3};
use std::f32::consts::PI;

/// XYZ to linear Rec.709 RGB (the extension's matrix).
const XYZ_TO_REC709: Mat3 = Mat3::from_cols_array(&[
    3.240_454,
    -0.969_266,
    0.055_643_4,
    -1.537_138_5,
    1.876_010_8,
    -0.204_025_9,
    -0.498_531_4,
    0.041_556,
    1.057_225_2,
]);

#[inline]
fn schlick(f0: f32, cos: f32) -> f32 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    f0 + (1.0 - f0) * m.powi(5)
}

#[inline]
fn ior_to_f0(transmitted: f32, incident: f32) -> f32 {
    ((transmitted - incident) / (transmitted + incident)).powi(2)
}

/// The interference term of order m at optical path difference `opd` (nm) and phase
/// `shift`, integrated against the colour matching functions, in RGB.
#[inline]
fn sensitivity(opd: f32, shift: Vec3) -> Vec3 {
    let phase = 2.0 * PI * opd * 1.0e-9;
    let val = Vec3::new(5.4856e-13, 4.4201e-13, 5.2481e-13);
    let pos = Vec3::new(1.6810e6, 1.7953e6, 2.2084e6);
    let var = Vec3::new(4.3278e9, 9.3046e9, 6.6121e9);
    let cos = |x: Vec3| Vec3::new(x.x.cos(), x.y.cos(), x.z.cos());
    let exp = |x: Vec3| Vec3::new(x.x.exp(), x.y.exp(), x.z.exp());
    let sqrt = |x: Vec3| Vec3::new(x.x.sqrt(), x.y.sqrt(), x.z.sqrt());
    let mut xyz = val * sqrt(2.0 * PI * var) * cos(pos * phase + shift) * exp(-phase * phase * var);
    xyz.x += 9.7470e-14
        * (2.0 * PI * 4.5282e9f32).sqrt()
        * (2.2399e6 * phase + shift.x).cos()
        * (-4.5282e9 * phase * phase).exp();
    XYZ_TO_REC709 * (xyz / 1.0685e-7)
}

/// Reflectance at `cos` (outside the film) of a base of normal reflectance `base_f0` (RGB)
/// under a film of index `film_ior` and `thickness` nm, in a medium of index `outside_ior`.
pub fn reflectance(
    outside_ior: f32,
    film_ior: f32,
    base_f0: Vec3,
    thickness: f32,
    cos: f32,
) -> Vec3 {
    // The film fades into the outside medium as it thins to nothing.
    let t = (thickness / 0.03).clamp(0.0, 1.0);
    let smooth = t * t * (3.0 - 2.0 * t);
    let film_ior = outside_ior + (film_ior - outside_ior) * smooth;
    let sin2_t = (outside_ior / film_ior).powi(2) * (1.0 - cos * cos);
    let cos2_t = 1.0 - sin2_t;
    if cos2_t <= 0.0 {
        return Vec3::ONE;
    }
    let cos_t = cos2_t.sqrt();
    // First interface: outside to film.
    let r12 = schlick(ior_to_f0(film_ior, outside_ior), cos);
    let t121 = 1.0 - r12;
    let phi12 = if film_ior < outside_ior { PI } else { 0.0 };
    let phi21 = PI - phi12;
    // Second interface: film to base (the base's index from its F0, extinction ignored).
    let base_f0 = base_f0.clamp(Vec3::ZERO, Vec3::splat(0.9999));
    let sqrt_f0 = Vec3::new(base_f0.x.sqrt(), base_f0.y.sqrt(), base_f0.z.sqrt());
    let base_ior = (Vec3::ONE + sqrt_f0) / (Vec3::ONE - sqrt_f0);
    let channel = |b: f32| {
        let r23 = schlick(ior_to_f0(b, film_ior), cos_t);
        let phi23 = if b < film_ior { PI } else { 0.0 };
        (r23, phi23)
    };
    let (r23x, p23x) = channel(base_ior.x);
    let (r23y, p23y) = channel(base_ior.y);
    let (r23z, p23z) = channel(base_ior.z);
    let r23 = Vec3::new(r23x, r23y, r23z);
    let phi = Vec3::splat(phi21) + Vec3::new(p23x, p23y, p23z);
    let opd = 2.0 * film_ior * thickness * cos_t;
    // Airy summation: the DC term, then two orders of interference.
    let r123 = (r12 * r23).clamp(Vec3::splat(1e-5), Vec3::splat(0.9999));
    let sqrt_r123 = Vec3::new(r123.x.sqrt(), r123.y.sqrt(), r123.z.sqrt());
    let rs = t121 * t121 * r23 / (Vec3::ONE - r123);
    let mut intensity = r12 + rs;
    let mut cm = rs - Vec3::splat(t121);
    for m in 1..=2 {
        cm *= sqrt_r123;
        intensity += cm * 2.0 * sensitivity(m as f32 * opd, m as f32 * phi);
    }
    intensity.max(Vec3::ZERO)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_film_is_the_base_and_films_colour_reflection() {
        // A vanishing film leaves about Schlick's reflectance of the base (the
        // extension's clamp of R12 R23 to 1e-5 lets the first order leak 0.007 in).
        let r = reflectance(1.0, 1.3, Vec3::splat(0.04), 0.0, 1.0);
        assert!((r - Vec3::splat(0.04)).abs().max_element() < 0.01, "{r}");
        // A soap-bubble film of a few hundred nanometres reflects coloured light, within
        // [0, 1], and the colour changes with the thickness.
        let a = reflectance(1.0, 1.33, Vec3::splat(0.04), 300.0, 0.9);
        let b = reflectance(1.0, 1.33, Vec3::splat(0.04), 450.0, 0.9);
        for c in [a, b] {
            assert!(c.min_element() >= 0.0 && c.max_element() <= 1.0, "{c}");
            assert!(
                c.max_element() - c.min_element() > 0.01,
                "not coloured: {c}"
            );
        }
        assert!((a - b).abs().max_element() > 0.01, "{a} {b}");
    }
}
