//! The AOV invariants of docs/reference.md ("The EXR"), per pixel, and the unbiasedness of the
//! single-technique direct-light layers.

use crate::common;

use common::scenes::{render, render_aovs};
use glam::{DVec3, Vec2, Vec3};
use lucerna::film::aov::{ALL, Aov, AovSet, LOBES};
use lucerna::film::record::{Contribution, FirstHit, Recorder, Source};
use lucerna::ingest;
use lucerna::integrator::estimator::RayCounts;
use lucerna::integrator::path::PathTracer;
use lucerna::integrator::split::FirstSplit;
use lucerna::integrator::{Settings, Split};
use lucerna::sampling::sampler::{Sampler, SamplerKind};
use lucerna::scene::{BsdfModel, Light, LightKind, Scene};
use lucerna::world::World;

/// The Cornell box with a point light, a spot light and a perfect mirror on the tall block,
/// so that both techniques have something only they can sample.
fn cornell_with_delta_paths() -> Scene {
    let mut scene = ingest::default_scene().unwrap();
    scene.lights.push(Light {
        name: "point".into(),
        kind: LightKind::Point {
            position: DVec3::new(0.2, 0.45, 0.25),
            intensity: Vec3::new(0.05, 0.04, 0.03),
        },
    });
    scene.lights.push(Light {
        name: "spot".into(),
        kind: LightKind::Spot {
            position: DVec3::new(0.4, 0.5, 0.1),
            direction: DVec3::new(-0.3, -1.0, 0.2),
            intensity: Vec3::splat(0.05),
            inner_cone: 0.3,
            outer_cone: 0.6,
        },
    });
    common::scenes::make_tall_block_a_mirror(&mut scene);
    scene
}

fn assert_close(name: &str, a: f32, b: f32) {
    assert!(
        (a - b).abs() <= 1e-5 * a.abs().max(b.abs()) + 1e-6,
        "{name}: {a} vs {b}"
    );
}

/// In every pixel and channel, `layers` plus the emission add up to the beauty.
fn assert_layers_and_emission_make_beauty(
    what: &str,
    layers: &[Vec<Vec<f32>>],
    emission: &[Vec<f32>],
    beauty: &[Vec<f32>],
) {
    for i in 0..beauty[0].len() {
        for c in 0..3 {
            let sum: f32 = layers.iter().map(|l| l[c][i]).sum();
            assert_close(what, beauty[c][i], sum + emission[c][i]);
        }
    }
}

#[test]
fn layer_sums_hold_in_every_pixel() {
    for scene in [ingest::default_scene().unwrap(), cornell_with_delta_paths()] {
        let (film, stats) = render(scene, (40, 40), 16, Settings::default(), 2);
        assert_eq!(stats.discarded, 0);
        let p = |aov: Aov| film.planes(aov);
        let (beauty, emission, direct, indirect) = (
            p(Aov::Beauty),
            p(Aov::Emission),
            p(Aov::Direct),
            p(Aov::Indirect),
        );
        let (nee, bsdf) = (p(Aov::Nee), p(Aov::Bsdf));
        let (dn, db, inn, ib) = (
            p(Aov::DirectNee),
            p(Aov::DirectBsdf),
            p(Aov::IndirectNee),
            p(Aov::IndirectBsdf),
        );
        for i in 0..beauty[0].len() {
            for c in 0..3 {
                assert_close(
                    "beauty = emission + direct + indirect",
                    beauty[c][i],
                    emission[c][i] + direct[c][i] + indirect[c][i],
                );
                assert_close(
                    "direct = direct_nee + direct_bsdf",
                    direct[c][i],
                    dn[c][i] + db[c][i],
                );
                assert_close(
                    "indirect = indirect_nee + indirect_bsdf",
                    indirect[c][i],
                    inn[c][i] + ib[c][i],
                );
                assert_close(
                    "beauty = emission + nee + bsdf",
                    beauty[c][i],
                    emission[c][i] + nee[c][i] + bsdf[c][i],
                );
                assert_close(
                    "nee = direct_nee + indirect_nee",
                    nee[c][i],
                    dn[c][i] + inn[c][i],
                );
            }
        }
        let (alpha, spp, var) = (&beauty[3], &p(Aov::Spp)[0], p(Aov::Variance));
        let (normal, albedo, depth) = (p(Aov::Normal), p(Aov::Albedo), &p(Aov::Depth)[0]);
        for i in 0..alpha.len() {
            assert!((0.0..=1.0).contains(&alpha[i]));
            assert_eq!(spp[i], 16.0);
            assert!(
                (0..3)
                    .all(|c| var[c][i] >= 0.0 && albedo[c][i] >= 0.0 && albedo[c][i] <= 1.0 + 1e-6)
            );
            let n = Vec3::new(normal[0][i], normal[1][i], normal[2][i]);
            assert!(n.length() <= 1.0 + 1e-5);
            // The camera sits outside the open box: every pixel sees a wall (depth > 0).
            assert!(depth[i] > 0.0 && depth[i] < 2.0, "depth {}", depth[i]);
        }
    }
}

