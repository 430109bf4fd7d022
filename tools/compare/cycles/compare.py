#!/usr/bin/env python3
"""lucerna against Cycles on real glTF assets: renders each asset with both under the same
camera and light, measures how far apart they are on the pixels the asset covers, and
writes a contact sheet (lucerna | Cycles) with the figures.

    .venv/bin/python tools/compare/cycles/compare.py --models DIR [--asset NAME ...]
        [--resolution 320x240] [--spp 256] [--out tools/compare/cycles/results] [--keep DIR]

DIR holds the Khronos sample assets as `DIR/NAME/glTF/NAME.gltf` (glTF-Sample-Assets'
`Models` folder). Cycles runs headless through `blender_render.py` (which lists the settings
that make its render comparable): `$BLENDER` names a Blender binary or a Python with pip's
`bpy` (recommended: `python3.11 -m venv bpyenv && bpyenv/bin/pip install bpy==5.0.1`, then
`BLENDER=bpyenv/bin/python`; Blender 5's Principled BSDF has glTF's sheen, specular and
coat), else `blender` on PATH (Debian's 3.4 works, with older material models).

Per asset: the asset's first camera, else lucerna's framing camera (vertical field of view
40 degrees, looking down -Z at the bounds' centre from the distance where their bounding
sphere fills it); a constant environment and a sun, so that glass has something to refract
and shadows show. lucerna renders the scene file `lucerna convert` writes, with that camera
and sun added; Blender imports the glTF with its COMPAT light units.

Each renderer renders twice (seeds 1 and 2). Figures are taken over the pixels lucerna's
alpha says the asset covers (alpha 1), leaving out fireflies: pixels where any of the four
renders exceeds 4 times the 99th percentile of their pooled luminances (caustics through
glass that only BSDF sampling finds: one Cycles pixel of AttenuationTest at 256 spp holds
6e4, and alone moves the asset's mean tenfold). `fireflies` is the share left out.

- relMSE(lucerna, Cycles) = mean of (x - c)^2 / (c^2 + 0.01), seed 1 of each;
- the noise floor: what that relMSE would be if both rendered the same image, half the sum
  of relMSE(lucerna seed 1, seed 2) and relMSE(Cycles seed 1, seed 2) (each is twice a
  renderer's own error, and the two errors add);
- the luminance ratio lucerna / Cycles of the mean luminance, both seeds of each averaged.

`--keep DIR` writes the four renders and the alpha of each asset to DIR/NAME.npz, and
`--from-kept DIR` makes the figures and the sheet from them without rendering.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import lucerna_tools as lt

ASSETS = ["TransmissionTest", "TransmissionRoughnessTest", "AttenuationTest", "SpecularTest", "SheenChair",
          "SheenCloth", "ClearCoatTest", "IridescenceLamp", "TextureTransformTest", "TextureTransformMultiTest",
          "NormalTangentMirrorTest", "DamagedHelmet"]
ENVIRONMENT = [0.5, 0.5, 0.5]
SUN = {"direction": [-0.35, -1.0, -0.55], "irradiance": 2.0}
BLENDER = os.environ.get("BLENDER", "blender")


def luminance(img):
    return 0.2126 * img[..., 0] + 0.7152 * img[..., 1] + 0.0722 * img[..., 2]


def relmse(x, ref, mask):
    return float(np.mean(((x - ref) ** 2 / (ref ** 2 + 0.01))[mask]))


def bounds(scene):
    """World-space bounds of a scene file's instanced meshes and spheres."""
    m = scene.manifest
    points = []
    for inst in m["instances"]:
        p = scene.arrays[inst["mesh"]]["positions"]
        if p is None or len(p) == 0:
            continue
        t = np.array(inst["transform"], dtype=np.float64).reshape(4, 4).T
        points.append(p @ t[:3, :3].T + t[:3, 3])
    for s in m["spheres"]:
        c, r = np.array(s["centre"]), s["radius"]
        points.append(np.array([c - r, c + r]))
    allp = np.concatenate(points)
    return allp.min(axis=0), allp.max(axis=0)


