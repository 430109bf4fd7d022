"""The same scene authored as glTF and as USD (scenes/usd-twin, centimetres and Z up in USD)
renders to the same image within the noise of the renderer."""

import subprocess
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from conftest import lucerna_bin

TWIN = Path(__file__).resolve().parents[3] / "scenes" / "usd-twin"


def render(scene, out, seed):
    subprocess.run([lucerna_bin(), "render", str(scene), "-o", str(out), "--spp", "128",
                    "--resolution", "96x64", "--seed", str(seed), "-q"], check=True,
                   capture_output=True)
    buf = oiio.ImageBuf(str(out))
    return buf.get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)


def rel_mse(a, b):
    return float(np.mean((a - b) ** 2 / (b ** 2 + 0.01)))


def test_usd_and_gltf_render_alike(tmp_path):
    gltf_a = render(TWIN / "usd-twin.gltf", tmp_path / "a.exr", 1)
    gltf_b = render(TWIN / "usd-twin.gltf", tmp_path / "b.exr", 2)
    usd = render(TWIN / "usd-twin.usda", tmp_path / "u.exr", 3)
    noise = rel_mse(gltf_a, gltf_b)
    twin = rel_mse(usd, gltf_b)
    # Independent renders of one scene: E[relMSE] is the same for both pairs. Over 18k
    # pixel channels the ratio spreads by about 10 % (fireflies); a wrong light, material, unit
    # or axis conversion moves it by far more than 35 %.
    assert twin < 1.35 * noise, (twin, noise)
    # The image means agree to within the noise of a mean over the image.
    sigma = np.sqrt(np.mean((gltf_a - gltf_b) ** 2) / 2 / gltf_a.size)
    assert abs(usd.mean() - gltf_b.mean()) < 5 * sigma * np.sqrt(2), (usd.mean(), gltf_b.mean(), sigma)
