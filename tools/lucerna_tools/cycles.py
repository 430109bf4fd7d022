"""Blender's Cycles as a peer (pip `bpy`, Blender 5.0): what the comparisons of
tools/compare/cycles share. A comparison writes the part of a Blender script that builds
its scene; `render` runs it between a common beginning (Cycles on the CPU, fixed samples and
seed, no adaptive sampling, denoiser or clamping, bounce limits of 1024, a 1-pixel box
filter unless `box_filter` is false, the Standard view, a linear 32-bit EXR, a uniform world
of radiance `sky`; helpers `material`, `grey_floor`, `blender` (glTF's Y up to Blender's Z
up), `sun`, `camera`) and the render call, with
the job's values in `job`. `figures` compares two seeds of each renderer."""

import json
import os
import subprocess
import sys

import numpy as np

import lucerna_tools as lt

PRELUDE = r'''
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
if job.get("box_filter", True):
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


def material(name):
    """A new material with no nodes but its output: (material, output node)."""
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    for n in list(m.node_tree.nodes):
        m.node_tree.nodes.remove(n)
    return m, m.node_tree.nodes.new("ShaderNodeOutputMaterial")


def grey_floor(half, height, albedo):
    """A Lambertian floor of `albedo`, 2 `half` wide, at glTF height `height`."""
    bpy.ops.mesh.primitive_plane_add(size=2 * half, location=(0, 0, height))
    floor = bpy.context.active_object
    grey, out = material("floor")
    diffuse = grey.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (albedo,) * 3 + (1,)
    grey.node_tree.links.new(diffuse.outputs[0], out.inputs["Surface"])
    floor.data.materials.append(grey)


def blender(p):
    """A glTF point or direction (Y up) in Blender's Z-up coordinates."""
    return (p[0], -p[2], p[1])


def sun(direction, irradiance):
    """A sun (no angle) shining along glTF `direction` with `irradiance`, which is Cycles'
    sun strength, as a glTF directional light of that many lux."""
    from mathutils import Vector

    data = bpy.data.lights.new("sun", "SUN")
    data.energy = irradiance
    data.angle = 0.0
    obj = bpy.data.objects.new("sun", data)
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = Vector(blender(direction)).to_track_quat("-Z", "Y")
    scene.collection.objects.link(obj)


def camera(position, vfov, near=None):
    """The scene's camera at glTF `position` (Y up) looking down -Z, in Blender's Z up."""
    data = bpy.data.cameras.new("cam")
    data.sensor_fit = "VERTICAL"
    data.angle_y = vfov
    if near is not None:
        data.clip_start = near
        data.clip_end = 1e5
    cam = bpy.data.objects.new("cam", data)
    x, y, z = position
    cam.location = (x, -z, y)
    cam.rotation_euler = (math.pi / 2, 0, 0)
    scene.collection.objects.link(cam)
    scene.camera = cam
'''

FINISH = r'''
scene.render.filepath = job["out"]
bpy.ops.render.render(write_still=True)
'''


def render(work, name, scene_script, job, seed):
    """Cycles' render (RGB, linear) of `scene_script` with `job` (width, height, spp, sky and
    the script's own values) and `seed`, in folder `work`; the Blender is $BLENDER."""
    job = dict(job, seed=seed, out=str(work / f"cycles_{seed}.exr"))
    (work / "job.json").write_text(json.dumps(job))
    script = work / f"blender_{name}.py"
    script.write_text(PRELUDE + scene_script + FINISH)
    blender = os.environ.get("BLENDER", "blender")
    proc = subprocess.run([blender, str(script), str(work / "job.json")], capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"blender failed: {proc.stdout[-2000:]} {proc.stderr[-2000:]}")
    channels, _ = lt.read_exr(job["out"])
    return lt.rgb(channels)


def lucerna_seeds(scene, work, resolution, spp, sky):
    """lucerna's two renders of `scene` that a comparison holds against Cycles' two: seeds 1
    and 2, a 1-pixel box filter (as the Cycles prelude's), a uniform sky of radiance `sky`;
    in folder `work`. Returns (seed 1 image, seed 2 image, seed 1 header)."""
    env = ",".join([str(sky)] * 3)
    ours, header, _ = lt.render(scene, work / "a.exr", resolution, spp=spp, seed=1, filter="box", env=env)
    ours_b, _, _ = lt.render(scene, work / "b.exr", resolution, spp=spp, seed=2, filter="box", env=env)
    return ours, ours_b, header


LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def relmse(x, reference, mask):
    return float(np.mean((x[mask] - reference[mask]) ** 2 / (reference[mask] ** 2 + 0.01)))


def figures(ours, ours_b, cycles_a, cycles_b, regions):
    """For each region (name: pixel mask): the luminance and channel ratios of both seeds of
    each renderer, the relMSE of lucerna's first seed against Cycles' and the noise floor
    (the mean of each renderer's relMSE between its two seeds)."""
    lum = lambda img, m: float((img[m] @ LUMINANCE).mean())  # noqa: E731
    return {name: {
        "luminance_ratio": (lum(ours, m) + lum(ours_b, m)) / (lum(cycles_a, m) + lum(cycles_b, m)),
        "channel_ratio": ((ours[m] + ours_b[m]).mean(0) / (cycles_a[m] + cycles_b[m]).mean(0)).tolist(),
        "relmse_lucerna_vs_cycles": relmse(ours, cycles_a, m),
        "noise_floor": (relmse(cycles_b, cycles_a, m) + relmse(ours_b, ours, m)) / 2}
        for name, m in regions.items()}


def lucerna_blur_renders(scene, work, resolution, spp, sky, frame, fps, shutter):
    """lucerna's renders for a motion blur comparison: seeds 1 and 2 with the shutter
    `shutter` (OPEN,CLOSE in frames) open at `frame`, and seed 3 without blur (the frozen
    frame), each with a 1-pixel box filter and a sky of radiance `sky`. Returns (seed 1,
    seed 2, frozen, seed 1 header)."""
    common = dict(spp=spp, filter="box", env=",".join([str(sky)] * 3), frame=frame, fps=fps)
    ours, header, _ = lt.render(scene, work / "a.exr", resolution, seed=1, shutter=shutter, **common)
    ours_b, _, _ = lt.render(scene, work / "b.exr", resolution, seed=2, shutter=shutter, **common)
    frozen, _, _ = lt.render(scene, work / "frozen.exr", resolution, seed=3, **common)
    return ours, ours_b, frozen, header


def blur_figures(ours, ours_b, frozen, cycles_a, cycles_b, header, spp, out, sheet):
    """A motion blur comparison's figures (`figures` over the image and over the pixels the
    motion changes: where lucerna's blurred frame differs from its frozen one), written to
    `out`/figures.json and printed, and its contact sheets: `sheet` (lucerna | Cycles) and
    blurred-and-frozen.png (lucerna blurred | frozen)."""
    moving = np.abs(ours - frozen).max(axis=-1) > 0.05
    height, width = moving.shape
    result = {"spp": spp, "resolution": [width, height], "moving_pixels": int(moving.sum())}
    result.update(figures(ours, ours_b, cycles_a, cycles_b,
                          {"image": np.ones(moving.shape, bool), "moving": moving}))
    result["seconds_lucerna"] = header["lucerna/render_seconds"]
    (out / "figures.json").write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result, indent=1))
    lt.difference_sheet(ours, cycles_a, out / sheet)
    lt.difference_sheet(ours, frozen, out / "blurred-and-frozen.png")