def camera(scene):
    """(column-major 4x4 camera-to-world, yfov): the scene's first perspective camera, else
    lucerna's framing camera (`camera::framing_camera`)."""
    for cam in scene.manifest["cameras"]:
        if "perspective" in cam["projection"]:
            return cam["transform"], cam["projection"]["perspective"]["yfov"]
    lo, hi = bounds(scene)
    yfov = math.radians(40.0)
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-9)
    distance = radius / math.sin(yfov / 2)
    return [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, centre[0], centre[1], centre[2] + distance, 1], yfov


def render_lucerna(gltf, work, width, height, spp, seed, model):
    scene_file = work / "scene.lucerna"
    if not scene_file.exists():
        lt.convert(gltf, scene_file)
    scene = lt.SceneFile(scene_file)
    matrix, yfov = camera(scene)
    m = scene.manifest
    m["cameras"] = [{"name": "compare", "projection": {"perspective": {"yfov": yfov, "aspect": None}},
                     "transform": matrix, "aperture_radius": 0.0, "focus_distance": 1.0, "clip_near": 1e-3,
                     "clip_far": None}]
    m["lights"] = [{"name": "sun", "kind": {"directional": {
        "direction": SUN["direction"], "irradiance": [SUN["irradiance"]] * 3, "angle": 0.0}}}]
    path = scene.write(work / "compare.lucerna")
    out = work / f"lucerna-{seed}.exr"
    start = time.perf_counter()
    # The glTF model is single-scattering GGX (as Cycles is told in that mode); imported,
    # both renderers compensate rough lobes for multiple scattering (their defaults).
    microfacet = "single" if model == "gltf" else "multiscatter"
    image, _, channels = lt.render(path, out, (width, height), spp=spp, seed=seed,
                                   env=",".join(map(str, ENVIRONMENT)), aov="beauty", microfacet=microfacet)
    return image, channels["A"], time.perf_counter() - start, (matrix, yfov)


def render_cycles(gltf, work, width, height, spp, cam, seed, model):
    job = {"model": model, "gltf": str(gltf), "out": str(work / f"cycles-{seed}.exr"), "width": width, "height": height, "spp": spp,
           "seed": seed, "camera": {"matrix": cam[0], "yfov": cam[1]}, "environment": ENVIRONMENT, "sun": SUN}
    (work / "job.json").write_text(json.dumps(job))
    start = time.perf_counter()
    script = str(Path(__file__).with_name("blender_render.py"))
    if Path(BLENDER).name.startswith("python"):
        command = [BLENDER, script, "--", str(work / "job.json")]
    else:
        command = [BLENDER, "-b", "--factory-startup", "--python", script, "--", str(work / "job.json")]
    proc = subprocess.run(command, capture_output=True, text=True)
    if proc.returncode != 0 or not Path(job["out"]).exists():
        raise RuntimeError(f"blender failed: {proc.stdout[-2000:]} {proc.stderr[-2000:]}")
    version = next((line.split("Blender", 1)[1].strip() for line in proc.stdout.splitlines()
                    if line.startswith("cycles_compare: Blender")), "?")
    channels, _ = lt.read_exr(job["out"])
    return lt.rgb(channels), time.perf_counter() - start, version


def figures(renders):
    """The figures (see the module doc) of one asset's renders: a dict with `lucerna`,
    `lucerna_b`, `cycles`, `cycles_b` (RGB) and `alpha`."""
    covered = renders["alpha"] >= 0.999
    images = [renders[k] for k in ("lucerna", "lucerna_b", "cycles", "cycles_b")]
    lums = [luminance(x) for x in images]
    threshold = 4.0 * np.quantile(np.concatenate([v[covered] for v in lums]), 0.99)
    keep = covered & np.all([v <= threshold for v in lums], axis=0)
    mask = np.repeat(keep[..., None], 3, axis=2)
    lucerna, lucerna_b, cycles, cycles_b = images
    f = {"relmse": relmse(lucerna, cycles, mask),
         "noise_lucerna": relmse(lucerna_b, lucerna, mask), "noise_cycles": relmse(cycles_b, cycles, mask),
         "luminance_ratio": float((lums[0] + lums[1])[keep].mean() / (lums[2] + lums[3])[keep].mean()),
         "covered": float(covered.mean()), "fireflies": float(1.0 - keep.sum() / max(covered.sum(), 1))}
    f["noise_floor"] = (f["noise_lucerna"] + f["noise_cycles"]) / 2
    return f


