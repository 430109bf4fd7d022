//! Meshes placed several times are traced once in object space through a two-level BVH:
//! the image equals the one of the same scene with every placement flattened, and memory
//! grows with the shared mesh, not with the number of placements.

use crate::common;

use common::scenes::{icosphere, material, ortho_camera, quad, rel_mse, render, scene};
use glam::{DMat4, DQuat, DVec3, Vec3};
use lucerna::integrator::{LightSelect, Settings};
use lucerna::scene::{BsdfModel, Instance, Scene};
use lucerna::world::{PlacedMesh, World};

/// A smooth sphere (vertex normals) placed nine times, rotated, scaled unevenly and in
/// three cases mirrored, above a floor placed once.
fn spheres(placements: usize) -> Scene {
    let mut ball = icosphere(2);
    ball.normals = Some(ball.positions.clone());
    let floor = quad();
    let mut s = scene(
        vec![(
            floor,
            DMat4::from_scale_rotation_translation(
                DVec3::splat(3.0),
                DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2),
                DVec3::new(0.0, -1.0, 0.0),
            ),
        )],
        material(BsdfModel::GltfPbr, Vec3::new(0.7, 0.5, 0.3), 0.5, 0.3),
        Vec3::ONE,
        ortho_camera(DVec3::new(1.0, 4.0, 6.0), 2.2),
    );
    s.meshes.push(ball);
    for i in 0..placements {
        let (x, z) = ((i % 3) as f64 - 1.0, (i / 3 % 3) as f64 - 1.0);
        let mirror = if i % 3 == 1 { -1.0 } else { 1.0 };
        s.instances.push(Instance {
            name: format!("ball{i}"),
            mesh: 1,
            motion: Vec::new(),
            transform: DMat4::from_scale_rotation_translation(
                DVec3::new(0.35 * mirror, 0.25 + 0.05 * x, 0.3),
                DQuat::from_euler(glam::EulerRot::XYZ, 0.4 * x, 0.7 * z, 0.2),
                DVec3::new(1.1 * x, -0.6, 1.1 * z),
            ),
        });
    }
    s
}

#[test]
fn placements_render_like_flattened_copies() {
    let res = (64, 64);
    let with_seed = |seed| Settings {
        seed,
        ..Settings::default()
    };
    let world = World::build(spheres(9), None, Some(res), LightSelect::Power).unwrap();
    assert_eq!(world.surfaces.placements.len(), 9);
    assert_eq!(world.surfaces.shared_meshes.len(), 1);
    let placed = render(spheres(9), res, 16, with_seed(1), 2).0;
    let flat = render(spheres(9).unshared(), res, 16, with_seed(1), 2).0;
    let other_seed = render(spheres(9).unshared(), res, 16, with_seed(2), 2).0;
    // The same samples through the same surfaces: the two differ only where float rounding
    // sends a path elsewhere, far below the noise between two seeds.
    let difference = rel_mse(&placed, &flat);
    let noise = rel_mse(&other_seed, &flat);
    assert!(
        difference < 0.02 * noise,
        "placed vs flattened {difference:e}, seed to seed {noise:e}"
    );
}

#[test]
fn memory_grows_with_the_shared_mesh_not_with_placements() {
    let bytes = |placements: usize| {
        let world =
            World::build(spheres(placements), None, Some((8, 8)), LightSelect::Power).unwrap();
        assert_eq!(world.surfaces.shared_meshes.len(), 1);
        world.bvh_bytes() + world.surfaces.placements.len() * size_of::<PlacedMesh>()
    };
    let (few, many) = (bytes(9), bytes(10_009));
    let per_placement = (many - few) as f64 / 10_000.0;
    let flattened = World::build(
        spheres(9).unshared(),
        None,
        Some((8, 8)),
        LightSelect::Power,
    )
    .unwrap()
    .bvh_bytes() as f64
        / 9.0;
    // Two transforms (tracing, shading) and a share of the top-level nodes, against a copy
    // of the sphere's 320 triangles and their nodes when flattened.
    assert!(
        per_placement < 400.0 && per_placement * 50.0 < flattened,
        "{per_placement} bytes per placement; {flattened} per flattened copy"
    );
}

/// The memory estimate follows sharing: 1,000 placements of a shared sphere cost a small
/// fraction of the same spheres flattened, and each estimate covers the BVH that is built.
#[test]
fn memory_estimate_follows_sharing() {
    use lucerna::world::build::estimate_memory;
    let placed = estimate_memory(&spheres(1000));
    let flat = estimate_memory(&spheres(1000).unshared());
    assert!(
        flat.bvh > 100 * placed.bvh && flat.geometry > 20 * placed.geometry,
        "placed {placed}; flattened {flat}"
    );
    for (scene, estimate) in [(spheres(1000), placed), (spheres(1000).unshared(), flat)] {
        let world = World::build(scene, None, Some((8, 8)), LightSelect::Power).unwrap();
        assert!(
            (world.bvh_bytes() as u64) < estimate.bvh,
            "{} BVH bytes built, {} estimated",
            world.bvh_bytes(),
            estimate.bvh
        );
    }
}
