#!/usr/bin/env python3
"""Render a lucerna scene file with Mitsuba 3 in a process of its own (Mitsuba's worker
threads keep spinning for a while after a render, which would slow down whatever runs next
in the same process) and print the timing as JSON on stdout.

    mitsuba_worker.py SCENE.lucerna --variant scalar_rgb --sampler multijitter \\
        --resolution 256x256 --spp 64 --seed 3 --out image.npy

Untimed warm-up renders come first: the LLVM variant compiles its kernels then, one per call
size when the sampler stratifies. The LLVM variant renders at most 64 samples per call (its
wavefront holds a whole call in memory) and averages the calls, weighted by the samples the
sampler took (multijitter rounds some counts up; the JSON reports the samples taken).
Timed: the render calls only (wall and the process's CPU seconds), as lucerna's own render
seconds exclude loading and output.
"""
import argparse
import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from lucerna_tools import mitsuba_export

LLVM_SPP_PER_CALL = 64


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("scene")
    parser.add_argument("--variant", default="scalar_rgb")
    parser.add_argument("--sampler", default="independent", help="Mitsuba sampler plugin, e.g. multijitter")
    parser.add_argument("--resolution", required=True)
    parser.add_argument("--spp", type=int, required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    import mitsuba as mi
    mi.set_variant(args.variant)
    width, height = map(int, args.resolution.split("x"))
    with tempfile.TemporaryDirectory() as workdir:
        scene = mi.load_dict(mitsuba_export.scene_dict(args.scene, width, height, workdir, sampler=args.sampler))
    llvm = args.variant.startswith("llvm")
    per_call = LLVM_SPP_PER_CALL if llvm else args.spp
    calls = [min(per_call, args.spp - done) for done in range(0, args.spp, per_call)]
    # Warm-up, untimed. The LLVM variant compiles its kernels on first use, and a stratifying
    # sampler (multijitter) bakes the sample count into them: every call size is compiled here.
    for spp in sorted(set(calls)) if llvm else [1]:
        np.array(mi.render(scene, spp=spp, seed=2**31 - 1))
    sampler = scene.sensors()[0].sampler()
    image = np.zeros((height, width, 3))
    taken = 0
    cpu, start = cpu_seconds(), time.perf_counter()
    for k, spp in enumerate(calls):
        # np.array forces evaluation: the LLVM variant computes lazily.
        frame = np.array(mi.render(scene, spp=spp, seed=args.seed * 1000 + k), dtype=np.float64)[:, :, :3]
        # The sampler may take more than asked (multijitter rounds up to a grid's size).
        count = sampler.sample_count()
        image += frame * count
        taken += count
    seconds, cpu = time.perf_counter() - start, cpu_seconds() - cpu
    np.save(args.out, image / taken)
    # Mitsuba's warnings end in a colour reset without a newline: the JSON gets its own line.
    print()
    print(json.dumps({"seconds": seconds, "cpu_seconds": cpu, "spp": taken, "mitsuba": mi.__version__}))


if __name__ == "__main__":
    main()
