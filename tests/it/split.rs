//! Split renders end to end: sample passes and crop windows merge into the render with all
//! the samples, and a render killed by a signal resumes to the image it would have made.

use crate::common;

use common::cli::{lucerna, lucerna_ok, temp_dir};
use lucerna::film::planes::Planes;
use lucerna::output::exr;
use std::path::Path;
#[cfg(unix)]
use std::process::Command;

fn path(dir: &Path, name: &str) -> String {
    dir.join(name).to_str().unwrap().to_string()
}

fn read(path: &str) -> Planes {
    exr::read(Path::new(path)).unwrap().0
}

/// Every channel of `a` and `b` agrees within `relative` of its magnitude (0: bit for bit).
fn assert_same_image(a: &Planes, b: &Planes, relative: f32) {
    assert_eq!(a.display, b.display);
    assert_eq!(a.window, b.window);
    let names = |p: &Planes| {
        p.channels
            .iter()
            .map(|(n, _)| n.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(names(a), names(b));
    for (name, plane) in &a.channels {
        let other = b.channel(name).unwrap();
        for (i, (x, y)) in plane.iter().zip(other).enumerate() {
            let tolerance = relative * x.abs().max(y.abs());
            assert!(
                (x - y).abs() <= tolerance,
                "{name} at pixel {i}: {x} vs {y} (tolerance {tolerance})"
            );
        }
    }
}

/// Merges `parts` into `dir`/merged.exr and returns its path.
fn merge(dir: &Path, parts: &[String]) -> String {
    let merged = path(dir, "merged.exr");
    let args: Vec<&str> = ["merge"]
        .into_iter()
        .chain(parts.iter().map(String::as_str))
        .chain(["-o", &merged])
        .collect();
    lucerna_ok(&args);
    merged
}

/// The default scene, all AOVs, at a size that is not a multiple of the 16-pixel tiles.
const RENDER: [&str; 6] = ["render", "-q", "--resolution", "40x36", "--aov", "all"];

/// Merging passes 1/4 … 4/4 gives the 16-spp render: every layer, including the pooled
/// variance and the summed `spp`, within float rounding (sums are re-formed from f32
/// means, so a few ulps).
#[test]
fn merge_of_four_passes_equals_the_single_render() {
    let dir = temp_dir("passes");
    let full = path(&dir, "full.exr");
    lucerna_ok(&[&RENDER[..], &["--spp", "16", "-o", &full]].concat());
    let mut parts = Vec::new();
    for k in 1..=4 {
        let part = path(&dir, &format!("pass{k}.exr"));
        let pass = format!("{k}/4");
        lucerna_ok(&[&RENDER[..], &["--spp", "16", "--pass", &pass, "-o", &part]].concat());
        let spp = read(&part).channel("spp.Y").unwrap().to_vec();
        assert!(
            spp.iter().all(|&s| s == 4.0),
            "pass {pass} takes 4 samples a pixel"
        );
        parts.push(part);
    }
    let merged = merge(&dir, &parts);
    assert_same_image(&read(&full), &read(&merged), 1e-5);
    let (_, header) = exr::read(Path::new(&merged)).unwrap();
    assert_eq!(header.number("lucerna/spp"), Some(16.0));
    assert_eq!(header.number("lucerna/samples"), Some(40.0 * 36.0 * 16.0));
    assert!(!header.text("lucerna/settings").unwrap().contains("pass"));
    // The rays of the passes add up; the summary line says the image was merged.
    let rays = |p: &str| {
        exr::read(Path::new(p))
            .unwrap()
            .1
            .number("lucerna/rays")
            .unwrap()
    };
    let passes: f64 = parts.iter().map(|p| rays(p)).sum();
    assert_eq!(header.number("lucerna/rays"), Some(passes));
    let summary = exr::summary(&header).unwrap();
    assert!(summary.contains("16 spp, 23040 samples"), "{summary}");
    assert!(summary.ends_with("merged from 4 parts"), "{summary}");
}

/// Four crop windows, on boundaries that cut the 16-pixel tiles, assemble bit for bit into
/// the whole render; each part's EXR carries its data window inside the full display window.
#[test]
fn four_tiles_assemble_to_the_single_render() {
    let dir = temp_dir("tiles");
    let full = path(&dir, "full.exr");
    lucerna_ok(&[&RENDER[..], &["--spp", "8", "-o", &full]].concat());
    let mut parts = Vec::new();
    for (i, crop) in ["0,0,21,17", "21,0,40,17", "0,17,21,36", "21,17,40,36"]
        .iter()
        .enumerate()
    {
        let part = path(&dir, &format!("tile{i}.exr"));
        lucerna_ok(&[&RENDER[..], &["--spp", "8", "--crop", crop, "-o", &part]].concat());
        let planes = read(&part);
        assert_eq!(planes.display, (40, 36));
        assert_eq!(planes.window.describe(), *crop);
        parts.push(part);
    }
    let merged = merge(&dir, &parts);
    assert_same_image(&read(&full), &read(&merged), 0.0);
}

/// Parts that do not belong together are refused with the file and the reason: samples of
/// one sequence twice, different settings, overlapping parts without sample counts; and
/// split renders that could not match the whole: a crop outside the image, a timed pass,
/// a pass that does not exist, an adaptive crop.
#[test]
fn merge_and_split_refuse_what_does_not_fit() {
    let dir = temp_dir("refuse");
    let a = path(&dir, "a.exr");
    let b = path(&dir, "b.exr");
    let c = path(&dir, "c.exr");
    let out = path(&dir, "out.exr");
    lucerna_ok(&[&RENDER[..], &["--spp", "8", "--pass", "1/2", "-o", &a]].concat());
    lucerna_ok(
        &[
            &RENDER[..],
            &["--spp", "8", "--pass", "2/2", "--mis", "balance", "-o", &b],
        ]
        .concat(),
    );
    lucerna_ok(&[&RENDER[..], &["--spp", "8", "-o", &c]].concat());
    let no_spp = |seed: &str, name: &str| {
        let out = path(&dir, name);
        lucerna_ok(&[
            "render",
            "-q",
            "--resolution",
            "40x36",
            "--aov",
            "direct",
            "--spp",
            "8",
            "--seed",
            seed,
            "-o",
            &out,
        ]);
        out
    };
    let (d, e) = (no_spp("1", "d.exr"), no_spp("2", "e.exr"));
    for (inputs, expected) in [
        (vec![&a, &a], "same samples"),
        (vec![&a, &c], "same samples"),
        (vec![&a, &b], "mis"),
        (vec![&d, &e], "spp layer"),
    ] {
        let args: Vec<&str> = ["merge"]
            .into_iter()
            .chain(inputs.iter().map(|s| s.as_str()))
            .chain(["-o", &out])
            .collect();
        let run = lucerna(&args);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{stderr}");
        assert!(stderr.contains(expected), "{expected:?} not in {stderr}");
    }
    assert!(!Path::new(&out).exists());
    for (args, expected) in [
        (vec!["--crop", "30,0,50,10"], "outside"),
        (vec!["--pass", "1/2", "--time", "1"], "fixed range"),
        (vec!["--pass", "3/2"], "1 <= K <= N"),
        (
            vec!["--crop", "0,0,8,8", "--noise-threshold", "0.1"],
            "adaptive",
        ),
        (vec!["--pass", "1/2", "--split", "auto"], "split = auto"),
        (vec!["--split", "auto", "--rr", "efficiency"], "choose one"),
        (vec!["--split", "auto", "--resume"], "cannot be resumed"),
    ] {
        let run = lucerna(&[&RENDER[..], &args[..], &["-o", &out]].concat());
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{expected:?} not in {stderr}");
    }
}

/// SIGTERM stops a render, which writes a valid, incomplete EXR with its per-pixel sample
/// counts and exits 143; `--resume` continues every pixel's sample sequence where it
/// stopped, giving the uninterrupted render's image (up to float rounding).
#[cfg(unix)]
#[test]
fn a_killed_render_resumes_to_the_same_image() {
    let dir = temp_dir("resume");
    let args = [
        "render",
        "-q",
        "--resolution",
        "24x24",
        "--spp",
        "2048",
        "--aov",
        "direct,variance,depth,spp",
    ];
    let full = path(&dir, "full.exr");
    lucerna_ok(&[&args[..], &["-o", &full]].concat());
    let checkpoint = path(&dir, "checkpoint.exr");
    let child = Command::new(env!("CARGO_BIN_EXE_lucerna"))
        .args([&args[..], &["-o", &checkpoint]].concat())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(700));
    let kill = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = child.wait_with_output().unwrap().status;
    assert_eq!(
        status.code(),
        Some(143),
        "the render should have been stopped by SIGTERM (it may have finished first)"
    );
    let (planes, header) = exr::read(Path::new(&checkpoint)).unwrap();
    assert_eq!(header.number("lucerna/complete"), Some(0.0));
    let spp = planes.channel("spp.Y").unwrap();
    assert!(spp.iter().all(|&s| s < 2048.0), "interrupted early");
    lucerna_ok(&[&args[..], &["-o", &checkpoint, "--resume"]].concat());
    let (resumed, header) = exr::read(Path::new(&checkpoint)).unwrap();
    assert_eq!(header.number("lucerna/complete"), Some(1.0));
    assert_same_image(&read(&full), &resumed, 1e-5);
    // A checkpoint of other settings is not continued.
    let run = lucerna(&[&args[..], &["-o", &checkpoint, "--resume", "--seed", "3"]].concat());
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("differ"));
}
