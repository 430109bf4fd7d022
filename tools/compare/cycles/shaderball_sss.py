#!/usr/bin/env python3
"""Subsurface scattering on a real asset against Cycles (Blender 5.0, pip `bpy`): the
usd-wg StandardShaderBall's material surface (CC BY 4.0) in its "bubblegum" OpenPBR
material (subsurface_weight 1, subsurface_color (1, 0.22, 0.493), subsurface_radius 0.0325
stage units with radius scale (1, 0, 0.068), specular_weight 0.383, roughness 0.176, ior
1.584), under a uniform white sky:

    BLENDER=/path/to/bpy-venv/bin/python .venv/bin/python tools/compare/cycles/shaderball_sss.py \\
        --shaderball DIR [--spp 256] [--resolution 200x200] [--out tools/compare/cycles/results/subsurface]

DIR is full_assets/StandardShaderBall of a checkout of github.com/usd-wg/assets. The tool
writes a stage that references its material_surface_geo/subdiv.usda (centimetres, Y up),
with the polygon cage rendered as it is (subdivisionScheme "none", so both renderers see the
same facets), binds the bubblegum as a UsdShade OpenPBR shader, and renders it with lucerna
(the USD plugin maps OpenPBR's subsurface to its random walk: docs/usd.md) and with Cycles:
Blender imports the same stage (geometry only) and the surface gets a Principled BSDF with
Random Walk subsurface, Base Color the subsurface colour, Subsurface Radius the radius scale,
Subsurface Scale the radius in metres, Roughness, IOR, and Specular IOR Level half the
specular weight (Blender's 0.5 leaves F0 unchanged, OpenPBR's weight scales it). Writes
shaderball.png (lucerna | Cycles | 4 x |difference|) and shaderball.json: luminance and
channel ratios and relMSE over the object's pixels, with the noise floor (two seeds each).
"""
import argparse
import json
import math
import tempfile
from pathlib import Path

import numpy as np

import lucerna_tools as lt
from lucerna_tools import cycles

BUBBLEGUM = {"subsurface_weight": 1.0, "specular_weight": 0.383, "specular_roughness": 0.176,
             "specular_ior": 1.584, "subsurface_color": (1.0, 0.22, 0.493),
             "subsurface_radius_scale": (1.0, 0.0, 0.068), "subsurface_radius": 0.0325}
CAMERA_CM = (0.0, 4.3, 26.0)
FOCAL, APERTURE = 50.0, 20.955

STAGE = '''#usda 1.0
(
    defaultPrim = "World"
    metersPerUnit = 0.01
    upAxis = "Y"
)

def Xform "World"
{{
    def Xform "shader_ball" (
        prepend references = @{geometry}@
    )
    {{
        over "material_surface" (
            prepend apiSchemas = ["MaterialBindingAPI"]
        )
        {{
            uniform token subdivisionScheme = "none"
            rel material:binding = </World/Looks/bubblegum>
        }}
    }}
    def Scope "Looks"
    {{
        def Material "bubblegum"
        {{
            token outputs:mtlx:surface.connect = </World/Looks/bubblegum/open_pbr_surface.outputs:out>
            def Shader "open_pbr_surface"
            {{
                uniform token info:id = "ND_open_pbr_surface_surfaceshader"
                float inputs:subsurface_weight = {subsurface_weight}
                float inputs:specular_weight = {specular_weight}
                float inputs:specular_roughness = {specular_roughness}
                float inputs:specular_ior = {specular_ior}
                color3f inputs:subsurface_color = {subsurface_color}
                color3f inputs:subsurface_radius_scale = {subsurface_radius_scale}
                float inputs:subsurface_radius = {subsurface_radius}
                token outputs:out
            }}
        }}
    }}
    def Camera "camera"
    {{
        float focalLength = {focal}
        float horizontalAperture = {aperture}
        float verticalAperture = {aperture}
        float2 clippingRange = (1, 1000)
        double3 xformOp:translate = {camera}
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
}}
'''

