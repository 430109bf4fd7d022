//! Transforms that move over the shutter: keys at evenly spaced times of the shutter,
//! interpolated at a ray's time as pbrt-v4's `AnimatedTransform` does. Each key is split by
//! polar decomposition into a translation, a rotation and a stretch (`M = T R S`, `S`
//! symmetric, so shear and non-uniform scale survive); between keys the translation and the
//! stretch are interpolated linearly and the rotation by slerp, so a spinning object turns
//! rather than shrinking through the chord as interpolated matrices would.
//!
//! Times are fractions of the shutter: 0 at its opening, 1 at its closing.

use glam::{Affine3A, DMat3, DMat4, DQuat, DVec3, Mat3A, Quat, Vec3, Vec3A};

/// One key, decomposed.
#[derive(Clone, Copy, Debug)]
struct Key {
    translation: DVec3,
    rotation: DQuat,
    /// The symmetric stretch, applied before the rotation.
    stretch: DMat3,
}

/// The most keys a motion may have (a key a frame's sixteenth over a shutter of a frame,
/// and then some).
pub const MAX_KEYS: usize = 64;

/// How finely [`MotionTransform::bounds`] follows the motion between two keys: the box is
/// the union of the object's boxes at this many steps a key interval, each grown by how far
/// a point may stray from the chord within its step.
const BOUND_STEPS: usize = 8;

/// A key interval in single precision, with what its slerp needs precomputed (the angle
/// and the reciprocal of its sine), for [`MotionTransform::affine_at`], which traversal
/// calls each time a ray enters a moving placement.
#[derive(Clone, Copy, Debug)]
struct Segment {
    translation: [Vec3A; 2],
    rotation: [Quat; 2],
    stretch: [Mat3A; 2],
    angle: f32,
    inv_sin: f32,
}

/// Below this angle (radians) between a segment's rotations, slerp is computed as a
/// normalised lerp (their difference is far below single precision's).
const NLERP_ANGLE: f32 = 1e-3;

/// A transform that moves over the shutter.
#[derive(Clone, Debug)]
pub struct MotionTransform {
    keys: Vec<Key>,
    segments: Vec<Segment>,
}

impl MotionTransform {
    /// The transform through `keys` (at least two, at evenly spaced times from the
    /// shutter's opening to its closing). `None` if a key is singular or not finite.
    pub fn new(keys: &[DMat4]) -> Option<Self> {
        if keys.len() < 2 {
            return None;
        }
        let mut decomposed: Vec<Key> = keys.iter().map(decompose).collect::<Option<_>>()?;
        // Each rotation on the near side of its predecessor, so slerp takes the short way.
        for i in 1..decomposed.len() {
            if decomposed[i].rotation.dot(decomposed[i - 1].rotation) < 0.0 {
                decomposed[i].rotation = -decomposed[i].rotation;
            }
        }
        let segments = decomposed
            .windows(2)
            .map(|w| {
                let (a, b) = (&w[0], &w[1]);
                // The angle between the quaternions (half the turn), which slerp weighs by.
                let angle = a.rotation.dot(b.rotation).clamp(-1.0, 1.0).acos() as f32;
                Segment {
                    translation: [
                        a.translation.as_vec3().into(),
                        b.translation.as_vec3().into(),
                    ],
                    rotation: [a.rotation.as_quat(), b.rotation.as_quat()],
                    stretch: [
                        Mat3A::from(a.stretch.as_mat3()),
                        Mat3A::from(b.stretch.as_mat3()),
                    ],
                    angle,
                    inv_sin: if angle > NLERP_ANGLE {
                        angle.sin().recip()
                    } else {
                        0.0
                    },
                }
            })
            .collect();
        Some(Self {
            keys: decomposed,
            segments,
        })
    }

    /// The transform at shutter time `time` (clamped to [0, 1]).
    pub fn at(&self, time: f32) -> DMat4 {
        let (i, u) = self.segment(time as f64);
        let (a, b) = (&self.keys[i], &self.keys[i + 1]);
        compose(&Key {
            translation: a.translation.lerp(b.translation, u),
            rotation: a.rotation.slerp(b.rotation, u),
            stretch: a.stretch * (1.0 - u) + b.stretch * u,
        })
    }

    /// [`MotionTransform::at`] in single precision, from the segments' precomputed slerp
    /// (no inverse cosine, two sines).
    #[inline]
    pub fn affine_at(&self, time: f32) -> Affine3A {
        let (i, u) = self.segment(time as f64);
        let s = &self.segments[i];
        let u = u as f32;
        let rotation = if s.inv_sin > 0.0 {
            let (wa, wb) = (
                ((1.0 - u) * s.angle).sin() * s.inv_sin,
                (u * s.angle).sin() * s.inv_sin,
            );
            s.rotation[0] * wa + s.rotation[1] * wb
        } else {
            s.rotation[0].lerp(s.rotation[1], u)
        }
        .normalize();
        let stretch = s.stretch[0] * (1.0 - u) + s.stretch[1] * u;
        Affine3A {
            matrix3: Mat3A::from_quat(rotation) * stretch,
            translation: s.translation[0].lerp(s.translation[1], u),
        }
    }

