//! White-furnace tests: under a uniform environment of radiance 1, an object that reflects
//! all light is invisible, and one that loses energy shows exactly its directional albedo.

use crate::common;

use common::scenes::{icosphere, material, mean_and_error, ortho_camera, quad, render, scene};
use glam::{DMat4, DVec3, Vec3, Vec4};
use lucerna::film::Film;
use lucerna::film::aov::Aov;
use lucerna::integrator::Settings;
use lucerna::material::{Bsdf, gltf_pbr::GltfPbr};
use lucerna::sampling::sampler::SamplerKind;
use lucerna::scene::BsdfModel;

fn settings() -> Settings {
    Settings {
        sampler: SamplerKind::Independent,
        seed: 7,
        ..Default::default()
    }
}

/// [`settings`] without roulette and with a depth bound no path reaches: every path of a
/// lossless scene then leaves with its full weight.
fn without_roulette() -> Settings {
    let mut exact = settings();
    exact.set("rr", "off").unwrap();
    exact.set("max-depth", "100000").unwrap();
    exact
}

/// The image mean is 1 within 1%.
fn assert_within_one_percent(name: &str, film: &Film) {
    for c in 0..3 {
        let (m, se) = mean_and_error(film, c, |_| true);
        assert!((m - 1.0).abs() < 0.01, "{name}: image mean {m} ± {se}");
    }
}

/// Every pixel (object or background) is 1: the image mean within 1% and within 4.5
/// standard errors, and every pixel within 5 of its own standard errors.
fn assert_invisible(name: &str, film: &Film) {
    assert_within_one_percent(name, film);
    for c in 0..3 {
        let (m, se) = mean_and_error(film, c, |_| true);
        assert!(
            (m - 1.0).abs() <= 4.5 * se + 1e-4,
            "{name}: image mean {m} ± {se}"
        );
    }
    let beauty = film.planes(Aov::Beauty);
    let var = film.planes(Aov::Variance);
    for i in 0..beauty[0].len() {
        for c in 0..3 {
            let (x, sd) = (beauty[c][i] as f64, (var[c][i] as f64).sqrt());
            assert!(
                (x - 1.0).abs() <= 5.0 * sd + 1e-4,
                "{name}: pixel {i} = {x} ± {sd}"
            );
        }
    }
}

#[test]
fn unit_albedo_lambert_sphere_disappears() {
    let s = scene(
        vec![(icosphere(4), DMat4::IDENTITY)],
        material(BsdfModel::Lambert, Vec3::ONE, 0.0, 1.0),
        Vec3::ONE,
        ortho_camera(DVec3::new(0.0, 0.0, 5.0), 1.1),
    );
    let (film, stats) = render(s, (40, 40), 64, settings(), 2);
    assert_eq!(stats.discarded, 0);
    assert_invisible("Lambert albedo 1", &film);
}

#[test]
fn f0_one_ggx_spheres_disappear() {
    // Base colour 1, metallic 1: F0 = 1. The smooth sphere is a perfect mirror: exactly 1.
    // Rough ones are compensated for the energy single-scattering GGX loses between facets
    // (`material::energy`), so they disappear at every roughness too (at roughness 1 a
    // single-scattering sphere reflects 31 % at its centre).
    for roughness in [0.0, 0.25, 0.6, 1.0] {
        let s = scene(
            vec![(icosphere(4), DMat4::IDENTITY)],
            material(BsdfModel::GltfPbr, Vec3::ONE, 1.0, roughness),
            Vec3::ONE,
            ortho_camera(DVec3::new(0.0, 0.0, 5.0), 1.1),
        );
        let (film, _) = render(s, (40, 40), 64, settings(), 2);
        assert_invisible(&format!("GGX F0=1 roughness {roughness}"), &film);
    }
}

