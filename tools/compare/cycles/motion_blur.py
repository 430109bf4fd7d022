#!/usr/bin/env python3
"""lucerna's transform motion blur against Cycles' (Blender 5.0, pip `bpy`): one animated
scene written twice, a glTF file for lucerna and a Blender scene built with `bpy` for
Cycles:

    BLENDER=/path/to/bpy-venv/bin/python .venv/bin/python tools/compare/cycles/motion_blur.py \\
        [--spp 256] [--resolution 240x160] [--out tools/compare/cycles/results/motion-blur]

An orange box slides 2 m a frame to the right and a blue blade (1.2 m wide) turns 60
degrees a frame about the vertical, on a grey floor under a sky and a sun; both keyed at frames 9
and 11 with linear interpolation (glTF LINEAR channels; Blender keyframes set to linear
interpolation, as they are inserted as Bezier, the blade's turn an Euler angle about one
axis, which is glTF's slerp). Frame
10 is rendered with a shutter of half a frame centred on it (lucerna `--frame 10
--shutter -0.25,0.25`; Cycles motion blur on, shutter 0.5, position centre, 9 motion steps
for both objects, as lucerna's 9 keys), at 24 fps. Materials are Lambertian (Cycles'
Diffuse BSDF; glTF with `extras.lucerna.bsdf = lambert`). Both use a 1-pixel box filter.

Writes a contact sheet (lucerna | Cycles | |difference| x 4), the frozen frame beside it,
and figures.json: relMSE and luminance ratio over the image and over the pixels the motion
changes (where lucerna's blurred frame differs from its frame rendered without blur), with
the noise floor (each renderer's two seeds against each other).
"""
import argparse
import math
import tempfile
from pathlib import Path

import numpy as np

import lucerna_tools as lt
from lucerna_tools import cycles
from lucerna_tools.gltf_writer import GltfWriter, box, unit

FPS = 24
FLOOR = 0.4
SLIDER_COLOUR = (0.8, 0.25, 0.1)
BLADE_COLOUR = (0.1, 0.3, 0.8)
SKY = 0.15
SUN = 3.0
SUN_DIRECTION = unit([0.4, -1.0, -0.5])
SLIDER = {"lo": (-0.3, 0.0, -0.3), "hi": (0.3, 0.6, 0.3), "z": 0.9, "x": (-2.0, 2.0)}
BLADE = {"lo": (-0.6, 0.0, -0.05), "hi": (0.6, 1.0, 0.05), "at": (0.0, 0.0, -0.8),
         "angle": (-60.0, 60.0)}
KEY_FRAMES = (9, 11)
FRAME = 10
SHUTTER = (-0.25, 0.25)
VFOV = 0.6
CAMERA = (0.0, 0.8, 4.5)

SCENE_SCRIPT = r'''
from bpy_extras import anim_utils

scene.render.fps = job["fps"]
scene.render.use_motion_blur = True
scene.render.motion_blur_shutter = job["shutter"][1] - job["shutter"][0]
scene.render.motion_blur_position = "CENTER"


def coloured_box(name, lo, hi, colour):
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    corners = [blender((x, y, z)) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(corners, [], faces)
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    m, out = material(name)
    diffuse = m.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = tuple(colour) + (1,)
    m.node_tree.links.new(diffuse.outputs[0], out.inputs["Surface"])
    obj.data.materials.append(m)
    if hasattr(obj, "cycles") and hasattr(obj.cycles, "motion_steps"):
        obj.cycles.motion_steps = 4  # 2^(4 - 1) + 1 = 9 steps
    return obj


slider = coloured_box("slider", job["slider"]["lo"], job["slider"]["hi"], job["slider_colour"])
for frame, x in zip(job["key_frames"], job["slider"]["x"]):
    slider.location = blender((x, 0.0, job["slider"]["z"]))
    slider.keyframe_insert("location", frame=frame)
blade = coloured_box("blade", job["blade"]["lo"], job["blade"]["hi"], job["blade_colour"])
blade.location = blender(job["blade"]["at"])
for frame, angle in zip(job["key_frames"], job["blade"]["angle"]):
    blade.rotation_euler = (0.0, 0.0, math.radians(angle))
    blade.keyframe_insert("rotation_euler", frame=frame)
# Keys are inserted as Bezier; linear, as glTF's LINEAR channels.
for obj in (slider, blade):
    bag = anim_utils.action_get_channelbag_for_slot(obj.animation_data.action,
                                                    obj.animation_data.action_slot)
    for curve in bag.fcurves:
        for key in curve.keyframe_points:
            key.interpolation = "LINEAR"
grey_floor(20.0, 0.0, job["floor"])
sun(job["sun_direction"], job["sun"])
camera(job["camera"], job["vfov"])
scene.frame_set(job["frame"])
'''


