#!/usr/bin/env python3
"""Render every USD stage under a folder (usd-wg/assets, OpenUSD's tutorials and test stages)
the way a pipeline would, with default settings, and tabulate what happened:

    python3 tools/experiments/usd_corpus/corpus.py DIR [--out tools/experiments/usd_corpus/results] [-- EXTRA RENDER ARGS]

Each stage is rendered at 32x24, 1 spp, beauty only, with a timeout of 300 s. A stage
"renders" when lucerna exits 0 with an EXR. The report groups refusals by their reason
(the element and reason of lucerna's one-line error, numbers and paths stripped), and
counts the plugin's warnings (validator findings, skipped prims, approximations).
Standard library only; needs the release binary (`cargo build --release`). With usd-core
in the repository's .venv (or $LUCERNA_PYTHON), every file is also classified: a file whose
composed stage holds no gprim, point instancer or light at all (a material library, a
camera or layout layer) is not a scene, and the report gives the rate over scenes too.
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
LUCERNA = os.environ.get("LUCERNA_BIN", str(ROOT / "target/release/lucerna"))
EXTENSIONS = {".usd", ".usda", ".usdc", ".usdz"}


def render(stage, extra, scratch):
    out = Path(scratch) / "out.exr"
    out.unlink(missing_ok=True)
    start = time.monotonic()
    try:
        proc = subprocess.run([LUCERNA, "render", str(stage), "-o", str(out), "--resolution",
                               "32x24", "--spp", "1", "--aov", "beauty", "-q", *extra],
                              capture_output=True, text=True, timeout=300)
        code, stderr = proc.returncode, proc.stderr
    except subprocess.TimeoutExpired:
        code, stderr = "timeout", ""
    seconds = time.monotonic() - start
    lines = stderr.splitlines()
    error = next((l for l in lines if l.startswith("error: ")), "")
    return {
        "stage": str(stage),
        "exit": code,
        "rendered": code == 0 and out.exists(),
        "seconds": round(seconds, 2),
        "error": error,
        "warnings": sum(1 for l in lines if "warning" in l.lower()),
        "panicked": "panicked" in stderr or "Traceback" in stderr,
    }


def reason_class(error, stage):
    """The error with the stage path, numbers and quoted names stripped: a refusal's kind."""
    text = error.removeprefix("error: ").replace(stage, "STAGE")
    text = re.sub(r"</[^>]*>|/[\w/.:\-\[\]]+", "PATH", text)
    text = re.sub(r"'[^']*'|\"[^\"]*\"", "NAME", text)
    text = re.sub(r"\d+(\.\d+)?", "N", text)
    return text[:160]


CLASSIFY = r'''
import json, sys
from pxr import Usd, UsdGeom, UsdLux
out = {}
for path in sys.argv[1:]:
    try:
        stage = Usd.Stage.Open(path)
    except Exception:
        out[path] = "unopenable"
        continue
    if stage is None:
        out[path] = "unopenable"
        continue
    kind = "layer"
    for prim in stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimAllPrimsPredicate)):
        if prim.IsA(UsdGeom.Gprim) or prim.IsA(UsdGeom.PointInstancer) or prim.HasAPI(UsdLux.LightAPI):
            kind = "scene"
            break
    out[path] = kind
print(json.dumps(out))
'''


def classify(stages):
    """{stage: "scene" | "layer" | "unopenable"} by usd-core, or {} without it."""
    python = os.environ.get("LUCERNA_PYTHON", str(ROOT / ".venv/bin/python"))
    if not Path(python).exists():
        return {}
    proc = subprocess.run([python, "-c", CLASSIFY, *map(str, stages)], capture_output=True,
                          text=True)
    try:
        return json.loads(proc.stdout.strip().splitlines()[-1])
    except (IndexError, ValueError):
        return {}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--out", type=Path, help="write report.md and results.json here")
    parser.add_argument("extra", nargs="*", help="further render arguments (after --)")
    args = parser.parse_args()
    stages = sorted(p for p in args.folder.rglob("*") if p.suffix.lower() in EXTENSIONS)
    results = []
    with tempfile.TemporaryDirectory() as scratch:
        for i, stage in enumerate(stages):
            r = render(stage, args.extra, scratch)
            results.append(r)
            status = "ok " if r["rendered"] else f"{r['exit']:>3}"
            print(f"[{i + 1}/{len(stages)}] {status} {r['seconds']:6.1f} s "
                  f"{stage.relative_to(args.folder)} {r['error'][:150]}", flush=True)
    kinds = classify(stages)
    for r in results:
        r["kind"] = kinds.get(r["stage"], "unknown")
    scenes = [r for r in results if r["kind"] != "layer"]
    scenes_rendered = sum(r["rendered"] for r in scenes)
    rendered = sum(r["rendered"] for r in results)
    reasons = Counter(reason_class(r["error"], r["stage"]) for r in results if not r["rendered"])
    lines = [
        f"# lucerna on {len(results)} USD stages of {args.folder.name}",
        "",
        f"Rendered with default settings{' ' + ' '.join(args.extra) if args.extra else ''}: "
        f"**{rendered} of {len(results)} ({100 * rendered / max(len(results), 1):.0f} %)**; "
        f"crashes (panic or traceback): {sum(r['panicked'] for r in results)}; "
        f"timeouts: {sum(r['exit'] == 'timeout' for r in results)}; "
        f"slowest {max((r['seconds'] for r in results), default=0):.1f} s.",
        "",
        f"Scenes (files whose composed stage has a gprim, point instancer or light, or that "
        f"usd-core cannot open): **{scenes_rendered} of {len(scenes)} "
        f"({100 * scenes_rendered / max(len(scenes), 1):.1f} %)**; the other "
        f"{len(results) - len(scenes)} files are layers without geometry or lights (material "
        "libraries, camera and layout layers), refused as having nothing to render.",
        "",
        "| refusals | reason |",
        "|---|---|",
    ]
    lines += [f"| {n} | {reason} |" for reason, n in reasons.most_common()]
    lines += ["", "Scenes not rendered:", ""]
    lines += [f"- `{Path(r['stage']).relative_to(args.folder)}`: {r['error'] or r['exit']}"
              for r in scenes if not r["rendered"]]
    report = "\n".join(lines) + "\n"
    print(report)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "report.md").write_text(report)
        (args.out / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