/// A white rough diffuse surface (OpenPBR's EON, no specular layer) reflects all the
/// light at every diffuse roughness: the sphere disappears.
#[test]
fn rough_diffuse_sphere_disappears() {
    for diffuse_roughness in [0.5f32, 1.0] {
        let s = scene(
            vec![(icosphere(4), DMat4::IDENTITY)],
            lucerna::scene::Material {
                diffuse_roughness,
                specular: lucerna::scene::Specular {
                    weight: 0.0,
                    ..Default::default()
                },
                ..material(BsdfModel::GltfPbr, Vec3::ONE, 0.0, 0.5)
            },
            Vec3::ONE,
            ortho_camera(DVec3::new(0.0, 0.0, 5.0), 1.1),
        );
        let (film, _) = render(s, (40, 40), 64, settings(), 2);
        assert_invisible(&format!("EON diffuse roughness {diffuse_roughness}"), &film);
    }
}

/// Directional albedo ∫ f cos dω of `bsdf` at `wo` by a midpoint rule in (cos θ, φ).
fn directional_albedo(bsdf: &Bsdf, wo: Vec3) -> f64 {
    let n = 600;
    let mut sum = 0.0f64;
    for i in 0..n {
        let z = (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        for j in 0..n {
            let phi = (j as f64 + 0.5) / n as f64 * 2.0 * std::f64::consts::PI;
            let wi = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
            sum += bsdf.eval(wo, wi).x as f64;
        }
    }
    sum * 2.0 * std::f64::consts::PI / (n * n) as f64
}

/// Single-scattering GGX (`--microfacet single`) loses energy: a white rough metal shows
/// exactly its directional albedo, below 1; compensated, the same plane shows 1.
#[test]
fn rough_f0_one_ggx_shows_its_directional_albedo() {
    // A tilted plane seen by an orthographic camera: every covered pixel sees the same angle.
    for multiscatter in [false, true] {
        for roughness in [0.5f32, 1.0] {
            for tilt in [0.0f64, 1.0] {
                let transform = DMat4::from_rotation_x(tilt);
                let s = scene(
                    vec![(quad(), transform)],
                    lucerna::scene::Material {
                        multiscatter,
                        ..material(BsdfModel::GltfPbr, Vec3::ONE, 1.0, roughness)
                    },
                    Vec3::ONE,
                    ortho_camera(DVec3::new(0.0, 0.0, 5.0), 0.4),
                );
                let (film, _) = render(s, (24, 24), 256, settings(), 2);
                let alpha = &film.planes(Aov::Beauty)[3];
                let wo = Vec3::new(0.0, tilt.sin() as f32, tilt.cos() as f32);
                let metal =
                    GltfPbr::new(Vec3::ONE, 1.0, roughness, 1.5).with_multiscatter(multiscatter);
                let expected = directional_albedo(&Bsdf::GltfPbr(metal), wo);
                let (m, se) = mean_and_error(&film, 0, |i| alpha[i] == 1.0);
                let name = format!("multiscatter {multiscatter} roughness {roughness} tilt {tilt}");
                assert!(
                    (m - expected).abs() <= 4.5 * se + 1e-3,
                    "{name}: rendered {m} ± {se}, albedo {expected}"
                );
                if multiscatter {
                    assert!((expected - 1.0).abs() < 2e-3, "{name}: albedo {expected}");
                } else {
                    assert!(expected < 0.95, "{name}: albedo {expected}");
                }
            }
        }
    }
}

/// A sun gives the same irradiance whatever its angular size: a Lambertian plane of albedo
/// 0.5 facing a sun of irradiance 1 shows 0.5 / π, through light sampling, and through BSDF
/// sampling alone once the sun has a size that escaping rays can find.
#[test]
fn sun_irradiance_does_not_depend_on_its_angle() {
    let expected = 0.5 / std::f64::consts::PI;
    for (angle, mis) in [
        (0.0f32, "power"),
        (0.01, "power"),
        (1.0, "power"),
        (2.0, "nee-only"),
        (2.0, "bsdf-only"),
    ] {
        let mut s = scene(
            vec![(quad(), DMat4::IDENTITY)],
            material(BsdfModel::Lambert, Vec3::splat(0.5), 0.0, 1.0),
            Vec3::ZERO,
            ortho_camera(DVec3::new(0.0, 0.0, 3.0), 0.9),
        );
        s.lights.push(lucerna::scene::Light {
            name: "sun".into(),
            kind: lucerna::scene::LightKind::Directional {
                direction: -DVec3::Z,
                irradiance: Vec3::ONE,
                angle,
            },
        });
        let mut settings = settings();
        settings.set("mis", mis).unwrap();
        let (film, _) = render(s, (16, 16), 64, settings, 2);
        let (m, se) = mean_and_error(&film, 0, |_| true);
        assert!(
            (m - expected).abs() <= 4.5 * se + 1e-5,
            "angle {angle}, {mis}: {m} ± {se}, expected {expected}"
        );
    }
}

/// A glTF glass material: transmission 1, smooth, ior 1.5 (or `ior`), bounding a volume
/// of absorption `absorption` per world unit, or a thin wall.
fn glass(volume: Option<Vec3>, ior: f32) -> lucerna::scene::Material {
    lucerna::scene::Material {
        transmission: 1.0,
        metallic: 0.0,
        roughness: 0.0,
        ior,
        volume: volume.map(lucerna::scene::Volume::absorbing),
        ..material(BsdfModel::GltfPbr, Vec3::ONE, 0.0, 0.0)
    }
}

/// Smooth glass loses nothing: a glass ball and a thin glass shell in a uniform
/// environment disappear (every path leaves with weight 1: reflections keep it, and the
/// 1/η² a refraction in carries is undone by the η² of the refraction out). Without
/// roulette (and with a depth bound no path reaches), so that every sample is exactly 1:
/// total internal reflection traps light in a faceted dense ball for hundreds of bounces,
/// and roulette's weights on those paths are a heavy tail that a few samples cannot
/// average, though the estimate stays unbiased (`tests/it/convergence.rs` checks roulette on
/// glass).
#[test]
fn smooth_glass_disappears() {
    for (name, m) in [
        ("glass ball", glass(Some(Vec3::ZERO), 1.5)),
        ("thin glass shell", glass(None, 1.5)),
        ("dense glass ball", glass(Some(Vec3::ZERO), 3.0)),
    ] {
        let s = scene(
            vec![(icosphere(3), DMat4::IDENTITY)],
            m,
            Vec3::ONE,
            ortho_camera(DVec3::new(0.0, 0.0, 5.0), 1.1),
        );
        let (film, stats) = render(s, (32, 32), 16, without_roulette(), 2);
        assert_eq!(stats.discarded, 0, "{name}");
        assert_invisible(name, &film);
    }
}

/// Rough glass loses nothing either once compensated: over a rough glass ball and a rough
/// thin glass shell the furnace reads 1, within noise and the albedo tables' interpolation
/// (2e-3 over the many crossings of a path), where single-scattering ones lose 3-4 %.
/// (Pixel by pixel the paths' weights are too heavy-tailed at these sample counts for
/// `assert_invisible`'s per-pixel bound.)
#[test]
fn rough_glass_disappears() {
    for roughness in [0.3f32, 0.7] {
        for (name, volume) in [
            ("rough glass ball", Some(Vec3::ZERO)),
            ("rough thin glass shell", None),
        ] {
            for multiscatter in [true, false] {
                let m = lucerna::scene::Material {
                    roughness,
                    multiscatter,
                    ..glass(volume, 1.5)
                };
                let s = scene(
                    vec![(icosphere(3), DMat4::IDENTITY)],
                    m,
                    Vec3::ONE,
                    ortho_camera(DVec3::new(0.0, 0.0, 5.0), 1.1),
                );
                let (film, _) = render(s, (32, 32), 256, without_roulette(), 2);
                let alpha = &film.planes(Aov::Beauty)[3];
                let name = format!("{name} roughness {roughness} multiscatter {multiscatter}");
                for c in 0..3 {
                    let (m, se) = mean_and_error(&film, c, |i| alpha[i] == 1.0);
                    if multiscatter {
                        assert!((m - 1.0).abs() <= 4.5 * se + 2e-3, "{name}: {m} ± {se}");
                    } else {
                        assert!(m < 0.98, "{name}: {m} ± {se}");
                    }
                }
            }
        }
    }
}

/// Diffuse transmission (KHR_materials_diffuse_transmission) moves light from the diffuse
/// reflection to the other side and loses none: a white ball whose diffuse base transmits
/// part of what it does not reflect, as a thin shell and as the boundary of a clear volume,
/// without a specular layer (KHR_materials_specular 0, so no Fresnel weighting enters), is
/// white in a white furnace.
#[test]
fn diffusely_transmitting_ball_disappears() {
    for (name, volume, share) in [
        ("thin translucent shell", None, 0.5f32),
        ("thin shell transmitting all", None, 1.0),
        (
            "translucent boundary of a clear volume",
            Some(lucerna::scene::Volume::absorbing(Vec3::ZERO)),
            0.7,
        ),
    ] {
        let m = lucerna::scene::Material {
            base_color: Vec4::ONE,
            metallic: 0.0,
            roughness: 0.5,
            specular: lucerna::scene::Specular {
                weight: 0.0,
                ..Default::default()
            },
            volume,
            diffuse_transmission: Some(lucerna::scene::DiffuseTransmission {
                factor: share,
                texture: None,
                color: Vec3::ONE,
                color_texture: None,
            }),
            ..Default::default()
        };
        assert_ball_in_furnace_is_white(name, m);
    }
}

/// Beer-Lambert: a slab of index-matched glass (nothing reflects or bends) whose
/// absorption halves the light over its thickness shows the environment at half, through
/// a volume entered and left once, whatever the scene's scale in render space.
#[test]
fn absorbing_slab_transmits_beer_lambert() {
    for (thickness, scale) in [(0.5f64, 1.0f64), (0.5, 1000.0)] {
        let sigma = (2.0f32).ln() / (thickness * scale) as f32;
        let slab = DMat4::from_scale(DVec3::new(2.0 * scale, 2.0 * scale, thickness * scale));
        let s = scene(
            vec![(lucerna_test_cube(), slab)],
            glass(Some(Vec3::new(sigma, 2.0 * sigma, 0.0)), 1.0),
            Vec3::ONE,
            ortho_camera(DVec3::new(0.0, 0.0, 5.0 * scale), (0.5 * scale) as f32),
        );
        let (film, _) = render(s, (8, 8), 4, settings(), 2);
        assert_every_pixel(&format!("scale {scale}"), &film, [0.5, 0.25, 1.0]);
    }
}

/// Every pixel of `film`'s beauty is `expected` within 1e-4 (exact renders: no sampling).
fn assert_every_pixel(name: &str, film: &Film, expected: [f32; 3]) {
    let beauty = film.planes(Aov::Beauty);
    let pixels = beauty[0].iter().zip(&beauty[1]).zip(&beauty[2]);
    for (i, ((&r, &g), &b)) in pixels.enumerate() {
        let rgb = [r, g, b];
        for c in 0..3 {
            assert!(
                (rgb[c] - expected[c]).abs() < 1e-4,
                "{name}: pixel {i} = {rgb:?}, expected {expected:?}"
            );
        }
    }
}

/// An interface (no surface) around a medium of absorption `absorption`, scattering
/// `scattering` and anisotropy `g` per world unit.
fn medium(absorption: Vec3, scattering: Vec3, g: f32) -> lucerna::scene::Material {
    lucerna::scene::Material {
        volume: Some(lucerna::scene::Volume {
            absorption,
            scattering,
            anisotropy: g,
            density: None,
            emission: Vec3::ZERO,
            blackbody: None,
            emission_field: None,
            scatter_color: None,
        }),
        ..material(BsdfModel::Interface, Vec3::ONE, 0.0, 0.0)
    }
}

/// A density grid over the box [-1, 1]³: lumps of density up to 4 and an empty slab.
fn smoke_grid() -> lucerna::scene::DensityGrid {
    let n = 20u32;
    let mut values = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let p = Vec3::new(x as f32, y as f32, z as f32) / n as f32 * 6.0;
                let lump = 2.0 + p.x.sin() * p.y.cos() + (1.3 * p.z).sin();
                values.push(if (8..11).contains(&y) {
                    0.0
                } else {
                    lump.max(0.0)
                });
            }
        }
    }
    lucerna::scene::DensityGrid {
        source: "smoke".into(),
        resolution: [n; 3],
        to_world: DMat4::from_translation(DVec3::splat(-1.0))
            * DMat4::from_scale(DVec3::splat(2.0)),
        values: values.into(),
    }
}