def render_both(gltf, name, width, height, spp, model):
    """Both renderers, two seeds each: (renders as `figures` takes them, timing)."""
    with tempfile.TemporaryDirectory(prefix=f"cycles-{name}-") as work:
        work = Path(work)
        lucerna, alpha, seconds, cam = render_lucerna(gltf, work, width, height, spp, 1, model)
        lucerna_b, _, _, _ = render_lucerna(gltf, work, width, height, spp, 2, model)
        cycles, cycles_seconds, blender = render_cycles(gltf, work, width, height, spp, cam, 1, model)
        cycles_b, _, _ = render_cycles(gltf, work, width, height, spp, cam, 2, model)
    renders = {"lucerna": lucerna, "lucerna_b": lucerna_b, "cycles": cycles, "cycles_b": cycles_b, "alpha": alpha}
    return renders, {"seconds_lucerna": seconds, "seconds_cycles": cycles_seconds, "blender": blender}


def to_srgb8(img):
    c = np.clip(img, 0.0, 1.0)
    c = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return (c * 255 + 0.5).astype(np.uint8)


def contact_sheet(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(len(rows), 2, figsize=(8, 3.1 * len(rows)), squeeze=False)
    for (name, lucerna, cycles, f), (a, b) in zip(rows, axes):
        a.imshow(to_srgb8(lucerna))
        b.imshow(to_srgb8(cycles))
        a.set_title(f"{name}: lucerna", fontsize=9)
        b.set_title(f"Cycles   relMSE {f['relmse']:.4f} (floor {f['noise_floor']:.4f})  lum {f['luminance_ratio']:.3f}",
                    fontsize=8)
        for ax in (a, b):
            ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--models", type=Path, required=True)
    parser.add_argument("--asset", action="append")
    parser.add_argument("--resolution", default="320x240")
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results")
    parser.add_argument("--cycles-model", choices=["imported", "gltf"], default="imported",
                        help="Cycles renders the importer's materials, or them brought to glTF's model "
                             "(blender_render.py says how)")
    parser.add_argument("--keep", type=Path, help="also write each asset's renders here as NAME.npz")
    parser.add_argument("--from-kept", type=Path, help="figures and sheet from the renders --keep wrote")
    args = parser.parse_args()
    width, height = map(int, args.resolution.split("x"))
    args.out.mkdir(parents=True, exist_ok=True)
    old = args.out / "figures.json"
    previous = json.loads(old.read_text()) if args.from_kept and old.exists() else {}
    rows, all_figures = [], {}
    for name in args.asset or ASSETS:
        if args.from_kept:
            renders = dict(np.load(args.from_kept / f"{name}.npz"))
            timing = {k: previous.get(name, {}).get(k) for k in ("seconds_lucerna", "seconds_cycles", "blender")}
        else:
            renders, timing = render_both(args.models / name / "glTF" / f"{name}.gltf", name, width, height, args.spp,
                                          args.cycles_model)
            if args.keep:
                args.keep.mkdir(parents=True, exist_ok=True)
                np.savez_compressed(args.keep / f"{name}.npz", **renders)
        f = figures(renders) | timing
        all_figures[name] = f
        rows.append((name, renders["lucerna"], renders["cycles"], f))
        print(f"{name:28} relMSE {f['relmse']:.4f} (floor {f['noise_floor']:.4f})  luminance ratio "
              f"{f['luminance_ratio']:.3f}  covered {f['covered']:.2f}  fireflies {f['fireflies']:.4f}", flush=True)
    (args.out / "figures.json").write_text(json.dumps(all_figures, indent=1) + "\n")
    contact_sheet(rows, args.out / "contact_sheet.png")


if __name__ == "__main__":
    main()
