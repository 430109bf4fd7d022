"""What the render plan saves and what adaptive sampling gains, measured (issue 7).

1. Feature costs. Pairs of renders of one scene that differ in one thing: beauty only
   against every AOV; the plan's specialised integrator against `--plan general` (every
   feature on) on a diffuse-only scene, a scene lit by punctual lights only, and the MIS
   plates. Each pair is rendered `--repeats` times, the two members back to back in
   alternating order; the table gives median render seconds and the median of the
   per-repeat ratios (the machine is shared: ratios of neighbours in time are what holds).
   Where valgrind is installed, each member is also counted in instructions by callgrind
   (one thread, a small image): exact, and free of the machine's noise.
2. Adaptive sampling against uniform sampling. For each scene, an adaptive render with a
   noise threshold, then a uniform render with the same number of samples in all; both
   are compared with the cached high-sample reference (tools/.cache). Efficiency is
   1 / (seconds x relMSE); the gain is adaptive's over uniform's, which is also how much
   less time adaptive needs to reach uniform's relMSE (relMSE falls as 1 / time).

Writes plan_bench.md and plan_bench.json under --out (default tools/bench/plan/results).
"""
import argparse
import json
import platform
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import lucerna_tools as lt

HERE = Path(__file__).resolve().parent

CORNELL = lt.ROOT / "scenes/cornell-box/cornell-box.gltf"
PLATES = lt.ROOT / "scenes/mis-plates/mis-plates.glb"
ROOM = lt.ROOT / "scenes/indirect-room/indirect-room.glb"
TWIN = lt.ROOT / "scenes/usd-twin/usd-twin.gltf"


def punctual_cornell(work):
    """The Cornell box with its panel dark, lit by a point light under the ceiling and a
    spot light: a scene whose only lights are delta lights."""
    path = work / "cornell.lucerna"
    lt.convert(CORNELL, path)
    scene = lt.SceneFile(path)
    for m in scene.manifest["materials"]:
        m["emissive"] = [0.0, 0.0, 0.0]
    scene.manifest["lights"] = [
        {"name": "bulb", "kind": {"point": {"position": [0.278, 0.5, 0.28], "intensity": [0.4, 0.4, 0.4]}}},
        {"name": "spot", "kind": {"spot": {"position": [0.4, 0.5, 0.1], "direction": [-0.3, -1.0, 0.2],
                                           "intensity": [0.3, 0.3, 0.3], "inner_cone": 0.3, "outer_cone": 0.6}}},
    ]
    return scene.write(work / "cornell-punctual.lucerna")


def render_seconds(scene, out, resolution, **settings):
    _, header, _ = lt.render(scene, out, resolution, **settings)
    return header["lucerna/render_seconds"]


def instructions(scene, out, resolution, **settings):
    """Instructions callgrind counts in the render loop (`render::render_into`: no loading,
    BVH or EXR writing) on one thread; None without valgrind (or if nothing was counted)."""
    profile = Path(out).with_suffix(".callgrind")
    cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={profile}",
           "--toggle-collect=lucerna::render::render_into", lt.BINARY, "render", str(scene),
           "-o", str(out), "-q", "--threads", "1", "--resolution", f"{resolution[0]}x{resolution[1]}"]
    for key, value in settings.items():
        cmd += [f"--{key.replace('_', '-')}", str(value)]
    try:
        subprocess.run(cmd, check=True, capture_output=True)
    except FileNotFoundError:
        return None
    for line in profile.read_text().splitlines():
        if line.startswith("totals:") or line.startswith("summary:"):
            return int(line.split()[1]) or None
    return None


