//! Analytic disk and cylinder lights render like finely tessellated copies of themselves
//! (which go through the well-tested triangle path): same camera-visible emission, same
//! light sampling and MIS, within the noise between two seeds.

use crate::common;

use common::scenes::{look_at, material, mean_and_error, rel_mse, render};
use glam::{DMat4, DVec3, Vec3};
use lucerna::integrator::Settings;
use lucerna::scene::{
    BsdfModel, Camera, Cylinder, Disk, Instance, Material, Mesh, Projection, Scene,
};
use std::f64::consts::PI;

const SEGMENTS: usize = 1024;

/// A floor, a disk light facing down at it and a cylinder light lying on its side, as
/// analytic shapes or as meshes of `SEGMENTS` sides with the same area.
fn scene(analytic: bool) -> Scene {
    let emitter = |name: &str, radiance: f32| Material {
        name: name.into(),
        base_color: glam::Vec4::new(0.0, 0.0, 0.0, 1.0),
        emissive: Vec3::splat(radiance),
        double_sided: false,
        ..material(BsdfModel::Lambert, Vec3::ZERO, 0.0, 1.0)
    };
    let mut s = Scene {
        source: "quadric lights".into(),
        materials: vec![
            material(BsdfModel::Lambert, Vec3::splat(0.6), 0.0, 1.0),
            emitter("disk", 4.0),
            emitter("tube", 2.0),
        ],
        cameras: vec![Camera {
            name: "camera".into(),
            projection: Projection::Perspective {
                yfov: 0.9,
                aspect: Some(1.0),
            },
            transform: look_at(DVec3::new(0.0, 2.5, 4.0), DVec3::new(0.0, 0.4, 0.0)),
            aperture_radius: 0.0,
            focus_distance: 1.0,
            clip_near: 0.0,
            clip_far: None,
            fit: Default::default(),
            motion: Vec::new(),
        }],
        ..Default::default()
    };
    let floor = Mesh {
        name: "floor".into(),
        positions: vec![
            Vec3::new(-3.0, 0.0, -3.0),
            Vec3::new(-3.0, 0.0, 3.0),
            Vec3::new(3.0, 0.0, 3.0),
            Vec3::new(3.0, 0.0, -3.0),
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        material: 0,
        ..Default::default()
    };
    let (disk_centre, disk_radius) = (DVec3::new(-0.8, 1.5, -0.5), 0.5);
    let (tube_centre, tube_radius, tube_length) = (DVec3::new(0.9, 0.5, 0.3), 0.15, 1.2);
    let mut meshes = vec![floor];
    if analytic {
        s.disks.push(Disk {
            name: "disk".into(),
            centre: disk_centre,
            normal: DVec3::new(0.3, -1.0, 0.1).normalize(),
            radius: disk_radius,
            material: 1,
        });
        s.cylinders.push(Cylinder {
            name: "tube".into(),
            centre: tube_centre,
            axis: DVec3::new(0.2, 0.1, 1.0).normalize(),
            radius: tube_radius,
            length: tube_length,
            material: 2,
        });
    } else {
        meshes.push(disk_mesh(
            disk_centre,
            DVec3::new(0.3, -1.0, 0.1).normalize(),
            disk_radius,
        ));
        meshes.push(tube_mesh(
            tube_centre,
            DVec3::new(0.2, 0.1, 1.0).normalize(),
            tube_radius,
            tube_length,
        ));
    }
    for (i, m) in meshes.into_iter().enumerate() {
        s.meshes.push(m);
        s.instances.push(Instance {
            name: format!("mesh{i}"),
            mesh: i as u32,
            motion: Vec::new(),
            transform: DMat4::IDENTITY,
        });
    }
    s
}

/// Two unit vectors perpendicular to `n` and to each other, right-handed with it.
fn basis(n: DVec3) -> (DVec3, DVec3) {
    let s = n.any_orthonormal_vector();
    (s, n.cross(s))
}

/// A regular polygon of the disk's area, wound to face `normal`.
fn disk_mesh(centre: DVec3, normal: DVec3, radius: f64) -> Mesh {
    let n = SEGMENTS as f64;
    let r = radius * (2.0 * PI / (n * (2.0 * PI / n).sin())).sqrt();
    let (s, t) = basis(normal);
    let mut positions = vec![centre.as_vec3()];
    for k in 0..SEGMENTS {
        let a = 2.0 * PI * k as f64 / n;
        positions.push((centre + r * (a.cos() * s + a.sin() * t)).as_vec3());
    }
    let triangles = (0..SEGMENTS as u32)
        .map(|k| [0, 1 + k, 1 + (k + 1) % SEGMENTS as u32])
        .collect();
    Mesh {
        name: "disk".into(),
        positions,
        triangles,
        material: 1,
        ..Default::default()
    }
}

/// A prism of the cylinder's lateral area (the polygon's perimeter is the circle's), wound
/// outwards, without caps.
fn tube_mesh(centre: DVec3, axis: DVec3, radius: f64, length: f64) -> Mesh {
    let n = SEGMENTS as f64;
    let r = radius * PI / (n * (PI / n).sin());
    let (s, t) = basis(axis);
    let mut positions = Vec::new();
    for end in [-0.5, 0.5] {
        for k in 0..SEGMENTS {
            let a = 2.0 * PI * k as f64 / n;
            positions
                .push((centre + end * length * axis + r * (a.cos() * s + a.sin() * t)).as_vec3());
        }
    }
    let m = SEGMENTS as u32;
    let triangles = (0..m)
        .flat_map(|k| {
            let k1 = (k + 1) % m;
            [[k, k1, m + k1], [k, m + k1, m + k]]
        })
        .collect();
    Mesh {
        name: "tube".into(),
        positions,
        triangles,
        material: 2,
        ..Default::default()
    }
}

#[test]
fn analytic_disk_and_cylinder_lights_render_like_their_tessellations() {
    for selection in ["power", "contribution"] {
        let settings = |seed| {
            let mut s = Settings {
                seed,
                ..Settings::default()
            };
            s.set("light-select", selection).unwrap();
            s
        };
        let res = (48, 48);
        let analytic = render(scene(true), res, 256, settings(1), 2).0;
        let mesh_a = render(scene(false), res, 256, settings(2), 2).0;
        let mesh_b = render(scene(false), res, 256, settings(3), 2).0;
        let difference = rel_mse(&analytic, &mesh_a);
        let noise = rel_mse(&mesh_b, &mesh_a);
        // Both differences are seed noise when the two agree: a ratio near 1.
        assert!(
            difference < 1.35 * noise,
            "{selection}: analytic vs mesh {difference:e}, mesh vs mesh {noise:e}"
        );
        // And the image means agree within their standard errors (from the variance layer):
        // a bias of a few percent in either light shows here first.
        let (ma, sa) = mean_and_error(&analytic, 0, |_| true);
        let (mm, sm) = mean_and_error(&mesh_a, 0, |_| true);
        assert!(
            (ma - mm).abs() <= 4.5 * (sa * sa + sm * sm).sqrt(),
            "{selection}: image mean {ma} ± {sa} vs {mm} ± {sm}"
        );
    }
}
