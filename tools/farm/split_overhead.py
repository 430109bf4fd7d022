"""The cost of splitting a frame: the summed seconds of its tasks (tiles and passes, each
a `lucerna render` process with one thread, plus the merge) against one process rendering
the whole frame with one thread. Tasks run one after another; each is measured by the CPU
seconds (user + system) its process used, which other load on this shared machine
disturbs far less than wall time (wall-time ratios are listed too). Configurations are
interleaved over the repeats and ratios taken within a repeat. What splitting costs is per-process work done once per task:
start-up, scene load and BVH build, EXR writing, and the merge.

    .venv/bin/python tools/farm/split_overhead.py [--repeats 3]

Writes tools/farm/results/split_overhead.md.
"""
import argparse
import platform
import resource
import statistics
import subprocess
import time
from pathlib import Path
from types import SimpleNamespace

import farm

ROOT = Path(__file__).resolve().parents[2]
LUCERNA = str(ROOT / "target/release/lucerna")
SCENES = {
    "cornell-box": (None, "160x160", 32),
    "sphere-field": (str(ROOT / "scenes/sphere-field/sphere-field.glb"), "160x120", 16),
}
# (label, tiles, passes)
SPLITS = [("4 tiles", "2x2", 1), ("4 passes", "1x1", 4), ("2 tiles x 2 passes", "2x1", 2),
          ("16 tiles", "4x4", 1), ("16 passes", "1x1", 16), ("4 tiles x 4 passes", "2x2", 4)]


def timed(args):
    """(CPU seconds, wall seconds) of running `args`."""
    def cpu():
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        return usage.ru_utime + usage.ru_stime
    cpu0, wall0 = cpu(), time.perf_counter()
    subprocess.run(args, check=True, capture_output=True)
    return cpu() - cpu0, time.perf_counter() - wall0


def split_seconds(scene, resolution, spp, tiles, passes, out):
    opts = SimpleNamespace(scene=scene, resolution=resolution, tiles=tiles, passes=passes,
                           spp=spp, camera=None, threads=1, output=str(out / "{frame}.exr"),
                           parts=str(out / "parts"), lucerna=LUCERNA, extra=[])
    tasks = farm.frame_graph(opts, "0", "0000")
    (out / "parts").mkdir(parents=True, exist_ok=True)
    renders = [timed(t.args) for t in tasks[:-1]]
    merge = timed(tasks[-1].args)
    return (sum(r[0] for r in renders) + merge[0], sum(r[1] for r in renders) + merge[1],
            merge[0])


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=3)
    opts = parser.parse_args()
    out = ROOT / "tools/.cache/split_overhead"
    rows = []
    for name, (scene, resolution, spp) in SCENES.items():
        cpu_ratios = {label: [] for label, _, _ in SPLITS}
        wall_ratios = {label: [] for label, _, _ in SPLITS}
        merges = {label: [] for label, _, _ in SPLITS}
        singles = []
        for _ in range(opts.repeats):
            single = timed([LUCERNA, "render", "-q", *([scene] if scene else []),
                            "--resolution", resolution, "--spp", str(spp), "--threads", "1",
                            "-o", str(out / "single.exr")])
            singles.append(single[0])
            for label, tiles, passes in SPLITS:
                cpu, wall, merge = split_seconds(scene, resolution, spp, tiles, passes, out)
                cpu_ratios[label].append(cpu / single[0])
                wall_ratios[label].append(wall / single[1])
                merges[label].append(merge)
        single = statistics.median(singles)
        for label, tiles, passes in SPLITS:
            cpu_ratio = statistics.median(cpu_ratios[label])
            wall_ratio = statistics.median(wall_ratios[label])
            merge = statistics.median(merges[label])
            tasks = (int(tiles[0]) * int(tiles[2])) * passes
            rows.append((name, f"{resolution}, {spp} spp", label, tasks, single, merge,
                         cpu_ratio, wall_ratio))
            print(f"{name} {label}: {tasks} tasks, one process {single:.2f} CPU s, (tasks + "
                  f"merge) / one process = {cpu_ratio:.3f} CPU, {wall_ratio:.3f} wall "
                  f"(merge {merge:.2f} CPU s)", flush=True)
    lines = ["# The cost of splitting a frame", "",
             f"Machine: {platform.machine()}, 2 cores, shared. Command: "
             "`.venv/bin/python tools/farm/split_overhead.py`. Each task and the single "
             f"process use one thread; median of {opts.repeats} interleaved repeats.", "",
             "| scene | image | split | tasks | one process (CPU s) | merge (CPU s) | "
             "(tasks + merge) / one process, CPU | same, wall |",
             "|---|---|---|---|---|---|---|---|"]
    for name, image, label, tasks, single, merge, cpu_ratio, wall_ratio in rows:
        lines.append(f"| {name} | {image} | {label} | {tasks} | {single:.2f} | {merge:.2f} | "
                     f"**{cpu_ratio:.3f}** | {wall_ratio:.3f} |")
    results = ROOT / "tools/farm/results"
    results.mkdir(parents=True, exist_ok=True)
    (results / "split_overhead.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {results / 'split_overhead.md'}")


if __name__ == "__main__":
    main()
