#!/usr/bin/env python3
"""lucerna's deformation blur against Cycles' (Blender 5.0, pip `bpy`): one animated,
deforming mesh written twice, a glTF file with a morph target for lucerna and a Blender mesh
with a shape key for Cycles:

    BLENDER=/path/to/bpy-venv/bin/python .venv/bin/python tools/compare/cycles/deformation_blur.py \\
        [--spp 256] [--resolution 240x160] [--out tools/compare/cycles/results/deformation-blur]

An orange banner (a grid of 24 x 8 quads, 1.6 m wide, triangulated alike in both) waves:
its morph target (a shape key in Blender) lifts each column by 0.5 sin(2 pi x / 1.6) m and
pushes it 0.25 cos(2 pi x / 1.6) m towards the camera, and the target's weight goes
from -1 at frame 9 to 1 at frame 11 (linear channels; Blender keyframes set to linear). Frame
10 is rendered with a shutter of half a frame centred on it (lucerna `--frame 10 --shutter
-0.25,0.25`; Cycles motion blur on, shutter 0.5, position centre, 9 motion steps, as
lucerna's 9 keys), at 24 fps, over a grey floor under a sky and a sun. Materials are
Lambertian; both use a 1-pixel box filter.

Writes a contact sheet (lucerna | Cycles | |difference| x 4), the frozen frame beside it,
and figures.json: relMSE and luminance ratio over the image and over the pixels the motion
changes, with the noise floor (each renderer's two seeds against each other).
"""
import argparse
import math
import tempfile
from pathlib import Path


import lucerna_tools as lt
from lucerna_tools import cycles
from lucerna_tools.gltf_writer import GltfWriter, unit

FPS = 24
FLOOR = 0.4
COLOUR = (0.8, 0.25, 0.1)
SKY = 0.15
SUN = 3.0
SUN_DIRECTION = unit([0.4, -1.0, -0.5])
COLUMNS, ROWS = 24, 8
WIDTH, HEIGHT, BOTTOM = 1.6, 0.5, 0.5
LIFT, PUSH = 0.5, 0.25
WEIGHTS = (-1.0, 1.0)
KEY_FRAMES = (9, 11)
FRAME = 10
SHUTTER = (-0.25, 0.25)
VFOV = 0.6
CAMERA = (0.0, 0.8, 4.0)


def banner():
    """(positions, triangles, displacements): the grid in glTF axes (Y up), its triangles
    counter-clockwise seen from +z, and the morph target's displacement of each vertex."""
    positions, displacements, triangles = [], [], []
    for j in range(ROWS + 1):
        for i in range(COLUMNS + 1):
            x = -WIDTH / 2 + WIDTH * i / COLUMNS
            positions.append((x, BOTTOM + HEIGHT * j / ROWS, 0.0))
            phase = 2 * math.pi * x / WIDTH
            displacements.append((0.0, LIFT * math.sin(phase), PUSH * math.cos(phase)))
    for j in range(ROWS):
        for i in range(COLUMNS):
            a = j * (COLUMNS + 1) + i
            b, c, d = a + 1, a + COLUMNS + 2, a + COLUMNS + 1
            triangles += [(a, b, c), (a, c, d)]
    return positions, triangles, displacements


