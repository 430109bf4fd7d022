#!/usr/bin/env python3
"""Time against error: lucerna and Mitsuba 3 on the scenes of bench.toml.

For every scene: a high-sample lucerna reference (cached under tools/.cache with its sample
count and its own noise, the relMSE it is expected to have against the converged image);
then, for every renderer, a ladder of equal-time budgets and a ladder of sample counts,
rung by rung with the renderers interleaved, repeated `repeats` times. Every image is
compared with the reference: relMSE (the project's metric), MSE, MAPE and HDR-FLIP. The
report: a markdown table (scene, renderer, seconds, spp, errors, efficiency =
1 / (seconds x relMSE)), the ratio of lucerna's efficiency to each Mitsuba variant's at each
budget, log-log plots of error against time, and the machine it ran on.

Mitsuba renders the scene exported from lucerna's own scene file (tools/lucerna_tools/mitsuba_export.py),
each render in a process of its own (tools/bench/mitsuba_worker.py). Its sample count for a
budget comes from its measured seconds per sample (at first from calibration renders of at
least half a second, then from its latest render); the efficiency uses the seconds it took.

    tools/bench/run [--quick] [--config tools/bench/bench.toml] [--out tools/bench/results]
"""
import argparse
import datetime
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np

import lucerna_tools as lt

WORKER = Path(__file__).resolve().parent / "mitsuba_worker.py"
METRICS = ["relmse", "mse", "mape", "flip"]


def cpu_of_children():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def steal_share():
    """A function returning the share of the machine's CPU time stolen by the hypervisor
    since this call (a measure of how noisy the shared machine was)."""
    def read():
        fields = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
        return sum(fields[:8]), fields[7] if len(fields) > 7 else 0
    try:
        total0, steal0 = read()
    except (OSError, ValueError):
        return lambda: float("nan")

    def since():
        total, steal = read()
        return (steal - steal0) / max(total - total0, 1)
    return since


def machine():
    cpu, _, isa = lt.cpu()
    mem = next((int(line.split()[1]) * 1024 for line in Path("/proc/meminfo").read_text().splitlines()
                if line.startswith("MemTotal")), 0)

    def out(cmd):
        try:
            return subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return "?"
    import mitsuba
    return {
        "cpu": cpu, "isa": isa, "cores": os.cpu_count(), "memory_gb": round(mem / 1e9, 1),
        "os": f"{platform.system()} {platform.release()}", "python": platform.python_version(),
        "rustc": out(["rustc", "--version"]), "mitsuba": mitsuba.__version__,
        "lucerna": out([lt.BINARY, "--version"]), "commit": out(["git", "-C", str(lt.ROOT), "describe", "--always", "--dirty"]),
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
    }


class Lucerna:
    def __init__(self, spec, scene, model):
        """`model`: the settings of bench.toml's `model`, which the references use too."""
        self.name, self.scene = spec["name"], scene
        self.settings = dict(model, **spec.get("settings", {}))

    def render(self, resolution, seed, out, budget=None, spp=None):
        settings = dict(self.settings, seed=seed, filter="box", aov="beauty")
        settings.update({"time": budget, "spp": 1 << 20} if budget else {"spp": spp})
        cpu, stolen = cpu_of_children(), steal_share()
        image, header, _ = lt.render(self.scene["path"], out, resolution, **settings)
        return image, {"seconds": header["lucerna/render_seconds"], "cpu_seconds": cpu_of_children() - cpu,
                       "spp": header["lucerna/spp"], "steal": stolen()}


def worker_failure(done):
    """Why a Mitsuba worker failed, in one line. Dr.Jit loads whichever libLLVM it finds; one
    too old for its kernels (Debian 12's LLVM 14 and 15) aborts the process with an LLVM
    ERROR, the last stderr line then being a kernel name."""
    lines = done.stderr.strip().splitlines()
    llvm = next((line for line in lines if line.startswith("LLVM ERROR")), None)
    if llvm:
        return f"Dr.Jit's LLVM backend cannot compile with this libLLVM (install a newer one: apt-get install libllvm19): {llvm}"
    return lines[-1] if lines else f"exit status {done.returncode}"


