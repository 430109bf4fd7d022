//! The render plan: what it finds in small scenes, that the specialised integrator renders
//! exactly what the general one does, that the packet kernel renders what the scalar one
//! does (to rounding), and adaptive sampling (its noise target, its bias, its determinism).

use crate::common;

use common::scenes::rel_mse;
use glam::{DVec3, Vec3, Vec4};
use lucerna::film::Film;
use lucerna::film::aov::{Aov, AovSet};
use lucerna::film::filter::PixelFilter;
use lucerna::ingest;
use lucerna::render::plan::{Kernel, PlanMode, RenderPlan};
use lucerna::render::{self, RenderOptions, RenderStats};
use lucerna::sampling::sampler::SamplerKind;
use lucerna::scene::features::{Lobes, SceneFeatures, strip_unused_attributes};
use lucerna::scene::{Environment, Light, LightKind, Scene};
use lucerna::world::World;
use std::path::Path;

fn cornell() -> Scene {
    ingest::default_scene().unwrap()
}

/// The Cornell box lit by a point and a spot light only (its panel no longer emits).
fn cornell_punctual() -> Scene {
    let mut scene = cornell();
    for m in &mut scene.materials {
        m.emissive = Vec3::ZERO;
    }
    scene.lights.push(Light {
        name: "point".into(),
        kind: LightKind::Point {
            position: DVec3::new(0.0, 0.4, 0.0),
            intensity: Vec3::splat(0.3),
        },
    });
    scene.lights.push(Light {
        name: "spot".into(),
        kind: LightKind::Spot {
            position: DVec3::new(0.2, 0.45, 0.1),
            direction: DVec3::new(-0.3, -1.0, 0.2),
            intensity: Vec3::splat(0.2),
            inner_cone: 0.3,
            outer_cone: 0.6,
        },
    });
    scene
}

/// The Cornell box with a mirror for its tall block and a dark point light besides its
/// panel: delta lobes and both kinds of light.
fn cornell_mirror() -> Scene {
    let mut scene = cornell();
    common::scenes::make_tall_block_a_mirror(&mut scene);
    scene.lights.push(Light {
        name: "off".into(),
        kind: LightKind::Point {
            position: DVec3::new(0.0, 0.4, 0.0),
            intensity: Vec3::ZERO,
        },
    });
    scene
}

/// The Cornell box (open at the front) lit by a constant environment only.
fn cornell_environment() -> Scene {
    let mut scene = cornell();
    for m in &mut scene.materials {
        m.emissive = Vec3::ZERO;
    }
    scene.environment = Some(Environment::Constant(Vec3::splat(0.8)));
    scene
}

fn shipped(path: &str) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(path);
    ingest::load(&path, &Default::default()).unwrap()
}

/// Every scene of the comparison, by name.
fn scenes() -> Vec<(&'static str, Scene)> {
    vec![
        ("cornell", cornell()),
        ("cornell-punctual", cornell_punctual()),
        ("cornell-mirror", cornell_mirror()),
        ("cornell-environment", cornell_environment()),
        ("mis-plates", shipped("scenes/mis-plates/mis-plates.glb")),
        ("usd-twin", shipped("scenes/usd-twin/usd-twin.gltf")),
        ("glass-box", shipped("scenes/glass-box/glass-box.gltf")),
    ]
}

fn plan_for(scene: &Scene, aovs: &str, mode: PlanMode) -> RenderPlan {
    RenderPlan::new(
        &SceneFeatures::of(scene),
        &AovSet::parse(aovs).unwrap(),
        mode,
        false,
        false,
    )
}