def write_gltf(path, width, height):
    w = GltfWriter("lucerna tools/compare/cycles/motion_blur.py")
    floor = w.material("floor", base=(FLOOR,) * 3, extras={"lucerna": {"bsdf": "lambert"}})
    w.node(name="floor", mesh=w.mesh("floor", [(-20, 0, -20), (-20, 0, 20), (20, 0, 20), (20, 0, -20)],
                                     [(0, 1, 2), (0, 2, 3)], floor))
    orange = w.material("orange", base=SLIDER_COLOUR, extras={"lucerna": {"bsdf": "lambert"}})
    blue = w.material("blue", base=BLADE_COLOUR, extras={"lucerna": {"bsdf": "lambert"}})
    slider = w.node(name="slider", mesh=w.mesh("slider", *box(SLIDER["lo"], SLIDER["hi"]), orange),
                    translation=[SLIDER["x"][0], 0.0, SLIDER["z"]])
    blade = w.node(name="blade", mesh=w.mesh("blade", *box(BLADE["lo"], BLADE["hi"]), blue),
                   translation=list(BLADE["at"]))
    times = w.accessor([f / FPS for f in KEY_FRAMES], "SCALAR")
    slides = w.accessor([(x, 0.0, SLIDER["z"]) for x in SLIDER["x"]], "VEC3")
    turns = w.accessor([(0.0, math.sin(math.radians(a) / 2), 0.0, math.cos(math.radians(a) / 2))
                        for a in BLADE["angle"]], "VEC4")
    w._list("animations", {
        "name": "motion",
        "samplers": [{"input": times, "output": slides, "interpolation": "LINEAR"},
                     {"input": times, "output": turns, "interpolation": "LINEAR"}],
        "channels": [{"sampler": 0, "target": {"node": slider, "path": "translation"}},
                     {"sampler": 1, "target": {"node": blade, "path": "rotation"}}]})
    w.sun(SUN_DIRECTION, SUN)
    w.camera("camera", VFOV, width / height, CAMERA, (CAMERA[0], CAMERA[1], CAMERA[2] - 1.0))
    w.write_gltf(path)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--resolution", default="240x160")
    parser.add_argument("--out", default=str(lt.ROOT / "tools" / "compare" / "cycles" / "results"
                                             / "motion-blur"))
    parser.add_argument("--keep", type=Path, help="also write the renders here (renders.npz)")
    args = parser.parse_args()
    width, height = map(int, args.resolution.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    shutter = f"{SHUTTER[0]},{SHUTTER[1]}"
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        gltf = work / "motion.gltf"
        write_gltf(gltf, width, height)
        ours, ours_b, frozen, header = cycles.lucerna_blur_renders(
            gltf, work, (width, height), args.spp, SKY, FRAME, FPS, shutter)
        job = {"width": width, "height": height, "spp": args.spp, "sky": SKY, "floor": FLOOR,
               "slider_colour": SLIDER_COLOUR, "blade_colour": BLADE_COLOUR, "sun": SUN, "sun_direction": SUN_DIRECTION, "slider": SLIDER,
               "blade": BLADE, "key_frames": KEY_FRAMES, "frame": FRAME, "shutter": SHUTTER,
               "fps": FPS, "vfov": VFOV, "camera": CAMERA}
        cycles_a, cycles_b = (cycles.render(work, "motion_blur", SCENE_SCRIPT, job, seed)
                              for seed in (1, 2))
    if args.keep:
        np.savez(args.keep / "renders.npz", ours=ours, ours_b=ours_b, frozen=frozen,
                 cycles_a=cycles_a, cycles_b=cycles_b)
    cycles.blur_figures(ours, ours_b, frozen, cycles_a, cycles_b, header, args.spp, out,
                        "motion-blur.png")


if __name__ == "__main__":
    main()
