#!/usr/bin/env python3
"""Render a lucerna scene file with Mitsuba 3 in a process of its own (Mitsuba's worker
threads keep spinning for a while after a render, which would slow down whatever runs next
in the same process) and print the timing as JSON on stdout.

    mitsuba_worker.py SCENE.lucerna --variant scalar_rgb --resolution 256x256 --spp 64 \\
        --seed 3 --out image.npy

A one-sample warm-up render comes first and is not timed (the LLVM variant compiles its
kernels then). The LLVM variant renders at most 64 samples per call (its wavefront holds a
whole call in memory) and averages the calls. Timed: the render calls only (wall and the
process's CPU seconds), as lucerna's own render seconds exclude loading and output.
"""
import argparse
import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import mitsuba_export  # noqa: E402

LLVM_SPP_PER_CALL = 64


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("scene")
    parser.add_argument("--variant", default="scalar_rgb")
    parser.add_argument("--resolution", required=True)
    parser.add_argument("--spp", type=int, required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    import mitsuba as mi
    mi.set_variant(args.variant)
    width, height = map(int, args.resolution.split("x"))
    with tempfile.TemporaryDirectory() as workdir:
        scene = mi.load_dict(mitsuba_export.scene_dict(args.scene, width, height, workdir))
    per_call = LLVM_SPP_PER_CALL if args.variant.startswith("llvm") else args.spp
    calls = [min(per_call, args.spp - done) for done in range(0, args.spp, per_call)]
    np.array(mi.render(scene, spp=1, seed=2**31 - 1))  # warm-up, untimed
    image = np.zeros((height, width, 3))
    cpu, start = cpu_seconds(), time.perf_counter()
    for k, spp in enumerate(calls):
        # np.array forces evaluation: the LLVM variant computes lazily.
        image += np.array(mi.render(scene, spp=spp, seed=args.seed * 1000 + k), dtype=np.float64)[:, :, :3] * spp
    seconds, cpu = time.perf_counter() - start, cpu_seconds() - cpu
    np.save(args.out, image / args.spp)
    print(json.dumps({"seconds": seconds, "cpu_seconds": cpu, "spp": args.spp, "mitsuba": mi.__version__}))


if __name__ == "__main__":
    main()
