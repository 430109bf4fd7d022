#!/usr/bin/env python3
"""What motion blur costs: a field of N x N boxes (one shared mesh, placed N^2 times), each
sliding 12 m a second and turning 344 degrees a second, on a floor under a grey sky. Frame
12 is rendered with a shutter of one frame (`--shutter -0.5,0.5`) and, alternately, without
(`--plan scalar`: the same kernel, every placement still); with `--baseline BINARY`, that
binary's blurred render is interleaved too. Prints render seconds (the header's, without
reading the scene) per repeat and the median ratios.

    PYTHONPATH=tools .venv/bin/python tools/bench/motion_blur.py \\
        [--lucerna target/release/lucerna] [--baseline OTHER] [--boxes 20] [--spp 64] [--repeats 5]
"""
import argparse
import math
import statistics
import subprocess
import tempfile
from pathlib import Path

from lucerna_tools import read_exr
from lucerna_tools.gltf_writer import GltfWriter, box

ROOT = Path(__file__).resolve().parents[2]
RESOLUTION = "240x160"


def write_scene(path, n):
    w = GltfWriter("lucerna tools/bench/motion_blur.py")
    grey = w.material("grey", base=(0.7, 0.7, 0.7), extras={"lucerna": {"bsdf": "lambert"}})
    floor = w.material("floor", base=(0.5, 0.5, 0.5), extras={"lucerna": {"bsdf": "lambert"}})
    w.node(name="floor", mesh=w.mesh("floor", [(-20, 0, -20), (-20, 0, 20), (20, 0, 20), (20, 0, -20)],
                                     [(0, 1, 2), (0, 2, 3)], floor))
    mesh = w.mesh("box", *box((-0.15, 0, -0.15), (0.15, 0.3, 0.15)), grey)
    times = w.accessor([0.0, 1.0], "SCALAR")
    samplers, channels = [], []
    for i in range(n):
        for j in range(n):
            x, z = -4 + 8 * i / (n - 1), -6 + 8 * j / (n - 1)
            node = w.node(name=f"box{i}_{j}", mesh=mesh, translation=[x, 0, z])
            slide = w.accessor([(x, 0, z), (x + 12.0, 0, z)], "VEC3")
            turn = w.accessor([(0, 0, 0, 1), (0, math.sin(3.0), 0, math.cos(3.0))], "VEC4")
            k = len(samplers)
            samplers += [{"input": times, "output": slide, "interpolation": "LINEAR"},
                         {"input": times, "output": turn, "interpolation": "LINEAR"}]
            channels += [{"sampler": k, "target": {"node": node, "path": "translation"}},
                         {"sampler": k + 1, "target": {"node": node, "path": "rotation"}}]
    w._list("animations", {"name": "go", "samplers": samplers, "channels": channels})
    w.camera("camera", yfov=0.8, aspect=1.5, translation=[0, 4, 6], target=[0, 0, -2])
    w.write_glb(path)


def render(lucerna, scene, out, spp, flags):
    subprocess.run([lucerna, "render", str(scene), "-o", str(out), "-q", "--resolution", RESOLUTION,
                    "--spp", str(spp), "--frame", "12", "--env", "0.5,0.5,0.5", "--seed", "1",
                    *flags], check=True, capture_output=True)
    return float(read_exr(out)[1]["lucerna/render_seconds"])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lucerna", default=str(ROOT / "target" / "release" / "lucerna"))
    ap.add_argument("--baseline")
    ap.add_argument("--boxes", type=int, default=20)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "boxes.glb"
        write_scene(scene, args.boxes)
        out = Path(tmp) / "out.exr"
        runs = [("still", args.lucerna, ["--plan", "scalar"]),
                ("blurred", args.lucerna, ["--shutter", "-0.5,0.5"])]
        if args.baseline:
            runs.append(("blurred, baseline", args.baseline, ["--shutter", "-0.5,0.5"]))
        seconds = {name: [] for name, _, _ in runs}
        for r in range(args.repeats):
            order = runs if r % 2 == 0 else runs[::-1]
            for name, binary, flags in order:
                seconds[name].append(render(binary, scene, out, args.spp, flags))
            print(f"repeat {r + 1}: " + ", ".join(f"{n} {seconds[n][-1]:.3f} s" for n, _, _ in runs),
                  flush=True)
    median = {n: statistics.median(s) for n, s in seconds.items()}
    print(f"{args.boxes}x{args.boxes} moving boxes, {RESOLUTION}, {args.spp} spp, medians over "
          f"{args.repeats}: " + ", ".join(f"{n} {m:.3f} s" for n, m in median.items()))
    print(f"blurred / still: {median['blurred'] / median['still']:.3f} (per repeat "
          + ", ".join(f"{b / s:.2f}" for b, s in zip(seconds['blurred'], seconds['still'])) + ")")
    if args.baseline:
        print(f"blurred / baseline's blurred: {median['blurred'] / median['blurred, baseline']:.3f} "
              "(per repeat " + ", ".join(f"{a / b:.2f}" for a, b in zip(seconds['blurred'],
                                                                          seconds['blurred, baseline'])) + ")")


if __name__ == "__main__":
    main()