#[test]
fn plans_of_small_scenes_are_as_expected() {
    let diffuse = Lobes {
        diffuse: true,
        ..Lobes::default()
    };
    let f = SceneFeatures::of(&cornell());
    assert_eq!(
        (f.lights.area, f.lights.delta, f.lights.environment),
        (2, 0, false)
    );
    assert_eq!(f.lobes, diffuse);
    assert_eq!((f.textured_materials, f.alpha_materials), (0, 0));

    let f = SceneFeatures::of(&cornell_punctual());
    assert_eq!((f.lights.area, f.lights.delta), (0, 2));
    assert!(!f.lights.reachable_by_bsdf_sampling());
    assert!(
        !plan_for(&cornell_punctual(), "", PlanMode::Auto)
            .kernel
            .emitter_hits
    );

    let f = SceneFeatures::of(&cornell_mirror());
    assert_eq!(
        (f.lights.area, f.lights.delta, f.lights.zero_power),
        (2, 1, 1)
    );
    assert_eq!(
        f.lobes,
        Lobes {
            specular: true,
            ..diffuse
        }
    );

    let f = SceneFeatures::of(&cornell_environment());
    assert!(f.lights.environment && f.lights.area == 0);
    assert!(
        plan_for(&cornell_environment(), "", PlanMode::Auto)
            .kernel
            .emitter_hits
    );

    let f = SceneFeatures::of(&shipped("scenes/mis-plates/mis-plates.glb"));
    assert_eq!(f.lights.area, 4);
    assert!(f.lobes.glossy && !f.lobes.specular && !f.lobes.transmission);

    // Texture coordinates stay where a texture reads them and go elsewhere, with tangents
    // that no normal map needs.
    let mut twin = shipped("scenes/usd-twin/usd-twin.gltf");
    assert_eq!(strip_unused_attributes(&mut twin), 0);
    let f = SceneFeatures::of(&twin);
    assert_eq!((f.textured_materials, f.meshes_with_uvs), (1, 1));
    let mut untextured = cornell();
    let mesh = &mut untextured.meshes[0];
    let n = mesh.positions.len();
    mesh.uvs = [
        Some(vec![glam::Vec2::ZERO; n]),
        Some(vec![glam::Vec2::ONE; n]),
    ];
    mesh.tangents = Some(vec![Vec4::X; n]);
    let f = SceneFeatures::of(&untextured);
    assert_eq!((f.meshes_with_uvs, f.meshes_with_tangents), (1, 1));
    assert_eq!(strip_unused_attributes(&mut untextured), 3);
    let f = SceneFeatures::of(&untextured);
    assert_eq!((f.meshes_with_uvs, f.meshes_with_tangents), (0, 0));

    // The request: AOVs decide the film and the kernel's data and routing.
    let scene = cornell();
    let beauty = plan_for(&scene, "", PlanMode::Auto);
    // Untextured Lambert: the lanes compute the shading points, where the CPU can run them.
    let available = lucerna::integrator::packet_kernel_available();
    assert_eq!(SceneFeatures::of(&scene).uniform_meshes, 7);
    assert_eq!(
        beauty.kernel,
        Kernel {
            emitter_hits: true,
            first_hit_data: false,
            routing: false,
            packet: available,
        }
    );
    assert_eq!(
        plan_for(&scene, "", PlanMode::Packet).kernel.packet,
        available
    );
    assert!(!plan_for(&scene, "", PlanMode::Scalar).kernel.packet);
    let plates = shipped("scenes/mis-plates/mis-plates.glb");
    assert_eq!(SceneFeatures::of(&plates).microfacet_materials, 4);
    assert_eq!(
        plan_for(&plates, "", PlanMode::Auto).kernel.packet,
        available
    );
    assert!(!plan_for(&plates, "albedo", PlanMode::Auto).kernel.packet);
    // Participating media are the scalar kernel's alone, even where asked for lanes; clear
    // glass volumes are not participating media.
    let fog = shipped("scenes/media/fog-spot.gltf");
    assert_eq!(SceneFeatures::of(&fog).participating_media, 1);
    for mode in [PlanMode::Auto, PlanMode::Packet] {
        assert!(!plan_for(&fog, "", mode).kernel.packet);
    }
    let glass = shipped("scenes/glass-box/glass-box.gltf");
    assert_eq!(SceneFeatures::of(&glass).participating_media, 0);
    assert_eq!((beauty.light_layers, beauty.squares), (1, false));
    let albedo = plan_for(&scene, "albedo", PlanMode::Auto);
    assert!(albedo.kernel.first_hit_data && !albedo.kernel.routing && !albedo.kernel.packet);
    assert_eq!(albedo.data_layers, vec![Aov::Albedo]);
    let direct = plan_for(&scene, "direct", PlanMode::Auto);
    assert!(direct.kernel.routing && !direct.kernel.first_hit_data && !direct.kernel.packet);
    let all = plan_for(&scene, "all", PlanMode::Auto);
    assert!(all.kernel.routing && all.kernel.first_hit_data);
    assert!(all.single_technique && all.squares);
    assert_eq!(all.data_layers.len(), 4);
    // General forces every feature on, whatever the scene and request.
    assert_eq!(
        plan_for(&cornell_punctual(), "", PlanMode::General).kernel,
        Kernel::GENERAL
    );
}

fn render(scene: Scene, aovs: &str, mode: PlanMode, spp: u32, threads: usize) -> Film {
    render_with(scene, aovs, mode, threads, |o| o.spp = Some(spp)).0
}

