//! glTF animation: channels sampled at the frame's time move the nodes they target (and
//! their children), and `--frames` renders a sequence into `{frame}`-named files.

use crate::common;

use common::cli::temp_dir;
use common::gltf_builder::Builder;
use glam::DVec3;
use serde_json::json;
use std::path::Path;
use std::process::Command;

/// An emissive quad under a parent node whose translation slides linearly from x = −3 to
/// x = 3 over the first second, whose rotation steps to 90° about Z at 0.5 s, and whose
/// scale grows along a cubic spline (zero tangents) from 1 to 3; a camera at the origin.
fn animated_scene(times: [f32; 2]) -> Builder {
    let mut b = Builder::new();
    let material = b.add(
        "materials",
        json!({"pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1]}, "emissiveFactor": [1, 1, 1]}),
    );
    let prim = b.quad_primitive(Some(material));
    let mesh = b.mesh(json!([prim]));
    let child = b.node(json!({"mesh": mesh, "scale": [0.4, 0.4, 0.4]}));
    let mover = b.root(json!({"name": "mover", "translation": [0, 5, -10], "children": [child]}));
    b.add(
        "cameras",
        json!({"type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": 2.0, "znear": 0.1}}),
    );
    b.root(json!({"name": "shot", "camera": 0}));
    let input = b.floats("SCALAR", &times);
    let translations = b.floats("VEC3", &[-3.0, 0.0, -10.0, 3.0, 0.0, -10.0]);
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let rotations = b.floats("VEC4", &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, s, s]);
    let step_input = b.floats("SCALAR", &[0.0, 0.5]);
    #[rustfmt::skip]
    let scales = b.floats("VEC3", &[
        0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, // in-tangent, value, out-tangent
        0.0, 0.0, 0.0, 3.0, 3.0, 3.0, 0.0, 0.0, 0.0,
    ]);
    b.add(
        "animations",
        json!({
            "name": "slide",
            "samplers": [
                {"input": input, "output": translations, "interpolation": "LINEAR"},
                {"input": step_input, "output": rotations, "interpolation": "STEP"},
                {"input": input, "output": scales, "interpolation": "CUBICSPLINE"}
            ],
            "channels": [
                {"sampler": 0, "target": {"node": mover, "path": "translation"}},
                {"sampler": 1, "target": {"node": mover, "path": "rotation"}},
                {"sampler": 2, "target": {"node": mover, "path": "scale"}}
            ]
        }),
    );
    b
}

fn scene_at(b: &Builder, time: Option<f64>) -> lucerna::Result<lucerna::scene::Scene> {
    lucerna::ingest::gltf::import_at(&b.glb(), "animated.glb", None, time)
}

/// [`scene_at`] `time` with the shutter open from `shutter.0` to `shutter.1` seconds.
fn with_shutter(
    b: &Builder,
    time: f64,
    shutter: Option<(f64, f64)>,
) -> lucerna::Result<lucerna::scene::Scene> {
    lucerna::ingest::gltf::import_with(
        &b.glb(),
        "animated.glb",
        None,
        Some(time),
        lucerna::ingest::gltf::Choices {
            shutter,
            ..Default::default()
        },
    )
}

/// The quad's placement follows each channel's interpolation, through the hierarchy.
#[test]
fn channels_pose_the_nodes_at_the_frame_time() {
    let b = animated_scene([0.0, 1.0]);
    let placement = |time: Option<f64>| scene_at(&b, time).unwrap().instances[0].transform;
    // Rest pose: the node's own translation, no rotation, unit scale (times the child's).
    let rest = placement(None);
    assert!(
        rest.transform_point3(DVec3::ZERO)
            .abs_diff_eq(DVec3::new(0.0, 5.0, -10.0), 1e-9)
    );
    for (time, x, quarter_turn, scale) in [
        (-1.0, -3.0, false, 1.0),
        (
            0.25,
            -1.5,
            false,
            1.0 + 2.0 * (3.0 * 0.0625 - 2.0 * 0.015625),
        ),
        (0.75, 1.5, true, 1.0 + 2.0 * (3.0 * 0.5625 - 2.0 * 0.421875)),
        (5.0, 3.0, true, 3.0),
    ] {
        let m = placement(Some(time));
        let origin = m.transform_point3(DVec3::ZERO);
        assert!(
            origin.abs_diff_eq(DVec3::new(x, 0.0, -10.0), 1e-6),
            "t = {time}: {origin}"
        );
        let x_axis = m.transform_vector3(DVec3::X);
        let expected = if quarter_turn { DVec3::Y } else { DVec3::X } * 0.4 * scale;
        assert!(
            x_axis.abs_diff_eq(expected, 1e-6),
            "t = {time}: {x_axis} vs {expected}"
        );
    }
    // Without a frame, an animated file says which pose it renders.
    let warnings = scene_at(&b, None).unwrap().warnings;
    assert!(warnings.iter().any(|w| w.contains("rest transforms")));
}