#[test]
fn depth_limits_route_to_the_right_layers() {
    let zero = |film: &lucerna::film::Film, aov| {
        film.planes(aov).iter().all(|p| p.iter().all(|&v| v == 0.0))
    };
    let settings = |d| Settings {
        max_depth: Some(d),
        ..Default::default()
    };
    let (film, _) = render(
        ingest::default_scene().unwrap(),
        (16, 16),
        4,
        settings(0),
        1,
    );
    assert!(zero(&film, Aov::Direct) && zero(&film, Aov::Indirect) && !zero(&film, Aov::Emission));
    let (film, _) = render(
        ingest::default_scene().unwrap(),
        (16, 16),
        4,
        settings(1),
        1,
    );
    assert!(zero(&film, Aov::Indirect) && !zero(&film, Aov::Direct));
}

#[test]
fn only_requested_layers_are_stored() {
    let set = AovSet::parse("direct,albedo").unwrap();
    assert_eq!(
        set.iter().collect::<Vec<_>>(),
        vec![Aov::Beauty, Aov::Direct, Aov::Albedo]
    );
    assert_eq!(AovSet::parse("all").unwrap().iter().count(), ALL.len());
    assert!(AovSet::parse("beauty,nonsense").is_err());
}

/// Per-sample statistics of direct light by the MIS combination and by each technique alone.
#[derive(Default)]
struct DirectStats {
    sample: [Vec3; 3],
    sum: [[f64; 3]; 2],
    sum2: [[f64; 3]; 2],
    n: u64,
}

impl Recorder for DirectStats {
    fn wants_single_technique(&self) -> bool {
        true
    }
    fn wants_lobes(&self) -> bool {
        false
    }
    fn contribution(&mut self, c: Contribution) {
        if c.depth == 1 {
            assert_ne!(c.source, Source::Emission);
            self.sample[0] += c.value;
            let single = c
                .single_technique
                .expect("direct contributions carry single-technique values");
            self.sample[1] += single[0];
            self.sample[2] += single[1];
        }
    }
    fn first_hit(&mut self, _: Option<FirstHit>) {}
}

impl DirectStats {
    fn end_sample(&mut self) {
        for k in 0..2 {
            let d = (self.sample[k + 1] - self.sample[0]).as_dvec3();
            for c in 0..3 {
                self.sum[k][c] += d[c];
                self.sum2[k][c] += d[c] * d[c];
            }
        }
        self.sample = [Vec3::ZERO; 3];
        self.n += 1;
    }
}

#[test]
fn single_technique_layers_estimate_direct_light_without_bias() {
    // Per sample, (technique alone − MIS combination) has expectation 0. Independent samples
    // over the image; |mean| within 4.5 standard errors (false alarm 7e-6 per channel).
    for scene in [ingest::default_scene().unwrap(), cornell_with_delta_paths()] {
        let world = World::build(
            scene,
            None,
            Some((24, 24)),
            lucerna::integrator::LightSelect::Power,
        )
        .unwrap();
        let settings = Settings {
            sampler: SamplerKind::Independent,
            ..Default::default()
        };
        let no_split = FirstSplit::fixed(Split { nee: 1, bsdf: 1 });
        let tracer = PathTracer::<true, false>::new(&world, &settings, None, no_split);
        let mut sampler = Sampler::new(settings.sampler, 3);
        let mut stats = DirectStats::default();
        let mut rays = RayCounts::default();
        for y in 0..24 {
            for x in 0..24 {
                for s in 0..256 {
                    sampler.start(x, y, s);
                    let cs = sampler.camera();
                    let ray = world
                        .camera
                        .generate_ray(Vec2::new(x as f32, y as f32) + cs.film, cs.lens);
                    tracer.trace(
                        ray,
                        0,
                        &mut sampler,
                        &mut stats,
                        &mut rays,
                        None,
                        None,
                        None,
                        None,
                    );
                    stats.end_sample();
                }
            }
        }
        for (k, name) in ["nee alone", "bsdf alone"].iter().enumerate() {
            for c in 0..3 {
                let n = stats.n as f64;
                let mean = stats.sum[k][c] / n;
                let se = ((stats.sum2[k][c] / n - mean * mean) / n).sqrt();
                assert!(
                    mean.abs() <= 4.5 * se,
                    "{name} channel {c}: bias {mean} ± {se}"
                );
                assert!(se > 0.0);
            }
        }
    }
}

