#!/usr/bin/env python3
"""lucerna's emitting participating media against Cycles' volume emission (Blender 5.0,
pip `bpy`): one scene written twice, a glTF file for lucerna (an interface cube holding a
medium given by `extras.lucerna.medium`: absorption, scattering, anisotropy, emission per
metre) and a Blender scene built with `bpy` for Cycles (the same cube with no surface
shader and a volume shader that adds Volume Absorption, Volume Scatter and Emission):

    BLENDER=/path/to/bpy-venv/bin/python .venv/bin/python tools/compare/cycles/emissive_medium.py \\
        [--spp 256] [--resolution 192x144] [--out tools/compare/cycles/results/emissive-medium]

A 1.2 m cube of glowing, absorbing, scattering medium (chromatic: see ABSORPTION,
SCATTERING, EMISSION) floating 2 cm above a 40 m Lambertian grey floor under a dim uniform sky,
seen from 5 m; the medium's light reaches the camera directly and by the floor. The
coefficients map to Cycles' nodes exactly: Volume Absorption of density D and colour C
absorbs D (1 - C) per metre, Volume Scatter of density D and colour C scatters D C, and an
Emission shader of colour E and strength 1 in a volume emits E per metre (Cycles'
`volume_emission_integrate`: E (1 - T) / σt over a segment, lucerna's `Medium::emitted`).
Cycles: every bounce limit 1024, no clamping, no denoiser, a 1-pixel box filter, Standard
view, linear EXR. Writes a contact sheet (lucerna | Cycles | |difference| x 4) and
figures.json: relMSE and luminance ratio over the image and over the cube's pixels, and
the same between two Cycles seeds and two lucerna seeds (the noise floor).
"""
import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

import lucerna_tools as lt
from lucerna_tools import cycles
from lucerna_tools.gltf_writer import GltfWriter, box

ABSORPTION = (1.5, 1.0, 0.6)
SCATTERING = (0.8, 1.2, 2.0)
EMISSION = (3.0, 1.2, 0.3)
ANISOTROPY = 0.3
FLOOR = 0.5
SKY = 0.2
HALF = 0.6  # the cube's half side, metres
LIFT = 0.02  # the cube floats this far above the floor (no coplanar faces)
VFOV = 0.5  # radians
CAMERA = (0.0, 1.0, 5.0)  # glTF (Y up), looking down -Z

SCENE_SCRIPT = r'''
half = job["half"]
bpy.ops.mesh.primitive_cube_add(size=2 * half, location=(0, 0, half + job["lift"]))
cube = bpy.context.active_object
glow, out = material("glow")
nodes, links = glow.node_tree.nodes, glow.node_tree.links
absorb = nodes.new("ShaderNodeVolumeAbsorption")
sa = job["absorption"]
absorb.inputs["Density"].default_value = max(sa)
absorb.inputs["Color"].default_value = tuple(1 - s / max(sa) for s in sa) + (1,)
scatter = nodes.new("ShaderNodeVolumeScatter")
ss = job["scattering"]
scatter.inputs["Density"].default_value = max(ss)
scatter.inputs["Color"].default_value = tuple(s / max(ss) for s in ss) + (1,)
scatter.inputs["Anisotropy"].default_value = job["anisotropy"]
emit = nodes.new("ShaderNodeEmission")
emit.inputs["Color"].default_value = tuple(job["emission"]) + (1,)
emit.inputs["Strength"].default_value = 1.0
add1 = nodes.new("ShaderNodeAddShader")
add2 = nodes.new("ShaderNodeAddShader")
links.new(absorb.outputs[0], add1.inputs[0])
links.new(scatter.outputs[0], add1.inputs[1])
links.new(add1.outputs[0], add2.inputs[0])
links.new(emit.outputs[0], add2.inputs[1])
links.new(add2.outputs[0], out.inputs["Volume"])
cube.data.materials.append(glow)
grey_floor(20.0, 0.0, job["floor"])
camera(job["camera"], job["vfov"])
'''


def write_gltf(path, width, height):
    w = GltfWriter("lucerna tools/compare/cycles/emissive_medium.py")
    floor = w.material("floor", base=(FLOOR,) * 3, extras={"lucerna": {"bsdf": "lambert"}})
    w.node(name="floor", mesh=w.mesh("floor", [(-20, 0, -20), (-20, 0, 20), (20, 0, 20), (20, 0, -20)],
                                     [(0, 1, 2), (0, 2, 3)], floor))
    glow = w.material("glow", extras={"lucerna": {"bsdf": "interface", "medium": {
        "absorption": list(ABSORPTION), "scattering": list(SCATTERING), "anisotropy": ANISOTROPY,
        "emission": list(EMISSION)}}})
    positions, triangles = box((-HALF, LIFT, -HALF), (HALF, LIFT + 2 * HALF, HALF))
    w.node(name="glow", mesh=w.mesh("glow", positions, triangles, glow))
    cam = w._list("cameras", {"name": "camera", "type": "perspective",
                              "perspective": {"yfov": VFOV, "aspectRatio": width / height, "znear": 0.01}})
    w.node(name="camera", camera=cam, translation=list(CAMERA))
    w.write_gltf(path)


def cube_mask(width, height):
    """Pixels whose centre ray hits the cube."""
    d = lt.pinhole_directions(width, height, VFOV)
    o = np.array(CAMERA)
    lo, hi = np.array([-HALF, LIFT, -HALF]), np.array([HALF, LIFT + 2 * HALF, HALF])
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = (lo - o) / d, (hi - o) / d
    near = np.nanmax(np.minimum(a, b), -1)
    far = np.nanmin(np.maximum(a, b), -1)
    return (near < far) & (far > 0)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--resolution", default="192x144")
    parser.add_argument("--out", default=str(lt.ROOT / "tools" / "compare" / "cycles" / "results" / "emissive-medium"))
    args = parser.parse_args()
    width, height = map(int, args.resolution.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        gltf = work / "glow.gltf"
        write_gltf(gltf, width, height)
        ours, ours_b, header = cycles.lucerna_seeds(gltf, work, (width, height), args.spp, SKY)
        job = {"width": width, "height": height, "spp": args.spp, "sky": SKY, "absorption": ABSORPTION,
               "scattering": SCATTERING, "emission": EMISSION, "anisotropy": ANISOTROPY, "floor": FLOOR,
               "half": HALF, "lift": LIFT, "vfov": VFOV, "camera": CAMERA}
        cycles_a, cycles_b = (cycles.render(work, "emissive_medium", SCENE_SCRIPT, job, seed) for seed in (1, 2))
    cube = cube_mask(width, height)
    figures = {"spp": args.spp, "resolution": [width, height]}
    figures.update(cycles.figures(ours, ours_b, cycles_a, cycles_b, {"image": np.ones_like(cube), "cube": cube}))
    figures["seconds_lucerna"] = header["lucerna/render_seconds"]
    (out / "figures.json").write_text(json.dumps(figures, indent=1) + "\n")
    print(json.dumps(figures, indent=1))
    lt.difference_sheet(ours, cycles_a, out / "cube.png")


if __name__ == "__main__":
    main()
