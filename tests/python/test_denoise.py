"""`--denoise`: Open Image Denoise (the venv's pyoidn, which tools/test.sh installs) adds a
`denoised` layer whose error against a converged reference is well below the noisy
beauty's. The full figures (256x256, 16 spp against 4096) come from
tools/compare/denoise/compare.py; this is its fast version."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("LUCERNA_BIN", str(ROOT / "target" / "release" / "lucerna"))
from lucerna_tools import read_exr, relmse, rgb

AVOCADO = ROOT / "tests/assets/gltf/Avocado/Avocado.gltf"


def render(tmp, scene, spp, seed, *extra):
    out = tmp / f"{Path(str(scene)).stem}.{spp}.{seed}.exr"
    cmd = [BIN, "render", *([str(scene)] if scene else []), "-o", str(out), "-q",
           "--progress", "none", "--resolution", "80x80", "--spp", str(spp),
           "--seed", str(seed), *extra]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return out, done.stderr


def check(tmp, scene, most_ratio):
    noisy, log = render(tmp, scene, 16, 1, "--denoise")
    assert "denoised in" in log, log
    channels = read_exr(noisy)[0]
    reference = rgb(read_exr(render(tmp, scene, 1024, 2)[0])[0])
    beauty, denoised = relmse(rgb(channels), reference), relmse(rgb(channels, "denoised"), reference)
    # The reference's own error (1/64 of the beauty's, by its sample count) is part of both.
    assert denoised < most_ratio * beauty, (scene, beauty, denoised)
    return channels


def test_denoised_layer_is_closer_to_the_reference(tmp_path):
    # Measured at 80x80: Cornell box 0.2 of the beauty's relMSE, Avocado 0.55 (its
    # environment-lit beauty is less noisy; the silhouette's antialiasing stays).
    channels = check(tmp_path, None, 0.4)
    # Every noisy layer is kept, and the denoiser's guides are written too.
    for name in ["R", "G", "B", "A", "denoised.R", "albedo.R", "normal.X"]:
        assert name in channels, sorted(channels)
    check(tmp_path, AVOCADO, 0.75)


def test_denoised_layer_is_half_with_exr_half_and_read_by_oiio(tmp_path):
    out, _ = render(tmp_path, None, 4, 1, "--denoise", "--exr-half")
    spec = oiio.ImageInput.open(str(out)).spec()
    formats = dict(zip(spec.channelnames, spec.channelformats))
    assert str(formats["denoised.R"]) == "half" and str(formats["normal.X"]) == "float", formats


def test_a_missing_library_is_a_clear_error(tmp_path):
    # An installed copy (outside the checkout) with no Python environment that has pyoidn.
    exe = tmp_path / "lucerna"
    exe.write_bytes(Path(BIN).read_bytes())
    exe.chmod(0o755)
    env = {"PATH": os.environ["PATH"], "HOME": str(tmp_path), "LUCERNA_PYTHON": "/nonexistent/python",
           "LUCERNA_OIDN": str(tmp_path / "nowhere")}
    done = subprocess.run([str(exe), "render", "-o", str(tmp_path / "x.exr"), "--spp", "1",
                           "--resolution", "8x8", "--denoise"], capture_output=True, text=True, env=env)
    assert done.returncode == 2, done.stderr
    assert "--denoise" in done.stderr and "lucerna setup" in done.stderr, done.stderr
    assert not (tmp_path / "x.exr").exists()


def test_preview_view_transforms(tmp_path):
    """The preview through standard, agx and an OCIO display/view (OCIO's built-in ACES
    2.0 config through OpenImageIO): a bright scene clips under standard, rolls off under
    agx and ACES, and exposure darkens it."""
    scene = ROOT / "tests/assets/gltf/Avocado/Avocado.gltf"

    def preview(*view):
        png = tmp_path / f"p{len(list(tmp_path.iterdir()))}.png"
        out, log = render(tmp_path, scene, 4, 1, "--env", "4", "--preview", str(png), *view)
        image = oiio.ImageInput.open(str(png))
        pixels = image.read_image(0, 0, 0, 3, "uint8")
        image.close()
        return np.asarray(pixels, dtype=np.float64) / 255, log

    standard, _ = preview()
    agx, _ = preview("--view-transform", "agx")
    aces, log = preview("--view-transform", "ocio")
    assert "ACES" in log, log
    darker, _ = preview("--view-transform", "ocio", "--exposure", "-2")
    # The background (radiance 4) is white in standard; both tone curves keep it below 1.
    assert standard[0, 0].min() == 1.0
    assert agx[0, 0].max() < 1.0 and aces[0, 0].max() <= 1.0
    assert darker.mean() < aces.mean() - 0.05
    bad = subprocess.run([BIN, "render", "-o", str(tmp_path / "b.exr"), "--spp", "1",
                          "--resolution", "8x8", "--preview", str(tmp_path / "b.png"),
                          "--view-transform", "ocio", "--ocio-display", "Cinema"],
                         capture_output=True, text=True)
    # Checked before rendering: exit 2 and no EXR.
    assert bad.returncode == 2 and "no display 'Cinema'" in bad.stderr, bad.stderr
    assert not (tmp_path / "b.exr").exists()


def test_merged_passes_are_denoised_whole(tmp_path):
    """Passes rendered with --denoise merge without their denoised layers; `lucerna denoise`
    then denoises the merged render."""
    parts = []
    for k in (1, 2):
        out, _ = render(tmp_path, None, 16, 1, "--denoise", "--pass", f"{k}/2")
        part = tmp_path / f"part{k}.exr"
        out.rename(part)
        parts.append(str(part))
    merged = tmp_path / "merged.exr"
    done = subprocess.run([BIN, "merge", *parts, "-o", str(merged)], capture_output=True, text=True)
    assert done.returncode == 0 and "left out" in done.stderr, done.stderr
    assert "denoised.R" not in read_exr(merged)[0]
    done = subprocess.run([BIN, "denoise", str(merged)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    channels = read_exr(merged)[0]
    reference = rgb(read_exr(render(tmp_path, None, 1024, 2)[0])[0])
    assert relmse(rgb(channels, "denoised"), reference) < 0.4 * relmse(rgb(channels), reference)
    # A render without the guides is refused, naming what is missing.
    plain, _ = render(tmp_path, None, 2, 1)
    done = subprocess.run([BIN, "denoise", str(plain)], capture_output=True, text=True)
    assert done.returncode == 2 and "albedo" in done.stderr, done.stderr