#[test]
fn per_depth_layers_partition_direct_and_indirect() {
    let settings = Settings {
        max_depth: Some(3),
        ..Default::default()
    };
    let scene = ingest::default_scene().unwrap();
    let aovs =
        AovSet::parse("direct,indirect,nee_d1,bsdf_d1,nee_d2,bsdf_d2,nee_d3,bsdf_d3").unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let (film, _) = pool.install(|| {
        let world = World::build(scene, None, Some((24, 24)), settings.light_select).unwrap();
        let options = lucerna::render::RenderOptions {
            spp: Some(8),
            settings,
            aovs,
            ..Default::default()
        };
        lucerna::render::render(&world, &options)
    });
    let p = |name: &str| film.planes(Aov::parse(name).unwrap());
    let (direct, indirect) = (p("direct"), p("indirect"));
    let layers: Vec<_> = [
        "nee_d1", "bsdf_d1", "nee_d2", "bsdf_d2", "nee_d3", "bsdf_d3",
    ]
    .iter()
    .map(|n| p(n))
    .collect();
    for i in 0..direct[0].len() {
        for c in 0..3 {
            assert_close(
                "direct = nee_d1 + bsdf_d1",
                direct[c][i],
                layers[0][c][i] + layers[1][c][i],
            );
            let deeper: f32 = layers[2..].iter().map(|l| l[c][i]).sum();
            assert_close("indirect = d2 + d3", indirect[c][i], deeper);
        }
    }
    assert!(layers[4][0].iter().any(|&v| v > 0.0), "depth 3 gets light");
    assert_eq!(Aov::parse("nee_d17"), None);
}

/// The Cornell box's walls in every BSDF lucerna has: the back wall a coated glTF
/// dielectric, the floor Phong, the tall block a perfect mirror, the rest Lambertian.
fn cornell_with_every_lobe() -> Scene {
    let mut scene = cornell_with_delta_paths();
    let mut restyle = |instance: &str, f: &dyn Fn(&mut lucerna::scene::Material)| {
        let mesh = scene
            .instances
            .iter()
            .find(|i| i.name == instance)
            .unwrap()
            .mesh as usize;
        let mut m = scene.materials[scene.meshes[mesh].material as usize].clone();
        f(&mut m);
        scene.materials.push(m);
        scene.meshes[mesh].material = (scene.materials.len() - 1) as u32;
    };
    restyle("back_wall", &|m| {
        m.model = BsdfModel::GltfPbr;
        m.roughness = 0.3;
        m.metallic = 0.2;
        m.clearcoat = 0.5;
        m.clearcoat_roughness = 0.1;
    });
    restyle("floor", &|m| {
        m.model = BsdfModel::Phong {
            exponent: 30.0,
            specular: Vec3::splat(0.2),
        };
    });
    scene
}

