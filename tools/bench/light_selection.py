#!/usr/bin/env python3
"""Learned light selection against the light BVH it mixes with, on the many-lights flat
(scenes/many-lights: 32 ceiling panels in 8 rooms, most behind walls from the camera).

Renders a reference once (selection by power, another seed, many samples), then for each
repeat renders the scene with `--light-select contribution` and `learned` alternately at
equal samples, and prints time, relMSE against the reference and equal-time efficiency
1 / (seconds x relMSE), as medians over the repeats and as the ratio learned / tree.

    PYTHONPATH=tools .venv/bin/python tools/bench/light_selection.py \\
        [--lucerna target/release/lucerna] [--spp 64] [--repeats 3] [--reference-spp 4096]
"""
import argparse
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from lucerna_tools import read_exr, relmse
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "many-lights" / "many-lights.glb"
RESOLUTION = "120x80"


def render(lucerna, out, spp, select, seed):
    start = time.perf_counter()
    subprocess.run([lucerna, "render", str(SCENE), "-o", str(out), "--resolution", RESOLUTION,
                    "--spp", str(spp), "--light-select", select, "--seed", str(seed),
                    "--threads", "2"], check=True, capture_output=True)
    seconds = time.perf_counter() - start
    channels, _ = read_exr(out)
    rgb = np.stack([channels[c] for c in ("R", "G", "B")], axis=-1)
    return seconds, rgb


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lucerna", default=str(ROOT / "target" / "release" / "lucerna"))
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--reference-spp", type=int, default=4096)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        _, reference = render(args.lucerna, tmp / "ref.exr", args.reference_spp, "power", 99)
        results = {"contribution": [], "learned": []}
        for repeat in range(args.repeats):
            for select in results:
                seconds, rgb = render(args.lucerna, tmp / f"{select}.exr", args.spp, select,
                                      1 + repeat)
                error = relmse(rgb, reference)
                results[select].append((seconds, error, 1.0 / (seconds * error)))
                print(f"repeat {repeat} {select:12s} {seconds:7.2f} s  relMSE {error:.5f}", flush=True)
    print(f"\n{args.spp} spp, {RESOLUTION}, {args.repeats} repeats (medians)")
    print("selection     seconds   relMSE    efficiency")
    med = {}
    for select, rows in results.items():
        med[select] = [statistics.median(r[i] for r in rows) for i in range(3)]
        print(f"{select:12s} {med[select][0]:8.2f} {med[select][1]:9.5f} {med[select][2]:10.3f}")
    ratios = [l[2] / c[2] for l, c in zip(results["learned"], results["contribution"])]
    print(f"learned / contribution: time {med['learned'][0] / med['contribution'][0]:.3f}, "
          f"relMSE {med['learned'][1] / med['contribution'][1]:.3f}, efficiency per pair "
          + ", ".join(f"{r:.2f}" for r in ratios))


if __name__ == "__main__":
    main()
