//! Deformation blur of real assets: the keys the glTF importer gives a skinned mesh
//! (Khronos CesiumMan) and a morphed one (AnimatedMorphCube) over the shutter are their
//! poses at the keys' times, and the blurred skinned figure is the average of its instants.

use crate::common::scenes::{look_at, ortho_camera};
use glam::{DVec3, Vec3};
use lucerna::ingest::gltf::{Choices, import_with};
use lucerna::scene::Scene;
use std::path::{Path, PathBuf};

fn asset(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/assets/gltf")
        .join(name)
}

/// `file` imported at `time` seconds, with the shutter open over `shutter` seconds.
fn import(file: &Path, time: f64, shutter: Option<(f64, f64)>) -> Scene {
    let bytes = std::fs::read(file).unwrap();
    let name = file.to_str().unwrap();
    import_with(
        &bytes,
        name,
        file.parent(),
        Some(time),
        Choices {
            shutter,
            ..Default::default()
        },
    )
    .unwrap()
}

/// The largest distance between corresponding points.
fn largest_gap(a: &[Vec3], b: &[Vec3]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f32::max)
}

/// Each key of the deformation is the mesh as an instantaneous import poses it at the
/// key's time (to single-precision rounding), and the mesh itself is the frame's; the
/// vertices move by far more than that over the shutter.
fn assert_keys_are_poses(file: &Path, time: f64, (open, close): (f64, f64)) {
    let scene = import(file, time, Some((open, close)));
    let frame = import(file, time, None);
    let (mesh, still) = (&scene.meshes[0], &frame.meshes[0]);
    let d = mesh
        .deformation
        .as_ref()
        .expect("the mesh deforms over the shutter");
    assert_eq!(d.keys(), 9);
    assert_eq!(largest_gap(&mesh.positions, &still.positions), 0.0);
    let size = mesh.bounds().map(|(lo, hi)| (hi - lo).length()).unwrap();
    for (k, key) in d.positions.iter().enumerate() {
        let at = open + (close - open) * k as f64 / 8.0;
        let posed = import(file, at, None);
        let gap = largest_gap(key, &posed.meshes[0].positions);
        assert!(gap < 1e-5 * size, "key {k}: {gap} from the pose at {at} s");
    }
    let travel = largest_gap(&d.positions[0], &d.positions[8]);
    assert!(travel > 0.01 * size, "the vertices travel {travel} only");
    if let (Some(normals), Some(still)) = (&d.normals, &still.normals) {
        assert_eq!(normals.len(), 9);
        assert_eq!(
            largest_gap(&normals[4], still),
            0.0,
            "the middle key is the frame"
        );
    }
}

#[test]
fn skinned_keys_are_the_poses_at_their_times() {
    assert_keys_are_poses(&asset("CesiumMan/CesiumMan.glb"), 0.5, (0.45, 0.55));
}

#[test]
fn morphed_keys_are_the_poses_at_their_times() {
    assert_keys_are_poses(
        &asset("AnimatedMorphCube/AnimatedMorphCube.gltf"),
        1.0,
        (0.9, 1.1),
    );
}

/// CesiumMan walking with the shutter open for 0.4 s, under a white sky, seen from the side: the
/// blurred figure is the average of the figure at 256 instants of the shutter (its vertices
/// where the keys put them), and the figure frozen at mid-shutter is not.
#[test]
fn a_walking_figure_is_the_average_of_its_instants() {
    let scene = |time: Option<f64>| {
        let mut scene = import(&asset("CesiumMan/CesiumMan.glb"), 0.5, Some((0.3, 0.7)));
        lucerna::ingest::set_constant_environment(&mut scene, Vec3::ONE);
        // Seen from the side, where the legs swing (the same camera for every instant: a
        // framing camera would follow each one's bounds).
        let (eye, target) = (DVec3::new(10.0, 0.76, 0.0), DVec3::new(0.0, 0.76, 0.0));
        scene.cameras = vec![lucerna::scene::Camera {
            transform: look_at(eye, target),
            ..ortho_camera(eye, 0.8)
        }];
        if let Some(t) = time {
            let mesh = &mut scene.meshes[0];
            let d = mesh.deformation.take().unwrap();
            mesh.positions = (0..mesh.positions.len())
                .map(|v| d.position(v, t as f32))
                .collect();
            mesh.normals = d.normals.as_ref().map(|_| {
                (0..mesh.positions.len())
                    .map(|v| d.normal(v, t as f32).unwrap().normalize_or_zero())
                    .collect()
            });
        }
        scene
    };
    crate::motion_blur::assert_average_of_instants(|t| scene(Some(t)), || scene(None));
}