/// A medium that scatters and does not absorb loses nothing: in a uniform environment a
/// ball of it disappears, whatever its anisotropy and whether its extinction differs by
/// channel (each channel's weights average to 1 under the channel-averaged flight density),
/// as does a glass ball filled with it. Light samples cross the medium (transmittance of
/// shadow rays through interfaces), phase samples continue, MIS weighs them. (At 1024
/// samples no pixel of these lies beyond 3.6 of its standard errors.)
#[test]
fn scattering_media_disappear() {
    let cases = [
        (
            "isotropic medium ball",
            medium(Vec3::ZERO, Vec3::splat(2.0), 0.0),
        ),
        (
            "forward-scattering medium ball",
            medium(Vec3::ZERO, Vec3::splat(2.0), 0.7),
        ),
        (
            "chromatic medium ball",
            medium(Vec3::ZERO, Vec3::new(0.5, 2.0, 6.0), -0.3),
        ),
        (
            "chromatic smoke ball (density grid)",
            lucerna::scene::Material {
                volume: Some(lucerna::scene::Volume {
                    density: Some(0),
                    ..medium(Vec3::ZERO, Vec3::new(0.3, 1.0, 2.5), 0.4)
                        .volume
                        .unwrap()
                }),
                ..medium(Vec3::ZERO, Vec3::ZERO, 0.0)
            },
        ),
        (
            "glass ball of scattering medium",
            lucerna::scene::Material {
                volume: Some(lucerna::scene::Volume {
                    absorption: Vec3::ZERO,
                    scattering: Vec3::splat(3.0),
                    anisotropy: 0.5,
                    density: None,
                    emission: Vec3::ZERO,
                    blackbody: None,
                    emission_field: None,
                    scatter_color: None,
                }),
                ..glass(Some(Vec3::ZERO), 1.5)
            },
        ),
    ];
    for (name, m) in cases {
        // The image and the ball's pixels within noise (a medium's paths are heavy-tailed
        // pixel by pixel, the chromatic one most: its channels' weights multiply at every
        // scattering event).
        assert_ball_in_furnace_is_white(name, m);
    }
}

