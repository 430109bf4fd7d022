"""Helpers for the plugin's tests: author a stage, convert it, read the scene file back."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

PLUGIN = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(PLUGIN))

from lucerna_usd.__main__ import convert  # noqa: E402

HEADER = '#usda 1.0\n(\n    defaultPrim = "World"\n    metersPerUnit = 1\n    upAxis = "Y"\n)\n'


class Scene:
    """A converted scene file: the manifest and typed access to its buffer."""

    def __init__(self, path):
        self.manifest = json.loads(Path(path).read_text())
        self.buffer = Path(path).with_name(self.manifest["buffer"]).read_bytes()

    def __getitem__(self, key):
        return self.manifest[key]

    def array(self, view, dtype, width):
        data = np.frombuffer(self.buffer, dtype=dtype, count=view["count"] * width, offset=view["offset"])
        return data.reshape(view["count"], width)

    def mesh(self, name):
        return next(m for m in self.manifest["meshes"] if m["name"] == name)

    def positions(self, mesh):
        return self.array(mesh["positions"], "<f4", 3)

    def triangles(self, mesh):
        return self.array(mesh["triangles"], "<u4", 3)

    def warnings_about(self, text):
        return [w for w in self.manifest["warnings"] if text in w]


@pytest.fixture
def stage_file(tmp_path):
    """Writes a .usda (HEADER prepended unless the text starts with '#usda') and returns
    its path."""

    def write(text, name="stage.usda"):
        path = tmp_path / name
        path.write_text(text if text.startswith("#usda") else HEADER + text)
        return path

    return write


@pytest.fixture
def converted(tmp_path):
    """Converts a stage file; returns the Scene (asserting success)."""

    def run(path, **options):
        """Options as `convert`'s: frame, no_validate."""
        out = tmp_path / (Path(path).stem + ".lucerna")
        status = convert(str(path), str(out), quiet=True, **options)
        assert status == 0, f"conversion failed with status {status}"
        return Scene(out)

    return run


def write_image(path, pixels, fmt=None):
    """Writes an image file (8-bit unless `fmt` is another OpenImageIO type), colour not
    premultiplied by alpha."""
    import OpenImageIO as oiio

    fmt = oiio.UINT8 if fmt is None else fmt
    pixels = np.asarray(pixels, dtype=np.uint8 if fmt == oiio.UINT8 else np.float32)
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], fmt)
    # The texels as given: OpenImageIO would otherwise divide colour by alpha on writing.
    spec.attribute("oiio:UnassociatedAlpha", 1)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    out.write_image(pixels)
    out.close()


def texels(scene, ref):
    """The texels of the texture a material slot refers to, (H, W, 4)."""
    t = scene["textures"][ref["texture"]]
    if t["encoding"] == "rgba8":
        return scene.array(t["texels"], "<u1", 4).reshape(t["height"], t["width"], 4)
    return scene.array(t["texels"], "<f4", 4).reshape(t["height"], t["width"], 4)


def lucerna_bin():
    """The renderer binary (LUCERNA_BIN, else the release build)."""
    path = os.environ.get("LUCERNA_BIN") or str(PLUGIN.parent.parent / "target" / "release" / "lucerna")
    if not os.path.exists(path):
        pytest.skip(f"no lucerna binary at {path} (cargo build --release)")
    return path


def run_plugin(*args):
    """Runs the plugin's command line as the renderer does; returns the CompletedProcess."""
    env = dict(os.environ, PYTHONPATH=str(PLUGIN))
    return subprocess.run([sys.executable, "-m", "lucerna_usd", *map(str, args)],
                          capture_output=True, text=True, env=env)
