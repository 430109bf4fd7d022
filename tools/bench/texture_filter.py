#!/usr/bin/env python3
"""Texture filtering (`--texture-filter mip`) against bilinear lookups: error, time and
efficiency at equal samples on the checkerboard plane to the horizon.

The plane (tools/bench/checker_plane.py) is unlit, so every error is aliasing. The
reference is a cached bilinear lucerna render (tools/.cache); error is the beauty's relMSE
against it, efficiency 1 / (render seconds x relMSE), each the mean over seeds.

    .venv/bin/python tools/bench/texture_filter.py [--spp 4,16,64,1024] [--seeds 2]
        [--reference-spp 4096]

Prints a Markdown table (the one in tools/bench/results/texture-filter.md).
"""
import argparse
import statistics
import sys
import tempfile
from pathlib import Path

import lucerna_tools as lt

sys.path.insert(0, str(Path(__file__).resolve().parent))
import checker_plane  # noqa: E402

RESOLUTION = (240, 160)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", default="4,16,64,1024")
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--reference-spp", type=int, default=4096)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "checker-plane.gltf"
        scene.write_text(__import__("json").dumps(checker_plane.scene()))
        reference, info = lt.reference(scene, RESOLUTION, args.reference_spp, texture_filter="bilinear")
        print(f"reference: {info['spp']} spp, its own noise relMSE {info['relmse_noise']:.1e}\n")
        print("| spp | filter | seconds | relMSE | efficiency |")
        print("|---|---|---|---|---|")
        for spp in (int(s) for s in args.spp.split(",")):
            for texture_filter in ("bilinear", "mip"):
                errors, seconds = [], []
                for seed in range(1, args.seeds + 1):
                    image, header, _ = lt.render(scene, Path(tmp) / "x.exr", RESOLUTION, spp=spp, seed=seed,
                                                 texture_filter=texture_filter)
                    errors.append(lt.relmse(image, reference))
                    seconds.append(header["lucerna/render_seconds"])
                e, t = statistics.mean(errors), statistics.mean(seconds)
                print(f"| {spp} | {texture_filter} | {t:.3f} | {e:.2e} | {1 / (e * t):.0f} |", flush=True)


if __name__ == "__main__":
    main()