    /// Key interval of `time` and the fraction of it.
    fn segment(&self, time: f64) -> (usize, f64) {
        let intervals = self.keys.len() - 1;
        let x = time.clamp(0.0, 1.0) * intervals as f64;
        let i = (x.floor() as usize).min(intervals - 1);
        (i, x - i as f64)
    }

    /// A box holding the object-space box `(lo, hi)` at every time of the shutter.
    ///
    /// Within a step `[a, b]` a point `p` of the box moves along `T(t) + R(t) S(t) p`; its
    /// path is no longer than `|ΔT| + θ·max|S p| + max|ΔS p|` (θ the angle the rotation
    /// turns through; the maxima over the box are at its corners), and every point of the path
    /// lies within half its length of one of the ends, which the boxes at `a` and `b` hold.
    pub fn bounds(&self, lo: Vec3, hi: Vec3) -> (Vec3, Vec3) {
        let corners: Vec<DVec3> = (0..8)
            .map(|c| {
                DVec3::new(
                    if c & 1 == 0 { lo.x } else { hi.x } as f64,
                    if c & 2 == 0 { lo.y } else { hi.y } as f64,
                    if c & 4 == 0 { lo.z } else { hi.z } as f64,
                )
            })
            .collect();
        let steps = (self.keys.len() - 1) * BOUND_STEPS;
        let key_at = |s: usize| {
            let (i, u) = self.segment(s as f64 / steps as f64);
            let (a, b) = (&self.keys[i], &self.keys[i + 1]);
            Key {
                translation: a.translation.lerp(b.translation, u),
                rotation: a.rotation.slerp(b.rotation, u),
                stretch: a.stretch * (1.0 - u) + b.stretch * u,
            }
        };
        let box_of = |k: &Key| {
            let m = compose(k);
            corners
                .iter()
                .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), &c| {
                    let q = m.transform_point3(c);
                    (lo.min(q), hi.max(q))
                })
        };
        let mut out = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        let mut previous = key_at(0);
        let mut previous_box = box_of(&previous);
        for s in 1..=steps {
            let key = key_at(s);
            let key_box = box_of(&key);
            let angle = previous.rotation.angle_between(key.rotation);
            let reach = corners
                .iter()
                .map(|&c| {
                    (previous.stretch * c)
                        .length()
                        .max((key.stretch * c).length())
                })
                .fold(0.0, f64::max);
            let stretch_change = corners
                .iter()
                .map(|&c| ((key.stretch - previous.stretch) * c).length())
                .fold(0.0, f64::max);
            let path =
                (key.translation - previous.translation).length() + angle * reach + stretch_change;
            let grow = DVec3::splat(0.5 * path);
            out.0 = out.0.min(previous_box.0.min(key_box.0) - grow);
            out.1 = out.1.max(previous_box.1.max(key_box.1) + grow);
            (previous, previous_box) = (key, key_box);
        }
        // Widened by a few ulps, as the single-precision traversal tests against it.
        let pad = (out.1 - out.0).max_element() * 1e-6;
        ((out.0 - pad).as_vec3(), (out.1 + pad).as_vec3())
    }
}

/// `M = T R S` by polar decomposition of the linear part (Shoemake and Duff 1992, as pbrt
/// does it): `R` is the limit of averaging a matrix with its inverse transpose. A mirroring
/// matrix gets the proper rotation and a stretch with the mirror in it.
fn decompose(m: &DMat4) -> Option<Key> {
    if !m.is_finite() {
        return None;
    }
    let linear = DMat3::from_mat4(*m);
    if linear.determinant().abs() < 1e-300 {
        return None;
    }
    let mut r = linear;
    for _ in 0..100 {
        let next = (r + r.inverse().transpose()) * 0.5;
        let change = (0..3)
            .map(|c| (next.col(c) - r.col(c)).abs().max_element())
            .fold(0.0, f64::max);
        r = next;
        if change < 1e-14 {
            break;
        }
    }
    if r.determinant() < 0.0 {
        r = -r;
    }
    let stretch = r.transpose() * linear;
    let rotation = DQuat::from_mat3(&r).normalize();
    rotation.is_finite().then_some(Key {
        translation: m.w_axis.truncate(),
        rotation,
        stretch,
    })
}

fn compose(k: &Key) -> DMat4 {
    let linear = DMat3::from_quat(k.rotation) * k.stretch;
    DMat4::from_cols(
        linear.x_axis.extend(0.0),
        linear.y_axis.extend(0.0),
        linear.z_axis.extend(0.0),
        k.translation.extend(1.0),
    )
}

/// Checks a scene's keys of a motion: none, or 2 to [`MAX_KEYS`] that decompose.
pub fn check_keys(keys: &[DMat4]) -> Result<(), String> {
    if keys.is_empty() {
        return Ok(());
    }
    if keys.len() == 1 || keys.len() > MAX_KEYS {
        return Err(format!(
            "{} keys; a motion has 2 to {MAX_KEYS} (or none)",
            keys.len()
        ));
    }
    match MotionTransform::new(keys) {
        Some(_) => Ok(()),
        None => Err("a key is not finite or is singular".into()),
    }
}