/// Renders a unit ball of material `m` (the density grid `smoke_grid` at index 0) in a
/// white furnace, 32 x 32 pixels at 128 samples, and asserts that the ball's pixels and the
/// whole image are 1 within 4.5 standard errors in every channel.
fn assert_ball_in_furnace_is_white(name: &str, m: lucerna::scene::Material) {
    let mut s = scene(
        vec![(icosphere(3), DMat4::IDENTITY)],
        m,
        Vec3::ONE,
        ortho_camera(DVec3::new(0.0, 0.0, 5.0), 1.1),
    );
    s.grids.push(smoke_grid());
    let (film, stats) = render(s, (32, 32), 128, without_roulette(), 2);
    assert_eq!(stats.discarded, 0, "{name}");
    let inside = |i: usize| {
        let (u, v) = ((i % 32) as f32 + 0.5, (i / 32) as f32 + 0.5);
        let (x, y) = ((u / 16.0 - 1.0) * 1.1, (v / 16.0 - 1.0) * 1.1);
        x * x + y * y < 0.9
    };
    for c in 0..3 {
        for (part, (m, se)) in [
            ("ball", mean_and_error(&film, c, inside)),
            ("image", mean_and_error(&film, c, |_| true)),
        ] {
            assert!(
                (m - 1.0).abs() <= 4.5 * se + 1e-3,
                "{name}: {part} {m} ± {se} in channel {c}"
            );
        }
    }
}