/// Key times that go backwards are refused with the channel named.
#[test]
fn malformed_animation_is_refused() {
    let b = animated_scene([1.0, 0.0]);
    let e = scene_at(&b, Some(0.5)).unwrap_err().to_string();
    assert!(
        e.contains("animations[0].channels[0]") && e.contains("increase"),
        "{e}"
    );
}

fn bright_centroid_x(exr: &Path) -> f32 {
    let (planes, _) = lucerna::output::exr::read(exr).unwrap();
    let r = planes.channel("R").unwrap();
    let w = planes.window.width as usize;
    let (mut sum, mut weight) = (0.0, 0.0);
    for (i, v) in r.iter().enumerate() {
        sum += v * (i % w) as f32;
        weight += v;
    }
    sum / weight
}

/// `--frames 6-18x6` at 24 fps renders t = 0.25, 0.5, 0.75 s into `{frame}`-named files,
/// and the quad moves right from frame to frame; several frames need a frame token, which
/// may also be `####`, `%03d` or `$F`.
#[test]
fn frames_render_a_sequence() {
    let dir = temp_dir("frames");
    let scene = animated_scene([0.0, 1.0]).write_glb(&dir, "slide");
    let pattern = dir.join("{scene}.{camera}.{frame}.exr");
    let run = Command::new(env!("CARGO_BIN_EXE_lucerna"))
        .args(["render", "-q", "--resolution", "64x32", "--spp", "4"])
        .arg(&scene)
        .args(["--frames", "6-18x6", "-o"])
        .arg(&pattern)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let centroids: Vec<f32> = [6, 12, 18]
        .iter()
        .map(|f| {
            let path = dir.join(format!("slide.shot.{f:04}.exr"));
            let (_, header) = lucerna::output::exr::read(&path).unwrap();
            assert_eq!(header.number("lucerna/frame"), Some(*f as f64));
            bright_centroid_x(&path)
        })
        .collect();
    assert!(
        centroids[0] < centroids[1] - 2.0 && centroids[1] < centroids[2] - 2.0,
        "{centroids:?}"
    );
    // The quad at x = 0 (t = 0.5) is centred.
    assert!((centroids[1] - 32.0).abs() < 1.0, "{centroids:?}");
    let run = Command::new(env!("CARGO_BIN_EXE_lucerna"))
        .args(["render", "-q", "--frames", "1-2", "-o"])
        .arg(dir.join("flat.exr"))
        .arg(&scene)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("{frame}"));
    // Nuke's, printf's and Houdini's frame tokens name the files as well.
    for (pattern, names) in [
        ("nuke.####.exr", ["nuke.0006.exr", "nuke.0012.exr"]),
        ("printf.%03d.exr", ["printf.006.exr", "printf.012.exr"]),
        ("houdini.$F.exr", ["houdini.6.exr", "houdini.12.exr"]),
    ] {
        let run = Command::new(env!("CARGO_BIN_EXE_lucerna"))
            .args(["render", "-q", "--resolution", "8x4", "--spp", "1"])
            .arg(&scene)
            .args(["--frames", "6-12x6", "-o"])
            .arg(dir.join(pattern))
            .output()
            .unwrap();
        assert!(
            run.status.success(),
            "{pattern}: {}",
            String::from_utf8_lossy(&run.stderr)
        );
        for name in names {
            assert!(dir.join(name).is_file(), "{pattern}: no {name}");
        }
    }
}

