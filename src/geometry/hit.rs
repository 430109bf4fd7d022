//! What a ray query answers: a primitive's intersection with a ray, the closest accepted
//! hit (with the placement it was found through), and the intersection flags a primitive
//! carries (back-face culling, alpha testing).

/// A primitive's intersection with a ray, before the caller's filter.
#[derive(Clone, Copy, Debug)]
pub struct PrimitiveHit {
    pub t: f32,
    /// Barycentric weights of triangle vertices 1 and 2 (vertex 0 has `1 - b1 - b2`); 0 for
    /// the analytic shapes.
    pub b1: f32,
    pub b2: f32,
    /// True when the ray arrives on the primitive's front (a triangle's counter-clockwise
    /// side, a sphere's outside).
    pub front: bool,
}

/// Intersection flag: the primitive is invisible from its back (glTF `doubleSided: false`).
pub const CULL_BACK: u8 = 1;
/// Intersection flag: the primitive's material has an alpha cut-out; the caller's filter
/// decides whether a hit counts.
pub const ALPHA_TESTED: u8 = 2;

/// A ray's closest accepted hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f32,
    /// Index of the primitive in the order given to [`Bvh::build`] (of the shared BVH for
    /// a placed hit).
    pub prim: u32,
    pub b1: f32,
    pub b2: f32,
    pub front: bool,
    /// The placement hit in an [`instances::InstancedBvh`], or [`NOT_PLACED`].
    pub instance: u32,
}

/// [`Hit::instance`] of a hit on geometry that is not placed through a shared BVH.
pub const NOT_PLACED: u32 = u32::MAX;