/// A medium that emits σa Le per unit length in surroundings of radiance Le is in
/// equilibrium with them (Kirchhoff's law): whatever its absorption, scattering, phase
/// function or density grid, the light inside and leaving it is Le everywhere, so the image
/// is uniform: the emission gathered along segments, the flights and the light samples
/// together must give exactly what the medium takes away. (At 256 samples no pixel of these
/// lies beyond 3.6 of its standard errors.)
#[test]
fn emitting_media_in_equilibrium_disappear() {
    let emitting = |absorption: Vec3, scattering: Vec3, g: f32, density: Option<u32>| {
        lucerna::scene::Material {
            volume: Some(lucerna::scene::Volume {
                density,
                emission: absorption,
                ..medium(absorption, scattering, g).volume.unwrap()
            }),
            ..medium(Vec3::ZERO, Vec3::ZERO, 0.0)
        }
    };
    let cases = [
        (
            "absorbing ball",
            emitting(Vec3::splat(2.0), Vec3::ZERO, 0.0, None),
        ),
        (
            "chromatic scattering ball",
            emitting(
                Vec3::new(0.5, 2.0, 6.0),
                Vec3::new(1.5, 0.5, 0.2),
                0.5,
                None,
            ),
        ),
        (
            "chromatic smoke ball (density grid)",
            emitting(
                Vec3::new(0.8, 0.3, 1.5),
                Vec3::new(0.3, 1.0, 0.5),
                -0.3,
                Some(0),
            ),
        ),
        (
            "absorbing smoke ball (density grid)",
            emitting(Vec3::new(2.0, 1.0, 0.5), Vec3::ZERO, 0.0, Some(0)),
        ),
    ];
    for (name, m) in cases {
        assert_ball_in_furnace_is_white(name, m);
    }
}