fn render_with(
    mut scene: Scene,
    aovs: &str,
    mode: PlanMode,
    threads: usize,
    configure: impl FnOnce(&mut RenderOptions),
) -> (Film, RenderStats) {
    if mode != PlanMode::General {
        strip_unused_attributes(&mut scene);
    }
    let mut options = RenderOptions {
        aovs: AovSet::parse(aovs).unwrap(),
        filter: PixelFilter::box_filter(),
        plan: mode,
        ..Default::default()
    };
    configure(&mut options);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let world = World::build(scene, None, Some((24, 24)), options.settings.light_select)
            .expect("test scene builds");
        render::render(&world, &options)
    })
}

/// Non-finite contributions are dropped and counted by the packet kernel as by the scalar
/// one: with every surface of the Cornell box emitting the largest finite radiance, light
/// samples from a wall towards a nearby part of another overflow to infinity. The two
/// kernels drop the same number, and their images agree.
#[test]
fn packet_kernel_drops_and_counts_the_scalar_kernels_overflows() {
    if !lucerna::integrator::packet_kernel_available() {
        eprintln!("no AVX2 and FMA here: the packet kernel is never chosen");
        return;
    }
    let mut scene = cornell();
    for m in &mut scene.materials {
        m.emissive = Vec3::splat(f32::MAX);
    }
    let run = |mode| render_with(scene.clone(), "spp", mode, 2, |o| o.spp = Some(4));
    let (packet, packet_stats) = run(PlanMode::Packet);
    let (scalar, scalar_stats) = run(PlanMode::Scalar);
    assert!(scalar_stats.discarded > 0, "nothing overflowed");
    assert_eq!(packet_stats.discarded, scalar_stats.discarded);
    let (a, b) = (packet.planes(Aov::Beauty), scalar.planes(Aov::Beauty));
    for c in 0..3 {
        for (i, (x, y)) in a[c].iter().zip(&b[c]).enumerate() {
            assert!(
                x == y || (x - y).abs() <= 1e-6 * y.abs(),
                "pixel {i} channel {c}: {x} against {y}"
            );
        }
    }
}

/// The specialised kernels only leave out work whose result is zero or unused, and draw
/// the same random numbers: from the same seed, every layer is bit-identical to the
/// general kernel's, which is stronger than "the same within noise".
#[test]
fn specialised_and_general_kernels_render_the_same_image() {
    for (name, scene) in scenes() {
        for aovs in ["", "albedo,depth", "direct,indirect", "all"] {
            let auto = render(scene.clone(), aovs, PlanMode::Scalar, 8, 2);
            let general = render(scene.clone(), aovs, PlanMode::General, 8, 2);
            let mut lit = 0;
            for aov in auto.aovs.iter() {
                let (a, g) = (auto.planes(aov), general.planes(aov));
                assert!(
                    a == g,
                    "{name}, --aov {aov:?}: layer {} differs",
                    aov.name()
                );
                lit += a[0].iter().filter(|&&v| v > 0.0).count();
            }
            assert!(lit > 0, "{name}: the image is black");
        }
    }
}

/// The packet kernel runs the scalar kernel's estimator on the same random numbers with the
/// same operations (its lanes round as the scalar code does), so its paths are the scalar
/// kernel's and only the order in which a pixel's samples are summed differs: on every
/// scene, with the default settings, a split first vertex, a learned one (the learning
/// samples record their parts in either kernel, and the two learn the same counts), other
/// MIS heuristics, roulettes, a depth limit and other light sampling and filter, every
/// pixel agrees to 1e-6 (float rounding of the sums), as do the sample counts and
/// discarded contributions.
#[test]
fn packet_kernel_renders_the_scalar_kernels_image() {
    if !lucerna::integrator::packet_kernel_available() {
        eprintln!("no AVX2 and FMA here: the packet kernel is never chosen");
        return;
    }
    let settings: [&[(&str, &str)]; 6] = [
        &[],
        &[("split", "nee=3,bsdf=2")],
        &[("split", "auto")],
        &[("mis", "balance"), ("rr", "fixed:0.6")],
        &[("mis", "cutoff"), ("max-depth", "3"), ("rr", "off")],
        &[
            ("light-sampling", "area"),
            ("light-select", "uniform"),
            ("filter", "blackman-harris"),
        ],
    ];
    for (name, scene) in scenes() {
        for setting in settings {
            let run = |mode: PlanMode, seed: &str| {
                render_with(scene.clone(), "spp", mode, 2, |o| {
                    o.spp = Some(8);
                    o.set("seed", seed).unwrap();
                    for (k, v) in setting {
                        o.set(k, v).unwrap();
                    }
                })
            };
            let (packet, packet_stats) = run(PlanMode::Packet, "1");
            let (scalar, scalar_stats) = run(PlanMode::Scalar, "1");
            let (a, b) = (packet.planes(Aov::Beauty), scalar.planes(Aov::Beauty));
            for c in 0..3 {
                for (i, (x, y)) in a[c].iter().zip(&b[c]).enumerate() {
                    assert!(
                        (x - y).abs() <= 1e-6 * y.abs().max(1e-3),
                        "{name} {setting:?}: pixel {i} channel {c}: {x} against {y}"
                    );
                }
            }
            assert!(b[0].iter().any(|&v| v > 0.0), "{name}: the image is black");
            assert!(packet.planes(Aov::Spp) == scalar.planes(Aov::Spp));
            assert_eq!(packet_stats.discarded, scalar_stats.discarded);
            assert_eq!(packet_stats.samples, scalar_stats.samples);
            assert_eq!(packet_stats.learned_split, scalar_stats.learned_split);
        }
    }
}

