//! Texture filtering by ray-cone footprints: on a checkerboard plane running to the
//! horizon, lookups filtered through MIP maps remove most of the aliasing of few samples
//! and converge to the image of full-resolution lookups.
//!
//! The plane is unlit, so a pixel's value is the texture's mean over the pixel and all the
//! error of a render is aliasing. The reference takes 1024 full-resolution samples (another
//! seed than the renders compared with it).

use crate::common::scenes::{look_at, quad, rel_mse, render};
use glam::{DMat4, DVec3, Vec2, Vec3};
use lucerna::film::Film;
use lucerna::film::aov::Aov;
use lucerna::integrator::Settings;
use lucerna::integrator::settings::TextureFilter;
use lucerna::scene::{
    Camera, Environment, Instance, Material, Projection, Scene, Texels, Texture, TextureRef, Wrap,
};
use std::sync::Arc;

const RESOLUTION: (u32, u32) = (120, 80);

/// A 400 × 400 plane in y = 0 whose 64-texel checker texture (8 × 8 checks, sRGB black and
/// white) repeats 200 times each way, seen from 1 unit above looking 8° down.
fn checker_plane() -> Scene {
    let mut mesh = quad();
    mesh.uvs[0] = Some(
        [(0.0, 0.0), (200.0, 0.0), (200.0, 200.0), (0.0, 200.0)]
            .map(|(u, v)| Vec2::new(u, v))
            .to_vec(),
    );
    let texels = (0..64 * 64)
        .map(|i| {
            let (x, y) = (i % 64 / 8, i / 64 / 8);
            if (x + y) % 2 == 1 {
                [255; 4]
            } else {
                [0, 0, 0, 255]
            }
        })
        .collect();
    let texture = Texture {
        name: "checker".into(),
        width: 64,
        height: 64,
        texels: Arc::new(Texels::Rgba8(texels)),
        mips: Default::default(),
        wrap_u: Wrap::Repeat,
        wrap_v: Wrap::Repeat,
        nearest: false,
        mipmaps: true,
        udim: None,
    };
    let material = Material {
        name: "checker".into(),
        unlit: true,
        double_sided: true,
        base_color_texture: Some(TextureRef {
            texture: 0,
            tex_coord: 0,
            transform: None,
        }),
        ..Default::default()
    };
    let pitch = 8f64.to_radians();
    let eye = DVec3::new(0.0, 1.0, 0.0);
    Scene {
        source: "checker plane".into(),
        materials: vec![material],
        textures: vec![texture],
        meshes: vec![mesh],
        instances: vec![Instance {
            name: "plane".into(),
            mesh: 0,
            motion: Vec::new(),
            // The quad (XY, ±1) laid in y = 0, 400 units wide.
            transform: DMat4::from_rotation_x(-std::f64::consts::FRAC_PI_2)
                * DMat4::from_scale(DVec3::splat(200.0)),
        }],
        environment: Some(Environment::Constant(Vec3::ONE)),
        cameras: vec![Camera {
            name: "view".into(),
            projection: Projection::Perspective {
                yfov: 0.6,
                aspect: None,
            },
            transform: look_at(eye, eye + DVec3::new(0.0, -pitch.sin(), -pitch.cos())),
            aperture_radius: 0.0,
            focus_distance: 1.0,
            clip_near: 0.0,
            clip_far: None,
            fit: Default::default(),
            motion: Vec::new(),
        }],
        ..Default::default()
    }
}

fn render_with(filter: TextureFilter, spp: u32, seed: u32) -> Film {
    let settings = Settings {
        texture_filter: filter,
        seed,
        ..Settings::default()
    };
    render(checker_plane(), RESOLUTION, spp, settings, 2).0
}

fn mean_beauty(film: &Film) -> f64 {
    let planes = film.planes(Aov::Beauty);
    planes[..3]
        .iter()
        .flat_map(|p| p.iter())
        .map(|&v| v as f64)
        .sum::<f64>()
        / (3 * planes[0].len()) as f64
}

#[test]
fn mip_maps_remove_aliasing_at_few_samples_and_converge_to_full_resolution() {
    let reference = render_with(TextureFilter::Bilinear, 1024, 1);
    let error = |f: TextureFilter, spp: u32| rel_mse(&render_with(f, spp, 2), &reference);
    // At 4 samples bilinear lookups alias towards the horizon; filtered ones do not (the
    // measured ratio is about a quarter).
    let (bilinear, mip) = (
        error(TextureFilter::Bilinear, 4),
        error(TextureFilter::Mip, 4),
    );
    assert!(
        mip < 0.6 * bilinear,
        "4 spp: mip {mip:.5}, bilinear {bilinear:.5}"
    );
    // At 256 samples both are the reference's noise and their own: a bias of the filter
    // would add to the error of the filtered render (half the noise would show).
    let (bilinear, mip) = (
        error(TextureFilter::Bilinear, 256),
        error(TextureFilter::Mip, 256),
    );
    assert!(
        mip < 1.5 * bilinear,
        "256 spp: mip {mip:.6}, bilinear {bilinear:.6}"
    );
    let ratio = mean_beauty(&render_with(TextureFilter::Mip, 256, 2)) / mean_beauty(&reference);
    assert!((ratio - 1.0).abs() < 2e-3, "mean ratio {ratio}");
}