/// A slab that absorbs and emits, behind interfaces, seen straight through: the light
/// behind it attenuated by Beer-Lambert plus its emission σe (1 − T) / σa, and σe d where
/// it emits without absorbing.
#[test]
fn an_emitting_slab_adds_its_closed_form_emission() {
    let slab = DMat4::from_scale(DVec3::new(2.0, 2.0, 0.5));
    let sigma = Vec3::new(2.0, 0.5, 0.0);
    let emission = Vec3::new(3.0, 1.0, 0.8);
    let m = lucerna::scene::Material {
        volume: Some(lucerna::scene::Volume {
            emission,
            ..medium(sigma, Vec3::ZERO, 0.0).volume.unwrap()
        }),
        ..medium(Vec3::ZERO, Vec3::ZERO, 0.0)
    };
    let s = scene(
        vec![(lucerna_test_cube(), slab)],
        m,
        Vec3::ONE,
        ortho_camera(DVec3::new(0.0, 0.0, 5.0), 0.5),
    );
    let (film, stats) = render(s, (8, 8), 4, without_roulette(), 1);
    assert_eq!(stats.discarded, 0);
    // The cube spans [-0.5, 0.5]: the slab is 0.5 thick.
    let d = 0.5f32;
    for c in 0..3 {
        let (s, e) = (sigma[c], emission[c]);
        let transmitted = (-s * d).exp();
        let emitted = if s > 0.0 {
            e * (1.0 - transmitted) / s
        } else {
            e * d
        };
        let expected = f64::from(transmitted + emitted);
        let (m, _) = mean_and_error(&film, c, |_| true);
        assert!(
            (m - expected).abs() < 1e-4 * expected,
            "channel {c}: {m}, expected {expected}"
        );
    }
}

