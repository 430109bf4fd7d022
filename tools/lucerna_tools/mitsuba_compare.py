#!/usr/bin/env python3
"""Render a scene (default scenes/cornell-box) with lucerna and with Mitsuba 3 (scalar_rgb)
and compare them.

The glTF is converted to lucerna's scene file (`lucerna convert`) and exported to Mitsuba from
there (tools/lucerna_tools/mitsuba_export.py): the same geometry, Lambertian and perfect GGX conductor
BSDFs, one-sided area lights, spheres and camera; both renderers use a box pixel filter and unlimited path depth, and lucerna renders
single-scattering GGX (`--microfacet single`) as Mitsuba's rough models are. The comparison:

    relMSE(lucerna, Mitsuba)   against   relMSE(Mitsuba seed A, Mitsuba seed B)

relMSE(x, ref) = mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01). Both are
dominated by noise when the renderers agree; a bias in lucerna adds to the first only. The
check passes when the first is within 2x the second.

    .venv/bin/python tools/lucerna_tools/mitsuba_compare.py [--scene S] [--spp 1024] [--resolution 256x256] [--json out.json]
    .venv/bin/python tools/lucerna_tools/mitsuba_compare.py --seeds 16 [--scene S] [--spp 1024] [--resolution 32x32]

With `--seeds N` it measures whether the image means agree instead: N renders of each with
independent seeds, the mean of the pixels that do not see a light directly (where the
light's pixels, identical in both, would dilute a difference), and the difference of the
two renderers' means with its standard error from the spread between seeds.

Needs numpy, mitsuba and OpenImageIO (tests/requirements.txt) and a release build of lucerna
($LUCERNA_BIN, default target/release/lucerna).
"""
import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import lucerna_tools as lt
from lucerna_tools import mitsuba_export

CORNELL = lt.ROOT / "scenes" / "cornell-box" / "cornell-box.gltf"


def render_mitsuba(scene, spp, seed):
    import mitsuba as mi
    start = time.perf_counter()
    image = np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)
    return image[:, :, :3], time.perf_counter() - start


def render_lucerna(scene, spp, seed, width, height, workdir):
    # Mitsuba's rough models are single-scattering GGX: lucerna leaves out its energy
    # compensation to compute the same image.
    image, header, _ = lt.render(scene, Path(workdir) / f"lucerna_{seed}.exr", (width, height), spp=spp, seed=seed,
                                 filter="box", aov="beauty", microfacet="single")
    return image, header["lucerna/render_seconds"]


def scene_file_of(scene, workdir, hard_spots=False):
    """lucerna's scene file of `scene` in `workdir`, which both renderers then render; with
    `hard_spots`, every spot light's inner cone widened to its outer one (a hard edge, the
    falloff both renderers share; glTF cannot say it)."""
    scene_file = Path(workdir) / "scene.lucerna"
    lt.convert(scene, scene_file)
    if hard_spots:
        manifest = json.loads(scene_file.read_text())
        for light in manifest["lights"]:
            if spot := light["kind"].get("spot"):
                spot["inner_cone"] = spot["outer_cone"]
        scene_file.write_text(json.dumps(manifest))
    return scene_file


def compare(spp, width, height, scene=CORNELL, hard_spots=False):
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    with tempfile.TemporaryDirectory() as workdir:
        scene_file = scene_file_of(scene, workdir, hard_spots)
        exported = mi.load_dict(mitsuba_export.scene_dict(scene_file, width, height, workdir))
        mitsuba_a, seconds_a = render_mitsuba(exported, spp, 1)
        mitsuba_b, seconds_b = render_mitsuba(exported, spp, 2)
        lucerna_a, lucerna_seconds = render_lucerna(scene_file, spp, 1, width, height, workdir)
    result = {
        "spp": spp,
        "resolution": [width, height],
        "relmse_lucerna_vs_mitsuba": lt.relmse(lucerna_a, mitsuba_a),
        "relmse_mitsuba_a_vs_b": lt.relmse(mitsuba_b, mitsuba_a),
        "mean_lucerna": lucerna_a.mean(axis=(0, 1)).tolist(),
        "mean_mitsuba": mitsuba_a.mean(axis=(0, 1)).tolist(),
        "seconds_lucerna": lucerna_seconds,
        "seconds_mitsuba": (seconds_a + seconds_b) / 2,
    }
    result["ratio"] = result["relmse_lucerna_vs_mitsuba"] / result["relmse_mitsuba_a_vs_b"]
    return result


