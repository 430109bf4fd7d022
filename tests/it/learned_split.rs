//! `--split auto`: the counts it learns follow where a scene's noise comes from (the MIS
//! plates' from the light samples at the first vertex, the indirect room's from the paths
//! beyond it), the same at every run, and the EXR header records them. That the learned
//! split converges to the same image is `tests/it/convergence.rs`'s.

use crate::common;

use common::cli::{header_text, lucerna_ok, temp_dir};
use lucerna::film::aov::AovSet;
use lucerna::film::filter::PixelFilter;
use lucerna::ingest;
use lucerna::integrator::{LightSelect, Settings, Split, SplitChoice};
use lucerna::render::{self, RenderOptions};
use lucerna::world::World;
use std::path::Path;

fn learned(scene: &str, threads: usize) -> Split {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(scene);
    let scene = ingest::load(&path, &Default::default()).unwrap();
    let world = World::build(scene, None, Some((64, 64)), LightSelect::Power).unwrap();
    let options = RenderOptions {
        spp: Some(8),
        settings: Settings {
            split: SplitChoice::Auto,
            ..Default::default()
        },
        aovs: AovSet::parse("beauty").unwrap(),
        filter: PixelFilter::box_filter(),
        ..Default::default()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let stats = pool.install(|| render::render(&world, &options).1);
    stats
        .learned_split
        .expect("8 samples include the learning samples")
}

#[test]
fn the_counts_follow_where_the_noise_comes_from() {
    let plates = learned("mis-plates/mis-plates.glb", 2);
    assert!(
        plates.nee >= 3 && plates.nee > plates.bsdf,
        "MIS plates: {plates:?}"
    );
    let room = learned("indirect-room/indirect-room.glb", 2);
    assert!(
        room.bsdf >= 3 && room.bsdf > room.nee,
        "indirect room: {room:?}"
    );
    // Sums in tile order: one thread learns what two do.
    assert_eq!(learned("mis-plates/mis-plates.glb", 1), plates);
}

#[test]
fn the_header_records_the_learned_counts() {
    let dir = temp_dir("learned-split");
    let out = dir.join("auto.exr");
    lucerna_ok(&[
        "render",
        "-q",
        "--resolution",
        "32x24",
        "--spp",
        "6",
        "--split",
        "auto",
        "-o",
        out.to_str().unwrap(),
    ]);
    let split = header_text(&out, "lucerna/split_learned");
    assert!(
        Split::parse(&split).is_ok() && split.starts_with("nee="),
        "{split}"
    );
    assert!(header_text(&out, "lucerna/settings").contains("split = \"auto\""));
}
