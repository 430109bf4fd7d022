//! The command line end to end: environment maps, preview PNGs, inspect, atomic output.

use crate::common;

use common::cli::{header_text, lucerna, lucerna_ok, lucerna_stderr, temp_dir};
use common::gltf_builder::{Builder, png_rgba};
use serde_json::json;
use std::path::{Path, PathBuf};

/// A scene whose only geometry is a tiny quad far below the camera, and a camera at the
/// origin looking along -Z (or along `forward` via a rotation about Y).
fn empty_looking_scene(dir: &Path, yaw: f64) -> PathBuf {
    let mut b = Builder::new();
    let prim = b.quad_primitive(None);
    let mesh = b.mesh(json!([prim]));
    b.root(json!({"mesh": mesh, "translation": [0, -100, 0], "scale": [0.01, 0.01, 0.01]}));
    b.add("cameras", json!({"type": "perspective", "perspective": {"yfov": 0.1, "aspectRatio": 1.0, "znear": 0.01}}));
    let (s, c) = ((yaw / 2.0).sin(), (yaw / 2.0).cos());
    b.root(json!({"camera": 0, "rotation": [0, s, 0, c]}));
    b.write_embedded(dir, &format!("look_{yaw}"))
}

fn centre_pixel(exr: &Path) -> [f32; 3] {
    let image = exr::prelude::read_first_flat_layer_from_file(exr).unwrap();
    let size = image.layer_data.size;
    let centre = (size.1 / 2) * size.0 + size.0 / 2;
    let channel = |name: &str| {
        let c = image
            .layer_data
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == name)
            .unwrap();
        c.sample_data.value_by_flat_index(centre).to_f32()
    };
    [channel("R"), channel("G"), channel("B")]
}