def mean_agreement(spp, width, height, seeds, scene=CORNELL, hard_spots=False):
    """Per renderer: the mean over `seeds` renders of the off-light pixel mean, its standard
    error, and the relative difference (lucerna / Mitsuba - 1) with its standard error."""
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    means = {"lucerna": [], "mitsuba": []}
    with tempfile.TemporaryDirectory() as workdir:
        scene_file = scene_file_of(scene, workdir, hard_spots)
        exported = mi.load_dict(mitsuba_export.scene_dict(scene_file, width, height, workdir))
        for s in range(seeds):
            mitsuba, _ = render_mitsuba(exported, spp, 1000 + s)
            lucerna, _ = render_lucerna(scene_file, spp, 1000 + s, width, height, workdir)
            off_light = mitsuba.max(axis=2) < 1.0
            means["mitsuba"].append(mitsuba[off_light].mean(axis=0))
            means["lucerna"].append(lucerna[off_light].mean(axis=0))
    l, m = np.array(means["lucerna"]), np.array(means["mitsuba"])
    se = lambda x: x.std(axis=0, ddof=1) / np.sqrt(len(x))  # noqa: E731
    return {
        "spp": spp, "resolution": [width, height], "seeds": seeds,
        "mean_lucerna": l.mean(axis=0).tolist(), "se_lucerna": se(l).tolist(),
        "mean_mitsuba": m.mean(axis=0).tolist(), "se_mitsuba": se(m).tolist(),
        "difference": (l.mean(axis=0) / m.mean(axis=0) - 1).tolist(),
        "difference_se": (np.sqrt(se(l) ** 2 + se(m) ** 2) / m.mean(axis=0)).tolist(),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=1024)
    parser.add_argument("--scene", default=str(CORNELL))
    parser.add_argument("--resolution", default="256x256", help="WxH")
    parser.add_argument("--json", help="also write the figures to this file")
    parser.add_argument("--seeds", type=int, help="compare the image means over this many seeds")
    parser.add_argument("--hard-spots", action="store_true",
                        help="make spot lights hard-edged in both renderers (see scene_file_of)")
    args = parser.parse_args()
    width, height = map(int, args.resolution.split("x"))
    if args.seeds:
        r = mean_agreement(args.spp, width, height, args.seeds, args.scene, args.hard_spots)
        print(f"{args.scene} {width}x{height}, {args.spp} spp, {args.seeds} seeds: mean of the off-light pixels")
        print(f"  lucerna {np.round(r['mean_lucerna'], 5)} ± {np.round(r['se_lucerna'], 5)}")
        print(f"  Mitsuba {np.round(r['mean_mitsuba'], 5)} ± {np.round(r['se_mitsuba'], 5)}")
        print(f"  lucerna / Mitsuba - 1 = {np.round(100 * np.array(r['difference']), 2)} % "
              f"± {np.round(100 * np.array(r['difference_se']), 2)} %")
        if args.json:
            Path(args.json).write_text(json.dumps(r, indent=1) + "\n")
        return
    r = compare(args.spp, width, height, args.scene, args.hard_spots)
    print(f"{args.scene} {width}x{height}, {args.spp} spp, box filter")
    print(f"  mean radiance   lucerna {np.round(r['mean_lucerna'], 5)}   Mitsuba {np.round(r['mean_mitsuba'], 5)}")
    print(f"  relMSE(lucerna, Mitsuba A)   = {r['relmse_lucerna_vs_mitsuba']:.6g}")
    print(f"  relMSE(Mitsuba B, Mitsuba A) = {r['relmse_mitsuba_a_vs_b']:.6g}")
    print(f"  ratio = {r['ratio']:.3f} (must be <= 2)")
    print(f"  seconds per render: lucerna {r['seconds_lucerna']:.1f}, Mitsuba {r['seconds_mitsuba']:.1f}")
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=1) + "\n")
    sys.exit(0 if r["ratio"] <= 2.0 else 1)


if __name__ == "__main__":
    main()
