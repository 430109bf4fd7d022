#!/usr/bin/env python3
"""lucerna against Mitsuba 3 on the participating-media scenes of scenes/media
(tools/generate/media_scenes.py): a contact sheet per scene (lucerna | Mitsuba | |difference|
x 10, tonemapped) and the figures: relMSE of lucerna against Mitsuba seed A beside relMSE of
Mitsuba seed B against seed A (the noise floor), and the luminance ratio of the images.
Mitsuba renders the scene lucerna renders (tools/lucerna_tools/mitsuba_export.py: `volpath`,
`volpathmis` for chromatic media), spot lights hard-edged in both.

    .venv/bin/python tools/compare/media/compare.py [--spp 512] [--resolution 192x192] [--scenes NAME ...] [--out DIR]

writes DIR/<scene>.png and DIR/figures.json (default tools/compare/media/results).
"""
import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

import lucerna_tools as lt
from lucerna_tools import mitsuba_compare as mc
from lucerna_tools import mitsuba_export

SCENES = ["fog-spot", "chromatic-cube", "scattering-glass", "smoke-plume", "chromatic-smoke"]


def tonemap(x):
    return np.clip((np.maximum(x, 0) / (1 + np.maximum(x, 0))) ** (1 / 2.2), 0, 1)


def luminance(x):
    return float((x @ np.array([0.2126, 0.7152, 0.0722])).mean())


def main():
    import mitsuba as mi
    import OpenImageIO as oiio
    mi.set_variant("scalar_rgb")
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=512)
    parser.add_argument("--resolution", default="192x192")
    parser.add_argument("--scenes", nargs="+", default=SCENES, choices=SCENES)
    parser.add_argument("--out", default=str(lt.ROOT / "tools" / "compare" / "media" / "results"))
    args = parser.parse_args()
    width, height = map(int, args.resolution.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    figures = {}
    for name in args.scenes:
        with tempfile.TemporaryDirectory() as workdir:
            scene_file = mc.scene_file_of(lt.ROOT / "scenes" / "media" / f"{name}.gltf", workdir, hard_spots=True)
            exported = mi.load_dict(mitsuba_export.scene_dict(scene_file, width, height, workdir))
            mitsuba_a, seconds_a = mc.render_mitsuba(exported, args.spp, 1)
            mitsuba_b, _ = mc.render_mitsuba(exported, args.spp, 2)
            ours, seconds = mc.render_lucerna(scene_file, args.spp, 1, width, height, workdir)
        f = {"spp": args.spp, "resolution": [width, height],
             "relmse_lucerna_vs_mitsuba": lt.relmse(ours, mitsuba_a),
             "relmse_mitsuba_b_vs_a": lt.relmse(mitsuba_b, mitsuba_a),
             "luminance_ratio": luminance(ours) / luminance(mitsuba_a),
             "seconds_lucerna": seconds, "seconds_mitsuba": seconds_a}
        figures[name] = f
        print(f"{name}: relMSE {f['relmse_lucerna_vs_mitsuba']:.5f} (Mitsuba seeds {f['relmse_mitsuba_b_vs_a']:.5f}), "
              f"luminance ratio {f['luminance_ratio']:.4f}, seconds lucerna {seconds:.1f}, Mitsuba {seconds_a:.1f}")
        sheet = np.concatenate([tonemap(ours), tonemap(mitsuba_a), np.clip(10 * np.abs(ours - mitsuba_a), 0, 1)], axis=1)
        image = oiio.ImageBuf(oiio.ImageSpec(sheet.shape[1], sheet.shape[0], 3, oiio.UINT8))
        image.set_pixels(oiio.ROI(), sheet.astype(np.float32))
        image.write(str(out / f"{name}.png"))
    (out / "figures.json").write_text(json.dumps(figures, indent=1) + "\n")


if __name__ == "__main__":
    main()
