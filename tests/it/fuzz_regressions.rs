//! Inputs the fuzz targets (tools/fuzz) found crashing, each kept under
//! tests/fuzz-regressions/<target>/ after its bug was fixed. Every file goes through what its
//! target does (load, prepare, render 4x4 at 1 spp; `image_decode` decodes; `density_grid`
//! walks rays through the grid's medium) and must give the outcome that
//! tests/fuzz-regressions/expected.json records: an error containing a fragment, or a render
//! with finite pixels (and no NaN contribution discarded, unless `discards` says so). Never
//! a panic.

use lucerna::film::aov::Aov;
use lucerna::integrator::LightSelect;
use lucerna::render::{self, RenderOptions};
use lucerna::world::World;
use std::path::Path;

#[path = "../../tools/fuzz/fuzz_targets/grid_walks.rs"]
mod grid_walks;

/// Loads `bytes` as `target` does: a glTF file, or a scene file's manifest, a zero byte
/// and its buffer.
fn load(target: &str, bytes: &[u8]) -> lucerna::Result<lucerna::scene::Scene> {
    match target {
        "gltf_ingest" => lucerna::ingest::gltf::import(bytes, "fuzz.gltf", None),
        "scene_file" => {
            let split = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
            let buffer = bytes.get(split + 1..).unwrap_or_default();
            lucerna::scene::file::parse(Path::new("fuzz.lucerna"), &bytes[..split], |_| {
                Ok(buffer.to_vec().into())
            })
        }
        _ => panic!("unknown fuzz target {target}"),
    }
}

/// What the fuzz targets do with an input: `Err(message)` if it is refused, else the
/// rendered pixels are checked finite (an image is only decoded).
fn run(target: &str, bytes: &[u8], discards: bool) -> Result<(), String> {
    if target == "density_grid" {
        return grid_walks::walk_the_grid(bytes);
    }
    if target == "vdb_decode" {
        return grid_walks::walk_the_vdb(bytes);
    }
    if target == "image_decode" {
        // Measuring from the header alone (the texture memory's decision) must not panic.
        let _ = lucerna::ingest::image::decoded_bytes(bytes);
        let image = lucerna::ingest::image::decode(bytes)?;
        assert!(image.width > 0 && image.height > 0);
        return Ok(());
    }
    let scene = load(target, bytes).map_err(|e| e.to_string())?;
    let world =
        World::build(scene, None, Some((4, 4)), LightSelect::Power).map_err(|e| e.to_string())?;
    let options = RenderOptions {
        spp: Some(1),
        ..Default::default()
    };
    let (film, stats) = render::render(&world, &options);
    // Corrupt data may make NaN contributions, which the film must drop (and count) where
    // expected.json says so; never a NaN pixel.
    assert!(
        discards || stats.discarded == 0,
        "{} discarded",
        stats.discarded
    );
    for plane in film.planes(Aov::Beauty) {
        assert!(plane.iter().all(|v| v.is_finite()));
    }
    Ok(())
}

#[test]
fn fuzz_findings_stay_fixed() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz-regressions");
    let expected: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("expected.json")).unwrap()).unwrap();
    let expected = expected.as_object().unwrap();
    let mut checked = 0;
    for target in [
        "gltf_ingest",
        "scene_file",
        "image_decode",
        "density_grid",
        "vdb_decode",
    ] {
        let Ok(entries) = std::fs::read_dir(dir.join(target)) else {
            continue;
        };
        for entry in entries {
            let path = entry.unwrap().path();
            let key = format!("{target}/{}", path.file_name().unwrap().to_string_lossy());
            let case = expected
                .get(&key)
                .unwrap_or_else(|| panic!("{key}: not described in expected.json"));
            let discards = case.get("discards").and_then(|d| d.as_bool()) == Some(true);
            let outcome = run(target, &std::fs::read(&path).unwrap(), discards);
            match (case.get("error").and_then(|e| e.as_str()), outcome) {
                (Some(fragment), Err(message)) => assert!(
                    message.contains(fragment),
                    "{key}: error {message:?} lacks {fragment:?}"
                ),
                (None, Ok(())) => {}
                (want, got) => panic!("{key}: expected error {want:?}, got {got:?}"),
            }
            checked += 1;
        }
    }
    assert_eq!(checked, expected.len(), "expected.json lists missing files");
}