/// The packet kernel's image does not depend on the thread count, and with independent
/// random numbers (which it draws in another order than the scalar kernel) its image mean
/// agrees with a many-sample render within the standard errors (|z| < 4.5).
#[test]
fn packet_kernel_is_deterministic_and_unbiased() {
    if !lucerna::integrator::packet_kernel_available() {
        eprintln!("no AVX2 and FMA here: the packet kernel is never chosen");
        return;
    }
    let configure = |o: &mut RenderOptions| {
        o.spp = Some(16);
        o.settings.sampler = SamplerKind::Independent;
        o.set("split", "nee=2,bsdf=3").unwrap();
    };
    let (two, _) = render_with(cornell(), "variance", PlanMode::Packet, 2, configure);
    let (one, _) = render_with(cornell(), "variance", PlanMode::Packet, 1, configure);
    for aov in two.aovs.iter() {
        assert!(two.planes(aov) == one.planes(aov), "{}", aov.name());
    }
    let reference = render(cornell(), "variance", PlanMode::Scalar, 1024, 2);
    for c in 0..3 {
        let (m, se) = common::scenes::mean_and_error(&two, c, |_| true);
        let (m_ref, se_ref) = common::scenes::mean_and_error(&reference, c, |_| true);
        let z = (m - m_ref) / (se * se + se_ref * se_ref).sqrt();
        assert!(z.abs() < 4.5, "channel {c}: {m} against {m_ref}, z = {z}");
    }
}

/// Mean over the image of the variance of the pixel mean, relative as relMSE weighs it:
/// the relMSE a render expects against the exact image.
fn predicted_rel_mse(film: &Film) -> f64 {
    let (beauty, variance) = (film.planes(Aov::Beauty), film.planes(Aov::Variance));
    let mut sum = 0.0;
    for c in 0..3 {
        for (m, v) in beauty[c].iter().zip(&variance[c]) {
            sum += *v as f64 / ((*m as f64).powi(2) + 0.01);
        }
    }
    sum / (3 * beauty[0].len()) as f64
}

/// Adaptive sampling stops where its target is met, samples pixels unevenly, and its
/// decisions do not depend on the thread count, in the scalar and the packet kernel.
#[test]
fn adaptive_sampling_meets_its_noise_target() {
    for mode in [PlanMode::Auto, PlanMode::Packet] {
        adaptive_sampling_meets_its_noise_target_in(mode);
    }
}

fn adaptive_sampling_meets_its_noise_target_in(mode: PlanMode) {
    let threshold = 0.05f32;
    let (film, stats) = render_with(cornell(), "variance,spp", mode, 2, |o| {
        o.noise_threshold = Some(threshold);
    });
    let predicted = predicted_rel_mse(&film);
    // The allocation aims at threshold²; deficits under a sixteenth of a pixel's count are
    // left, so the prediction may exceed it by that much (and by estimation noise).
    assert!(
        predicted < 1.25 * (threshold * threshold) as f64,
        "predicted relMSE {predicted} against target {}",
        threshold * threshold
    );
    let spp = &film.planes(Aov::Spp)[0];
    let (lo, hi) = spp
        .iter()
        .fold((f32::MAX, 0.0f32), |(lo, hi), &s| (lo.min(s), hi.max(s)));
    assert!(lo >= render::DEFAULT_MIN_SPP as f32);
    assert!(hi >= 2.0 * lo, "samples range over {lo}..{hi}");
    assert_eq!(stats.spp as f32, hi);

    let (one_thread, _) = render_with(cornell(), "variance,spp", mode, 1, |o| {
        o.noise_threshold = Some(threshold);
    });
    for aov in film.aovs.iter() {
        assert!(film.planes(aov) == one_thread.planes(aov), "{}", aov.name());
    }
}

