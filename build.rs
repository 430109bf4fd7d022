//! Build facts for `lucerna --version` (the commit and date of the build) and the USD
//! plugin's sources, embedded so that an installed binary carries its plugin
//! (src/install.rs writes them out on first use).

use std::path::Path;
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
        .filter(|s| !s.is_empty())
}

fn main() {
    let commit = git(&["rev-parse", "--short=12", "HEAD"]).unwrap_or_else(|| "unknown".into());
    let dirty =
        git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
    let date = git(&["log", "-1", "--format=%cs"]).unwrap_or_else(|| "unknown".into());
    println!(
        "cargo:rustc-env=LUCERNA_COMMIT={commit}{}",
        if dirty { "-modified" } else { "" }
    );
    println!("cargo:rustc-env=LUCERNA_COMMIT_DATE={date}");
    for file in [".git/HEAD", ".git/index"] {
        if Path::new(file).exists() {
            println!("cargo:rerun-if-changed={file}");
        }
    }

    // The plugin's Python sources, as (relative path, include_str!) pairs.
    let root = Path::new("plugins/usd");
    let mut files: Vec<String> = Vec::new();
    for entry in std::fs::read_dir(root.join("lucerna_usd")).expect("plugins/usd/lucerna_usd") {
        let path = entry.expect("a directory entry").path();
        if path.extension().is_some_and(|e| e == "py") {
            files.push(format!(
                "lucerna_usd/{}",
                path.file_name().unwrap().to_string_lossy()
            ));
        }
    }
    files.push("requirements.txt".into());
    files.sort();
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap();
    let mut code = String::from(
        "/// The USD plugin's files: (path under the plugin folder, contents).\npub const PLUGIN_FILES: &[(&str, &str)] = &[\n",
    );
    for f in &files {
        code.push_str(&format!(
            "    ({f:?}, include_str!({:?})),\n",
            format!("{manifest}/plugins/usd/{f}")
        ));
    }
    code.push_str("];\n");
    let out = Path::new(&std::env::var("OUT_DIR").unwrap()).join("plugin_files.rs");
    std::fs::write(out, code).expect("OUT_DIR is writable");
    println!("cargo:rerun-if-changed=plugins/usd/lucerna_usd");
    println!("cargo:rerun-if-changed=plugins/usd/requirements.txt");
}
