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
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import lucerna_tools as lt
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

BLENDER_SCRIPT = r'''
import json, math, sys
import bpy
job = json.loads(open(sys.argv[-1]).read())
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.engine = "CYCLES"
c = scene.cycles
c.device = "CPU"
c.samples = job["spp"]
c.seed = job["seed"]
c.use_adaptive_sampling = False
c.use_denoising = False
for attr in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
             "volume_bounces", "transparent_max_bounces"):
    setattr(c, attr, 1024)
c.sample_clamp_direct = 0.0
c.sample_clamp_indirect = 0.0
c.pixel_filter_type = "BOX"
c.filter_width = 1.0
scene.render.resolution_x, scene.render.resolution_y = job["width"], job["height"]
scene.render.resolution_percentage = 100
scene.view_settings.view_transform = "Standard"
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
world = bpy.data.worlds.new("sky")
world.use_nodes = True
world.node_tree.nodes["Background"].inputs["Color"].default_value = (job["sky"],) * 3 + (1,)
world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
scene.world = world

half = job["half"]
bpy.ops.mesh.primitive_cube_add(size=2 * half, location=(0, 0, half + job["lift"]))
cube = bpy.context.active_object
glow = bpy.data.materials.new("glow")
glow.use_nodes = True
nodes, links = glow.node_tree.nodes, glow.node_tree.links
for n in list(nodes):
    nodes.remove(n)
out = nodes.new("ShaderNodeOutputMaterial")
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

bpy.ops.mesh.primitive_plane_add(size=40.0, location=(0, 0, 0))
floor = bpy.context.active_object
grey = bpy.data.materials.new("floor")
grey.use_nodes = True
gn = grey.node_tree.nodes
for n in list(gn):
    gn.remove(n)
diffuse = gn.new("ShaderNodeBsdfDiffuse")
diffuse.inputs["Color"].default_value = (job["floor"],) * 3 + (1,)
fout = gn.new("ShaderNodeOutputMaterial")
grey.node_tree.links.new(diffuse.outputs[0], fout.inputs["Surface"])
floor.data.materials.append(grey)

cam_data = bpy.data.cameras.new("cam")
cam_data.sensor_fit = "VERTICAL"
cam_data.angle_y = job["vfov"]
cam = bpy.data.objects.new("cam", cam_data)
x, y, z = job["camera"]
cam.location = (x, -z, y)
cam.rotation_euler = (math.pi / 2, 0, 0)
scene.collection.objects.link(cam)
scene.camera = cam
scene.render.filepath = job["out"]
bpy.ops.render.render(write_still=True)
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


def render_cycles(work, width, height, spp, seed):
    job = {"width": width, "height": height, "spp": spp, "seed": seed, "absorption": ABSORPTION,
           "scattering": SCATTERING, "emission": EMISSION, "anisotropy": ANISOTROPY, "floor": FLOOR,
           "sky": SKY, "half": HALF, "lift": LIFT, "vfov": VFOV, "camera": CAMERA, "out": str(work / f"cycles_{seed}.exr")}
    (work / "job.json").write_text(json.dumps(job))
    (work / "blender_emissive_medium.py").write_text(BLENDER_SCRIPT)
    blender = os.environ.get("BLENDER", "blender")
    proc = subprocess.run([blender, str(work / "blender_emissive_medium.py"), str(work / "job.json")],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"blender failed: {proc.stdout[-2000:]} {proc.stderr[-2000:]}")
    channels, _ = lt.read_exr(job["out"])
    return lt.rgb(channels)


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
        env = ",".join([str(SKY)] * 3)
        ours, header, _ = lt.render(gltf, work / "a.exr", (width, height), spp=args.spp, seed=1, filter="box", env=env)
        ours_b, _, _ = lt.render(gltf, work / "b.exr", (width, height), spp=args.spp, seed=2, filter="box", env=env)
        cycles_a = render_cycles(work, width, height, args.spp, 1)
        cycles_b = render_cycles(work, width, height, args.spp, 2)
    cube = cube_mask(width, height)
    everywhere = np.ones_like(cube)
    weights = np.array([0.2126, 0.7152, 0.0722])
    lum = lambda img, m: float((img[m] @ weights).mean())  # noqa: E731
    rel = lambda x, ref, m: float(np.mean((x[m] - ref[m]) ** 2 / (ref[m] ** 2 + 0.01)))  # noqa: E731
    figures = {"spp": args.spp, "resolution": [width, height]}
    for name, m in (("image", everywhere), ("cube", cube)):
        figures[name] = {
            "luminance_ratio": (lum(ours, m) + lum(ours_b, m)) / (lum(cycles_a, m) + lum(cycles_b, m)),
            "channel_ratio": ((ours[m] + ours_b[m]).mean(0) / (cycles_a[m] + cycles_b[m]).mean(0)).tolist(),
            "relmse_lucerna_vs_cycles": rel(ours, cycles_a, m),
            "noise_floor": (rel(cycles_b, cycles_a, m) + rel(ours_b, ours, m)) / 2}
    figures["seconds_lucerna"] = header["lucerna/render_seconds"]
    (out / "figures.json").write_text(json.dumps(figures, indent=1) + "\n")
    print(json.dumps(figures, indent=1))
    lt.difference_sheet(ours, cycles_a, out / "cube.png")


if __name__ == "__main__":
    main()
