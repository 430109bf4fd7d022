#!/usr/bin/env python3
"""How much --denoise lowers the error: renders each scene at a low sample count with
--denoise and at a high one (the reference), and prints relMSE (lucerna_tools.relmse) of
the noisy beauty and of the `denoised` layer against the reference, with the reference's
own noise floor (two reference seeds against each other, halved: the error of one).

    .venv/bin/python tools/compare/denoise/compare.py [SCENE ...] [--spp 16] [--reference-spp 4096]
        [--resolution 256x256] [--sheet tools/compare/denoise/results/contact_sheet.png]

Without SCENE: the embedded Cornell box, the vendored Avocado (a textured asset lit by
the default white environment) and scenes/usd-twin (a checker-textured room, area light). The
Open Image Denoise library comes from the venv's pyoidn (`lucerna setup` installs it).
"""

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from lucerna_tools import BINARY, ROOT, read_exr, relmse, rgb

AVOCADO = ROOT / "tests/assets/gltf/Avocado/Avocado.gltf"
CHECKER = ROOT / "scenes/usd-twin/usd-twin.gltf"


def render(scene, out, resolution, spp, seed, denoise):
    cmd = [BINARY, "render", *([str(scene)] if scene else []), "-o", str(out), "-q",
           "--progress", "none", "--resolution", resolution, "--spp", str(spp),
           "--seed", str(seed)]
    if denoise:
        cmd.append("--denoise")
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(done.stderr)
    return read_exr(out)[0]


def compare(scene, resolution, spp, reference_spp, tmp):
    name = Path(scene).stem if scene else "cornell-box"
    noisy = render(scene, tmp / f"{name}.exr", resolution, spp, 1, True)
    ref_a = rgb(render(scene, tmp / f"{name}.ref_a.exr", resolution, reference_spp, 2, False))
    ref_b = rgb(render(scene, tmp / f"{name}.ref_b.exr", resolution, reference_spp, 3, False))
    reference = 0.5 * (ref_a + ref_b)
    beauty, denoised = rgb(noisy), rgb(noisy, "denoised")
    return {
        "scene": name,
        "beauty": relmse(beauty, reference),
        "denoised": relmse(denoised, reference),
        # Two references differ by twice the error of one; their mean has half that.
        "floor": relmse(ref_a, ref_b) / 4,
        "images": (beauty, denoised, reference),
    }


def write_sheet(rows, path):
    from PIL import Image
    tiles = []
    for row in rows:
        tiles.append(np.concatenate(row["images"], axis=1))
    sheet = np.concatenate(tiles, axis=0)
    encoded = np.where(sheet <= 0.0031308, 12.92 * sheet, 1.055 * np.power(np.clip(sheet, 0.0031308, None), 1 / 2.4) - 0.055)
    Image.fromarray((np.clip(encoded, 0, 1) * 255 + 0.5).astype(np.uint8)).save(path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*")
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--reference-spp", type=int, default=4096)
    parser.add_argument("--resolution", default="256x256")
    parser.add_argument("--sheet")
    args = parser.parse_args()
    scenes = args.scenes or [None, AVOCADO, CHECKER]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for scene in scenes:
            row = compare(scene, args.resolution, args.spp, args.reference_spp, Path(tmp))
            rows.append(row)
            print(f"{row['scene']:<16} {args.spp} spp: relMSE beauty {row['beauty']:.3e}, "
                  f"denoised {row['denoised']:.3e} (ratio {row['denoised'] / row['beauty']:.3f}); "
                  f"reference ({args.reference_spp} spp x2) noise {row['floor']:.1e}", flush=True)
    if args.sheet:
        write_sheet(rows, args.sheet)
        print(f"contact sheet (noisy | denoised | reference): {args.sheet}")


if __name__ == "__main__":
    main()