/// Two animations of one node are clips: the first plays (warned, naming --animation);
/// `--animation NAME` or an index plays another; an unknown one is refused with the list.
#[test]
fn animation_clips_are_chosen_by_name_or_index() {
    let mut b = animated_scene([0.0, 1.0]);
    let mover = 1; // animated_scene's nodes: the quad, then its parent "mover"
    let input = b.floats("SCALAR", &[0.0, 1.0]);
    let lifted = b.floats("VEC3", &[0.0, 7.0, -10.0, 0.0, 7.0, -10.0]);
    b.add(
        "animations",
        json!({
            "name": "lift",
            "samplers": [{"input": input, "output": lifted}],
            "channels": [{"sampler": 0, "target": {"node": mover, "path": "translation"}}]
        }),
    );
    let glb = b.glb();
    let origin = |animation: Option<&str>| {
        let scene = lucerna::ingest::gltf::import_with(
            &glb,
            "clips.glb",
            None,
            Some(0.5),
            lucerna::ingest::gltf::Choices {
                animation,
                ..Default::default()
            },
        )?;
        let p = scene.instances[0].transform.transform_point3(DVec3::ZERO);
        Ok::<_, lucerna::Error>((p, scene.warnings))
    };
    let (p, warnings) = origin(None).unwrap();
    assert!(p.abs_diff_eq(DVec3::new(0.0, 0.0, -10.0), 1e-6), "{p}");
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("\"lift\"") && w.contains("--animation")),
        "{warnings:?}"
    );
    for chosen in ["lift", "1"] {
        let (p, warnings) = origin(Some(chosen)).unwrap();
        assert!(
            p.abs_diff_eq(DVec3::new(0.0, 7.0, -10.0), 1e-6),
            "{chosen}: {p}"
        );
        assert!(
            !warnings.iter().any(|w| w.contains("clips")),
            "{warnings:?}"
        );
    }
    let err = origin(Some("run")).unwrap_err().to_string();
    assert!(
        err.contains("\"run\"") && err.contains("\"slide\", \"lift\""),
        "{err}"
    );
}

/// With an open shutter the importer gives a moving node's instances their transforms at
/// evenly spaced times of it (the channels sampled there, through the hierarchy); a node
/// that does not move gets none, nor does a closed shutter.
#[test]
fn an_open_shutter_samples_the_motion() {
    let mut b = animated_scene([0.0, 1.0]);
    let prim = b.quad_primitive(None);
    let still = b.mesh(json!([prim]));
    b.root(json!({"name": "still", "mesh": still}));
    let import = |shutter| with_shutter(&b, 0.3, shutter).unwrap();
    let scene = import(Some((0.2, 0.4)));
    let moving = &scene.instances[0];
    assert_eq!(moving.motion.len(), 9);
    for (k, key) in moving.motion.iter().enumerate() {
        let at = scene_at(&b, Some(0.2 + 0.2 * k as f64 / 8.0))
            .unwrap()
            .instances[0]
            .transform;
        assert!(key.abs_diff_eq(at, 1e-9), "key {k}: {key} vs {at}");
    }
    // The frame's own pose is kept.
    assert!(moving.transform.abs_diff_eq(
        scene_at(&b, Some(0.3)).unwrap().instances[0].transform,
        1e-12
    ));
    assert!(scene.instances[1].motion.is_empty(), "the still node moved");
    assert!(import(Some((0.3, 0.3))).instances[0].motion.is_empty());
    assert!(import(None).instances[0].motion.is_empty());
}

