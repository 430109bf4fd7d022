//! What sampling a light gives (a [`LightSample`]), the measure area lights are sampled in
//! ([`LightSampling`]), and the conversion every area light shares from a point on its
//! surface to a sample seen from a shading point.

use crate::geometry::ray::{Ray, offset_ray_origin};
use glam::{Vec2, Vec3};

/// A point on a light as seen from a shading point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shading point towards the light.
    pub wi: Vec3,
    /// Where a shadow ray must end (already offset off the light's surface), or `None` for
    /// lights at infinity.
    pub target: Option<Vec3>,
    /// For area lights: the primitive and its surface coordinates at the sampled point
    /// (triangle barycentrics b1 b2, sphere lat-long uv), so the caller can evaluate
    /// textured emission.
    pub area_point: Option<(u32, Vec2)>,
    /// Radiance (area, environment) or irradiance-like quantity (delta lights) arriving;
    /// for area lights the factor that multiplies the emission at `area_point`.
    pub radiance: Vec3,
    /// Solid-angle density of the sample, excluding the light selection probability; for
    /// delta lights 1.
    pub pdf: f32,
    pub delta: bool,
}

impl LightSample {
    /// The shadow ray from `origin` towards the sample: to its (offset) point, or along
    /// `wi` without end for lights at infinity; at shutter time `time`.
    #[inline]
    pub fn shadow_ray(&self, origin: Vec3, time: f32) -> Ray {
        match self.target {
            Some(target) => Ray {
                origin,
                dir: target - origin,
                tmax: 1.0,
                time,
            },
            None => Ray::new(origin, self.wi).at_time(time),
        }
    }
}

/// The measure area lights are sampled in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightSampling {
    /// Uniformly by area.
    Area,
    /// Uniformly in the solid angle they subtend (triangles: spherical triangles; spheres:
    /// the cone of directions), where that is numerically sound, else by area.
    SolidAngle,
    /// Spheres in the cone they subtend, other shapes by area: the cone costs about what
    /// an area sample does and never samples the sphere's hidden side (on the MIS plates'
    /// spheres, half the relMSE at equal samples), while spherical triangles cost several
    /// times an area sample and gain little for lights that are small from where they are
    /// seen (the Cornell box's).
    Auto,
}

impl LightSampling {
    /// Parses `area`, `solid-angle` or `auto`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "area" => Ok(Self::Area),
            "solid-angle" => Ok(Self::SolidAngle),
            "auto" => Ok(Self::Auto),
            _ => Err(format!(
                "unknown light sampling {s:?} (area, solid-angle, auto)"
            )),
        }
    }

    /// The textual form [`LightSampling::parse`] reads.
    pub fn describe(&self) -> &'static str {
        match self {
            Self::Area => "area",
            Self::SolidAngle => "solid-angle",
            Self::Auto => "auto",
        }
    }

    /// Whether triangles are sampled as spherical triangles (where numerically sound).
    #[inline]
    pub fn triangles_by_solid_angle(self) -> bool {
        self == Self::SolidAngle
    }

    /// Whether spheres are sampled in the cone they subtend (from outside them).
    #[inline]
    pub fn spheres_by_cone(self) -> bool {
        self != Self::Area
    }
}

/// An area-light sample from a point `y` with unit normal `n` on the light, seen from `p`,
/// and the factor that converts a density by area at `y` into one by solid angle at `p`.
/// `None` when `p` is behind a one-sided emitter.
#[inline]
pub(super) fn area_sample(
    p: Vec3,
    y: Vec3,
    n: Vec3,
    two_sided: bool,
    prim: u32,
    coords: Vec2,
) -> Option<(LightSample, f32)> {
    let to_light = y - p;
    let d2 = to_light.length_squared();
    if !(d2 > 0.0) {
        return None;
    }
    let wi = to_light / d2.sqrt();
    let cos_light = -n.dot(wi);
    if cos_light <= 0.0 && !two_sided || cos_light == 0.0 {
        return None;
    }
    let facing = if cos_light > 0.0 { n } else { -n };
    let sample = LightSample {
        wi,
        target: Some(offset_ray_origin(y, facing)),
        area_point: Some((prim, coords)),
        radiance: Vec3::ONE,
        pdf: 0.0,
        delta: false,
    };
    // The conversion from area to solid angle density.
    Some((sample, d2 / cos_light.abs()))
}
