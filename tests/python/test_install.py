"""Install anywhere: a `cargo install --root` copy of lucerna renders a USD stage with the
checkout out of its reach. The plugin comes from the binary itself (written to the cache
folder on first use); Python from the environment `lucerna setup` makes (here the test
venv, placed where setup would put it: running setup itself needs PyPI)."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
USD_TWIN = ROOT / "scenes/usd-twin/usd-twin.usda"


def test_an_installed_copy_renders_a_usd_stage_without_the_checkout(tmp_path):
    root = tmp_path / "root"
    subprocess.run(["cargo", "install", "--path", str(ROOT), "--root", str(root), "--locked",
                    "--offline", "--target-dir", str(ROOT / "target"), "--quiet"],
                   check=True, capture_output=True)
    exe = root / "bin" / "lucerna"
    home = tmp_path / "home"
    venv = home / "lucerna"
    venv.mkdir(parents=True)
    (venv / "venv").symlink_to(Path(sys.prefix))
    stage_dir = tmp_path / "shot"
    shutil.copytree(USD_TWIN.parent, stage_dir)
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path / "user"),
           "LUCERNA_HOME": str(venv), "XDG_CACHE_HOME": str(tmp_path / "cache")}
    done = subprocess.run([str(exe), "render", "usd-twin.usda", "-o", "out.exr", "--spp", "2",
                           "--resolution", "24x16", "--log-level", "debug"],
                          cwd=stage_dir, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert (stage_dir / "out.exr").exists()
    plugin_line = next(l for l in done.stderr.splitlines() if "USD plugin:" in l)
    assert str(venv / "venv" / "bin" / "python") in plugin_line, plugin_line
    assert str(tmp_path / "cache" / "lucerna" / "usd-plugin-") in plugin_line, plugin_line
    assert str(ROOT) not in plugin_line, plugin_line
    # The written-out plugin is reused by the next render.
    plugins = list((tmp_path / "cache" / "lucerna").glob("usd-plugin-*"))
    assert len(plugins) == 1 and (plugins[0] / "lucerna_usd" / "convert.py").exists()


def test_without_usd_core_the_error_says_how_to_set_up(tmp_path):
    exe = tmp_path / "lucerna"
    shutil.copy(os.environ.get("LUCERNA_BIN", ROOT / "target/release/lucerna"), exe)
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "XDG_CACHE_HOME": str(tmp_path / "c"),
           "LUCERNA_PYTHON": "/usr/bin/python3"}
    probe = subprocess.run(["/usr/bin/python3", "-c", "import pxr"], capture_output=True)
    if probe.returncode == 0:
        pytest.skip("this machine's /usr/bin/python3 has usd-core: there is nothing to refuse")
    done = subprocess.run([str(exe), "render", str(USD_TWIN), "-o", str(tmp_path / "o.exr")],
                          env=env, capture_output=True, text=True)
    assert done.returncode != 0 and "lucerna setup" in done.stderr, done.stderr


def test_the_wheel_installs_into_an_empty_venv_and_renders(tmp_path):
    """The wheel tools/test.sh builds (distribution lucerna-render: the PyPI name lucerna is
    another project's) installs into an empty venv with nothing else and, away from the
    checkout, renders the default scene and a USD stage. usd-core comes from the `usd` extra
    on a user's machine; here the test venv's Python, which has it, stands in for it (the
    extra needs PyPI)."""
    wheels = sorted((ROOT / "target" / "wheels").glob("lucerna_render-*-abi3-manylinux_*.whl"))
    assert wheels, "no lucerna_render wheel in target/wheels (tools/test.sh builds it)"
    venv = tmp_path / "empty"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet", "--no-index",
                    "--no-deps", "--disable-pip-version-check", str(wheels[-1])], check=True)
    work = tmp_path / "work"
    shutil.copytree(USD_TWIN.parent, work / "shot")
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path / "user"), "XDG_CACHE_HOME": str(tmp_path / "cache"),
           "LUCERNA_PYTHON": sys.executable}
    lucerna = str(venv / "bin" / "lucerna")
    for scene in [[], ["shot/usd-twin.usda"]]:
        done = subprocess.run([lucerna, "render", *scene, "-o", "out.exr", "--spp", "2", "--resolution", "32x24"],
                              cwd=work, env=env, capture_output=True, text=True)
        assert done.returncode == 0 and (work / "out.exr").exists(), done.stderr
        assert "wrote out.exr" in done.stderr, done.stderr
        (work / "out.exr").unlink()


def test_the_release_tarball_unpacks_anywhere_and_renders(tmp_path):
    """tools/package/release.py: a reproducible tarball (the same bytes twice) with a
    checksum file `sha256sum -c` accepts; unpacked away from the checkout, its binary renders
    the default scene and a USD stage (the plugin is embedded in it) and its man pages and
    completions are there."""
    digests = []
    for k in range(2):
        out = tmp_path / f"dist{k}"
        subprocess.run([sys.executable, str(ROOT / "tools/package/release.py"), "--out", str(out)], check=True,
                       capture_output=True)
        [checksum] = out.glob("*.sha256")
        done = subprocess.run(["sha256sum", "-c", checksum.name], cwd=out, capture_output=True, text=True)
        assert done.returncode == 0 and ": OK" in done.stdout, done.stdout + done.stderr
        digests.append(checksum.read_text().split()[0])
    assert digests[0] == digests[1]
    [archive] = (tmp_path / "dist0").glob("lucerna-*.tar.gz")
    unpacked = tmp_path / "opt"
    unpacked.mkdir()
    subprocess.run(["tar", "xzf", str(archive), "-C", str(unpacked)], check=True)
    [release] = unpacked.iterdir()
    for part in ["bin/lucerna", "share/man/man1/lucerna-render.1", "share/bash-completion/completions/lucerna",
                 "LICENSE-MIT", "LICENSE-APACHE", "README.md"]:
        assert (release / part).is_file(), part
    work = tmp_path / "work"
    shutil.copytree(USD_TWIN.parent, work / "shot")
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path / "user"), "XDG_CACHE_HOME": str(tmp_path / "cache"),
           "LUCERNA_PYTHON": sys.executable}
    for scene in [[], ["shot/usd-twin.usda"]]:
        done = subprocess.run([str(release / "bin" / "lucerna"), "render", *scene, "-o", "out.exr", "--spp", "2",
                               "--resolution", "32x24"], cwd=work, env=env, capture_output=True, text=True)
        assert done.returncode == 0 and (work / "out.exr").exists(), done.stderr
        (work / "out.exr").unlink()
