//! Textures beyond the texture memory: read from tiled copies through the tile cache, they
//! render the image of the same render with every texture in memory, pixel for pixel, from
//! glTF and from scene files, and the render says so.

use crate::common::cli::{lucerna_ok, lucerna_stderr, temp_dir};
use lucerna::output::exr;
use std::path::Path;

const AVOCADO: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/assets/gltf/Avocado/Avocado.gltf"
);

/// The beauty of a 16-spp render of `scene` to `out` with `extra` options, and its stderr.
fn render(scene: &Path, out: &Path, extra: &[&str]) -> (Vec<f32>, String) {
    let mut args = vec![
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--spp",
        "16",
        "--resolution",
        "96x96",
        "--env",
        "1,1,1",
    ];
    args.extend_from_slice(extra);
    let (ok, stderr) = lucerna_stderr(&args);
    assert!(ok, "{stderr}");
    let (planes, _) = exr::read(out).unwrap();
    let beauty = ["R", "G", "B"]
        .iter()
        .flat_map(|c| planes.channel(c).unwrap().to_vec())
        .collect();
    (beauty, stderr)
}

#[test]
fn textures_through_the_cache_render_the_image_of_textures_in_memory() {
    let dir = temp_dir("texture-cache");
    let scene_file = dir.join("avocado.lucerna");
    lucerna_ok(&["convert", AVOCADO, "-o", scene_file.to_str().unwrap()]);
    for scene in [Path::new(AVOCADO), &scene_file] {
        for filter in ["bilinear", "mip"] {
            // A render of `scene` with this filter and `extra` options.
            let run = |out: &str, extra: &[&str]| {
                let mut args = vec!["--texture-filter", filter];
                args.extend_from_slice(extra);
                render(scene, &dir.join(out), &args)
            };
            let (memory, said) = run("memory.exr", &[]);
            assert!(!said.contains("tiled copies"), "{said}");
            // Three 128 x 128 images (192 KiB, 256 KiB with MIP levels) in a texture memory
            // of 64 KiB: all read through a cache of 64 KiB, evicting and reading tiles again.
            let stats = dir.join("stats.json");
            let (cached, said) = run(
                "cache.exr",
                &[
                    "--texture-memory",
                    "64K",
                    "--stats-json",
                    stats.to_str().unwrap(),
                ],
            );
            assert!(
                said.contains(match filter {
                    "mip" => "the textures need 256.0 KiB in memory with their MIP levels, more than the texture memory of 64.0 KiB",
                    _ => "the textures need 192.0 KiB in memory, more than the texture memory of 64.0 KiB",
                })
                    && said.contains("texture cache: 3 images in tiled files"),
                "{said}"
            );
            let same_as_in_memory = |image: &Vec<f32>| {
                assert!(
                    memory == *image,
                    "{} {filter}: the images differ",
                    scene.display()
                )
            };
            same_as_in_memory(&cached);
            // The two largest go to the cache (ties in file order) until one, with its MIP
            // levels where they are built, fits in half the texture memory.
            let memory_size = if filter == "mip" { "200K" } else { "150K" };
            let (mixed, said) = run("mixed.exr", &["--texture-memory", memory_size]);
            assert!(
                said.contains("the 2 largest of 3 images are read from tiled copies")
                    && said.contains("texture cache: 2 images in tiled files"),
                "{said}"
            );
            same_as_in_memory(&mixed);
            let stats: serde_json::Value =
                serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
            let cache = &stats["texture_cache"];
            assert_eq!(cache["images"], 3);
            assert!(cache["tiles_read"].as_u64().unwrap() > 0, "{cache}");
            assert!(
                cache["resident_bytes"].as_u64().unwrap() <= 64 << 10,
                "{cache}"
            );
        }
    }
}

#[test]
fn the_texture_memory_is_chosen_by_its_option() {
    let dir = temp_dir("texture-memory-option");
    let out = dir.join("x.exr");
    // Half of 64 MiB holds the Avocado's 256 KiB of textures; 100 KiB does not.
    let (_, said) = render(Path::new(AVOCADO), &out, &["--max-memory", "64M"]);
    assert!(!said.contains("tiled copies"), "{said}");
    let (_, said) = render(
        Path::new(AVOCADO),
        &out,
        &["--max-memory", "64M", "--texture-memory", "100K"],
    );
    assert!(said.contains("texture memory of 100.0 KiB"), "{said}");
    let (_, said) = render(
        Path::new(AVOCADO),
        &out,
        &["--max-memory", "off", "--texture-memory", "off"],
    );
    assert!(!said.contains("tiled copies"), "{said}");
}

#[test]
fn a_folder_that_takes_no_copies_is_a_clear_error() {
    let dir = temp_dir("texture-cache-no-folder");
    let out = dir.join("x.exr");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_lucerna"))
        .args(["render", AVOCADO, "-o", out.to_str().unwrap(), "--spp", "1"])
        .args(["--texture-memory", "64K"])
        .env("TMPDIR", dir.join("missing"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("images[0]: writing its tiled copy failed: in ")
            && stderr.contains("missing"),
        "{stderr}"
    );
    assert!(!out.exists());
}

#[test]
fn inspect_shows_what_a_render_with_the_same_limits_would_do() {
    let inspect = |extra: &[&str]| {
        let mut args = vec!["inspect", AVOCADO];
        args.extend_from_slice(extra);
        let run = crate::common::cli::lucerna(&args);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        String::from_utf8_lossy(&run.stdout).into_owned()
    };
    let cached = inspect(&["--texture-memory", "64K"]);
    assert!(
        cached.contains("textures: 3 (too large for the texture memory: 3 images in tiled files of 196608 bytes, read through a tile cache of 65536 bytes; 0 bytes of texels in memory)"),
        "{cached}"
    );
    let resident = inspect(&["--max-memory", "1G"]);
    assert!(
        resident.contains("textures: 3 (196608 bytes of texels;"),
        "{resident}"
    );
}
