#!/usr/bin/env python3
"""lucerna's random-walk subsurface scattering against Cycles' (Blender 5.0, pip `bpy`) on
a sphere: one scene written twice, a USD stage with a standard_surface material for lucerna
(its plugin turns `subsurface_*` into OpenPBR's subsurface slab: docs/usd.md) and a Blender
scene built with `bpy` with the Principled BSDF's Random Walk subsurface for Cycles:

    BLENDER=/path/to/bpy-venv/bin/python .venv/bin/python tools/compare/cycles/subsurface.py \\
        [--spp 256] [--resolution 256x192] [--out tools/compare/cycles/results/subsurface]

A unit sphere (radius 1 m) on a grey floor under a uniform white sky (radiance 1), seen
from 5 m; the subsurface colour (0.8, 0.5, 0.3), mean free path (1, 0.5, 0.25) x `--scale`
(default 0.1 m), ior 1.4, specular roughness 0.3. Cycles: every bounce limit 1024, no
clamping, no denoiser, box-like filter 1 pixel, Standard view, linear EXR. Writes a contact
sheet (lucerna | Cycles | |difference| x 4) and figures.json: luminance ratio and relMSE
over the sphere's pixels, and the same between two Cycles seeds (the noise floor).
"""
import argparse
import json
import math
import tempfile
from pathlib import Path

import numpy as np

import lucerna_tools as lt
from lucerna_tools import cycles

COLOUR = (0.8, 0.5, 0.3)
RADIUS = (1.0, 0.5, 0.25)
IOR = 1.4
ROUGHNESS = 0.3
VFOV = 0.5  # radians
CAMERA_DISTANCE = 5.0

STAGE = """#usda 1.0
(
    defaultPrim = "World"
    metersPerUnit = 1
    upAxis = "Y"
)
def Xform "World"
{{
    def Material "Skin"
    {{
        token outputs:mtlx:surface.connect = </World/Skin/S.outputs:out>
        def Shader "S"
        {{
            uniform token info:id = "ND_standard_surface_surfaceshader"
            float inputs:subsurface = 1
            color3f inputs:subsurface_color = {colour}
            color3f inputs:subsurface_radius = {radius}
            float inputs:subsurface_scale = {scale}
            float inputs:specular_IOR = {ior}
            float inputs:specular_roughness = {roughness}
            token outputs:out
        }}
    }}
    def Material "Floor"
    {{
        token outputs:surface.connect = </World/Floor/P.outputs:surface>
        def Shader "P"
        {{
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor = (0.5, 0.5, 0.5)
            float inputs:roughness = 1
            token outputs:surface
        }}
    }}
    def Sphere "Ball" (prepend apiSchemas = ["MaterialBindingAPI"])
    {{
        double radius = 1
        double3 xformOp:translate = (0, 1, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
        rel material:binding = </World/Skin>
    }}
    def Mesh "Ground" (prepend apiSchemas = ["MaterialBindingAPI"])
    {{
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(-20, 0, -20), (-20, 0, 20), (20, 0, 20), (20, 0, -20)]
        rel material:binding = </World/Floor>
    }}
    def DomeLight "Sky"
    {{
        float inputs:intensity = 1
    }}
    def Camera "Cam"
    {{
        float focalLength = 50
        float verticalAperture = {aperture}
        float horizontalAperture = {haperture}
        double3 xformOp:translate = (0, 1, {distance})
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
}}
"""

SCENE_SCRIPT = r'''
bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128, radius=1.0, location=(0, 0, 1))
ball = bpy.context.active_object
bpy.ops.object.shade_smooth()
skin = bpy.data.materials.new("skin")
skin.use_nodes = True
p = skin.node_tree.nodes["Principled BSDF"]
p.subsurface_method = "RANDOM_WALK"
p.inputs["Base Color"].default_value = (*job["colour"], 1)
p.inputs["Subsurface Weight"].default_value = 1.0
p.inputs["Subsurface Radius"].default_value = job["radius"]
p.inputs["Subsurface Scale"].default_value = job["scale"]
p.inputs["IOR"].default_value = job["ior"]
p.inputs["Roughness"].default_value = job["roughness"]
ball.data.materials.append(skin)
bpy.ops.mesh.primitive_plane_add(size=40.0, location=(0, 0, 0))
floor = bpy.context.active_object
grey = bpy.data.materials.new("floor")
grey.use_nodes = True
g = grey.node_tree.nodes["Principled BSDF"]
g.inputs["Base Color"].default_value = (0.5, 0.5, 0.5, 1)
g.inputs["Roughness"].default_value = 1.0
floor.data.materials.append(grey)
camera((0, 1, job["distance"]), job["vfov"])
'''


def cycles_job(width, height, spp, scale):
    """The values SCENE_SCRIPT reads (Cycles' default pixel filter, a white sky)."""
    return {"width": width, "height": height, "spp": spp, "sky": 1.0, "box_filter": False, "colour": COLOUR,
            "radius": RADIUS, "scale": scale, "ior": IOR, "roughness": ROUGHNESS, "vfov": VFOV,
            "distance": CAMERA_DISTANCE}


def sphere_mask(width, height):
    """Pixels whose centre ray hits the sphere."""
    d = lt.pinhole_directions(width, height, VFOV)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    oc = np.array([0.0, 0.0, CAMERA_DISTANCE])  # camera minus centre (centre at camera height)
    b = (d * oc).sum(-1)
    return b * b - (oc @ oc - 1.0) > 0


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--resolution", default="256x192")
    parser.add_argument("--scale", type=float, default=0.1)
    parser.add_argument("--out", default=str(lt.ROOT / "tools" / "compare" / "cycles" / "results" / "subsurface"))
    args = parser.parse_args()
    width, height = map(int, args.resolution.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        aperture = 2 * 50 * math.tan(VFOV / 2)
        stage = work / "subsurface.usda"
        stage.write_text(STAGE.format(colour=COLOUR, radius=RADIUS, scale=args.scale, ior=IOR,
                                      roughness=ROUGHNESS, aperture=aperture,
                                      haperture=aperture * width / height, distance=CAMERA_DISTANCE))
        ours, header, _ = lt.render(stage, work / "lucerna.exr", (width, height), spp=args.spp, seed=1,
                                    filter="box")
        job = cycles_job(width, height, args.spp, args.scale)
        cycles_a, cycles_b = (cycles.render(work, "subsurface", SCENE_SCRIPT, job, seed) for seed in (1, 2))
    mask = sphere_mask(width, height)
    lum = lambda img: float((img[mask] @ np.array([0.2126, 0.7152, 0.0722])).mean())  # noqa: E731
    rel = lambda x, ref: float(np.mean((x[mask] - ref[mask]) ** 2 / (ref[mask] ** 2 + 0.01)))  # noqa: E731
    figures = {"spp": args.spp, "resolution": [width, height], "scale": args.scale,
               "luminance_ratio": lum(ours) / lum(cycles_a),
               "channel_ratio": (ours[mask].mean(0) / cycles_a[mask].mean(0)).tolist(),
               "relmse_lucerna_vs_cycles": rel(ours, cycles_a),
               "relmse_cycles_b_vs_a": rel(cycles_b, cycles_a),
               "seconds_lucerna": header["lucerna/render_seconds"]}
    (out / "figures.json").write_text(json.dumps(figures, indent=1) + "\n")
    print(json.dumps(figures, indent=1))
    lt.difference_sheet(ours, cycles_a, out / "sphere.png")


if __name__ == "__main__":
    main()
