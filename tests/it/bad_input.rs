//! Every broken file under tests/bad-gltf/ (made by tools/generate/bad_gltf.py) makes `render`
//! and `inspect` exit with code 2 and one line naming the file, the element and the
//! reason: no panic, no output file.

use std::path::Path;
use std::process::Command;

fn corpus() -> Vec<(String, String, String)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bad-gltf");
    let expected: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("expected.json")).unwrap()).unwrap();
    expected
        .as_object()
        .unwrap()
        .iter()
        .map(|(file, e)| {
            (
                dir.join(file).display().to_string(),
                e["element"].as_str().unwrap().to_string(),
                e["reason"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

#[test]
fn broken_gltf_files_fail_cleanly() {
    let out_dir = std::env::temp_dir().join(format!("lucerna-bad-input-{}", std::process::id()));
    std::fs::create_dir_all(&out_dir).unwrap();
    let cases = corpus();
    assert!(
        cases.len() >= 20,
        "the corpus is generated: python3 tools/generate/bad_gltf.py"
    );
    for (file, element, reason) in &cases {
        let output = out_dir.join("out.exr");
        for args in [
            vec![
                "render",
                file.as_str(),
                "-o",
                output.to_str().unwrap(),
                "--spp",
                "1",
                "-q",
            ],
            vec!["inspect", file.as_str()],
        ] {
            let run = Command::new(env!("CARGO_BIN_EXE_lucerna"))
                .args(&args)
                .output()
                .unwrap();
            let stderr = String::from_utf8_lossy(&run.stderr);
            assert_eq!(
                run.status.code(),
                Some(2),
                "{args:?}: exit status {:?}, stderr {stderr}",
                run.status
            );
            assert!(!stderr.contains("panicked"), "{file}: {stderr}");
            let lines: Vec<&str> = stderr.lines().collect();
            assert_eq!(lines.len(), 1, "{file}: one line expected, got {stderr}");
            let line = lines[0];
            assert!(line.starts_with(&format!("error: {file}: ")), "{line}");
            assert!(
                line.contains(element.as_str()),
                "{file}: element {element:?} missing from {line}"
            );
            assert!(
                line.contains(reason.as_str()),
                "{file}: reason {reason:?} missing from {line}"
            );
            assert!(run.stdout.is_empty());
        }
        let left: Vec<_> = std::fs::read_dir(&out_dir).unwrap().collect();
        assert!(left.is_empty(), "{file}: files left behind: {left:?}");
    }
    std::fs::remove_dir_all(&out_dir).unwrap();
}

#[test]
fn bad_options_exit_with_code_2() {
    for args in [
        vec!["render", "--resolution", "0x10"],
        vec!["render", "--mis", "nonsense"],
        vec!["render", "--aov", "beauty,unknown"],
        vec!["render", "--env", "1,2"],
        vec!["render", "scene.obj"],
        vec!["render", "--camera", "nope", "--spp", "1"],
    ] {
        let run = Command::new(env!("CARGO_BIN_EXE_lucerna"))
            .args(&args)
            .current_dir(std::env::temp_dir())
            .output()
            .unwrap();
        assert_eq!(
            run.status.code(),
            Some(2),
            "{args:?}: {}",
            String::from_utf8_lossy(&run.stderr)
        );
        assert!(!String::from_utf8_lossy(&run.stderr).contains("panicked"));
    }
}
