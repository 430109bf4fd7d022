"""lucerna: a physically based path tracer for glTF and USD scenes, from Python.

    import lucerna
    result = lucerna.render("shot.usda", spp=64, resolution="640x360", aov="comp")
    result.layers["beauty"]      # float32 array (height, width, 4)
    result.stats["samples"]      # the render's figures
    lucerna.render("asset.glb", output="out.exr", denoise=True)   # also writes the EXR

Settings are the command line's options without `--`, with `_` for `-` (``max_depth=4``,
``exr_half=True``); a list gives a repeatable option (``variant=["shading=red"]``). The
`lucerna` command installed with this package is the same command line as the binary's.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from typing import Any

from . import _native

__version__ = _native.__version__

# The USD plugin runs in a Python that has usd-core: by default this one (the `usd` extra of
# this package), and the Open Image Denoise library is looked for beside it (the `denoise`
# extra): pip install "./python[usd,denoise]" from a checkout.
os.environ.setdefault("LUCERNA_PYTHON", sys.executable)


@dataclass
class Render:
    """One rendered view: its layers, its figures and the files written."""

    layers: dict[str, Any]
    stats: dict[str, Any]
    outputs: list[str] = field(default_factory=list)


def _pairs(settings: dict[str, Any]) -> list[tuple[str, str]]:
    pairs = []
    for key, value in settings.items():
        key = key.replace("_", "-")
        values = value if isinstance(value, (list, tuple)) else [value]
        for v in values:
            if v is None or v is False:
                continue
            pairs.append((key, "true" if v is True else str(v)))
    return pairs


def render(scene: str | os.PathLike | None = None, output: str | os.PathLike | None = None,
           **settings: Any) -> Render | list[Render]:
    """Renders `scene` (the embedded Cornell box when None) and returns its layers as numpy
    arrays with the render's stats. With `output` the EXR (and any preview or stats JSON
    asked for) is written as `lucerna render -o OUTPUT` would; without, nothing is written.
    Several frames or render products give a list. Bad input raises ValueError with
    lucerna's message; Ctrl-C stops the render and raises KeyboardInterrupt."""
    if output is not None:
        settings["output"] = os.fspath(output)
    views = _native.render(None if scene is None else os.fspath(scene), _pairs(settings),
                           output is not None)
    results = [Render(layers, stats, outputs) for layers, stats, outputs in views]
    return results[0] if len(results) == 1 else results


def inspect(scene: str | os.PathLike, **settings: Any) -> str:
    """`lucerna inspect`'s summary of a scene, as text."""
    return _native.inspect(os.fspath(scene), _pairs(settings))


def convert(scene: str | os.PathLike, output: str | os.PathLike, **settings: Any) -> None:
    """Writes `scene` as a lucerna scene file (`lucerna convert`)."""
    _native.convert(os.fspath(scene), os.fspath(output), _pairs(settings))


def merge(inputs: list[str | os.PathLike], output: str | os.PathLike) -> None:
    """Combines the EXRs of a split render (`lucerna merge`)."""
    _native.merge([os.fspath(p) for p in inputs], os.fspath(output))


def denoise(input: str | os.PathLike, output: str | os.PathLike | None = None) -> None:
    """Adds the `denoised` layer to a render with albedo and normal layers (`lucerna
    denoise`), writing `output` or replacing `input`."""
    _native.denoise(os.fspath(input), None if output is None else os.fspath(output))


def main(argv: list[str] | None = None) -> int:
    """The `lucerna` command line."""
    args = ["lucerna", *(sys.argv[1:] if argv is None else argv)]
    code = _native.cli(args, [sys.executable, "-m", "lucerna"])
    if argv is None:
        sys.exit(code)
    return code
