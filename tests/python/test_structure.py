"""The structure rules of docs/architecture.md hold: no file-level import circle in src/, no
file over 900 lines unless its doc says it is one concept, no file pointing outside the
repository (tools/check/structure.py)."""
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_structure_rules_hold():
    result = subprocess.run([sys.executable, str(ROOT / "tools/check/structure.py"), str(ROOT)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_the_check_finds_a_circle(tmp_path):
    src = tmp_path / "src"
    (src / "a").mkdir(parents=True)
    (src / "lib.rs").write_text("pub mod a;\npub mod b;\n")
    (src / "a" / "mod.rs").write_text("mod inner;\nuse inner::X;\n")
    (src / "a" / "inner.rs").write_text("use super::Y;\npub struct X;\n")
    (src / "b.rs").write_text("//! small\n")
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    result = subprocess.run([sys.executable, str(ROOT / "tools/check/structure.py"), str(tmp_path)],
                            capture_output=True, text=True)
    assert result.returncode == 1 and "import circle: src/a/inner.rs src/a/mod.rs" in result.stdout, result.stdout
