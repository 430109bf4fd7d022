#!/usr/bin/env python3
"""lucerna's KHR_materials_diffuse_transmission against Cycles' Translucent BSDF (Blender
5.0, pip `bpy`): one scene written twice, a glTF file for lucerna and a Blender scene built
with `bpy` for Cycles:

    BLENDER=/path/to/bpy-venv/bin/python .venv/bin/python tools/compare/cycles/diffuse_transmission.py \\
        [--spp 256] [--resolution 200x150] [--out tools/compare/cycles/results/diffuse-transmission]

A leaf-green panel (1.4 x 1.2 m) and a thin spherical lampshade (radius 0.6 m), both thin
walls whose diffuse base transmits part of what it does not reflect, stand on a grey floor
under a dim sky and a sun shining from behind them towards the camera: what the camera sees
of them is mostly light that crossed them. The materials have KHR_materials_specular
specularFactor 0, so the extension's BSDF is exactly
`mix(diffuse_brdf(base), diffuse_btdf(colour), factor)`, which is Cycles' Mix Shader of a
Diffuse BSDF and a Translucent BSDF by the same factor. glTF's directional light of
intensity E lux is irradiance E, as Cycles' sun of strength E. Cycles: every bounce limit
1024, no clamping, no denoiser, a 1-pixel box filter, Standard view, linear EXR. Writes a
contact sheet (lucerna | Cycles | |difference| x 4) and figures.json: relMSE and luminance
ratio over the image, the panel's and the shade's pixels, and the same between two seeds of
each renderer (the noise floor).
"""
import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

import lucerna_tools as lt
from lucerna_tools import cycles
from lucerna_tools.gltf_writer import GltfWriter, unit

FLOOR = 0.5
SKY = 0.1
SUN = 3.0
SUN_DIRECTION = unit([0.3, -0.6, 1.0])  # travelling from behind the objects towards the camera
PANEL = {"x": (-1.5, -0.1), "y": (0.1, 1.3), "z": 0.0}
PANEL_BASE = (0.25, 0.5, 0.15)
PANEL_SHARE = 0.6
PANEL_COLOUR = (0.9, 0.8, 0.2)
SHADE_CENTRE = (0.8, 0.7, 0.0)
SHADE_RADIUS = 0.6
SHADE_BASE = (0.8, 0.8, 0.8)
SHADE_SHARE = 0.5
SHADE_COLOUR = (1.0, 0.6, 0.3)
VFOV = 0.6  # radians
CAMERA = (0.0, 0.8, 5.0)  # glTF (Y up), looking down -Z

SCENE_SCRIPT = r'''
def translucent(name, base, share, colour):
    m, out = material(name)
    nodes, links = m.node_tree.nodes, m.node_tree.links
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = tuple(base) + (1,)
    through = nodes.new("ShaderNodeBsdfTranslucent")
    through.inputs["Color"].default_value = tuple(colour) + (1,)
    mix = nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = share
    links.new(diffuse.outputs[0], mix.inputs[1])
    links.new(through.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], out.inputs["Surface"])
    return m


(x0, x1), (y0, y1), z = job["panel"]["x"], job["panel"]["y"], job["panel"]["z"]
corners = [blender(p) for p in [(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)]]
mesh = bpy.data.meshes.new("panel")
mesh.from_pydata(corners, [], [(0, 1, 2, 3)])
panel = bpy.data.objects.new("panel", mesh)
scene.collection.objects.link(panel)
panel.data.materials.append(translucent("leaf", job["panel_base"], job["panel_share"], job["panel_colour"]))
bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128, radius=job["shade_radius"],
                                     location=blender(job["shade_centre"]))
shade = bpy.context.active_object
bpy.ops.object.shade_smooth()
shade.data.materials.append(translucent("shade", job["shade_base"], job["shade_share"], job["shade_colour"]))
grey_floor(20.0, 0.0, job["floor"])
sun(job["sun_direction"], job["sun"])
camera(job["camera"], job["vfov"])
'''


