"""Renders a glTF file with Cycles inside Blender, as tools/compare/cycles/compare.py asks:

    blender -b --factory-startup --python blender_render.py -- job.json

job.json: {"gltf", "out" (an OpenEXR path), "width", "height", "spp", "seed",
"camera": {"matrix": 16 numbers, column-major, glTF world space, "yfov": radians},
"environment": [r, g, b], "sun": {"direction": glTF world, "irradiance": W/m^2} or null,
"model": "imported" or "gltf"}.

"imported" renders what Blender's importer makes of the file. "gltf" then changes the
four things in which the imported materials depart from the glTF specification's model
where the difference is a choice of the importer or of Cycles rather than a feature Cycles
lacks:

- every Principled BSDF uses single-scattering GGX, the specification's BRDF and lucerna's
  (Cycles defaults to multiple-scattering GGX, which adds the energy that single scattering
  loses on rough surfaces);
- volume absorption is glTF's Beer-Lambert coefficient -ln(attenuationColor) /
  attenuationDistance (the importer's Volume Absorption node computes density x (1 -
  colour), which agrees only for colours near white);
- a fully transmissive material (Transmission Weight 1, not textured) has its base colour
  squared: glTF tints light by the base colour at every boundary it crosses (through a
  closed object twice), while Cycles' Principled BSDF tints by its square root, so that a
  closed object is tinted once;
- KHR_materials_iridescence, which the importer ignores, becomes the Principled BSDF's
  thin film: its index, and the middle of the thickness range (the thickness texture is
  not read; a `.glb` file's materials are left as imported).

Settings chosen to render what lucerna renders: the glTF importer's COMPAT light units
(candela read as W/sr), the world a constant colour, a sun of that irradiance (Cycles' sun
strength is irradiance), every bounce limit 1024 (roulette ends paths, as in lucerna), no
clamping, no glossy filter, caustics on, no denoiser, no adaptive sampling, a
Blackman-Harris pixel filter 1.5 pixels wide, the Standard view transform, linear float
EXR output.
"""
import json
import math
import sys

import numpy as np

# Debian's numpy 1.24 removed the alias Blender 3.4's glTF importer still uses.
if "bool" not in np.__dict__:
    np.bool = bool

import bpy  # noqa: E402
from mathutils import Matrix, Vector  # noqa: E402

job = json.load(open(sys.argv[sys.argv.index("--") + 1]))
print("cycles_compare: Blender", bpy.app.version_string, flush=True)

bpy.ops.wm.read_factory_settings(use_empty=True)
# The light-unit option was renamed in Blender 3.6.
lighting = ("export_import_convert_lighting_mode" if bpy.app.version >= (3, 6, 0)
            else "convert_lighting_mode")
bpy.ops.import_scene.gltf(filepath=job["gltf"], **{lighting: "COMPAT"})
scene = bpy.context.scene


def gltf_model():
    """The "gltf" model: see the module doc."""
    iridescence = {}
    if job["gltf"].endswith(".gltf"):
        for m in json.load(open(job["gltf"])).get("materials", []):
            film = m.get("extensions", {}).get("KHR_materials_iridescence")
            if film and film.get("iridescenceFactor", 0.0) > 0.0:
                thickness = (film.get("iridescenceThicknessMinimum", 100.0)
                             + film.get("iridescenceThicknessMaximum", 400.0)) / 2
                if "iridescenceThicknessTexture" not in film:
                    thickness = film.get("iridescenceThicknessMaximum", 400.0)
                iridescence[m.get("name")] = (thickness, film.get("iridescenceIor", 1.3))
    for material in bpy.data.materials:
        if not material.node_tree:
            continue
        tree = material.node_tree
        for node in list(tree.nodes):
            if node.type == "BSDF_PRINCIPLED":
                node.distribution = "GGX"
                if material.name in iridescence:
                    thickness, ior = iridescence[material.name]
                    node.inputs["Thin Film Thickness"].default_value = thickness
                    node.inputs["Thin Film IOR"].default_value = ior
                weight = node.inputs["Transmission Weight"]
                if weight.is_linked or weight.default_value < 1.0:
                    continue
                base = node.inputs["Base Color"]
                if base.is_linked:
                    source = base.links[0].from_socket
                    square = tree.nodes.new("ShaderNodeMix")
                    square.data_type = "RGBA"
                    square.blend_type = "MULTIPLY"
                    square.inputs["Factor"].default_value = 1.0
                    # The colour sockets (the node has a float, vector and colour A and B).
                    tree.links.new(source, square.inputs[6])
                    tree.links.new(source, square.inputs[7])
                    tree.links.new(square.outputs[2], base)
                else:
                    c = base.default_value
                    base.default_value = (c[0] ** 2, c[1] ** 2, c[2] ** 2, c[3])
            elif node.type == "VOLUME_ABSORPTION":
                colour = list(node.inputs["Color"].default_value)[:3]
                density = node.inputs["Density"].default_value
                sigma = [-math.log(min(max(c, 1e-6), 1.0)) * density for c in colour]
                top = max(sigma)
                if top > 0.0:
                    node.inputs["Color"].default_value = (*[1.0 - x / top for x in sigma], 1.0)
                    node.inputs["Density"].default_value = top