def feature_cost_cases(work):
    punctual = punctual_cornell(work)
    return [
        # (case, scene, resolution, settings A, settings B, what the ratio B/A says)
        ("Cornell box: all AOVs / beauty only", CORNELL, (256, 256),
         {"aov": "beauty"}, {"aov": "all"}),
        ("MIS plates: all AOVs / beauty only", PLATES, (240, 160),
         {"aov": "beauty"}, {"aov": "all"}),
        ("Cornell box (diffuse only): general / plan", CORNELL, (256, 256),
         {"aov": "beauty"}, {"aov": "beauty", "plan": "general"}),
        ("Cornell box, punctual lights only: general / plan", punctual, (256, 256),
         {"aov": "beauty"}, {"aov": "beauty", "plan": "general"}),
        ("MIS plates: general / plan", PLATES, (240, 160),
         {"aov": "beauty"}, {"aov": "beauty", "plan": "general"}),
    ]


def feature_costs(work, repeats, quick, cases=None):
    """Render seconds (interleaved pairs) and render-loop instructions of each case of
    `cases` (default: the render plan's)."""
    cases = feature_cost_cases(work) if cases is None else cases
    spp = 8 if quick else 32
    rows = []
    for name, scene, resolution, a, b in cases:
        seconds = {"a": [], "b": []}
        ratios = []
        for r in range(repeats):
            order = ["a", "b"] if r % 2 == 0 else ["b", "a"]
            t = {}
            for which in order:
                settings = a if which == "a" else b
                t[which] = render_seconds(scene, work / "cost.exr", resolution, spp=spp, **settings)
                seconds[which].append(t[which])
            ratios.append(t["b"] / t["a"])
        small = (64, 64)
        ir_a = instructions(scene, work / "ir-a.exr", small, spp=8, **a)
        ir_b = instructions(scene, work / "ir-b.exr", small, spp=8, **b)
        row = {"case": name, "scene": str(Path(scene).name), "resolution": list(resolution), "spp": spp,
               "a": a, "b": b, "seconds_a": statistics.median(seconds["a"]),
               "seconds_b": statistics.median(seconds["b"]), "ratio": statistics.median(ratios),
               "ratios": ratios, "instructions_a": ir_a, "instructions_b": ir_b,
               "instruction_ratio": ir_b / ir_a if ir_a and ir_b else None}
        print(f"{name}: {row['seconds_a']:.2f} s vs {row['seconds_b']:.2f} s, median ratio {row['ratio']:.3f}"
              + (f", instructions {ir_a:,} vs {ir_b:,} ({row['instruction_ratio']:.3f})" if ir_a else ""),
              flush=True)
        rows.append(row)
    return rows


def adaptive_gains(work, repeats, quick):
    # (scene, resolution, reference spp, noise threshold): thresholds chosen so that the
    # adaptive render takes a few seconds here.
    cases = [
        ("cornell-box", CORNELL, (256, 256), 4096, 0.05),
        ("mis-plates", PLATES, (240, 160), 16384, 0.05),
        ("indirect-room", ROOM, (120, 80), 4096, 0.15),
        ("usd-twin", TWIN, (192, 128), 4096, 0.02),
    ]
    if quick:
        cases = cases[:2]
    rows = []
    for name, scene, resolution, reference_spp, threshold in cases:
        print(f"{name}: reference ({reference_spp} spp, cached under {lt.CACHE})", flush=True)
        ref, info = lt.reference(scene, resolution, reference_spp, filter="box")
        runs = []
        for r in range(repeats):
            out = work / "adaptive.exr"
            image, header, channels = lt.render(scene, out, resolution, filter="box", aov="beauty,spp",
                                                noise_threshold=threshold)
            spp = channels["spp.Y"]
            t_a = header["lucerna/render_seconds"]
            e_a = lt.relmse(image, ref)
            uniform_spp = max(1, round(float(spp.mean())))
            image, header, _ = lt.render(scene, work / "uniform.exr", resolution, filter="box", aov="beauty",
                                         spp=uniform_spp)
            t_u = header["lucerna/render_seconds"]
            e_u = lt.relmse(image, ref)
            runs.append({"adaptive_seconds": t_a, "adaptive_relmse": e_a, "spp_mean": float(spp.mean()),
                         "spp_min": float(spp.min()), "spp_max": float(spp.max()),
                         "uniform_spp": uniform_spp, "uniform_seconds": t_u, "uniform_relmse": e_u,
                         "gain": (t_u * e_u) / (t_a * e_a)})
        med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
        row = {"scene": name, "resolution": list(resolution), "threshold": threshold,
               "reference": info, "runs": runs, **med}
        print(f"  adaptive {med['adaptive_seconds']:.2f} s relMSE {med['adaptive_relmse']:.3e} "
              f"(spp {med['spp_min']:.0f}..{med['spp_max']:.0f}, mean {med['spp_mean']:.1f}); uniform "
              f"{med['uniform_spp']:.0f} spp {med['uniform_seconds']:.2f} s relMSE {med['uniform_relmse']:.3e}; "
              f"efficiency gain {med['gain']:.2f}", flush=True)
        rows.append(row)
    return rows