/// Per pixel, the lobe layers plus `emission` make the beauty (up to float rounding), the
/// lobe colours lie in [0, 1] and add up to the albedo, and where a single lobe exists its
/// colour is the albedo: Lambertian walls (diffuse), the mirror and the metal plates
/// (glossy). In the glass box, light through the glass ball and the rough slab fills the
/// transmission layers (the thin pane is a filter: what is seen through it keeps the lobes
/// of what lies behind); in the chromatic cube, light first scattered in the medium fills
/// the volume layers, and they are empty everywhere else.
#[test]
fn lobe_layers_and_emission_make_the_beauty() {
    let plates = ingest::load(
        std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/scenes/mis-plates/mis-plates.glb"
        )),
        &Default::default(),
    )
    .unwrap();
    let glass = ingest::load(
        std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/scenes/glass-box/glass-box.gltf"
        )),
        &Default::default(),
    )
    .unwrap();
    let media = ingest::load(
        std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/scenes/media/chromatic-cube.gltf"
        )),
        &Default::default(),
    )
    .unwrap();
    let aovs = AovSet::parse("lobes,emission,albedo,direct,indirect").unwrap();
    // (scene, whether it has diffuse surfaces (the plates are all metal), glossy ones
    // (the media scene is Lambertian), whether it transmits, whether light scatters in a
    // medium)
    let scenes = [
        (cornell_with_every_lobe(), true, true, false, false),
        (plates, false, true, false, false),
        (glass, true, true, true, false),
        (media, true, false, false, true),
    ];
    for (scene, has_diffuse, has_glossy, transmits, scatters_in_media) in scenes {
        let (film, stats) = render_aovs(scene, (48, 40), 16, Settings::default(), 2, aovs.clone());
        assert_eq!(stats.discarded, 0);
        let p = |aov: Aov| film.planes(aov);
        let (beauty, emission, albedo) = (p(Aov::Beauty), p(Aov::Emission), p(Aov::Albedo));
        let (direct, indirect) = (p(Aov::Direct), p(Aov::Indirect));
        // The eight light layers of LOBES (then come the colours).
        let lobes: Vec<_> = LOBES[..8].iter().map(|&a| p(a)).collect();
        let colours = [Aov::DiffuseColor, Aov::GlossyColor, Aov::TransmissionColor].map(p);
        assert_layers_and_emission_make_beauty(
            "lobes + emission = beauty",
            &lobes,
            &emission,
            &beauty,
        );
        let (mut glossy_light, mut diffuse_light, mut transmitted_light) = (0.0, 0.0, 0.0);
        let mut medium_light = 0.0;
        for i in 0..beauty[0].len() {
            for c in 0..3 {
                let direct_sum = lobes[0][c][i] + lobes[2][c][i] + lobes[4][c][i] + lobes[6][c][i];
                assert_close("direct lobes = direct", direct[c][i], direct_sum);
                let indirect_sum =
                    lobes[1][c][i] + lobes[3][c][i] + lobes[5][c][i] + lobes[7][c][i];
                assert_close("indirect lobes = indirect", indirect[c][i], indirect_sum);
                if !transmits {
                    assert!(
                        lobes[4][c][i] == 0.0 && lobes[5][c][i] == 0.0,
                        "nothing transmits"
                    );
                }
                let [d, g, t] = [0, 1, 2].map(|k| colours[k][c][i]);
                for v in [d, g, t] {
                    assert!((0.0..=1.0 + 1e-6).contains(&v), "lobe colour {v}");
                }
                assert_close("lobe colours add up to the albedo", albedo[c][i], d + g + t);
                if [d, g, t].iter().filter(|&&v| v > 0.0).count() <= 1 {
                    assert_close(
                        "a single lobe's colour is the albedo",
                        albedo[c][i],
                        d.max(g).max(t),
                    );
                }
                diffuse_light += lobes[0][c][i] + lobes[1][c][i];
                glossy_light += lobes[2][c][i] + lobes[3][c][i];
                transmitted_light += lobes[4][c][i] + lobes[5][c][i];
                medium_light += lobes[6][c][i] + lobes[7][c][i];
            }
        }
        assert_eq!(diffuse_light > 0.0, has_diffuse);
        assert_eq!(glossy_light > 0.0, has_glossy);
        assert_eq!(transmitted_light > 0.0, transmits);
        assert_eq!(medium_light > 0.0, scatters_in_media);
    }
}

/// Per pixel, the light-group layers plus `emission` make the beauty: two groups the scene
/// declares (the punctual lights, the ceiling light) and `default` for what no group names
/// (the environment); each group's layer holds light.
#[test]
fn light_groups_and_emission_make_the_beauty() {
    let mut scene = cornell_with_delta_paths();
    ingest::set_constant_environment(&mut scene, Vec3::new(0.2, 0.3, 0.4));
    for member in ["point", "spot"] {
        scene.add_to_light_group("warm", member);
    }
    scene.add_to_light_group("ceiling", "light");
    let aovs = AovSet::parse("lightgroups,emission").unwrap();
    let (film, stats) = render_aovs(scene, (40, 40), 16, Settings::default(), 2, aovs);
    assert_eq!(stats.discarded, 0);
    let groups: Vec<Aov> = film
        .aovs
        .iter()
        .filter(|a| matches!(a, Aov::LightGroup(_)))
        .collect();
    let names: Vec<String> = groups.iter().map(|&a| film.aovs.layer_name(a)).collect();
    assert_eq!(names, ["lg_warm", "lg_ceiling", "lg_default"]);
    let (beauty, emission) = (film.planes(Aov::Beauty), film.planes(Aov::Emission));
    let layers: Vec<_> = groups.iter().map(|&a| film.planes(a)).collect();
    assert_layers_and_emission_make_beauty(
        "groups + emission = beauty",
        &layers,
        &emission,
        &beauty,
    );
    let mut totals = vec![0.0f64; layers.len()];
    for i in 0..beauty[0].len() {
        for c in 0..3 {
            for (t, l) in totals.iter_mut().zip(&layers) {
                *t += l[c][i] as f64;
            }
        }
    }
    assert!(totals.iter().all(|&t| t > 0.0), "{totals:?}");
}
