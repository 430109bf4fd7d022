//! What pipelines need from the command line: the help and its defaults, settings files with
//! every option, version facts, completions and man pages, logs, periodic checkpoints and
//! SIGUSR1 snapshots.

use crate::common;

use common::cli::{lucerna, lucerna_ok, lucerna_stderr as stderr_of, temp_dir};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Every `render` option that takes a value states its default in `--help`; the help is
/// grouped by topic.
#[test]
fn render_help_shows_every_default_and_is_grouped() {
    let out = lucerna(&["render", "--help"]);
    assert!(out.status.success());
    let help = String::from_utf8_lossy(&out.stdout);
    for heading in [
        "Scene input:",
        "Output:",
        "Sampling:",
        "Integrator:",
        "Lighting:",
        "Running:",
    ] {
        assert!(help.contains(heading), "no {heading}\n{help}");
    }
    // Each option's entry: from its `--name <VALUE>` line to the next option.
    let mut entries: Vec<(String, String)> = Vec::new();
    for line in help.lines() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("--") || trimmed.starts_with("-o") || trimmed.starts_with("-q") {
            entries.push((trimmed.to_string(), String::new()));
        } else if let Some(last) = entries.last_mut() {
            last.1.push_str(trimmed);
            last.1.push(' ');
        }
    }
    let mut checked = 0;
    for (head, rest) in &entries {
        let takes_value = head.split_whitespace().any(|w| w.starts_with('<'));
        if !takes_value || head.starts_with("--help") {
            continue;
        }
        checked += 1;
        let text = format!("{head} {rest}");
        assert!(
            text.contains("[default:"),
            "option without a stated default: {text}"
        );
    }
    assert!(checked >= 40, "only {checked} options with values found");
}