def diffuse_roughness():
    """lucerna's `extras.lucerna.diffuse_roughness` (glTF has no diffuse roughness; the
    importer ignores extras) as the Principled BSDF's Diffuse Roughness, whose model is the
    same (OpenPBR's EON), in both modes. A `.glb` file's materials are left as imported."""
    if not job["gltf"].endswith(".gltf"):
        return
    roughness = {m.get("name"): m["extras"]["lucerna"]["diffuse_roughness"]
                 for m in json.load(open(job["gltf"])).get("materials", [])
                 if "diffuse_roughness" in m.get("extras", {}).get("lucerna", {})}
    for material in bpy.data.materials:
        if material.node_tree and material.name in roughness:
            for node in material.node_tree.nodes:
                if node.type == "BSDF_PRINCIPLED":
                    node.inputs["Diffuse Roughness"].default_value = roughness[material.name]


diffuse_roughness()
if job.get("model", "imported") == "gltf":
    gltf_model()
for obj in [o for o in scene.objects if o.type == "CAMERA"]:
    bpy.data.objects.remove(obj, do_unlink=True)

# glTF's Y-up world to Blender's Z-up one: (x, y, z) -> (x, -z, y). Cameras look down their
# local -Z with +Y up in both, so a camera's Blender matrix is the axis change times its glTF
# matrix.
TO_BLENDER = Matrix(((1, 0, 0, 0), (0, 0, -1, 0), (0, 1, 0, 0), (0, 0, 0, 1)))
gltf_matrix = Matrix([job["camera"]["matrix"][i::4] for i in range(4)])
camera_data = bpy.data.cameras.new("compare")
camera_data.sensor_fit = "VERTICAL"
camera_data.angle_y = job["camera"]["yfov"]
camera_data.clip_start = 1e-3
camera_data.clip_end = 1e6
camera = bpy.data.objects.new("compare", camera_data)
scene.collection.objects.link(camera)
camera.matrix_world = TO_BLENDER @ gltf_matrix
scene.camera = camera

world = bpy.data.worlds.new("compare")
world.use_nodes = True
background = world.node_tree.nodes["Background"]
background.inputs["Color"].default_value = (*job["environment"], 1.0)
background.inputs["Strength"].default_value = 1.0
scene.world = world

if job.get("sun"):
    sun_data = bpy.data.lights.new("sun", "SUN")
    sun_data.energy = job["sun"]["irradiance"]
    sun_data.angle = 0.0
    sun = bpy.data.objects.new("sun", sun_data)
    scene.collection.objects.link(sun)
    d = job["sun"]["direction"]
    direction = (TO_BLENDER.to_3x3() @ Vector(d)).normalized()
    # A sun shines down its local -Z.
    sun.rotation_mode = "QUATERNION"
    sun.rotation_quaternion = (-direction).to_track_quat("Z", "Y")

render = scene.render
render.engine = "CYCLES"
render.resolution_x, render.resolution_y = job["width"], job["height"]
render.resolution_percentage = 100
render.filter_size = 1.5
render.film_transparent = False
render.image_settings.file_format = "OPEN_EXR"
render.image_settings.color_depth = "32"
render.image_settings.color_mode = "RGBA"
scene.view_settings.view_transform = "Standard"
scene.view_settings.look = "None"
scene.view_settings.exposure = 0.0
cycles = scene.cycles
cycles.device = "CPU"
cycles.samples = job["spp"]
cycles.seed = job.get("seed", 0)
cycles.use_adaptive_sampling = False
cycles.use_denoising = False
cycles.pixel_filter_type = "BLACKMAN_HARRIS"
cycles.filter_width = 1.5
for bounces in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
                "volume_bounces", "transparent_max_bounces"):
    setattr(cycles, bounces, 1024)
cycles.sample_clamp_direct = 0.0
cycles.sample_clamp_indirect = 0.0
cycles.blur_glossy = 0.0
cycles.caustics_reflective = True
cycles.caustics_refractive = True
render.threads_mode = "AUTO"
render.filepath = job["out"]
bpy.ops.render.render(write_still=True)
print("cycles_compare: rendered", job["out"], flush=True)
