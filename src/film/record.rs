//! What the film accepts: the contributions a path produces, with the tags that route them
//! to AOVs (depth, technique, first-hit lobes, light), the data of the camera ray's first
//! hit, and the [`Recorder`] interface through which an integrator hands both over. The film
//! defines these, as pbrt's and Mitsuba's films define what they accept, so that every
//! kernel writes to it the same way and a new AOV is a change of the film alone.

use crate::material::PerLobe;
use glam::Vec3;

/// Where a contribution came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// An emitter (or the environment) seen directly by the camera.
    Emission,
    /// Light sampling at a path vertex.
    Nee,
    /// A BSDF-sampled direction that hit an emitter (or escaped to the environment).
    Bsdf,
}

/// Radiance a path adds to its pixel, with its tags.
#[derive(Clone, Copy, Debug)]
pub struct Contribution {
    /// The MIS-weighted contribution (what the beauty receives).
    pub value: Vec3,
    /// Number of scattering events before the light arrived (0 for emission seen
    /// directly, 1 for direct illumination).
    pub depth: u32,
    pub source: Source,
    /// The same contribution weighted for light sampling alone and BSDF sampling alone
    /// (each the unbiased single-technique estimator), when the recorder asks for them.
    pub single_technique: Option<[Vec3; 2]>,
    /// Shares of `value` owed to each lobe of the first scattering event, when the
    /// recorder asks for them (depth >= 1).
    pub lobes: Option<PerLobe>,
    /// The light it came from (light sampling and BSDF-sampled emitter hits).
    pub light: Option<u32>,
}

/// What the camera ray saw first: the data AOVs.
#[derive(Clone, Copy, Debug)]
pub struct FirstHit {
    pub albedo: Vec3,
    /// World-space shading normal, facing the camera.
    pub normal: Vec3,
    /// Distance along the camera's viewing axis, world units.
    pub depth: f32,
    /// World-space position.
    pub position: Vec3,
    /// How the point moves on screen (pixels a frame, u right and v up) and in the world
    /// (units a frame) while the shutter is open; zero where nothing moves.
    pub motion: glam::Vec2,
    pub velocity: Vec3,
    /// Directional albedo of each lobe kind.
    pub lobe_albedo: PerLobe,
    /// The object and the material hit (indices: `World::objects`, the materials).
    pub object: u32,
    pub material: u32,
}

/// Receives what a path produces.
pub trait Recorder {
    /// Whether to compute [`Contribution::single_technique`] for direct light.
    fn wants_single_technique(&self) -> bool;
    /// Whether to compute [`Contribution::lobes`].
    fn wants_lobes(&self) -> bool;
    fn contribution(&mut self, c: Contribution);
    /// The camera ray hit a surface (coverage); with its data when the kernel computes it.
    fn first_hit(&mut self, hit: Option<FirstHit>);
}
