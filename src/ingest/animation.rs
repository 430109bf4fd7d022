//! Keyframe tracks sampled at a time, as glTF 2.0 defines them (section 3.11 and Appendix
//! C): STEP holds a key's value, LINEAR interpolates (spherically for rotations), CUBICSPLINE
//! is the cubic Hermite spline of (in-tangent, value, out-tangent) triples with tangents
//! scaled by the key interval. Before the first key the track holds its first value, after
//! the last its last.

use glam::{DQuat, DVec4};

/// How a track interpolates between keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    Step,
    Linear,
    CubicSpline,
}

/// A track of `N`-component keys (3: translation or scale, 4: a rotation quaternion x, y,
/// z, w). `times` are strictly increasing seconds; `values` has one entry a key, or three
/// (in-tangent, value, out-tangent) for cubic splines.
pub struct Track<'a, const N: usize> {
    pub times: &'a [f32],
    pub values: &'a [[f32; N]],
    pub interpolation: Interpolation,
}

impl<const N: usize> Track<'_, N> {
    /// Checks the track's shape: key times finite and strictly increasing, values finite,
    /// and as many values as the interpolation needs.
    pub fn check(&self) -> Result<(), String> {
        if self.times.is_empty() {
            return Err("the track has no keys".into());
        }
        if let Some(i) = self.times.iter().position(|t| !t.is_finite()) {
            return Err(format!("key time {i} is not finite"));
        }
        if let Some(i) = self.times.windows(2).position(|w| w[1] <= w[0]) {
            return Err(format!(
                "key times must increase: key {} at {} follows {}",
                i + 1,
                self.times[i + 1],
                self.times[i]
            ));
        }
        let per_key = if self.interpolation == Interpolation::CubicSpline {
            3
        } else {
            1
        };
        if self.values.len() != per_key * self.times.len() {
            return Err(format!(
                "{} output values for {} keys; {:?} needs {}",
                self.values.len(),
                self.times.len(),
                self.interpolation,
                per_key * self.times.len()
            ));
        }
        if self.values.iter().flatten().any(|v| !v.is_finite()) {
            return Err("an output value is not finite".into());
        }
        Ok(())
    }

    /// The key value of key `i`.
    fn value(&self, i: usize) -> DVec4 {
        let at = if self.interpolation == Interpolation::CubicSpline {
            3 * i + 1
        } else {
            i
        };
        widen(&self.values[at])
    }

    /// The track's value at `time` seconds; rotations (`N` = 4) come out normalised. The
    /// track must have passed [`Track::check`].
    pub fn sample(&self, time: f64) -> DVec4 {
        let rotation = N == 4;
        let times = self.times;
        let last = times.len() - 1;
        let value = if time <= times[0] as f64 {
            self.value(0)
        } else if time >= times[last] as f64 {
            self.value(last)
        } else {
            // times[i] <= time < times[i + 1]
            let i = times.partition_point(|&t| t as f64 <= time) - 1;
            let (t0, t1) = (times[i] as f64, times[i + 1] as f64);
            let dt = t1 - t0;
            let s = (time - t0) / dt;
            match self.interpolation {
                Interpolation::Step => self.value(i),
                Interpolation::Linear if rotation => {
                    let q0 = DQuat::from_vec4(self.value(i)).normalize();
                    let q1 = DQuat::from_vec4(self.value(i + 1)).normalize();
                    DVec4::from(q0.slerp(q1, s))
                }
                Interpolation::Linear => self.value(i).lerp(self.value(i + 1), s),
                Interpolation::CubicSpline => {
                    let p0 = self.value(i);
                    let m0 = widen(&self.values[3 * i + 2]) * dt;
                    let p1 = self.value(i + 1);
                    let m1 = widen(&self.values[3 * (i + 1)]) * dt;
                    let (s2, s3) = (s * s, s * s * s);
                    p0 * (2.0 * s3 - 3.0 * s2 + 1.0)
                        + m0 * (s3 - 2.0 * s2 + s)
                        + p1 * (-2.0 * s3 + 3.0 * s2)
                        + m1 * (s3 - s2)
                }
            }
        };
        if rotation {
            value.normalize_or(DVec4::W)
        } else {
            value
        }
    }
}

