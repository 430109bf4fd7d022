//! Geometry in render space: render space itself (`space`), the primitives (`triangle`,
//! `sphere`, `quadric`) and what a BVH holds of them (`primitive`), the BVH (`bvh`, over
//! eight-wide nodes of `wide`), placements of shared meshes through a top-level BVH
//! (`instances`) and their motion over the shutter (`motion`), meshes that change shape
//! over it (`deformation`), rays and hits, ray cones (`cone`), shading frames, and
//! subdivision surfaces refined into triangles.

pub mod bvh;
pub mod cone;
pub mod deformation;
pub mod frame;
pub mod hit;
pub mod instances;
pub mod motion;
pub mod primitive;
pub mod quadric;
pub mod ray;
pub mod space;
pub mod sphere;
pub mod subdivision;
pub mod triangle;
pub mod wide;

pub use bvh::Bvh;
pub use hit::{ALPHA_TESTED, CULL_BACK, Hit, NOT_PLACED, PrimitiveHit};
pub use primitive::Primitive;