SCENE_SCRIPT = r'''
bpy.ops.wm.usd_import(filepath=job["stage"], import_cameras=False, import_lights=False,
                      import_materials=False)
surface = [o for o in scene.objects if o.type == "MESH"][0]
# The stage's centimetres come in as a parent's scale of 0.01: bake it into the mesh, so
# that the subsurface radius (in metres) is not scaled with the object.
bpy.ops.object.select_all(action="DESELECT")
surface.select_set(True)
bpy.context.view_layer.objects.active = surface
bpy.ops.object.parent_clear(type="CLEAR_KEEP_TRANSFORM")
bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
gum, out = material("bubblegum")
p = gum.node_tree.nodes.new("ShaderNodeBsdfPrincipled")
p.subsurface_method = "RANDOM_WALK"
p.inputs["Base Color"].default_value = tuple(job["color"]) + (1,)
p.inputs["Subsurface Weight"].default_value = job["weight"]
p.inputs["Subsurface Radius"].default_value = job["radius"]
p.inputs["Subsurface Scale"].default_value = job["scale"]
p.inputs["Roughness"].default_value = job["roughness"]
p.inputs["IOR"].default_value = job["ior"]
p.inputs["Specular IOR Level"].default_value = job["specular_level"]
gum.node_tree.links.new(p.outputs[0], out.inputs["Surface"])
surface.data.materials.clear()
surface.data.materials.append(gum)
camera(job["camera"], job["vfov"], 0.01)
'''


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shaderball", required=True, help="full_assets/StandardShaderBall of usd-wg/assets")
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--resolution", default="200x200")
    parser.add_argument("--out", default=str(lt.ROOT / "tools" / "compare" / "cycles" / "results" / "subsurface"))
    args = parser.parse_args()
    width, height = map(int, args.resolution.split("x"))
    geometry = Path(args.shaderball).resolve() / "material_surface_geo" / "subdiv.usda"
    if not geometry.exists():
        raise SystemExit(f"{geometry} does not exist: --shaderball names full_assets/StandardShaderBall")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    g = BUBBLEGUM
    tuple_text = lambda v: "(" + ", ".join(str(c) for c in v) + ")"  # noqa: E731
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        stage = work / "bubblegum.usda"
        stage.write_text(STAGE.format(
            geometry=geometry, focal=FOCAL, aperture=APERTURE, camera=tuple_text(CAMERA_CM),
            **{k: tuple_text(v) if isinstance(v, tuple) else v for k, v in g.items()}))
        runs = [lt.render(stage, work / f"lucerna_{seed}.exr", (width, height), spp=args.spp, seed=seed,
                          filter="box", env="1,1,1") for seed in (1, 2)]
        (ours, header, channels), (ours_b, _, _) = runs
        job = {"width": width, "height": height, "spp": args.spp, "sky": 1.0, "stage": str(stage),
               "color": g["subsurface_color"], "weight": g["subsurface_weight"],
               "radius": g["subsurface_radius_scale"], "scale": g["subsurface_radius"] * 0.01,
               "roughness": g["specular_roughness"], "ior": g["specular_ior"],
               "specular_level": g["specular_weight"] / 2,
               "camera": [c * 0.01 for c in CAMERA_CM], "vfov": 2 * math.atan(APERTURE / 2 / FOCAL)}
        cycles_a, cycles_b = (cycles.render(work, "shaderball_sss", SCENE_SCRIPT, job, seed) for seed in (1, 2))
    # The object's pixels: those the surface covers entirely in lucerna's render.
    mask = channels["A"] > 0.999
    figures = {"spp": args.spp, "resolution": [width, height], "object_pixels": int(mask.sum()),
               "seconds_lucerna": header["lucerna/render_seconds"]}
    figures.update(cycles.figures(ours, ours_b, cycles_a, cycles_b, {"object": mask}))
    (out / "shaderball.json").write_text(json.dumps(figures, indent=1) + "\n")
    print(json.dumps(figures, indent=1))
    lt.difference_sheet(ours, cycles_a, out / "shaderball.png")


if __name__ == "__main__":
    main()
