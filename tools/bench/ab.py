#!/usr/bin/env python3
"""Two builds of lucerna against each other: the change a commit makes to speed, memory and
the image.

Each scene is rendered by build A and build B in turns (A B B A A B ..., so that a drift of
the shared machine's speed falls on both alike), `--repeats` times, with a fixed seed and
sample count. For every scene: the median render seconds of each build (the header's
`lucerna/render_seconds`, which leaves out reading and preparing the scene), the median
rays per second, the peak resident memory of the process, and the ratio B/A of each with
the spread of the per-pair ratios; and whether B's image is A's bit for bit (else the relMSE
between them, which for a change of the estimator must be within both renders' noise).

    .venv/bin/python tools/bench/ab.py A_BINARY B_BINARY [--repeats 5] [--spp 64]
        [--scene NAME=PATH[,RESOLUTION[,FLAGS]]] ... [--out FILE.md]

Without --scene: the Cornell box, the MIS plates, the indirect room and the sphere field at
their benchmark resolutions, each as lucerna renders it by default.
"""
import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import lucerna_tools as lt

DEFAULT_SCENES = [
    ("cornell-box", "scenes/cornell-box/cornell-box.gltf", "256x256", ""),
    ("mis-plates", "scenes/mis-plates/mis-plates.glb", "240x160", ""),
    ("indirect-room", "scenes/indirect-room/indirect-room.glb", "256x256", ""),
    ("sphere-field", "scenes/sphere-field/sphere-field.glb", "256x256", ""),
]


def render(binary, scene, resolution, flags, spp, out):
    """One render in a process of its own: (seconds, rays per second, peak bytes, image)."""
    cmd = [binary, "render", str(lt.ROOT / scene), "-o", str(out), "-q", "--resolution", resolution,
           "--spp", str(spp), "--seed", "1", "--stats-json", str(out.with_suffix(".json"))]
    cmd += flags.split()
    run = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if run.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{run.stderr}")
    stats = json.loads(out.with_suffix(".json").read_text())
    rays = (stats["rays_closest"] + stats["rays_shadow"]) / stats["render_seconds"]
    channels, _ = lt.read_exr(out)
    return stats["render_seconds"], rays, stats["peak_memory_bytes"] or 0, lt.rgb(channels)


def spread(ratios):
    return f"{min(ratios):.3f}-{max(ratios):.3f}"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("a")
    parser.add_argument("b")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--scene", action="append", help="NAME=PATH[,WxH[,FLAGS]]")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    scenes = DEFAULT_SCENES
    if args.scene:
        scenes = []
        for spec in args.scene:
            name, rest = spec.split("=", 1)
            parts = rest.split(",", 2)
            resolution = parts[1] if len(parts) > 1 else "256x256"
            flags = parts[2] if len(parts) > 2 else ""
            scenes.append((name, parts[0], resolution, flags))
    lines = [f"# A/B: {args.a} (A) against {args.b} (B)", "",
             f"{args.repeats} interleaved pairs a scene, {args.spp} spp, seed 1; medians; "
             "ratios B/A with the range of the per-pair ratios.", "",
             "| scene | A s | B s | time B/A | rays/s B/A | peak memory B/A | image |",
             "|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name, path, resolution, flags in scenes:
            runs = {"a": [], "b": []}
            for k in range(args.repeats):
                order = ("a", "b") if k % 2 == 0 else ("b", "a")
                for which in order:
                    binary = args.a if which == "a" else args.b
                    runs[which].append(render(binary, path, resolution, flags, args.spp, tmp / f"{which}.exr"))
            image_a, image_b = runs["a"][0][3], runs["b"][0][3]
            same = image_a.tobytes() == image_b.tobytes()
            image = "identical" if same else f"relMSE {lt.relmse(image_b, image_a):.2e}"
            ratio = [rb[0] / ra[0] for ra, rb in zip(runs["a"], runs["b"])]
            rays = [rb[1] / ra[1] for ra, rb in zip(runs["a"], runs["b"])]
            memory = [rb[2] / ra[2] for ra, rb in zip(runs["a"], runs["b"]) if ra[2]]
            ta = statistics.median(r[0] for r in runs["a"])
            tb = statistics.median(r[0] for r in runs["b"])
            line = (f"| {name} | {ta:.3f} | {tb:.3f} | {statistics.median(ratio):.3f} ({spread(ratio)}) | "
                    f"{statistics.median(rays):.3f} ({spread(rays)}) | "
                    f"{statistics.median(memory) if memory else float('nan'):.3f} | {image} |")
            lines.append(line)
            print(line, flush=True)
    model, cores, isa = lt.cpu()
    lines += ["", f"Machine: {model}, {cores} logical cores, {isa}."]
    text = "\n".join(lines) + "\n"
    if args.out:
        args.out.write_text(text)
    else:
        sys.stdout.write("\n" + text)


if __name__ == "__main__":
    main()