class Mitsuba:
    def __init__(self, spec, scene):
        self.name, self.variant, self.scene = spec["name"], spec["variant"], scene
        # Without one, the worker's default (Mitsuba's own: independent).
        self.sampler = spec.get("sampler")
        self.seconds_per_spp = None

    def run(self, resolution, spp, seed, out):
        npy = Path(out).with_suffix(".npy")
        cmd = [sys.executable, str(WORKER), str(self.scene["scene_file"]), "--variant", self.variant,
               "--resolution", f"{resolution[0]}x{resolution[1]}", "--spp", str(spp), "--seed", str(seed),
               "--out", str(npy)] + (["--sampler", self.sampler] if self.sampler else [])
        stolen = steal_share()
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"{self.name}: {worker_failure(done)}")
        timing = json.loads(done.stdout.strip().splitlines()[-1])
        timing["steal"] = stolen()
        # Running estimate of seconds per sample per pixel, for the next budget.
        self.seconds_per_spp = timing["seconds"] / spp
        return np.load(npy), timing

    def calibrate(self, resolution, out, seconds=0.5, max_spp=4096):
        """Measures seconds per sample for the first budget, from a render of at least
        `seconds`: a short one is dominated by each call's fixed cost (on the MIS plates, 4 spp
        of llvm_ad_rgb suggested 271 spp for a 1 s budget, which took 0.36 s)."""
        spp = 4
        while True:
            _, timing = self.run(resolution, spp, 0, out)
            if timing["seconds"] >= seconds or spp >= max_spp:
                return
            spp = min(max_spp, max(2 * spp, round(1.2 * seconds / max(self.seconds_per_spp, 1e-9))))

    def render(self, resolution, seed, out, budget=None, spp=None):
        if budget:
            spp = max(1, round(budget / self.seconds_per_spp))
        image, timing = self.run(resolution, spp, seed, out)
        return image, {k: timing[k] for k in ("seconds", "cpu_seconds", "spp", "steal")}


def metrics(image, ref):
    import flip_evaluator as flip
    _, mean_flip, _ = flip.evaluate(ref.astype(np.float32), np.maximum(image, 0).astype(np.float32), "HDR",
                                    applyMagma=False)
    return {"relmse": lt.relmse(image, ref), "mse": lt.mse(image, ref), "mape": lt.mape(image, ref),
            "flip": float(mean_flip)}


def median_rows(rows):
    """One row per (scene, renderer, ladder, rung): medians over the repeats."""
    groups = {}
    for r in rows:
        groups.setdefault((r["scene"], r["renderer"], r["ladder"], r["rung"]), []).append(r)
    out = []
    for (scene, renderer, ladder, rung), rs in groups.items():
        m = {"scene": scene, "renderer": renderer, "ladder": ladder, "rung": rung, "repeats": len(rs)}
        for key in ["seconds", "cpu_seconds", "spp", "steal", "efficiency", "cpu_efficiency"] + METRICS:
            m[key] = statistics.median(r[key] for r in rs)
        out.append(m)
    return out


def ratio_table(medians, scenes, renderers):
    """Per scene and budget: lucerna's efficiency over each other renderer's."""
    base = renderers[0]
    budgets = sorted({m["rung"] for m in medians if m["ladder"] == "time"})
    lines = []
    for other in renderers[1:]:
        lines += [f"#### {base} / {other}", "", "| scene | " + " | ".join(f"{b:g} s" for b in budgets) +
                  " | geometric mean |", "|---" * (len(budgets) + 2) + "|"]
        for scene in scenes:
            ratios = []
            for b in budgets:
                a = find(medians, scene, base, "time", b)
                o = find(medians, scene, other, "time", b)
                ratios.append(a["efficiency"] / o["efficiency"] if a and o else float("nan"))
            good = [r for r in ratios if r == r]
            gm = float(np.exp(np.mean(np.log(good)))) if good else float("nan")
            lines.append(f"| {scene} | " + " | ".join(f"{r:.2f}" for r in ratios) + f" | **{gm:.2f}** |")
        lines.append("")
    return lines