def translucent(w, name, base, share, colour):
    """A glTF material whose diffuse base transmits `share` of itself, coloured `colour`,
    with no specular layer."""
    index = w.material(name, base=base, double_sided=True)
    w.doc["materials"][index]["extensions"] = {
        "KHR_materials_specular": {"specularFactor": 0.0},
        "KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": share,
                                               "diffuseTransmissionColorFactor": list(colour)}}
    w._use("KHR_materials_specular")
    w._use("KHR_materials_diffuse_transmission")
    return index


def write_gltf(path, width, height):
    w = GltfWriter("lucerna tools/compare/cycles/diffuse_transmission.py")
    floor = w.material("floor", base=(FLOOR,) * 3, extras={"lucerna": {"bsdf": "lambert"}})
    w.node(name="floor", mesh=w.mesh("floor", [(-20, 0, -20), (-20, 0, 20), (20, 0, 20), (20, 0, -20)],
                                     [(0, 1, 2), (0, 2, 3)], floor))
    (x0, x1), (y0, y1), z = PANEL["x"], PANEL["y"], PANEL["z"]
    leaf = translucent(w, "leaf", PANEL_BASE, PANEL_SHARE, PANEL_COLOUR)
    w.node(name="panel", mesh=w.mesh("panel", [(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)],
                                     [(0, 1, 2), (0, 2, 3)], leaf))
    shade = translucent(w, "shade", SHADE_BASE, SHADE_SHARE, SHADE_COLOUR)
    w.sphere("shade", SHADE_CENTRE, SHADE_RADIUS, shade, subdivisions=3)
    w.sun(SUN_DIRECTION, SUN)
    w.camera("camera", VFOV, width / height, CAMERA, (CAMERA[0], CAMERA[1], CAMERA[2] - 1.0))
    w.write_gltf(path)


def masks(width, height):
    """The pixels whose centre ray hits the panel first, and those that hit the shade."""
    d = lt.pinhole_directions(width, height, VFOV)
    o = np.array(CAMERA)
    t = (PANEL["z"] - o[2]) / d[..., 2]
    p = o + t[..., None] * d
    on_panel = ((p[..., 0] > PANEL["x"][0]) & (p[..., 0] < PANEL["x"][1])
                & (p[..., 1] > PANEL["y"][0]) & (p[..., 1] < PANEL["y"][1]))
    n = d / np.linalg.norm(d, axis=-1, keepdims=True)
    oc = o - np.array(SHADE_CENTRE)
    b = (n * oc).sum(-1)
    on_shade = b * b - (oc @ oc - SHADE_RADIUS ** 2) > 0
    return on_panel & ~on_shade, on_shade


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--resolution", default="200x150")
    parser.add_argument("--out", default=str(lt.ROOT / "tools" / "compare" / "cycles" / "results"
                                             / "diffuse-transmission"))
    args = parser.parse_args()
    width, height = map(int, args.resolution.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        gltf = work / "translucent.gltf"
        write_gltf(gltf, width, height)
        ours, ours_b, header = cycles.lucerna_seeds(gltf, work, (width, height), args.spp, SKY)
        job = {"width": width, "height": height, "spp": args.spp, "sky": SKY, "floor": FLOOR, "sun": SUN,
               "sun_direction": SUN_DIRECTION, "panel": PANEL, "panel_base": PANEL_BASE,
               "panel_share": PANEL_SHARE, "panel_colour": PANEL_COLOUR, "shade_centre": SHADE_CENTRE,
               "shade_radius": SHADE_RADIUS, "shade_base": SHADE_BASE, "shade_share": SHADE_SHARE,
               "shade_colour": SHADE_COLOUR, "vfov": VFOV, "camera": CAMERA}
        cycles_a, cycles_b = (cycles.render(work, "diffuse_transmission", SCENE_SCRIPT, job, seed)
                              for seed in (1, 2))
    panel, shade = masks(width, height)
    figures = {"spp": args.spp, "resolution": [width, height]}
    figures.update(cycles.figures(ours, ours_b, cycles_a, cycles_b,
                                  {"image": np.ones_like(panel), "panel": panel, "shade": shade}))
    figures["seconds_lucerna"] = header["lucerna/render_seconds"]
    (out / "figures.json").write_text(json.dumps(figures, indent=1) + "\n")
    print(json.dumps(figures, indent=1))
    lt.difference_sheet(ours, cycles_a, out / "translucent.png")


if __name__ == "__main__":
    main()