/// True if the keys differ (beyond rounding): the transform moves.
pub fn keys_move(keys: &[DMat4]) -> bool {
    keys.windows(2).any(|w| {
        let scale = w[0]
            .to_cols_array()
            .iter()
            .fold(1.0f64, |m, v| m.max(v.abs()));
        !w[0].abs_diff_eq(w[1], 1e-9 * scale)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::pcg::Pcg32;

    fn close(a: DMat4, b: DMat4, tolerance: f64) -> bool {
        a.abs_diff_eq(b, tolerance)
    }

    /// `n` keys of random scale (0.5 to 1.5 per axis), rotation (Euler angles up to `turn`)
    /// and translation (within `reach` of the origin per axis).
    fn random_keys(rng: &mut Pcg32, n: usize, turn: f64, reach: f64) -> Vec<DMat4> {
        let mut u = || rng.next_f32() as f64;
        (0..n)
            .map(|_| {
                DMat4::from_scale_rotation_translation(
                    DVec3::new(0.5 + u(), 0.5 + u(), 0.5 + u()),
                    DQuat::from_euler(glam::EulerRot::XYZ, turn * u(), turn * u(), turn * u()),
                    (DVec3::new(u(), u(), u()) * 2.0 - 1.0) * reach,
                )
            })
            .collect()
    }

    /// The keys come back at their times, sheared and mirrored ones too.
    #[test]
    fn keys_are_reproduced() {
        let keys = [
            DMat4::from_scale_rotation_translation(
                DVec3::new(1.0, 2.0, 0.5),
                DQuat::from_rotation_y(0.3),
                DVec3::new(1.0, 0.0, 0.0),
            ),
            // Shear and a mirror.
            DMat4::from_cols_array(&[
                1.0, 0.5, 0.0, 0.0, 0.0, -1.0, 0.2, 0.0, 0.1, 0.0, 2.0, 0.0, 3.0, 1.0, -2.0, 1.0,
            ]),
            DMat4::from_rotation_z(2.5) * DMat4::from_scale(DVec3::splat(0.1)),
        ];
        let motion = MotionTransform::new(&keys).unwrap();
        for (i, &key) in keys.iter().enumerate() {
            let m = motion.at(i as f32 / 2.0);
            assert!(close(m, key, 1e-9), "key {i}: {m} vs {key}");
        }
    }

    /// Halfway between a rotation by 0 and by 160 degrees about z is the rotation by 80
    /// degrees (slerp), not the chord's matrix average.
    #[test]
    fn rotation_is_slerped() {
        let angle = 160f64.to_radians();
        let keys = [DMat4::IDENTITY, DMat4::from_rotation_z(angle)];
        let motion = MotionTransform::new(&keys).unwrap();
        let half = motion.at(0.5);
        assert!(
            close(half, DMat4::from_rotation_z(angle / 2.0), 1e-6),
            "{half}"
        );
    }

    /// Every point of a box at any time of the motion lies inside the motion's bounds.
    #[test]
    fn bounds_hold_the_swept_box() {
        let mut rng = Pcg32::new(7, 1);
        for case in 0..20 {
            let keys = random_keys(&mut rng, 2 + case % 3, 3.0, 1.0);
            let motion = MotionTransform::new(&keys).unwrap();
            let (lo, hi) = (Vec3::new(-1.0, -0.5, 0.0), Vec3::new(1.0, 0.5, 2.0));
            let (blo, bhi) = motion.bounds(lo, hi);
            for _ in 0..2000 {
                let t = rng.next_f32();
                let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                let p = lo + (hi - lo) * p;
                let q = motion.affine_at(t).transform_point3(p);
                assert!(
                    q.cmpge(blo - 1e-5).all() && q.cmple(bhi + 1e-5).all(),
                    "case {case}: {q} at {t} outside {blo}..{bhi}"
                );
            }
        }
    }

    /// The single-precision transform traversal uses is the double-precision one, to
    /// single precision, in turns both large and tiny (the normalised-lerp branch).
    #[test]
    fn single_precision_follows_double() {
        let mut rng = Pcg32::new(5, 2);
        for case in 0..40 {
            let turn = if case % 2 == 0 { 3.0 } else { 1e-5 };
            let keys = random_keys(&mut rng, 3, turn, 2.0);
            let motion = MotionTransform::new(&keys).unwrap();
            for k in 0..=16 {
                let t = k as f32 / 16.0;
                let (single, double) = (motion.affine_at(t), motion.at(t).as_mat4());
                assert!(
                    glam::Mat4::from(single).abs_diff_eq(double, 2e-5),
                    "case {case} at {t}: {single} vs {double}"
                );
            }
        }
    }

    #[test]
    fn still_keys_do_not_move() {
        let m = DMat4::from_translation(DVec3::new(1e4, 0.0, 0.0));
        assert!(!keys_move(&[m, m, m]));
        assert!(keys_move(&[
            m,
            DMat4::from_translation(DVec3::new(1e4, 1.0, 0.0))
        ]));
    }
}
