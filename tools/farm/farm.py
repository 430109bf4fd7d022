"""Distributed rendering: a lucerna render split into frames x tiles x passes, each piece a
`lucerna render --frame F --crop ... --pass K/N` task, then one `lucerna merge` a frame
that depends on its pieces.

    farm.py run    [SCENE] --frames 1-2 --resolution 320x240 --tiles 2x2 --passes 2 --spp 64
                   -o 'out/{scene}.{frame}.exr' [--scheduler tcp://host:8786] [--workers 2]
                   [--report report.json] [-- extra render flags]
    farm.py opencue [SCENE] ... --outline job.outline      # an OpenCue job (pyoutline)

`run` submits the task graph to Dask distributed: a LocalCluster of `--workers` worker
processes by default, or the scheduler at `--scheduler` (workers started with
`dask worker tcp://host:8786` on the render nodes, which must see the same paths). Dask
rather than Ray: the graph is a few hundred subprocess calls with file dependencies, which
`Client.submit` with futures as arguments expresses directly; `distributed` is pure Python,
installs with pip in seconds, runs a scheduler and workers as plain processes, and needs no
object store or cluster manager. Every task runs the lucerna binary (`--lucerna`, default
target/release/lucerna) and reports its seconds; the report sums them against the wall time.

`opencue` writes the same graph as a native outline script (pyoutline, package
`opencue-pyoutline`): one Shell layer a (tile, pass) over the frame range and a merge layer
depending on them frame by frame; submit it with `pycuerun job.outline 1-2`. Commands use
pyoutline's `%{FRAME}` and `%{ZFRAME}` tokens.
"""
import argparse
import json
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


@dataclass
class Task:
    """One command of the graph; `after` lists the keys of the tasks it needs."""
    key: str
    args: list
    after: tuple = ()


def parse_frames(text):
    """`1-4`, `1-9x2`, `1,5,7-8` as lucerna's --frames reads them."""
    frames = []
    for item in text.split(","):
        rng, _, step = item.partition("x")
        a, _, b = rng.partition("-")
        frames.extend(range(int(a), int(b or a) + 1, int(step or 1)))
    return frames