def report(result, path):
    lines = ["# Render plan and adaptive sampling", "",
             f"Machine: {result['machine']}. Command: `tools/bench/plan/run{' --quick' if result['quick'] else ''}`.", "",
             "## Feature costs", "",
             f"Render seconds (median of {result['repeats']} repeats, the two renders of a pair back to back "
             "in alternating order), the median of the per-repeat ratios, and callgrind's instruction counts "
             "in the render loop (64x64, 8 spp, one thread).", "",
             "| case | spp | seconds A | seconds B | B / A (time) | instructions A | instructions B | B / A (instructions) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in result["costs"]:
        ir = (f"{r['instructions_a']:,} | {r['instructions_b']:,} | {r['instruction_ratio']:.3f}"
              if r["instruction_ratio"] else "n/a | n/a | n/a")
        lines.append(f"| {r['case']} | {r['spp']} | {r['seconds_a']:.2f} | {r['seconds_b']:.2f} | "
                     f"{r['ratio']:.3f} | {ir} |")
    lines += ["", "## Adaptive against uniform sampling", "",
              f"Median of {result['adaptive_repeats']} repeats. Uniform takes the adaptive render's mean sample count. "
              "Gain = efficiency ratio (adaptive over uniform), efficiency = 1 / (seconds x relMSE) against the "
              "reference; the reference's own noise (its expected relMSE) is listed.", "",
              "| scene | threshold | adaptive s | adaptive relMSE | spp min..max (mean) | uniform spp | uniform s | "
              "uniform relMSE | reference noise | gain |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["adaptive"]:
        lines.append(f"| {r['scene']} | {r['threshold']} | {r['adaptive_seconds']:.2f} | {r['adaptive_relmse']:.3e} | "
                     f"{r['spp_min']:.0f}..{r['spp_max']:.0f} ({r['spp_mean']:.1f}) | {r['uniform_spp']:.0f} | "
                     f"{r['uniform_seconds']:.2f} | {r['uniform_relmse']:.3e} | "
                     f"{r['reference']['relmse_noise']:.1e} | **{r['gain']:.2f}** |")
    path.write_text("\n".join(lines) + "\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer samples, two scenes for adaptive sampling")
    parser.add_argument("--repeats", type=int, default=None, help="repeats of each measurement (default 5, quick 2)")
    parser.add_argument("--out", type=Path, default=HERE / "results")
    args = parser.parse_args()
    repeats = args.repeats or (2 if args.quick else 5)
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        result = {"machine": f"{platform.processor() or platform.machine()}, "
                             f"{subprocess.run(['nproc'], capture_output=True, text=True).stdout.strip()} cores",
                  "quick": args.quick, "repeats": repeats, "adaptive_repeats": max(1, repeats // 2),
                  "costs": feature_costs(work, repeats, args.quick),
                  "adaptive": adaptive_gains(work, max(1, repeats // 2), args.quick)}
    (args.out / "plan_bench.json").write_text(json.dumps(result, indent=1))
    report(result, args.out / "plan_bench.md")
    print(f"wrote {args.out / 'plan_bench.md'}")


if __name__ == "__main__":
    main()
