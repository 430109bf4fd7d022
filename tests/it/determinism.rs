//! An image depends on the scene, the settings and the seed, never on the thread count.

use crate::common;

use common::scenes::render;
use lucerna::film::aov::ALL;
use lucerna::ingest;
use lucerna::integrator::Settings;
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