def crops(width, height, columns, rows):
    """The tiles of a width x height image, row by row, as X0,Y0,X1,Y1 windows."""
    xs = [width * i // columns for i in range(columns + 1)]
    ys = [height * j // rows for j in range(rows + 1)]
    return [f"{xs[i]},{ys[j]},{xs[i + 1]},{ys[j + 1]}"
            for j in range(rows) for i in range(columns)]


def frame_graph(opts, frame_arg, frame_digits):
    """The tasks of one frame. `frame_arg` is what --frame gets and `frame_digits` what
    names its files: a frame number for Dask, pyoutline's tokens for OpenCue."""
    width, height = (int(v) for v in opts.resolution.lower().split("x"))
    columns, rows = (int(v) for v in opts.tiles.lower().split("x"))
    stem = Path(opts.scene).stem if opts.scene else "default"
    output = (opts.output.replace("{frame}", frame_digits).replace("{scene}", stem)
              .replace("{camera}", opts.camera or "default"))
    parts_dir = Path(opts.parts or Path(output).parent / ".parts")
    base = [opts.lucerna, "render", "--quiet"] + ([opts.scene] if opts.scene else []) + [
        "--frame", frame_arg, "--resolution", opts.resolution, "--spp", str(opts.spp),
        "--threads", str(opts.threads)]
    if opts.camera:
        base += ["--camera", opts.camera]
    tasks = []
    for t, crop in enumerate(crops(width, height, columns, rows)):
        for k in range(1, opts.passes + 1):
            part = parts_dir / f"{stem}.{frame_digits}.t{t}.p{k}.exr"
            args = base + ["--crop", crop, "--pass", f"{k}/{opts.passes}", "-o", str(part)]
            tasks.append(Task(f"render-{frame_digits}-t{t}-p{k}", args + opts.extra))
    merge = [opts.lucerna, "merge"] + [t.args[t.args.index("-o") + 1] for t in tasks] + [
        "-o", output]
    tasks.append(Task(f"merge-{frame_digits}", merge, tuple(t.key for t in tasks)))
    return tasks


def run_command(args, *_dependencies):
    """Runs one task (on a worker); raises with its stderr if it fails."""
    Path(args[args.index("-o") + 1]).parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    proc = subprocess.run(args, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"{shlex.join(args)} exited {proc.returncode}: {proc.stderr.strip()}")
    return {"args": args, "seconds": seconds}


def run(opts):
    from dask.distributed import Client, LocalCluster, wait
    graph = [t for f in opts.frames for t in frame_graph(opts, str(f), f"{f:04d}")]
    cluster = None
    if opts.scheduler:
        client = Client(opts.scheduler)
    else:
        cluster = LocalCluster(n_workers=opts.workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    start = time.perf_counter()
    try:
        futures = {}
        for task in graph:
            needs = [futures[k] for k in task.after]
            futures[task.key] = client.submit(run_command, task.args, *needs, key=task.key,
                                              pure=False)
        wait(list(futures.values()))
        wall = time.perf_counter() - start
        results, failed = {}, []
        for key, future in futures.items():
            if future.status == "finished":
                results[key] = future.result()
            else:
                failed.append((key, str(future.exception())))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    task_seconds = sum(r["seconds"] for r in results.values())
    report = {"tasks": len(graph), "failed": [dict(key=k, error=e) for k, e in failed],
              "wall_seconds": wall, "task_seconds": task_seconds,
              "per_task": {k: r["seconds"] for k, r in results.items()}}
    for key, error in failed:
        print(f"FAILED {key}: {error}", file=sys.stderr)
    print(f"{len(graph) - len(failed)} of {len(graph)} tasks done in {wall:.2f} s wall, "
          f"{task_seconds:.2f} s summed over tasks")
    if opts.report:
        Path(opts.report).write_text(json.dumps(report, indent=1) + "\n")
    return 1 if failed else 0


def outline_script(opts):
    """The native pyoutline script of the graph: layers over the frame range."""
    tasks = frame_graph(opts, "%{FRAME}", "%{ZFRAME}")
    frame_range = ",".join(str(f) for f in opts.frames)
    name = lambda key: key.replace("-%{ZFRAME}", "")  # noqa: E731 (one layer per piece)
    lines = [
        f'"""OpenCue job: lucerna {opts.scene or "default scene"}, frames {frame_range}, '
        f'tiles {opts.tiles}, {opts.passes} passes.',
        f"Written by tools/farm/farm.py; submit with: pycuerun {opts.outline} {frame_range}",
        '"""',
        "from outline.modules.shell import Shell",
        "",
        "LAYERS = {}",
    ]
    for task in tasks:
        lines.append(f"LAYERS[{name(task.key)!r}] = Shell({name(task.key)!r}, "
                     f"command={task.args!r}, range={frame_range!r}, threads={opts.threads})")
        for dep in task.after:
            lines.append(f"LAYERS[{name(task.key)!r}].depend_on(LAYERS[{name(dep)!r}])")
    return "\n".join(lines) + "\n"


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    extra = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1:]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("command", choices=["run", "opencue"])
    parser.add_argument("scene", nargs="?", help="scene file (default: the Cornell box)")
    parser.add_argument("--frames", type=parse_frames, default=[1])
    parser.add_argument("--resolution", required=True, help="WxH, needed to cut tiles")
    parser.add_argument("--tiles", default="1x1", help="COLUMNSxROWS")
    parser.add_argument("--passes", type=int, default=1)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--camera")
    parser.add_argument("--threads", type=int, default=1, help="threads of each task")
    parser.add_argument("-o", "--output", required=True, help="pattern with {frame}")
    parser.add_argument("--parts", help="directory of the partial EXRs (default: .parts "
                        "beside the output)")
    parser.add_argument("--lucerna", default=str(ROOT / "target/release/lucerna"))
    parser.add_argument("--scheduler", help="a Dask scheduler address (default: a local "
                        "cluster)")
    parser.add_argument("--workers", type=int, default=2, help="local cluster workers")
    parser.add_argument("--report", help="write the task seconds as JSON")
    parser.add_argument("--outline", help="the outline script to write (opencue)")
    opts = parser.parse_args(argv)
    opts.extra = extra
    if len(opts.frames) > 1 and "{frame}" not in opts.output:
        parser.error("several frames need {frame} in --output")
    # Workers may run elsewhere: every path is made absolute.
    opts.output = str(Path(opts.output).absolute())
    if opts.scene:
        opts.scene = str(Path(opts.scene).resolve())
    if opts.command == "run":
        return run(opts)
    if not opts.outline:
        parser.error("opencue needs --outline PATH")
    Path(opts.outline).write_text(outline_script(opts))
    print(f"wrote {opts.outline}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
