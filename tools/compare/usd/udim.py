#!/usr/bin/env python3
"""A UDIM set against the texture it was cut from: Khronos's Avocado (tests/assets) with its
three images enlarged to 640x640 and cut into tiles 1001-1010 along u (st spread 10x), as
the plugin's tests build it, rendered whole, as a set, as a set with --texture-filter mip,
and as a set missing base-colour tiles 1003-1006 (the fallback, black, shows there).
Prints relMSE and luminance ratio of each against the whole render with the same seed, and
writes a labelled contact sheet.

    .venv/bin/python tools/compare/usd/udim.py [--spp 256] [--out tools/compare/usd/results/udim.png]
"""
import argparse
import sys
import tempfile
from pathlib import Path

import lucerna_tools as lt

sys.path.insert(0, str(lt.ROOT / "plugins" / "usd" / "tests"))
import test_udim as asset  # noqa: E402  (the stage builders of the plugin's UDIM tests)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--resolution", default="320x320")
    parser.add_argument("--out", type=Path, default=lt.ROOT / "tools/compare/usd/results/udim.png")
    args = parser.parse_args()
    size = tuple(int(x) for x in args.resolution.split("x"))
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        whole = asset.avocado_stage(d / "whole.usda", asset.write_textures(d / "tex", None))
        tiled = asset.avocado_stage(d / "tiled.usda", asset.write_textures(d / "tex", asset.udim_name),
                                    "<UDIM>")
        holes = d / "holes"
        files = asset.write_textures(holes / "tex", asset.udim_name)
        for n in (1003, 1004, 1005, 1006):
            (holes / "tex" / asset.udim_name("baseColor", n)).unlink()
        holes = asset.avocado_stage(holes / "holes.usda", files, "<UDIM>")
        runs = [("whole textures", whole, {}), ("UDIM 1001-1010", tiled, {}),
                ("whole, mip", whole, {"texture_filter": "mip"}),
                ("UDIM, mip", tiled, {"texture_filter": "mip"}),
                ("UDIM without 1003-1006", holes, {})]
        images = {}
        for label, stage, extra in runs:
            images[label], _, _ = lt.render(stage, d / "out.exr", size, spp=args.spp, seed=1, **extra)
    for label, ref in (("UDIM 1001-1010", "whole textures"), ("UDIM, mip", "whole, mip"),
                       ("UDIM without 1003-1006", "whole textures")):
        x, r = images[label], images[ref]
        print(f"{label} against {ref}: relMSE {lt.relmse(x, r):.3g}, "
              f"luminance ratio {x.mean() / r.mean():.7f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    lt.grid_png(list(images.values()), list(images), args.out, columns=5,
                title=f"Avocado: UDIM set against the uncut textures, {args.spp} spp, seed 1")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
