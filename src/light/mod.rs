//! Lights in render space and their sampling. Each kind is one file holding its sampling,
//! density, power and light-tree bounds: emissive triangles (`triangle`) and spheres
//! (`sphere`), sampled by area or by solid angle; disks and cylinders (`quadric`), by area;
//! point and spot lights (`point`, `spot`); directional lights and distant lights with an
//! angular size (`distant`); and the environment (`environment`). [`Light`] is the closed
//! set of kinds and dispatches to them, as the BSDFs' enum does; which light to sample is
//! `selection`'s job, with `tree` for selection by contribution and `learned` for selection
//! by what light samples found.
//!
//! A new kind of light is a new file here, an arm of [`Light`] and of its dispatch, and its
//! construction in `world::build`.

pub mod distant;
pub mod emission_texture;
pub mod environment;
pub mod groups;
#[cfg(target_arch = "x86_64")]
pub(crate) mod lanes;
pub mod learned;
pub mod point;
pub mod quadric;
pub mod sample;
pub mod selection;
pub mod solid_angle;
pub mod sphere;
pub mod spot;
pub mod tree;
pub mod triangle;

pub use distant::{DirectionalLight, DistantCone};
use environment::Environment;
use glam::{Vec2, Vec3};
pub use point::PointLight;
pub use quadric::QuadricLight;
pub use sample::{LightSample, LightSampling};
pub use selection::{LightSelect, LightSet};
pub use sphere::SphereLight;
pub use spot::SpotLight;
use tree::LightBounds;
pub use triangle::TriangleLight;

/// One light.
#[derive(Clone, Debug)]
pub enum Light {
    Triangle(TriangleLight),
    Sphere(SphereLight),
    Quadric(QuadricLight),
    Point(PointLight),
    Spot(SpotLight),
    Directional(DirectionalLight),
    DistantCone(DistantCone),
    /// The environment of the [`LightSet`] (there is at most one).
    Environment,
}

impl Light {
    /// Emitted power (luminance-weighted), the weight for selection by power. `radius` is
    /// the scene's bounding radius, which scales infinite lights as in pbrt.
    pub fn power(&self, environment: Option<&Environment>, radius: f32) -> f32 {
        match self {
            Self::Triangle(t) => t.power(),
            Self::Sphere(s) => s.power(),
            Self::Quadric(q) => q.power(),
            Self::Point(l) => l.power(),
            Self::Spot(l) => l.power(),
            Self::Directional(l) => l.power(radius),
            Self::DistantCone(l) => l.power(radius),
            Self::Environment => environment.map_or(0.0, |e| e.power(radius)),
        }
    }

    /// True for lights only light sampling can reach.
    pub fn is_delta(&self) -> bool {
        matches!(self, Self::Point(_) | Self::Spot(_) | Self::Directional(_))
    }

    /// Samples the light from shading point `p`. Textured area emission is left to the
    /// caller (see [`LightSample::area_point`]).
    pub fn sample(
        &self,
        p: Vec3,
        environment: Option<&Environment>,
        sampling: LightSampling,
        u: Vec2,
    ) -> Option<LightSample> {
        match self {
            Self::Triangle(t) => t.sample(p, sampling, u),
            Self::Sphere(s) => s.sample(p, sampling, u),
            Self::Quadric(q) => q.sample(p, u),
            Self::Point(l) => l.sample(p),
            Self::Spot(l) => l.sample(p),
            Self::Directional(l) => Some(l.sample()),
            Self::DistantCone(l) => Some(l.sample(u)),
            Self::Environment => environment?.light_sample(u),
        }
    }

    /// Solid-angle density with which [`Light::sample`] from `p` produces the point of this
    /// area light found at distance `dist` along unit direction `wi` (excluding selection);
    /// for a distant cone, the density of direction `wi`.
    /// The same rules as sampling decide the measure.
    #[inline]
    pub fn pdf(&self, p: Vec3, wi: Vec3, dist: f32, sampling: LightSampling) -> f32 {
        match self {
            Self::Triangle(t) => t.pdf(p, wi, dist, sampling),
            Self::Sphere(s) => s.pdf(p, wi, dist, sampling),
            Self::Quadric(q) => q.pdf(p, wi, dist),
            Self::DistantCone(l) => l.pdf(wi),
            Self::Point(_) | Self::Spot(_) | Self::Directional(_) | Self::Environment => 0.0,
        }
    }

    /// Radiance a ray escaping the scene along unit direction `dir` receives from this
    /// light, for lights at infinity other than the environment.
    #[inline]
    pub fn radiance_at_infinity(&self, dir: Vec3) -> Vec3 {
        match self {
            Self::DistantCone(l) => l.radiance_at_infinity(dir),
            _ => Vec3::ZERO,
        }
    }

    /// What the light tree knows of the light, of power `phi`; `None` for lights at
    /// infinity, which no bound contains.
    pub fn bounds(&self, phi: f32) -> Option<LightBounds> {
        match self {
            Self::Triangle(t) => Some(t.bounds(phi)),
            Self::Sphere(s) => Some(s.bounds(phi)),
            Self::Quadric(q) => Some(q.bounds(phi)),
            Self::Point(l) => Some(l.bounds(phi)),
            Self::Spot(l) => Some(l.bounds(phi)),
            Self::Directional(_) | Self::DistantCone(_) | Self::Environment => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn area_light_pdfs_agree_with_sampling() {
        let tri = Light::Triangle(TriangleLight {
            prim: 0,
            p: [
                Vec3::new(-1.0, 2.0, -1.0),
                Vec3::new(1.0, 2.0, -1.0),
                Vec3::new(0.0, 2.0, 1.0),
            ],
            n: -Vec3::Y,
            area: 2.0,
            two_sided: false,
            mean_radiance: Vec3::ONE,
            emission: None,
        });
        let sphere = Light::Sphere(SphereLight {
            prim: 1,
            centre: Vec3::new(0.5, 3.0, 0.2),
            radius: 0.7,
            two_sided: false,
            textured: false,
            mean_radiance: Vec3::ONE,
        });
        for light in [tri.clone(), sphere] {
            for sampling in [
                LightSampling::Area,
                LightSampling::SolidAngle,
                LightSampling::Auto,
            ] {
                for u in [Vec2::new(0.3, 0.6), Vec2::new(0.9, 0.1)] {
                    let Some(s) = light.sample(Vec3::ZERO, None, sampling, u) else {
                        continue;
                    };
                    let dist = s.target.unwrap().length();
                    let pdf = light.pdf(Vec3::ZERO, s.wi, dist, sampling);
                    assert!(
                        (pdf - s.pdf).abs() < 2e-3 * s.pdf,
                        "{sampling:?}: {pdf} vs {}",
                        s.pdf
                    );
                }
            }
        }
        // Seen from above, a one-sided light facing down gives nothing.
        assert!(
            tri.sample(
                Vec3::new(0.0, 3.0, 0.0),
                None,
                LightSampling::Area,
                Vec2::new(0.3, 0.6)
            )
            .is_none()
        );
    }
}
