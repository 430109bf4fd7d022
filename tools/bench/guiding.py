#!/usr/bin/env python3
"""Path guiding against unguided rendering: error, time and efficiency at equal samples.

Each scene is rendered with each configuration for three seeds at a fixed sample count; the
error is the beauty's relMSE against a cached lucerna reference (unguided, tools/.cache),
efficiency 1 / (render seconds x relMSE). Configurations: unguided in the packet kernel
(beauty only), unguided and guided (`on`, `auto`) with light layers (`--aov comp`), where
the scalar kernel runs either way.

    .venv/bin/python tools/bench/guiding.py [--spp 256] [--scene NAME] [--seeds 3]

Prints a Markdown table (the one in tools/bench/results/guiding.md).
"""
import argparse
import statistics
import tempfile
from pathlib import Path

import lucerna_tools as lt

SCENES = {
    "indirect-room": ("scenes/indirect-room/indirect-room.glb", (256, 256), 4096),
    "gap-room": ("scenes/gap-room/gap-room.glb", (240, 160), 8192),
}
CONFIGURATIONS = [
    ("`--guiding off` (beauty, packet kernel)", {"guiding": "off"}),
    ("`--guiding off --aov comp`", {"guiding": "off", "aov": "comp"}),
    ("`--guiding on --aov comp`", {"guiding": "on", "aov": "comp"}),
    ("`--guiding auto --aov comp`", {"guiding": "auto", "aov": "comp"}),
]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--scene", action="append", choices=sorted(SCENES))
    args = parser.parse_args()
    print("| scene | flags | seconds | relMSE (range over seeds) | efficiency |")
    print("|---|---|---|---|---|")
    for name in args.scene or list(SCENES):
        path, resolution, reference_spp = SCENES[name]
        scene = lt.ROOT / path
        reference, _ = lt.reference(scene, resolution, reference_spp)
        for label, settings in CONFIGURATIONS:
            errors, seconds = [], []
            with tempfile.TemporaryDirectory() as tmp:
                for seed in range(1, args.seeds + 1):
                    image, header, _ = lt.render(scene, Path(tmp) / "x.exr", resolution, spp=args.spp,
                                                 seed=seed, **settings)
                    errors.append(lt.relmse(image, reference))
                    seconds.append(header["lucerna/render_seconds"])
            e, t = statistics.mean(errors), statistics.mean(seconds)
            print(f"| {name} | {label} | {t:.2f} | {e:.3e} ({min(errors):.2e}-{max(errors):.2e}) | "
                  f"{1 / (e * t):.2f} |", flush=True)


if __name__ == "__main__":
    main()
