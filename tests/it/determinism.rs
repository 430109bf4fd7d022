//! An image depends on the scene, the settings and the seed, never on the thread count.

use crate::common;

use common::scenes::render;
use lucerna::film::aov::ALL;
use lucerna::ingest;
use lucerna::integrator::Settings;
use lucerna::integrator::guiding::GuidingMode;
use lucerna::sampling::sampler::SamplerKind;

#[test]
fn identical_images_with_one_and_two_threads() {
    for sampler in [SamplerKind::Sobol, SamplerKind::Independent] {
        let settings = Settings {
            sampler,
            seed: 11,
            ..Default::default()
        };
        let (one, _) = render(
            ingest::default_scene().unwrap(),
            (37, 29),
            20,
            settings.clone(),
            1,
        );
        let (two, _) = render(
            ingest::default_scene().unwrap(),
            (37, 29),
            20,
            settings.clone(),
            2,
        );
        for aov in ALL {
            assert!(
                one.planes(aov) == two.planes(aov),
                "{sampler:?}: {} differs",
                aov.name()
            );
        }
        let other_seed = Settings {
            seed: 12,
            ..settings
        };
        let (three, _) = render(
            ingest::default_scene().unwrap(),
            (37, 29),
            20,
            other_seed,
            2,
        );
        assert!(
            one.planes(ALL[0]) != three.planes(ALL[0]),
            "the seed changes the noise"
        );
    }
}

/// Path guiding learns from every tile in tile order: a guided render is the same with one
/// thread and with two, and it is guided (it differs from the unguided render).
#[test]
fn guided_images_are_identical_with_one_and_two_threads() {
    let settings = Settings {
        seed: 5,
        guiding: GuidingMode::On,
        ..Default::default()
    };
    let scene = || ingest::default_scene().unwrap();
    let (one, _) = render(scene(), (40, 30), 40, settings.clone(), 1);
    let (two, _) = render(scene(), (40, 30), 40, settings.clone(), 2);
    let beauty = ALL[0];
    assert!(
        one.planes(beauty) == two.planes(beauty),
        "guided renders differ"
    );
    let unguided = Settings {
        guiding: GuidingMode::Off,
        ..settings
    };
    let (plain, _) = render(scene(), (40, 30), 40, unguided, 2);
    assert!(
        one.planes(beauty) != plain.planes(beauty),
        "guiding changed nothing"
    );
}

/// Learned light selection merges what tiles learned in tile order: its render is the same
/// with one thread and with two, and it selects differently from the light tree alone
/// (the flat of eight rooms, where what is learned matters).
#[test]
fn learned_light_selection_is_identical_with_one_and_two_threads() {
    use lucerna::integrator::LightSelect;
    let settings = Settings {
        seed: 3,
        light_select: LightSelect::Learned,
        ..Default::default()
    };
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/many-lights/many-lights.glb");
    let scene = || ingest::load(&path, &Default::default()).unwrap();
    let (one, _) = render(scene(), (48, 32), 40, settings.clone(), 1);
    let (two, _) = render(scene(), (48, 32), 40, settings.clone(), 2);
    let beauty = ALL[0];
    assert!(
        one.planes(beauty) == two.planes(beauty),
        "learned selection renders differ"
    );
    let tree = Settings {
        light_select: LightSelect::Contribution,
        ..settings
    };
    let (plain, _) = render(scene(), (48, 32), 40, tree, 2);
    assert!(
        one.planes(beauty) != plain.planes(beauty),
        "learned selection changed nothing"
    );
}