/// A medium that only absorbs, behind an interface, is Beer-Lambert's exactly: the
/// interface neither reflects nor bends, and the camera ray crosses one slab of it.
#[test]
fn absorbing_medium_behind_an_interface_transmits_beer_lambert() {
    let sigma = (2.0f32).ln() / 0.5;
    let slab = DMat4::from_scale(DVec3::new(2.0, 2.0, 0.5));
    let s = scene(
        vec![(lucerna_test_cube(), slab)],
        medium(Vec3::new(sigma, 2.0 * sigma, 0.0), Vec3::ZERO, 0.0),
        Vec3::ONE,
        ortho_camera(DVec3::new(0.0, 0.0, 5.0), 0.5),
    );
    let (film, _) = render(s, (8, 8), 4, settings(), 2);
    assert_every_pixel("behind an interface", &film, [0.5, 0.25, 1.0]);
}

/// A camera inside a medium is in it from the start (`Media::around`): inside an absorbing
/// cube it sees the environment through the medium between it and the wall, Beer-Lambert's
/// exactly; inside a cube of scattering medium that does not absorb, in a white furnace,
/// it sees 1 everywhere.
#[test]
fn a_camera_inside_a_medium_starts_in_it() {
    let sigma = (2.0f32).ln() / 1.5;
    let cube = DMat4::from_scale(DVec3::splat(2.0));
    // At z = 0.5 looking down -z: every ray crosses 1.5 of the medium to the wall at z = -1.
    let camera = ortho_camera(DVec3::new(0.0, 0.0, 0.5), 0.5);
    let s = scene(
        vec![(lucerna_test_cube(), cube)],
        medium(Vec3::new(sigma, 2.0 * sigma, 0.0), Vec3::ZERO, 0.0),
        Vec3::ONE,
        camera.clone(),
    );
    let (film, _) = render(s, (8, 8), 4, settings(), 2);
    assert_every_pixel("inside an absorbing cube", &film, [0.5, 0.25, 1.0]);
    let s = scene(
        vec![(lucerna_test_cube(), cube)],
        medium(Vec3::ZERO, Vec3::new(0.5, 1.0, 2.0), 0.3),
        Vec3::ONE,
        camera,
    );
    let (film, _) = render(s, (16, 16), 64, without_roulette(), 2);
    for c in 0..3 {
        let (m, se) = mean_and_error(&film, c, |_| true);
        assert!(
            (m - 1.0).abs() <= 4.5 * se + 1e-3,
            "inside the medium: {m} ± {se}"
        );
        assert!(se > 0.0, "the medium scatters what the camera sees");
    }
}

/// A medium too dense for floats to step through (scattering 1e30 per unit, albedo 1:
/// every free flight ends where it starts) still ends its paths (the roulette's cap after
/// a few bounces, whatever the throughput) and gives no NaN: no hang, no discarded sample.
#[test]
fn a_medium_too_dense_to_step_through_ends_its_paths() {
    let s = scene(
        vec![(icosphere(2), DMat4::IDENTITY)],
        medium(Vec3::ZERO, Vec3::splat(1e30), 0.0),
        Vec3::ONE,
        ortho_camera(DVec3::new(0.0, 0.0, 5.0), 1.1),
    );
    let (film, stats) = render(s, (16, 16), 16, settings(), 2);
    assert_eq!(stats.discarded, 0);
    let beauty = film.planes(Aov::Beauty);
    assert!(beauty.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
}

/// A closed unit cube centred on the origin (12 outward-facing triangles).
fn lucerna_test_cube() -> lucerna::scene::Mesh {
    let v: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { -0.5 } else { 0.5 },
                if i & 2 == 0 { -0.5 } else { 0.5 },
                if i & 4 == 0 { -0.5 } else { 0.5 },
            )
        })
        .collect();
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let triangles = quads
        .iter()
        .flat_map(|[a, b, c, d]| [[*a, *b, *c], [*a, *c, *d]])
        .collect();
    lucerna::scene::Mesh {
        name: "cube".into(),
        positions: v,
        triangles,
        ..Default::default()
    }
}