#[test]
fn environment_map_orientation_follows_the_latlong_convention() {
    // A 4x2 map: columns red, green, blue, white; the centre (u = 0.5) must be seen looking
    // along -Z, u = 0.75 looking along +X.
    let dir = temp_dir("env");
    let row = [
        [255, 0, 0, 255],
        [0, 255, 0, 255],
        [0, 0, 255, 255],
        [255, 255, 255, 255],
    ];
    let map = dir.join("map.png");
    std::fs::write(&map, png_rgba(4, 2, &[row, row].concat())).unwrap();
    // Aim at texel centres (u = 0.375, 0.625, 0.875): the camera looks along
    // (-sin yaw, 0, -cos yaw), whose u is 0.5 - yaw / 2π.
    use std::f64::consts::FRAC_PI_4;
    for (yaw, expected) in [
        (FRAC_PI_4, [0.0, 1.0, 0.0]),
        (-FRAC_PI_4, [0.0, 0.0, 1.0]),
        (-3.0 * FRAC_PI_4, [1.0, 1.0, 1.0]),
    ] {
        let scene = empty_looking_scene(&dir, yaw);
        let out = dir.join("env.exr");
        lucerna_ok(&[
            "render",
            scene.to_str().unwrap(),
            "--env-map",
            map.to_str().unwrap(),
            "--spp",
            "4",
            "--resolution",
            "9x9",
            "-q",
            "-o",
            out.to_str().unwrap(),
        ]);
        let c = centre_pixel(&out);
        for k in 0..3 {
            assert!(
                (c[k] - expected[k]).abs() < 0.02,
                "yaw {yaw}: {c:?} vs {expected:?}"
            );
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn preview_png_and_inspect() {
    let dir = temp_dir("preview");
    let exr = dir.join("a.exr");
    let png = dir.join("a.png");
    let run = lucerna(&[
        "render",
        "--spp",
        "2",
        "--resolution",
        "20x10",
        "-q",
        "-o",
        exr.to_str().unwrap(),
        "--preview",
        png.to_str().unwrap(),
    ]);
    assert!(run.status.success());
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let reader = decoder.read_info().unwrap();
    assert_eq!((reader.info().width, reader.info().height), (20, 10));
    let summary = String::from_utf8_lossy(&run.stderr);
    for figure in [
        "samples/s",
        "rays/s",
        "NaN/Inf contributions discarded",
        "BVH built in",
    ] {
        assert!(summary.contains(figure), "{summary}");
    }
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into())
        .collect();
    assert_eq!(names.len(), 2, "no temporary files left: {names:?}");

    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-box/cornell-box.gltf");
    let run = lucerna(&["inspect", scene.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success());
    for line in [
        "32 triangles",
        "materials: 4 (lambert)",
        "2 emissive triangles",
        "cameras: camera",
        "render plan (auto):",
        "lobes: diffuse yes, glossy no, specular no, transmission no",
        "emitter lookups and MIS at BSDF hits on, first-hit data on, AOV routing on",
    ] {
        assert!(text.contains(line), "{line} missing from:\n{text}");
    }
    let run = lucerna(&["inspect", scene.to_str().unwrap(), "--aov", "beauty"]);
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(
        text.contains("first-hit data off, AOV routing off"),
        "beauty only:\n{text}"
    );
    // A scene lit by a glowing medium says so, and is not given the default light.
    let glow = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/media/glowing-smoke.gltf");
    let run = lucerna(&["inspect", glow.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(
        text.contains("participating media: inside 1 material, 1 emitting"),
        "{text}"
    );
    let out = dir.join("glow.exr");
    let run = lucerna(&[
        "render",
        glow.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--spp",
        "1",
        "--resolution",
        "8x8",
    ]);
    let errors = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{errors}");
    assert!(!errors.contains("has no light"), "{errors}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Adaptive sampling from the command line: per-pixel counts in the `spp` layer, the
/// threshold in the header's settings, bad values refused.
#[test]
fn noise_threshold_samples_pixels_unevenly() {
    let dir = temp_dir("adaptive");
    let out = dir.join("a.exr");
    lucerna_ok(&[
        "render",
        "--resolution",
        "32x32",
        "--noise-threshold",
        "0.1",
        "--min-spp",
        "8",
        "--aov",
        "spp",
        "-q",
        "-o",
        out.to_str().unwrap(),
    ]);
    let settings = header_settings(&out);
    assert_eq!(settings["noise-threshold"].as_str(), Some("0.1"));
    assert_eq!(settings["min-spp"].as_integer(), Some(8));
    let image = exr::prelude::read_first_flat_layer_from_file(&out).unwrap();
    let spp = image
        .layer_data
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "spp.Y")
        .unwrap();
    let counts: Vec<f32> = spp.sample_data.values_as_f32().collect();
    let (lo, hi) = counts
        .iter()
        .fold((f32::MAX, 0.0f32), |(lo, hi), &c| (lo.min(c), hi.max(c)));
    assert!(lo >= 8.0 && hi > lo, "samples per pixel {lo}..{hi}");
    for bad in ["0", "-1", "nan", "x"] {
        let run = lucerna(&["render", "--noise-threshold", bad, "-o", "x.exr"]);
        assert_eq!(run.status.code(), Some(2), "--noise-threshold {bad}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_scene_without_camera_is_framed_automatically() {
    let dir = temp_dir("nocam");
    let mut b = Builder::new();
    let m = b.add(
        "materials",
        json!({"emissiveFactor": [1, 1, 1], "doubleSided": true}),
    );
    let prim = b.quad_primitive(Some(m));
    let mesh = b.mesh(json!([prim]));
    b.root(json!({"mesh": mesh, "translation": [1000, 50, -7], "scale": [3, 3, 3]}));
    let scene = b.write_embedded(&dir, "nocam");
    let out = dir.join("nocam.exr");
    lucerna_ok(&[
        "render",
        scene.to_str().unwrap(),
        "--spp",
        "1",
        "-q",
        "-o",
        out.to_str().unwrap(),
    ]);
    let c = centre_pixel(&out);
    assert_eq!(c, [1.0, 1.0, 1.0], "the framed quad fills the centre");
    std::fs::remove_dir_all(&dir).unwrap();
}

fn header_settings(exr: &Path) -> toml::Table {
    header_text(exr, "lucerna/settings").parse().unwrap()
}

#[test]
fn settings_file_flags_and_time_budget() {
    let dir = temp_dir("settings");
    let file = dir.join("look.toml");
    std::fs::write(&file, "mis = \"balance\"\nrr = \"fixed:0.5\"\nspp = 3\nlight-select = \"uniform\"\nsplit = \"nee=2\"\n").unwrap();
    let out = dir.join("s.exr");
    lucerna_ok(&[
        "render",
        "--settings",
        file.to_str().unwrap(),
        "--spp",
        "5",
        "--resolution",
        "8x8",
        "-q",
        "-o",
        out.to_str().unwrap(),
    ]);
    let s = header_settings(&out);
    assert_eq!(s["mis"].as_str(), Some("balance"));
    assert_eq!(s["rr"].as_str(), Some("fixed:0.5"));
    assert_eq!(s["light-select"].as_str(), Some("uniform"));
    assert_eq!(s["split"].as_str(), Some("nee=2,bsdf=1"));
    assert_eq!(
        s["spp"].as_integer(),
        Some(5),
        "the flag overrides the file"
    );

    // The header's settings are a settings file that reproduces the image.
    let replay_file = dir.join("replay.toml");
    std::fs::write(&replay_file, toml::to_string(&s).unwrap()).unwrap();
    let replay = dir.join("replay.exr");
    lucerna_ok(&[
        "render",
        "--settings",
        replay_file.to_str().unwrap(),
        "--resolution",
        "8x8",
        "-q",
        "-o",
        replay.to_str().unwrap(),
    ]);
    assert_eq!(centre_pixel(&replay), centre_pixel(&out));

    // A time budget: render until about a second has passed; the header has the count.
    let timed = dir.join("t.exr");
    let start = std::time::Instant::now();
    let run = lucerna(&[
        "render",
        "--time",
        "1",
        "--resolution",
        "32x32",
        "-q",
        "-o",
        timed.to_str().unwrap(),
    ]);
    let seconds = start.elapsed().as_secs_f64();
    assert!(run.status.success());
    assert!((0.9..4.0).contains(&seconds), "{seconds} s");
    assert!(header_settings(&timed)["spp"].as_integer().unwrap() > 1);

    std::fs::write(&file, "colour = \"red\"\n").unwrap();
    let run = lucerna(&[
        "render",
        "--settings",
        file.to_str().unwrap(),
        "-q",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("unknown setting \"colour\""));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Light groups end to end: two emissive quads grouped `key` by their glTF node `extras`,
/// a point light matched by `--light-group rim=fi*`; each group gets its `lg_` layer and
/// nothing is left for `lg_default`.
#[test]
fn light_groups_come_from_extras_and_the_command_line() {
    let dir = temp_dir("light-groups");
    let mut b = Builder::new();
    let grey = b.add("materials", json!({"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0}}));
    let glow = b.add("materials", json!({"pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1]}, "emissiveFactor": [1, 0.8, 0.6]}));
    let floor = b.quad_primitive(Some(grey));
    let floor = b.mesh(json!([floor]));
    let lamp = b.quad_primitive(Some(glow));
    let lamp = b.mesh(json!([lamp]));
    b.root(json!({"name": "floor", "mesh": floor, "translation": [0, 0, -3], "scale": [4, 4, 1]}));
    // Facing down: a quarter turn about X.
    let s = std::f64::consts::FRAC_1_SQRT_2;
    for (name, x) in [("lamp_a", -1.0), ("lamp_b", 1.0)] {
        b.root(json!({"name": name, "mesh": lamp, "translation": [x, 1.5, -2], "rotation": [s, 0, 0, s], "scale": [0.3, 0.3, 0.3], "extras": {"lucerna": {"light_group": "key"}}}));
    }
    b.json["extensionsUsed"] = json!(["KHR_lights_punctual"]);
    b.json["extensions"] = json!({"KHR_lights_punctual": {"lights": [{"type": "point", "color": [1, 1, 1], "intensity": 2}]}});
    b.root(json!({"name": "fill", "extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [0, 0, -1]}));
    b.add("cameras", json!({"type": "perspective", "perspective": {"yfov": 1.0, "aspectRatio": 1.0, "znear": 0.01}}));
    b.root(json!({"camera": 0}));
    let scene = b.write_embedded(&dir, "groups");
    let out = dir.join("groups.exr");
    lucerna_ok(&[
        "render",
        "-q",
        scene.to_str().unwrap(),
        "--resolution",
        "24x24",
        "--spp",
        "8",
        "--aov",
        "lightgroups,emission",
        "--light-group",
        "rim=fi*",
        "-o",
        out.to_str().unwrap(),
    ]);
    let (planes, _) = lucerna::output::exr::read(&out).unwrap();
    let layers: Vec<&str> = planes
        .channels
        .iter()
        .filter_map(|(n, _)| n.strip_suffix(".R"))
        .filter(|n| n.starts_with("lg_"))
        .collect();
    assert_eq!(layers, ["lg_key", "lg_rim"]);
    let sum = |name: &str| planes.channel(name).unwrap().iter().sum::<f32>();
    assert!(sum("lg_key.R") > 0.0 && sum("lg_rim.R") > 0.0);
    let total = sum("lg_key.G") + sum("lg_rim.G") + sum("emission.G");
    assert!(
        (total - sum("G")).abs() <= 1e-4 * sum("G"),
        "{total} vs {}",
        sum("G")
    );
}

/// A scene without any light (most glTF assets ship none) gets a warning and a constant
/// white environment; `--no-default-light` renders it black, still warned.
#[test]
fn a_scene_without_light_gets_a_default_environment() {
    let dir = temp_dir("no-light");
    let scene = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/assets/gltf/Avocado/Avocado.gltf"
    );
    let mean = |extra: &[&str]| {
        let out = dir.join("out.exr");
        let out_s = out.to_str().unwrap();
        let mut args = vec![
            "render",
            scene,
            "-o",
            out_s,
            "--spp",
            "2",
            "--resolution",
            "32x32",
            "--aov",
            "beauty",
            "-q",
        ];
        args.extend_from_slice(extra);
        let (ok, stderr) = lucerna_stderr(&args);
        assert!(ok, "{stderr}");
        let (planes, _) = lucerna::output::exr::read(&out).unwrap();
        let r = planes.channel("R").unwrap();
        (
            r.iter().map(|&v| v as f64).sum::<f64>() / r.len() as f64,
            stderr,
        )
    };
    let (lit, warning) = mean(&[]);
    assert!(lit > 0.2, "{lit}");
    assert!(
        warning.contains("has no light") && warning.contains("constant white environment"),
        "{warning}"
    );
    let (dark, warning) = mean(&["--no-default-light"]);
    assert_eq!(dark, 0.0);
    assert!(warning.contains("renders black"), "{warning}");
    let (chosen, warning) = mean(&["--env", "0.5,0.5,0.5"]);
    assert!(chosen > 0.1 && chosen < lit, "{chosen}");
    assert!(!warning.contains("has no light"), "{warning}");
}

/// Off a terminal (a farm log, a batch child's log), progress comes as plain lines every
/// `--progress-interval` seconds, with or without `--quiet`; `--progress alfred` prints
/// Tractor's ALF_PROGRESS lines; `--progress none` prints none.
#[test]
fn progress_lines_off_a_terminal() {
    let dir = temp_dir("progress");
    let out = dir.join("p.exr");
    let stderr = |extra: &[&str]| {
        let mut args = vec![
            "render",
            "-o",
            out.to_str().unwrap(),
            "--spp",
            "16",
            "--resolution",
            "96x96",
            "-q",
        ];
        args.extend_from_slice(extra);
        let (ok, stderr) = lucerna_stderr(&args);
        assert!(ok, "{stderr}");
        stderr
    };
    let text = stderr(&["--progress-interval", "0.05"]);
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("lucerna: progress"))
        .collect();
    assert!(!lines.is_empty(), "{text}");
    let last = lines.last().unwrap();
    assert!(
        last.contains("100.0%") && last.contains("of 16 spp") && last.contains("M samples/s"),
        "{last}"
    );
    let alfred = stderr(&["--progress", "alfred", "--progress-interval", "0.05"]);
    assert!(alfred.lines().any(|l| l == "ALF_PROGRESS 100%"), "{alfred}");
    assert!(!alfred.contains("lucerna: progress"), "{alfred}");
    let none = stderr(&["--progress", "none"]);
    assert!(
        !none.contains("lucerna: progress") && !none.contains("ALF_PROGRESS"),
        "{none}"
    );
}

/// `--stats-json` writes the render's figures, counts as integers, one file per frame
/// (frame tokens expand as in `-o`).
#[test]
fn stats_json_has_the_figures_as_integers() {
    let dir = temp_dir("stats-json");
    let out = dir.join("s.exr");
    let stats = dir.join("s.json");
    lucerna_ok(&[
        "render",
        "-o",
        out.to_str().unwrap(),
        "--spp",
        "4",
        "--resolution",
        "40x30",
        "--stats-json",
        stats.to_str().unwrap(),
        "-q",
        "--progress",
        "none",
    ]);
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    for key in [
        "width",
        "height",
        "spp",
        "samples",
        "rays_closest",
        "rays_shadow",
        "nan_inf_discarded",
        "samples_per_second",
        "threads",
    ] {
        assert!(v[key].is_u64(), "{key} is not an integer: {}", v[key]);
    }
    assert_eq!(
        (v["width"].as_u64(), v["height"].as_u64()),
        (Some(40), Some(30))
    );
    assert_eq!(v["samples"].as_u64(), Some(40 * 30 * 4));
    assert_eq!(v["outputs"][0].as_str(), out.to_str());
    assert!(v["render_seconds"].as_f64().unwrap() > 0.0);
    assert_eq!(v["interrupted"], false);
    let scene = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/assets/gltf/RiggedSimple/RiggedSimple.gltf"
    );
    let frames = dir.join("f.{frame}.exr");
    let per_frame = dir.join("f.{frame}.json");
    lucerna_ok(&[
        "render",
        scene,
        "--frames",
        "1-2",
        "-o",
        frames.to_str().unwrap(),
        "--spp",
        "1",
        "--resolution",
        "16x16",
        "--stats-json",
        per_frame.to_str().unwrap(),
        "-q",
        "--progress",
        "none",
    ]);
    for f in ["0001", "0002"] {
        let v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join(format!("f.{f}.json"))).unwrap())
                .unwrap();
        assert_eq!(v["frame"].as_f64(), Some(f.parse::<f64>().unwrap()));
    }
}

/// An output into a directory that does not exist yet is written, and the directory made
/// for it is said (a typo in a path is seen at once, not after the render).
#[test]
fn a_missing_output_directory_is_made_and_said() {
    let dir = temp_dir("missing-output-directory");
    let out = dir.join("shot").join("frame.exr");
    let (ok, stderr) = lucerna_stderr(&[
        "render",
        "--spp",
        "1",
        "--resolution",
        "8x8",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(out.is_file());
    assert!(
        stderr.contains(&format!(
            "{}: created the directory for --output",
            dir.join("shot").display()
        )),
        "{stderr}"
    );
    // Once it exists, nothing is said.
    let (ok, stderr) = lucerna_stderr(&[
        "render",
        "--spp",
        "1",
        "--resolution",
        "8x8",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok && !stderr.contains("created the directory"), "{stderr}");
}
