#!/usr/bin/env python3
"""Render a scene (default scenes/cornell-box) with lucerna and with Mitsuba 3 (scalar_rgb)
and compare them.

The glTF is converted to lucerna's scene file (`lucerna convert`) and exported to Mitsuba from
there (tools/mitsuba_export.py): the same geometry, Lambertian and perfect GGX conductor
BSDFs, one-sided area lights, spheres and camera; both renderers use a box pixel filter and unlimited path depth. The comparison:

    relMSE(lucerna, Mitsuba)   against   relMSE(Mitsuba seed A, Mitsuba seed B)

relMSE(x, ref) = mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01). Both are
dominated by noise when the renderers agree; a bias in lucerna adds to the first only. The
check passes when the first is within 2x the second.

    .venv/bin/python tools/mitsuba_compare.py [--scene S] [--spp 1024] [--resolution 256x256] [--json out.json]

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

sys.path.insert(0, str(Path(__file__).resolve().parent))
import lucerna_tools as lt  # noqa: E402
import mitsuba_export  # noqa: E402

CORNELL = lt.ROOT / "scenes" / "cornell-box" / "cornell-box.gltf"


def render_mitsuba(scene, spp, seed):
    import mitsuba as mi
    start = time.perf_counter()
    image = np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)
    return image[:, :, :3], time.perf_counter() - start


def render_lucerna(scene, spp, seed, width, height, workdir):
    image, header, _ = lt.render(scene, Path(workdir) / f"lucerna_{seed}.exr", (width, height), spp=spp, seed=seed,
                                 filter="box", aov="beauty")
    return image, header["lucerna/render_seconds"]


def compare(spp, width, height, scene=CORNELL):
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    with tempfile.TemporaryDirectory() as workdir:
        scene_file = Path(workdir) / "scene.lucerna"
        lt.convert(scene, scene_file)
        exported = mi.load_dict(mitsuba_export.scene_dict(scene_file, width, height, workdir))
        mitsuba_a, seconds_a = render_mitsuba(exported, spp, 1)
        mitsuba_b, seconds_b = render_mitsuba(exported, spp, 2)
        lucerna_a, lucerna_seconds = render_lucerna(scene, spp, 1, width, height, workdir)
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


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=1024)
    parser.add_argument("--scene", default=str(CORNELL))
    parser.add_argument("--resolution", default="256x256", help="WxH")
    parser.add_argument("--json", help="also write the figures to this file")
    args = parser.parse_args()
    width, height = map(int, args.resolution.split("x"))
    r = compare(args.spp, width, height, args.scene)
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