def find(medians, scene, renderer, ladder, rung):
    return next((m for m in medians if (m["scene"], m["renderer"], m["ladder"], m["rung"]) == (scene, renderer, ladder, rung)), None)


def plot(medians, scene, renderers, ref_info, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, metric, label in [(axes[0], "relmse", "relMSE"), (axes[1], "flip", "mean HDR-FLIP")]:
        for i, renderer in enumerate(renderers):
            colour = f"C{i}"
            for ladder, style in [("time", "o-"), ("spp", "x:")]:
                pts = sorted((m["seconds"], m[metric]) for m in medians
                             if m["scene"] == scene and m["renderer"] == renderer and m["ladder"] == ladder)
                if pts:
                    ax.plot(*zip(*pts), style, color=colour,
                            label=f"{renderer} ({'equal time' if ladder == 'time' else 'equal spp'})")
        if metric == "relmse":
            ax.axhline(ref_info["relmse_noise"], color="grey", ls="--", lw=0.8, label="reference's own noise")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("render seconds (wall)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", lw=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{scene}: error against time (medians of the repeats)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def renderer_names(result):
    """The renderers' names, in the configuration's order (the specs are in the result)."""
    return [r["name"] for r in result["renderers"]]


def report(result, out):
    medians, scenes = result["medians"], [s["name"] for s in result["scenes"]]
    renderers = renderer_names(result)
    m = result["machine"]
    lines = ["# tools/bench: time against error", "",
             f"Machine: {m['cpu']} ({m.get('isa', '?')}), {m['cores']} cores, {m['memory_gb']} GB, {m['os']}; "
             f"shared (see the steal column: the share of CPU time the hypervisor gave to others during the render).",
             f"Software: {m['lucerna']} ({m['commit']}), {m['rustc']}, Mitsuba {m['mitsuba']}, Python {m['python']}. "
             f"Run {m['date']}, {result['repeats']} repeat(s), renderers interleaved rung by rung.", "",
             "Command: `tools/bench/run` (configuration `tools/bench/bench.toml`).", "",
             "relMSE = mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01); efficiency = 1 / (wall seconds x "
             "relMSE); CPU efficiency uses the process's CPU seconds instead (lucerna: the whole process; Mitsuba: its "
             "render calls). Values are medians over the repeats.", ""]
    for s in result["scenes"]:
        ref = s["reference"]
        lines.append(f"- **{s['name']}** ({s['path']}, {s['resolution'][0]}x{s['resolution'][1]}): reference "
                     f"{ref['spp']} spp by lucerna{' at ' + ref['commit'] if 'commit' in ref else ''}, "
                     f"{ref['seconds']:.0f} s, its own noise relMSE {ref['relmse_noise']:.2e}.")
    for spec in result["renderers"]:
        settings = {k: v for k, v in spec.items() if k not in ("name", "kind")}
        # lucerna's flags (a table) read as flags; Mitsuba's variant and sampler as they are.
        settings.update({f"--{k}": v for k, v in settings.pop("settings", {}).items()})
        lines.append(f"- renderer **{spec['name']}** ({spec['kind']}): "
                     + (", ".join(f"{k} {v}" for k, v in settings.items() if v) or "its defaults") + ".")
    for skipped in result["skipped"]:
        lines.append(f"- skipped: {skipped}")
    lines += ["", "## Efficiency ratios at equal time", ""] + ratio_table(medians, scenes, renderers)
    lines += ["## All renders", "",
              "| scene | renderer | ladder | seconds | CPU s | spp | relMSE | MSE | MAPE | FLIP | efficiency | CPU eff. | steal |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(medians, key=lambda r: (r["scene"], r["ladder"], r["rung"], r["renderer"])):
        rung = f"{r['rung']:g} s" if r["ladder"] == "time" else f"{r['rung']} spp"
        lines.append(f"| {r['scene']} | {r['renderer']} | {rung} | {r['seconds']:.2f} | {r['cpu_seconds']:.2f} | "
                     f"{r['spp']:.0f} | {r['relmse']:.3e} | {r['mse']:.3e} | {r['mape']:.4f} | {r['flip']:.4f} | "
                     f"{r['efficiency']:.4g} | {r['cpu_efficiency']:.4g} | {r['steal']:.0%} |")
    lines += ["", "Plots: " + ", ".join(f"[{s['name']}]({s['name']}.png)" for s in result["scenes"]), ""]
    (out / "bench.md").write_text("\n".join(lines))
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", default=str(Path(__file__).resolve().parent / "bench.toml"))
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    parser.add_argument("--quick", action="store_true", help="budgets 1 and 2 s, 4 spp, one repeat (a smoke run)")
    parser.add_argument("--scene", action="append", help="only these scenes (by name)")
    args = parser.parse_args()
    config = tomllib.loads(Path(args.config).read_text())
    budgets, spps, repeats = config["budgets"], config["spp"], config["repeats"]
    if args.quick:
        budgets, spps, repeats = budgets[:2], spps[:1], 1
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result = {"machine": machine(), "repeats": repeats, "scenes": [], "rows": [], "skipped": [],
              "renderers": config["renderer"]}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for scene in config["scene"]:
            if args.scene and scene["name"] not in args.scene:
                continue
            scene = dict(scene, path=str(lt.ROOT / scene["path"]))
            resolution = tuple(scene["resolution"])
            scene["scene_file"] = tmp / f"{scene['name']}.lucerna"
            lt.convert(scene["path"], scene["scene_file"])
            reference_spp = scene.get("reference_spp", config["reference_spp"])
            print(f"{scene['name']}: reference ({reference_spp} spp, cached under {lt.CACHE})", flush=True)
            ref, ref_info = lt.reference(scene["path"], resolution, reference_spp, filter="box",
                                         **config.get("model", {}))
            renderers = []
            for spec in config["renderer"]:
                r = (Lucerna(spec, scene, config.get("model", {})) if spec["kind"] == "lucerna"
                     else Mitsuba(spec, scene))
                if isinstance(r, Mitsuba):
                    try:
                        r.calibrate(resolution, tmp / "calibration")
                    except RuntimeError as e:
                        # The error names the renderer already.
                        result["skipped"].append(f"{e} (scene {scene['name']})")
                        print(f"  skipped: {e}", flush=True)
                        continue
                renderers.append(r)
            rungs = [("time", b) for b in budgets] + [("spp", n) for n in spps]
            for repeat in range(repeats):
                for ladder, rung in rungs:
                    for r in renderers:
                        seed = 1 + repeat * 100 + rungs.index((ladder, rung))
                        kwargs = {"budget": rung} if ladder == "time" else {"spp": rung}
                        image, timing = r.render(resolution, seed, tmp / "render.exr", **kwargs)
                        row = {"scene": scene["name"], "renderer": r.name, "ladder": ladder, "rung": rung,
                               "repeat": repeat, **timing, **metrics(image, ref)}
                        row["efficiency"] = 1.0 / (row["seconds"] * row["relmse"])
                        row["cpu_efficiency"] = 1.0 / (row["cpu_seconds"] * row["relmse"])
                        result["rows"].append(row)
                        print(f"  [{repeat + 1}/{repeats}] {r.name:16} {ladder:4} {rung:>5}: {row['seconds']:6.2f} s "
                              f"{row['spp']:6.0f} spp  relMSE {row['relmse']:.3e}  FLIP {row['flip']:.4f}  "
                              f"efficiency {row['efficiency']:8.2f}  steal {row['steal']:.0%}", flush=True)
            result["scenes"].append({"name": scene["name"], "path": str(Path(scene["path"]).relative_to(lt.ROOT)),
                                     "resolution": list(resolution), "reference": ref_info})
    result["medians"] = median_rows(result["rows"])
    names = [s["name"] for s in result["scenes"]]
    names_of_renderers = renderer_names(result)
    for s in result["scenes"]:
        plot(result["medians"], s["name"], names_of_renderers, s["reference"], out / f"{s['name']}.png")
    (out / "bench.json").write_text(json.dumps(result, indent=1, default=str) + "\n")
    print()
    print("\n".join(["Efficiency ratios at equal time:"] + ratio_table(result["medians"], names, names_of_renderers)))
    report(result, out)
    print(f"wrote {out / 'bench.md'}, {out / 'bench.json'} and the plots")


if __name__ == "__main__":
    main()