/// A settings file takes every option of the command (the flags without `--`), booleans
/// and lists included; the command line overrides it.
#[test]
fn settings_files_take_every_option() {
    let dir = temp_dir("settings-every");
    let out = dir.join("from-settings.exr");
    let preview = dir.join("p.png");
    let stats = dir.join("s.json");
    let settings = dir.join("s.toml");
    std::fs::write(
        &settings,
        format!(
            r#"output = "{}"
resolution = "24x16"
spp = 2
exr-half = true
exr-compression = "piz"
preview = "{}"
view-transform = "agx"
exposure = -1
stats-json = "{}"
progress = "none"
quiet = true
light-group = ["lamp=Light*"]
aov = "beauty,lightgroups"
"#,
            out.display(),
            preview.display(),
            stats.display()
        ),
    )
    .unwrap();
    let (ok, err) = stderr_of(&["render", "--settings", settings.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(out.exists() && preview.exists() && stats.exists(), "{err}");
    let image = exr::prelude::read_all_flat_layers_from_file(&out).unwrap();
    let layer = &image.layer_data[0];
    assert_eq!((layer.size.0, layer.size.1), (24, 16));
    assert_eq!(layer.encoding.compression, exr::prelude::Compression::PIZ);
    let beauty = layer
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "R")
        .unwrap();
    assert!(matches!(
        beauty.sample_data,
        exr::prelude::FlatSamples::F16(_)
    ));
    assert!(
        layer
            .channel_data
            .list
            .iter()
            .any(|c| c.name.to_string().starts_with("lg_lamp.")),
        "{:?}",
        layer
            .channel_data
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect::<Vec<_>>()
    );
    // The command line wins over the file.
    let (ok, err) = stderr_of(&[
        "render",
        "--settings",
        settings.to_str().unwrap(),
        "--resolution",
        "8x8",
    ]);
    assert!(ok, "{err}");
    let image = exr::prelude::read_all_flat_layers_from_file(&out).unwrap();
    assert_eq!(image.layer_data[0].size.0, 8);
    // An unknown key names the file, the key and what is known.
    std::fs::write(&settings, "colour = \"red\"\n").unwrap();
    let (ok, err) = stderr_of(&["render", "--settings", settings.to_str().unwrap()]);
    assert!(
        !ok && err.contains("colour") && err.contains("s.toml"),
        "{err}"
    );
}

#[test]
fn a_non_exr_output_is_refused() {
    let dir = temp_dir("non-exr");
    let png = dir.join("beauty.png");
    let out = lucerna(&["render", "-o", png.to_str().unwrap(), "--spp", "1"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("not an .exr file") && err.contains("--preview"),
        "{err}"
    );
    assert!(!png.exists());
}

#[test]
fn version_names_commit_date_and_kernel() {
    let out = lucerna(&["--version"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(text.contains(env!("CARGO_PKG_VERSION")), "{text}");
    assert!(text.contains("commit "), "{text}");
    assert!(text.contains("kernel: "), "{text}");
    let date = text.split(", ").nth(1).unwrap_or("");
    assert!(
        date.starts_with("20") || date.starts_with("unknown"),
        "{text}"
    );
}

#[test]
fn completions_and_man_pages() {
    for shell in ["bash", "zsh", "fish"] {
        let out = lucerna(&["completions", shell]);
        assert!(out.status.success());
        let script = String::from_utf8_lossy(&out.stdout);
        assert!(
            script.contains("exr-compression") && script.contains("lucerna"),
            "{shell}"
        );
    }
    let dir = temp_dir("man");
    lucerna_ok(&["man", dir.to_str().unwrap()]);
    let page = std::fs::read_to_string(dir.join("lucerna-render.1")).unwrap();
    assert!(
        page.contains(".TH") && page.contains("checkpoint"),
        "{page}"
    );
    assert!(dir.join("lucerna.1").exists());
}

#[test]
fn log_level_and_timestamps() {
    let dir = temp_dir("log-level");
    let out = dir.join("l.exr");
    let args = [
        "render",
        "-o",
        out.to_str().unwrap(),
        "--spp",
        "1",
        "--resolution",
        "8x8",
        "--progress",
        "none",
    ];
    let (ok, info) = stderr_of(&args);
    assert!(ok && info.contains("lucerna: wrote"), "{info}");
    let (ok, quiet) = stderr_of(&[&args[..], &["--log-level", "warn"]].concat());
    assert!(ok && !quiet.contains("wrote"), "{quiet}");
    let (ok, stamped) = stderr_of(&[&args[..], &["--log-timestamps"]].concat());
    assert!(ok, "{stamped}");
    let line = stamped.lines().find(|l| l.contains("wrote")).unwrap();
    // 2026-12-03T22:40:01.123Z lucerna: wrote ...
    let (stamp, rest) = line.split_once(' ').unwrap();
    assert!(
        stamp.len() == 24 && stamp.ends_with('Z') && stamp.as_bytes()[10] == b'T',
        "{line}"
    );
    assert!(rest.starts_with("lucerna: wrote"), "{line}");
    let (ok, err) = stderr_of(&[&args[..], &["--log-level", "loud"]].concat());
    assert!(!ok && err.contains("loud"), "{err}");
}

/// Reads the `lucerna/complete` attribute and the smallest spp of a checkpoint.
fn checkpoint_facts(path: &Path) -> (i32, f32) {
    let image = exr::prelude::read_all_flat_layers_from_file(path).unwrap();
    let layer = &image.layer_data[0];
    let complete = match layer
        .attributes
        .other
        .get(&exr::prelude::Text::from("lucerna/complete"))
    {
        Some(exr::prelude::AttributeValue::I32(v)) => *v,
        other => panic!("{other:?}"),
    };
    let spp = layer
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "spp.Y")
        .map(|c| {
            (0..layer.size.area())
                .map(|i| c.sample_data.value_by_flat_index(i).to_f32())
                .fold(f32::INFINITY, f32::min)
        })
        .unwrap_or(f32::NAN);
    (complete, spp)
}

/// Starts a render of the Cornell box long enough to take several passes; returns it.
fn long_render(out: &Path, spp: &str, extra: &[&str]) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_lucerna"))
        .args([
            "render",
            "-o",
            out.to_str().unwrap(),
            "--spp",
            spp,
            "--resolution",
            "64x64",
            "--progress",
            "none",
        ])
        .args(extra)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits until `path` exists (a checkpoint) while `child` runs; copies it aside.
fn catch_checkpoint(child: &mut std::process::Child, path: &Path, copy: &Path) -> bool {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(60) {
        if path.exists() && std::fs::copy(path, copy).is_ok() {
            return true;
        }
        if child.try_wait().unwrap().is_some() {
            return false;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    false
}

/// `--checkpoint-interval` writes resumable checkpoints while rendering; `--resume` of one
/// finishes the render; the final file is complete.
#[test]
fn periodic_checkpoints_are_resumable() {
    let dir = temp_dir("checkpoint-interval");
    let out = dir.join("c.exr");
    let caught = dir.join("caught.exr");
    let mut child = long_render(&out, "1024", &["--checkpoint-interval", "0.2"]);
    assert!(
        catch_checkpoint(&mut child, &out, &caught),
        "no checkpoint was written while rendering"
    );
    let (complete, spp) = checkpoint_facts(&caught);
    assert_eq!(complete, 0);
    assert!((16.0..1024.0).contains(&spp), "{spp}");
    // Stop the long render; finish the caught checkpoint with fewer samples in all.
    let _ = child.kill();
    let _ = child.wait();
    let resumed = dir.join("r.exr");
    std::fs::copy(&caught, &resumed).unwrap();
    // The checkpoint records --spp 1024; a continuation takes the same settings.
    let mut finish = long_render(&resumed, "1024", &["--resume"]);
    let status = finish.wait().unwrap();
    let mut err = String::new();
    std::io::Read::read_to_string(finish.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert!(status.success(), "{err}");
    assert!(err.contains("continuing"), "{err}");
    assert_eq!(checkpoint_facts(&resumed).0, 1, "{err}");
}

/// SIGUSR1 writes a snapshot (a checkpoint) and the render goes on to finish.
#[test]
#[cfg(unix)]
fn sigusr1_writes_a_snapshot_and_the_render_goes_on() {
    let dir = temp_dir("sigusr1");
    let out = dir.join("u.exr");
    let caught = dir.join("caught.exr");
    let mut child = long_render(&out, "1024", &[]);
    std::thread::sleep(Duration::from_millis(300));
    // SAFETY: kill(2) with the pid of a child not yet reaped.
    unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGUSR1) };
    assert!(catch_checkpoint(&mut child, &out, &caught), "no snapshot");
    assert_eq!(checkpoint_facts(&caught).0, 0);
    let status = child.wait().unwrap();
    let mut err = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert!(status.success(), "{err}");
    assert!(err.contains("checkpoint:"), "{err}");
    assert_eq!(checkpoint_facts(&out).0, 1);
}

/// SIGUSR1 sent to `lucerna batch` reaches the frame being rendered, which writes a
/// snapshot and goes on.
#[test]
#[cfg(unix)]
fn sigusr1_to_a_batch_reaches_its_render() {
    let dir = temp_dir("batch-sigusr1");
    let job = dir.join("job.toml");
    std::fs::write(
        &job,
        "[settings]\nspp = 1024\nprogress = \"none\"\n\n[[render]]\noutput = \"b.exr\"\nresolution = \"64x64\"\n",
    )
    .unwrap();
    let out = dir.join("b.exr");
    let caught = dir.join("caught.exr");
    let mut batch = Command::new(env!("CARGO_BIN_EXE_lucerna"))
        .args(["batch", job.to_str().unwrap()])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    // SAFETY: kill(2) with the pid of a child not yet reaped.
    unsafe { libc::kill(batch.id() as libc::pid_t, libc::SIGUSR1) };
    assert!(catch_checkpoint(&mut batch, &out, &caught), "no snapshot");
    assert_eq!(checkpoint_facts(&caught).0, 0);
    assert!(batch.wait().unwrap().success());
    assert_eq!(checkpoint_facts(&out).0, 1);
}
