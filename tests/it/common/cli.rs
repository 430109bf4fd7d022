//! Running the `lucerna` binary from integration tests, and their scratch directories.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the binary with `args`.
pub fn lucerna(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lucerna"))
        .args(args)
        .output()
        .unwrap()
}

/// Runs the binary with `args`: whether it succeeded, and its stderr.
pub fn lucerna_stderr(args: &[&str]) -> (bool, String) {
    let out = lucerna(args);
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs the binary with `args` and asserts that it succeeded (showing its stderr if not).
pub fn lucerna_ok(args: &[&str]) {
    let run = lucerna(args);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

/// A scratch directory of a test, removed when dropped unless the test is failing (its
/// files are then left for a look), so that test runs leave nothing behind.
pub struct TempDir(PathBuf);

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// An empty directory of this test process named after `name`.
pub fn temp_dir(name: &str) -> TempDir {
    let dir = std::env::temp_dir().join(format!("lucerna-test-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    TempDir(dir)
}

/// The text attribute `name` of the header of the EXR at `exr`; panics if it has none.
pub fn header_text(exr: &Path, name: &str) -> String {
    let image = exr::prelude::read_first_flat_layer_from_file(exr).unwrap();
    match image
        .layer_data
        .attributes
        .other
        .get(&exr::prelude::Text::from(name))
    {
        Some(exr::prelude::AttributeValue::Text(t)) => t.to_string(),
        other => panic!("no text {name} in the header: {other:?}"),
    }
}
