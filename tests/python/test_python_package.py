"""The pip package (python/, built with maturin and installed into the test venv by
tools/test.sh): the Python API, its `lucerna` command, and USD through it."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import lucerna

ROOT = Path(__file__).resolve().parents[2]
AVOCADO = ROOT / "tests/assets/gltf/Avocado/Avocado.gltf"
USD_TWIN = ROOT / "scenes/usd-twin/usd-twin.usda"
VENV_BIN = Path(sys.executable).parent


def test_render_returns_layers_as_arrays_and_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = lucerna.render(spp=4, resolution="32x24", aov="albedo,depth")
    assert r.layers["beauty"].shape == (24, 32, 4) and r.layers["beauty"].dtype == np.float32
    assert r.layers["albedo"].shape == (24, 32, 3) and r.layers["depth"].shape == (24, 32, 1)
    assert 0.05 < float(r.layers["beauty"][..., :3].mean()) < 1.0
    assert r.stats["samples"] == 32 * 24 * 4 and isinstance(r.stats["samples"], int)
    assert r.outputs == [] and list(tmp_path.iterdir()) == []


def test_render_with_output_writes_the_exr_as_the_command_line_does(tmp_path):
    out = tmp_path / "a.exr"
    r = lucerna.render(output=out, spp=2, resolution="16x16", exr_half=True, denoise=True)
    assert r.outputs == [str(out)] and out.exists()
    assert r.layers["denoised"].shape == (16, 16, 3)
    import OpenImageIO as oiio
    spec = oiio.ImageInput.open(str(out)).spec()
    assert "denoised.R" in spec.channelnames


def test_bad_settings_raise_value_error_with_lucernas_message():
    with pytest.raises(ValueError, match="spp"):
        lucerna.render(spp=0)
    with pytest.raises(ValueError, match="cannot read"):
        lucerna.render(ROOT / "no-such-scene.gltf")


def test_inspect_and_usd_through_the_package(tmp_path):
    assert "scene:" in lucerna.inspect(AVOCADO)
    # The plugin embedded in the package runs with this Python (which has usd-core).
    r = lucerna.render(USD_TWIN, spp=2, resolution="24x16")
    assert r.layers["beauty"].shape == (16, 24, 4)
    lucerna.convert(USD_TWIN, tmp_path / "twin.lucerna")
    assert (tmp_path / "twin.lucerna").exists()


def test_the_packages_command_line_and_batch(tmp_path):
    out = tmp_path / "cli.exr"
    done = subprocess.run([str(VENV_BIN / "lucerna"), "render", "-o", str(out), "--spp", "1",
                           "--resolution", "8x8"], capture_output=True, text=True)
    assert done.returncode == 0 and out.exists(), done.stderr
    version = subprocess.run([sys.executable, "-m", "lucerna", "--version"],
                             capture_output=True, text=True)
    assert "commit" in version.stdout, version
    # Batch children run the package's command line again (python -m lucerna).
    job = tmp_path / "job.toml"
    job.write_text('[settings]\nspp = 2\n\n[[render]]\noutput = "b.exr"\nresolution = "8x8"\n')
    done = subprocess.run([sys.executable, "-m", "lucerna", "batch", str(job)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "job.summary.json").read_text())
    assert summary["rendered"] == 1 and summary["frames"][0]["spp"] == 2
    assert "-m lucerna" in (tmp_path / "job.logs").joinpath(
        Path(summary["frames"][0]["log"]).name).read_text().splitlines()[0]
    bad = subprocess.run([str(VENV_BIN / "lucerna"), "render", "--spp", "0"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "error: --spp" in bad.stderr, bad.stderr