/// `--shutter` blurs the sliding quad (made black against a white sky): it darkens more
/// columns than the frame's instant does, its darkness spread over the 0.5 s the shutter
/// is open; a shutter of no width renders the frame's image to the bit.
#[test]
fn shutter_blurs_a_sliding_quad() {
    let dir = temp_dir("shutter");
    let mut b = animated_scene([0.0, 1.0]);
    b.json["materials"][0] = json!({"pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1]}});
    let scene = b.write_glb(&dir, "slide");
    // Frame 12 of the scene into `name` with the options `extra`: its pixels and header.
    let render = |name: &str, extra: &[&str]| {
        let out = dir.join(name);
        let (out_text, scene_text) = (out.to_str().unwrap(), scene.to_str().unwrap());
        let mut args = vec!["render", "-q", "--resolution", "64x32", "--spp", "16"];
        args.extend([
            "--env", "1,1,1", "--frame", "12", "-o", out_text, scene_text,
        ]);
        args.extend(extra);
        common::cli::lucerna_ok(&args);
        lucerna::output::exr::read(&out).unwrap()
    };
    let dark_columns = |planes: &lucerna::film::planes::Planes| {
        let r = planes.channel("R").unwrap();
        let w = planes.window.width as usize;
        (0..w)
            .filter(|&x| r.iter().skip(x).step_by(w).any(|&v| v < 0.9))
            .count()
    };
    let frame = render("frame.exr", &[]).0;
    let blurred = render("blurred.exr", &["--shutter", "-6,6"]).0;
    let (sharp, smeared) = (dark_columns(&frame), dark_columns(&blurred));
    assert!(
        smeared >= sharp + 8,
        "{sharp} columns sharp, {smeared} blurred"
    );
    // Without blur: the frame's image, and the quad's motion in the motion layer (the
    // quad slides 6 units a second, 0.25 units a frame at 24 fps).
    let vectors = render(
        "vectors.exr",
        &[
            "--shutter",
            "-0.5,0.5",
            "--no-motion-blur",
            "--aov",
            "motion",
        ],
    )
    .0;
    assert_eq!(dark_columns(&vectors), sharp);
    let u = vectors.channel("motion.u").unwrap();
    let fastest = u.iter().cloned().fold(0.0f32, f32::max);
    assert!(
        fastest > 1.0,
        "the quad's motion: at most {fastest} pixels a frame"
    );
    // Without a shutter, asking for the motion layer takes the motion over half a frame
    // each way, without blur, and says so in the header.
    let (implicit, header) = render("implicit.exr", &["--aov", "motion"]);
    assert_eq!(
        header.text("lucerna/shutter"),
        Some("-0.5,0.5 without blur")
    );
    assert_eq!(dark_columns(&implicit), sharp);
    assert_eq!(implicit.channel("motion.u"), vectors.channel("motion.u"));
    // Without a frame the rest transforms are rendered, whatever the layers asked for.
    let rest = |name: &str, aov: &str| {
        let out = dir.join(name);
        let (out_text, scene_text) = (out.to_str().unwrap(), scene.to_str().unwrap());
        common::cli::lucerna_ok(&[
            "render",
            "-q",
            "--resolution",
            "16x8",
            "--spp",
            "2",
            "--aov",
            aov,
            "-o",
            out_text,
            scene_text,
        ]);
        lucerna::output::exr::read(&out).unwrap()
    };
    let (with_motion, header) = rest("rest-motion.exr", "motion");
    assert_eq!(header.text("lucerna/shutter"), None);
    assert_eq!(
        with_motion.channel("R"),
        rest("rest.exr", "albedo").0.channel("R")
    );
    let closed = render("closed.exr", &["--shutter", "0,0"]).0;
    assert_eq!(frame.channel("R").unwrap(), closed.channel("R").unwrap());
    let refused = Command::new(env!("CARGO_BIN_EXE_lucerna"))
        .args(["render", "-q", "--shutter", "0.5,-0.5"])
        .arg(&scene)
        .output()
        .unwrap();
    assert_eq!(refused.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("closes before it opens"));
}

/// An emitter that moves while the shutter is open is rendered where it is at the frame,
/// with a warning naming it (lights do not move).
#[test]
fn a_moving_emitter_is_named_in_a_warning() {
    let dir = temp_dir("moving-emitter");
    let scene = animated_scene([0.0, 1.0]).write_glb(&dir, "slide");
    let run = Command::new(env!("CARGO_BIN_EXE_lucerna"))
        .args([
            "render",
            "--resolution",
            "16x8",
            "--spp",
            "1",
            "--frame",
            "12",
        ])
        .args(["--shutter", "-0.5,0.5", "-o"])
        .arg(dir.join("out.exr"))
        .arg(&scene)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(
        stderr.contains("nodes[0] emit light and move") && stderr.contains("not blurred"),
        "{stderr}"
    );
}

/// A node scaled to nothing while the shutter is open cannot be interpolated (its keys do
/// not decompose): its mesh keeps the frame's transform, unblurred, with a warning naming
/// the mesh's node.
#[test]
fn a_node_that_vanishes_during_the_shutter_is_not_blurred() {
    let mut b = animated_scene([0.0, 1.0]);
    let input = b.floats("SCALAR", &[0.0, 1.0]);
    let scales = b.floats("VEC3", &[1.0, 1.0, 1.0, 0.0, 0.0, 0.0]);
    b.json["animations"][0]["samplers"][2] =
        json!({"input": input, "output": scales, "interpolation": "LINEAR"});
    let scene = with_shutter(&b, 0.9, Some((0.8, 1.0))).unwrap();
    assert!(scene.instances[0].motion.is_empty());
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("nodes[0]") && w.contains("singular during the shutter")),
        "{:?}",
        scene.warnings
    );
}