/// The stopping rule reads a pixel's neighbours, not its own samples, so the image mean
/// of adaptive renders is unbiased: over 12 seeds, the mean image agrees with a uniform
/// render of many more samples within the standard errors of both (|z| < 4.5), and the
/// relMSE of each adaptive render is close to what it predicted.
#[test]
fn adaptive_sampling_is_unbiased() {
    let reference = render(cornell(), "variance", PlanMode::Auto, 2048, 2);
    // The green channel's image mean and the variance of that mean.
    let mean_and_var = |film: &Film| {
        let (b, v) = (film.planes(Aov::Beauty), film.planes(Aov::Variance));
        let n = b[1].len() as f64;
        let m = b[1].iter().map(|&x| x as f64).sum::<f64>() / n;
        let var = v[1].iter().map(|&x| x as f64).sum::<f64>() / (n * n);
        (m, var)
    };
    let (m_ref, var_ref) = mean_and_var(&reference);
    let (mut sum, mut var_sum) = (0.0, 0.0);
    let seeds = 12;
    for seed in 0..seeds {
        // Independent samples: the variance layer then predicts the error exactly (Sobol
        // points do better than their sample variance says).
        let (film, _) = render_with(cornell(), "variance", PlanMode::Auto, 2, |o| {
            o.noise_threshold = Some(0.05);
            o.settings.seed = 100 + seed;
            o.settings.sampler = SamplerKind::Independent;
        });
        let (m, var) = mean_and_var(&film);
        sum += m;
        var_sum += var;
        let actual = rel_mse(&film, &reference);
        let predicted = predicted_rel_mse(&film);
        assert!(
            actual < 1.5 * predicted && actual > 0.5 * predicted,
            "seed {seed}: relMSE {actual} against the predicted {predicted}"
        );
    }
    let mean = sum / seeds as f64;
    let se = (var_sum / (seeds * seeds) as f64 + var_ref).sqrt();
    let z = (mean - m_ref) / se;
    eprintln!("adaptive mean {mean:.6}, uniform {m_ref:.6}, z {z:.2}");
    assert!(z.abs() < 4.5, "adaptive mean {mean} vs {m_ref}: z = {z}");
}

/// Path guiding runs in the scalar kernel: `on` keeps the packet kernel out; `auto` guides
/// only where the scalar kernel runs anyway (here: light layers) and never a scene whose
/// every lobe is a delta.
#[test]
fn guiding_plans_keep_to_the_scalar_kernel() {
    use lucerna::integrator::guiding::GuidingMode;
    let scene = cornell();
    let beauty = plan_for(&scene, "beauty", PlanMode::Packet);
    let packet = beauty.kernel.packet;
    let auto = beauty.clone().with_guiding(GuidingMode::Auto);
    assert_eq!((auto.guiding, auto.kernel.packet), (!packet, packet));
    let on = beauty.clone().with_guiding(GuidingMode::On);
    assert!(on.guiding && !on.kernel.packet);
    let off = beauty.with_guiding(GuidingMode::Off);
    assert_eq!((off.guiding, off.kernel.packet), (false, packet));
    let comp = plan_for(&scene, "comp", PlanMode::Auto).with_guiding(GuidingMode::Auto);
    assert!(comp.guiding && !comp.kernel.packet);
    assert!(comp.to_string().contains("path guiding on"), "{comp}");
    let mut mirrors = plan_for(&scene, "comp", PlanMode::Auto);
    mirrors.features.lobes = Lobes {
        specular: true,
        ..Lobes::default()
    };
    assert!(!mirrors.with_guiding(GuidingMode::Auto).guiding);
}

/// Learned light selection runs in the scalar kernel: the plan keeps the packet kernel out
/// and says so.
#[test]
fn learned_light_selection_keeps_to_the_scalar_kernel() {
    use lucerna::integrator::LightSelect;
    let scene = cornell();
    let beauty = plan_for(&scene, "beauty", PlanMode::Packet);
    let learned = beauty.clone().with_light_selection(LightSelect::Learned);
    assert!(learned.learned_lights && !learned.kernel.packet);
    assert!(
        learned.to_string().contains("learned light selection on"),
        "{learned}"
    );
    let tree = beauty
        .clone()
        .with_light_selection(LightSelect::Contribution);
    assert_eq!(
        (tree.learned_lights, tree.kernel.packet),
        (false, beauty.kernel.packet)
    );
}
