#!/usr/bin/env python3
"""Reproduce the path-tracing lecture's experiments with lucerna and write a comparison
sheet: a labelled PNG grid per experiment and a table of seconds, relMSE and efficiency
(1 / (seconds x relMSE)), relative to the default setting of each experiment.

(a) the six MIS settings on scenes/mis-plates, at equal time;
(b) path termination on scenes/indirect-room: depth < 11, depth < 101, RR p = 0.3,
    RR on throughput / 0.01, efficiency-based RR, at equal time;
(c) direct light on the Cornell box: 4 camera x 100 shadow rays against 64 camera x 1.

Every image is compared with a high-sample reference of the same scene (cached under
tools/.cache, with its own noise level recorded). Needs tools/requirements.txt in the venv:

    .venv/bin/pip install -r tools/requirements.txt
    .venv/bin/python tools/experiments/lecture.py [--seconds 10] [--out tools/experiments/results/lecture]
"""
import argparse
import json
import sys
import tempfile
from pathlib import Path

import lucerna_tools as lt

SCENES = lt.ROOT / "scenes"


def run(name, scene, resolution, reference_settings, reference_spp, settings, default_label, out, title):
    """Renders every (label, settings) of `settings` and compares them with the reference."""
    ref, ref_info = lt.reference(scene, resolution, reference_spp, **reference_settings)
    rows, images = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for label, s in settings:
            image, header, _ = lt.render(scene, Path(tmp) / "x.exr", resolution, **s)
            seconds = header["lucerna/render_seconds"]
            error = lt.relmse(image, ref)
            rows.append({"setting": label, "flags": s, "seconds": seconds, "spp": header["lucerna/spp"],
                         "relmse": error, "efficiency": 1.0 / (seconds * error)})
            images.append(image)
    default = next(r for r in rows if r["setting"] == default_label)
    for r in rows:
        r["relative_efficiency"] = r["efficiency"] / default["efficiency"]
    labels = [f"{r['setting']}\n{r['seconds']:.1f} s, {r['spp']} spp, relMSE {r['relmse']:.2e}, eff x{r['relative_efficiency']:.2f}"
              for r in rows]
    lt.grid_png(images + [ref], labels + [f"reference ({ref_info['spp']} spp)"], out / f"{name}.png", title=title)
    return {"experiment": name, "title": title, "reference": ref_info, "rows": rows}


def table(result):
    lines = [f"### {result['title']}", "",
             f"Reference: {result['reference']['spp']} spp, its own noise relMSE {result['reference']['relmse_noise']:.1e}.", "",
             "| setting | seconds | spp | relMSE | efficiency | relative to default |",
             "|---|---|---|---|---|---|"]
    for r in result["rows"]:
        lines.append(f"| {r['setting']} | {r['seconds']:.2f} | {r['spp']} | {r['relmse']:.4g} | {r['efficiency']:.4g} | "
                     f"{r['relative_efficiency']:.2f} |")
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=10.0, help="time budget of each equal-time render")
    parser.add_argument("--out", default=str(lt.ROOT / "tools" / "experiments" / "results" / "lecture"))
    parser.add_argument("--reference-spp", type=int, default=4096)
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t = args.seconds
    results = []

    mis = [(m, {"mis": m, "time": t, "filter": "box"}) for m in
           ["balance", "power", "maximum", "cutoff", "nee-only", "bsdf-only"]]
    results.append(run("a-mis", SCENES / "mis-plates" / "mis-plates.glb", (240, 160), {"filter": "box"},
                       args.reference_spp, mis, "power", out, "(a) MIS heuristics on the plates, equal time"))

    termination = [
        ("depth < 11", {"rr": "off", "max_depth": 10, "time": t, "filter": "box"}),
        ("depth < 101", {"rr": "off", "max_depth": 100, "time": t, "filter": "box"}),
        ("RR p = 0.3", {"rr": "fixed:0.3", "time": t, "filter": "box"}),
        ("RR throughput / 0.01", {"rr": "throughput:0.01", "time": t, "filter": "box"}),
        ("RR throughput / 0.1", {"rr": "throughput:0.1", "time": t, "filter": "box"}),
        ("efficiency RR", {"rr": "efficiency", "time": t, "filter": "box"}),
        ("efficiency RR, splitting <= 4", {"rr": "efficiency:4", "time": t, "filter": "box"}),
    ]
    results.append(run("b-termination", SCENES / "indirect-room" / "indirect-room.glb", (120, 80), {"filter": "box"},
                       args.reference_spp, termination, "RR throughput / 0.01", out,
                       "(b) path termination on the indirect room, equal time"))

    direct = [
        ("64 camera x 1 shadow ray", {"spp": 64, "max_depth": 1, "filter": "box"}),
        ("4 camera x 100 shadow rays", {"spp": 4, "split": "nee=100", "max_depth": 1, "filter": "box"}),
    ]
    results.append(run("c-direct", None, (128, 128), {"max_depth": 1, "filter": "box"}, args.reference_spp, direct,
                       "64 camera x 1 shadow ray", out, "(c) direct light: camera samples against shadow rays"))

    (out / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / "results.md").write_text("# Lecture experiments\n\n" + "\n".join(table(r) for r in results))
    print((out / "results.md").read_text())


if __name__ == "__main__":
    main()