/// A render is continued (`--resume`) only with the shutter it was made with: the header
/// records it (`lucerna/shutter`), and another shutter, or none, is refused naming it.
#[test]
fn a_render_resumes_only_with_its_shutter() {
    let dir = temp_dir("resume-shutter");
    let scene = animated_scene([0.0, 1.0]).write_glb(&dir, "slide");
    let out = dir.join("out.exr");
    let render = |spp: &str, shutter: &[&str], resume: bool| {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_lucerna"));
        cmd.args([
            "render",
            "-q",
            "--resolution",
            "16x8",
            "--frame",
            "12",
            "--aov",
            "spp",
        ])
        .args(["--spp", spp])
        .args(shutter)
        .arg("-o")
        .arg(&out)
        .arg(&scene);
        if resume {
            cmd.arg("--resume");
        }
        cmd.output().unwrap()
    };
    assert!(
        render("2", &["--shutter", "-0.5,0.5"], false)
            .status
            .success()
    );
    let (_, header) = lucerna::output::exr::read(&out).unwrap();
    assert_eq!(header.text("lucerna/shutter"), Some("-0.5,0.5"));
    for other in [
        &["--shutter", "0,0.5"][..],
        &[],
        &["--shutter", "-0.5,0.5", "--no-motion-blur"],
    ] {
        let refused = render("4", other, true);
        assert_eq!(refused.status.code(), Some(2), "{other:?}");
        let stderr = String::from_utf8_lossy(&refused.stderr);
        assert!(stderr.contains("lucerna/shutter"), "{other:?}: {stderr}");
    }
    let resumed = render("4", &["--shutter", "-0.5,0.5"], true);
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
}

/// A light that moves while the shutter is open stays where it is at the frame, with a
/// warning naming its node (lights do not move yet); a still one is not warned about.
#[test]
fn a_moving_light_is_named_in_a_warning() {
    let mut b = animated_scene([0.0, 1.0]);
    b.json["extensionsUsed"] = json!(["KHR_lights_punctual"]);
    b.json["extensions"] =
        json!({"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": 10.0}]}});
    let lamp = b.node(json!({"extensions": {"KHR_lights_punctual": {"light": 0}}}));
    b.json["nodes"][1]["children"]
        .as_array_mut()
        .unwrap()
        .push(json!(lamp));
    b.root(json!({"name": "fixed", "extensions": {"KHR_lights_punctual": {"light": 0}}}));
    let scene = with_shutter(&b, 0.3, Some((0.2, 0.4))).unwrap();
    let warned: Vec<&String> = scene
        .warnings
        .iter()
        .filter(|w| w.contains("the light moves while the shutter is open"))
        .collect();
    assert_eq!(warned.len(), 1, "{:?}", scene.warnings);
    assert!(warned[0].contains(&format!("nodes[{lamp}]")), "{warned:?}");
}