SCENE_SCRIPT = r'''
from bpy_extras import anim_utils

scene.render.fps = job["fps"]
scene.render.use_motion_blur = True
scene.render.motion_blur_shutter = job["shutter"][1] - job["shutter"][0]
scene.render.motion_blur_position = "CENTER"

mesh = bpy.data.meshes.new("banner")
mesh.from_pydata([blender(p) for p in job["positions"]], [], [tuple(t) for t in job["triangles"]])
obj = bpy.data.objects.new("banner", mesh)
scene.collection.objects.link(obj)
m, out = material("banner")
diffuse = m.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
diffuse.inputs["Color"].default_value = tuple(job["colour"]) + (1,)
m.node_tree.links.new(diffuse.outputs[0], out.inputs["Surface"])
obj.data.materials.append(m)
obj.cycles.motion_steps = 4  # 2^(4 - 1) + 1 = 9 steps
obj.shape_key_add(name="Basis")
wave = obj.shape_key_add(name="wave")
for point, p, d in zip(wave.data, job["positions"], job["displacements"]):
    point.co = blender([a + b for a, b in zip(p, d)])
wave.slider_min, wave.slider_max = -1.0, 1.0
for frame, weight in zip(job["key_frames"], job["weights"]):
    wave.value = weight
    wave.keyframe_insert("value", frame=frame)
keys = mesh.shape_keys.animation_data
bag = anim_utils.action_get_channelbag_for_slot(keys.action, keys.action_slot)
for curve in bag.fcurves:
    for key in curve.keyframe_points:
        key.interpolation = "LINEAR"
grey_floor(20.0, 0.0, job["floor"])
sun(job["sun_direction"], job["sun"])
camera(job["camera"], job["vfov"])
scene.frame_set(job["frame"])
'''


def write_gltf(path, width, height, positions, triangles, displacements):
    w = GltfWriter("lucerna tools/compare/cycles/deformation_blur.py")
    floor = w.material("floor", base=(FLOOR,) * 3, extras={"lucerna": {"bsdf": "lambert"}})
    w.node(name="floor", mesh=w.mesh("floor", [(-20, 0, -20), (-20, 0, 20), (20, 0, 20), (20, 0, -20)],
                                     [(0, 1, 2), (0, 2, 3)], floor))
    orange = w.material("orange", base=COLOUR, extras={"lucerna": {"bsdf": "lambert"}})
    node = w.node(name="banner", mesh=w.mesh("banner", positions, triangles, orange,
                                             targets=[displacements]))
    times = w.accessor([f / FPS for f in KEY_FRAMES], "SCALAR")
    weights = w.accessor(list(WEIGHTS), "SCALAR")
    w._list("animations", {
        "name": "wave",
        "samplers": [{"input": times, "output": weights, "interpolation": "LINEAR"}],
        "channels": [{"sampler": 0, "target": {"node": node, "path": "weights"}}]})
    w.sun(SUN_DIRECTION, SUN)
    w.camera("camera", VFOV, width / height, CAMERA, (CAMERA[0], CAMERA[1], CAMERA[2] - 1.0))
    w.write_gltf(path)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--resolution", default="240x160")
    parser.add_argument("--out", default=str(lt.ROOT / "tools" / "compare" / "cycles" / "results"
                                             / "deformation-blur"))
    args = parser.parse_args()
    width, height = map(int, args.resolution.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    shutter = f"{SHUTTER[0]},{SHUTTER[1]}"
    positions, triangles, displacements = banner()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        gltf = work / "deformation.gltf"
        write_gltf(gltf, width, height, positions, triangles, displacements)
        ours, ours_b, frozen, header = cycles.lucerna_blur_renders(
            gltf, work, (width, height), args.spp, SKY, FRAME, FPS, shutter)
        job = {"width": width, "height": height, "spp": args.spp, "sky": SKY, "floor": FLOOR,
               "colour": COLOUR, "sun": SUN, "sun_direction": SUN_DIRECTION,
               "positions": positions, "triangles": triangles, "displacements": displacements,
               "weights": WEIGHTS, "key_frames": KEY_FRAMES, "frame": FRAME, "shutter": SHUTTER,
               "fps": FPS, "vfov": VFOV, "camera": CAMERA}
        cycles_a, cycles_b = (cycles.render(work, "deformation_blur", SCENE_SCRIPT, job, seed)
                              for seed in (1, 2))
    cycles.blur_figures(ours, ours_b, frozen, cycles_a, cycles_b, header, args.spp, out,
                        "deformation-blur.png")


if __name__ == "__main__":
    main()
