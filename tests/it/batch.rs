//! `lucerna batch`: a job with a broken scene renders the others, logs every frame, writes a
//! summary naming the failure and exits non-zero; a rerun skips what is complete.

use crate::common;

use common::cli::temp_dir;
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output};

fn batch(job: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lucerna"))
        .arg("batch")
        .arg(job)
        .output()
        .unwrap()
}

fn summary(dir: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(dir.join("job.summary.json")).unwrap()).unwrap()
}

const JOB: &str = r#"
[settings]
spp = 4

[[render]]
output = "out/{scene}.{frame}.exr"
frames = "1-2"
resolution = "16x16"
settings = { aov = "direct,spp" }

[[render]]
scene = "broken.gltf"
output = "out/broken.exr"

[[render]]
output = "out/single.exr"
resolution = "8x8"
"#;

#[test]
fn a_broken_scene_fails_alone_and_a_rerun_skips_complete_frames() {
    let dir = temp_dir("broken");
    std::fs::write(dir.join("broken.gltf"), b"{ not json").unwrap();
    let job = dir.join("job.toml");
    std::fs::write(&job, JOB).unwrap();

    let run = batch(&job);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    let s = summary(&dir);
    assert_eq!(
        (s["rendered"].as_u64(), s["failed"].as_u64()),
        (Some(3), Some(1)),
        "{s}"
    );
    let frames = s["frames"].as_array().unwrap();
    let statuses: Vec<&str> = frames
        .iter()
        .map(|f| f["status"].as_str().unwrap())
        .collect();
    assert_eq!(statuses, ["rendered", "rendered", "failed", "rendered"]);
    assert_eq!(frames[0]["frame"].as_f64(), Some(1.0));
    assert_eq!(frames[0]["samples"].as_f64(), Some(16.0 * 16.0 * 4.0));
    assert_eq!(frames[0]["nan_inf_discarded"].as_f64(), Some(0.0));
    let failure = &frames[2];
    assert_eq!(failure["exit_code"].as_i64(), Some(2));
    assert!(
        failure["error"].as_str().unwrap().contains("broken.gltf"),
        "{failure}"
    );
    for name in ["default.0001.exr", "default.0002.exr", "single.exr"] {
        assert!(dir.join("out").join(name).exists(), "{name}");
    }
    // One log per frame, each its own file.
    let logs: std::collections::HashSet<&str> =
        frames.iter().map(|f| f["log"].as_str().unwrap()).collect();
    assert_eq!(logs.len(), frames.len());
    assert!(logs.iter().all(|l| Path::new(l).exists()), "{logs:?}");
    let log = std::fs::read_to_string(failure["log"].as_str().unwrap()).unwrap();
    assert!(
        log.contains("error: ") && log.contains("broken.gltf"),
        "{log}"
    );
    assert!(!dir.join("out/broken.exr").exists());

    // The rerun renders nothing that is complete, and still reports the failure.
    let run = batch(&job);
    assert_eq!(run.status.code(), Some(1));
    let s = summary(&dir);
    assert_eq!(
        (s["skipped"].as_u64(), s["failed"].as_u64()),
        (Some(3), Some(1)),
        "{s}"
    );
    assert_eq!(s["frames"][0]["samples"].as_f64(), Some(16.0 * 16.0 * 4.0));
}

#[test]
fn malformed_jobs_are_refused_before_rendering() {
    let dir = temp_dir("malformed");
    let job = dir.join("job.toml");
    for (text, expected) in [
        (
            "[[render]]\noutput = \"a.exr\"\nsettings = { mis = \"best\" }\n",
            "render[0].settings",
        ),
        (
            "[[render]]\noutput = \"a.exr\"\nframes = \"1-3\"\n",
            "{frame}",
        ),
        ("[[render]]\nouput = \"a.exr\"\n", "ouput"),
        ("[settings]\nspp = 4\n", "missing field `render`"),
    ] {
        std::fs::write(&job, text).unwrap();
        let run = batch(&job);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{text}: {stderr}");
        assert!(stderr.contains(expected), "{expected:?} not in {stderr}");
    }
    assert!(!dir.join("a.exr").exists());
}

/// A rerun after the job's shutter changed renders the frame again (the scene file is the
/// same); with the shutter unchanged it is skipped.
#[test]
fn a_changed_shutter_renders_again() {
    let dir = temp_dir("batch-shutter");
    let job = dir.join("job.toml");
    let write = |shutter: &str| {
        std::fs::write(
            &job,
            format!(
                "[settings]\nspp = 2\nshutter = \"{shutter}\"\n\n[[render]]\noutput = \"out/still.exr\"\nresolution = \"8x8\"\n"
            ),
        )
        .unwrap()
    };
    let statuses = || {
        let run = batch(&job);
        assert_eq!(
            run.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        summary(&dir)["frames"][0]["status"]
            .as_str()
            .unwrap()
            .to_string()
    };
    write("-0.5,0.5");
    assert_eq!(statuses(), "rendered");
    assert_eq!(statuses(), "skipped");
    write("-0.25,0.25");
    assert_eq!(statuses(), "rendered");
    let summary = summary(&dir);
    assert!(
        summary["frames"][0]["note"]
            .as_str()
            .unwrap_or_default()
            .contains("shutter"),
        "{summary}"
    );
}