/// An `N`-component key as a 4-vector (unused components zero).
fn widen<const N: usize>(v: &[f32; N]) -> DVec4 {
    let mut out = [0.0f64; 4];
    for (o, x) in out.iter_mut().zip(v) {
        *o = *x as f64;
    }
    DVec4::from_array(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TIMES: [f32; 3] = [0.0, 1.0, 3.0];
    const VALUES: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [2.0, 4.0, -2.0], [6.0, 4.0, 0.0]];

    fn track(interpolation: Interpolation) -> Track<'static, 3> {
        Track {
            times: &TIMES,
            values: &VALUES,
            interpolation,
        }
    }

    #[test]
    fn step_and_linear_follow_the_keys_and_clamp_outside_them() {
        let step = track(Interpolation::Step);
        let linear = track(Interpolation::Linear);
        assert_eq!(step.sample(0.99).truncate().to_array(), [0.0, 0.0, 0.0]);
        assert_eq!(step.sample(1.0).truncate().to_array(), [2.0, 4.0, -2.0]);
        assert_eq!(linear.sample(0.5).truncate().to_array(), [1.0, 2.0, -1.0]);
        assert_eq!(linear.sample(2.0).truncate().to_array(), [4.0, 4.0, -1.0]);
        assert_eq!(linear.sample(-5.0).truncate().to_array(), [0.0, 0.0, 0.0]);
        assert_eq!(linear.sample(9.0).truncate().to_array(), [6.0, 4.0, 0.0]);
    }

    /// A cubic Hermite spline reproduces a cubic exactly when its tangents are the cubic's
    /// derivatives: f(t) = t³ − t with keys at 0, 1, 3.
    #[test]
    fn cubic_spline_reproduces_a_cubic() {
        let f = |t: f32| t * t * t - t;
        let df = |t: f32| 3.0 * t * t - 1.0;
        let values: Vec<[f32; 3]> = TIMES
            .iter()
            .flat_map(|&t| [[df(t), 0.0, 0.0], [f(t), 1.0, 0.0], [df(t), 0.0, 0.0]])
            .collect();
        let track = Track {
            times: &TIMES,
            values: &values,
            interpolation: Interpolation::CubicSpline,
        };
        track.check().unwrap();
        for t in [0.25f32, 0.5, 1.0, 1.7, 2.9] {
            let v = track.sample(t as f64);
            assert!((v.x - f(t) as f64).abs() < 1e-5, "{t}: {} vs {}", v.x, f(t));
            assert!((v.y - 1.0).abs() < 1e-12);
        }
    }

    /// Rotations interpolate along the great arc at constant angular speed, the short way.
    #[test]
    fn rotations_are_spherically_interpolated() {
        let half = std::f32::consts::FRAC_PI_4;
        // 0° and 90° about Z, the second given as its negation (same rotation).
        let values = [[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, -half.sin(), -half.cos()]];
        let track = Track {
            times: &[0.0, 1.0],
            values: &values,
            interpolation: Interpolation::Linear,
        };
        track.check().unwrap();
        let q = DQuat::from_vec4(track.sample(1.0 / 3.0));
        let (axis, angle) = q.to_axis_angle();
        assert!(
            (angle - std::f64::consts::FRAC_PI_6).abs() < 1e-6,
            "{angle}"
        );
        assert!((axis.z.abs() - 1.0).abs() < 1e-6);
        assert!((q.length() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn malformed_tracks_are_refused() {
        let values = [[0.0f32; 3]; 2];
        let bad = |times: &[f32], interpolation| {
            Track {
                times,
                values: &values,
                interpolation,
            }
            .check()
            .unwrap_err()
        };
        assert!(bad(&[1.0, 0.5], Interpolation::Linear).contains("increase"));
        assert!(bad(&[0.0, f32::NAN], Interpolation::Linear).contains("finite"));
        assert!(bad(&[0.0, 1.0], Interpolation::CubicSpline).contains("needs 6"));
        assert!(bad(&[], Interpolation::Step).contains("no keys"));
    }
}
