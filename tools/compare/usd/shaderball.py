#!/usr/bin/env python3
"""lucerna against Cycles (Blender 5.0, pip `bpy`) on usd-wg's StandardShaderBall, one
render per example material:

    .venv/bin/python tools/compare/usd/shaderball.py /path/to/StandardShaderBall/standard_shader_ball_scene.usda \
        --blender /path/to/bpy-venv/bin/python --out tools/compare/usd/results [--spp 64]

For each example_material variant the stage is composed with usd-core (the variant
selected, referenced .mtlx documents read as lucerna's plugin reads them), flattened, and
imported into Blender with its USD importer (cameras, lights, meshes, UsdPreviewSurface
materials; subdivision off, as lucerna renders the control cage). Blender's importer reads
no MaterialX, so for the MaterialX variants the ball's material in Blender is a Principled
BSDF set from the open_pbr_surface inputs, read here straight from the stage (Blender 4+'s
Principled BSDF follows OpenPBR's parameterisation). Both render 320x240 at the same spp,
no denoiser, Standard view; the report gives, per variant, the luminance ratio
lucerna/Cycles and the relMSE over the shader ball's pixels, and writes a contact sheet
(lucerna left, Cycles right).
"""
import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "plugins" / "usd"))

VARIANTS = ["usdpreview_plastic", "usdpreview_copper", "usdpreview_glass", "mtlx_plastic",
            "mtlx_gold", "mtlx_glass", "mtlx_bubblegum"]
BALL = "/standard_shader_ball_scene/shader_ball/material_surface"

BLENDER_SCRIPT = r'''
import json, sys, bpy
args = json.loads(sys.argv[sys.argv.index("--") + 1])
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=args["stage"], import_subdivision=False, import_all_materials=False,
                      create_world_material=True)
scene = bpy.context.scene
cams = [o for o in scene.objects if o.type == "CAMERA"]
if cams:
    scene.camera = cams[0]
    # USD's default conform policy, expandAperture, keeps the whole aperture in view; the
    # importer fits the sensor's width whatever the image's shape.
    cam = cams[0].data
    aspect = args["resolution"][0] / args["resolution"][1]
    cam.sensor_fit = "VERTICAL" if aspect >= cam.sensor_width / cam.sensor_height else "HORIZONTAL"
# A texture without a file renders magenta (or, on an emission input, white) in Blender;
# lucerna uses the input's fallback: 0.8 grey for a base colour (MaterialX's default),
# black for emission. The same here.
import os
for mat in bpy.data.materials:
    if not mat.node_tree:
        continue
    for node in list(mat.node_tree.nodes):
        if node.type != "TEX_IMAGE":
            continue
        if node.image is not None and os.path.exists(bpy.path.abspath(node.image.filepath)):
            continue
        for link in list(node.outputs[0].links):
            socket = link.to_socket
            mat.node_tree.links.remove(link)
            if socket.name == "Base Color":
                socket.default_value = (0.8, 0.8, 0.8, 1.0)
            elif socket.name.startswith("Emission"):
                socket.default_value = (0.0, 0.0, 0.0, 1.0)
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = args["spp"]
scene.cycles.use_adaptive_sampling = False
scene.cycles.use_denoising = False
scene.cycles.max_bounces = 64
scene.cycles.transparent_max_bounces = 64
scene.cycles.transmission_bounces = 64
scene.cycles.glossy_bounces = 64
scene.cycles.diffuse_bounces = 64
scene.cycles.filter_width = 1.5
scene.view_settings.view_transform = "Standard"
scene.render.resolution_x, scene.render.resolution_y = args["resolution"]
scene.render.resolution_percentage = 100
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
p = args.get("principled")
if p:
    ball = next(o for o in scene.objects if o.type == "MESH" and o.name.startswith("material_surface"))
    mat = bpy.data.materials.new("openpbr")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*p["base_color"], 1.0)
    bsdf.inputs["Metallic"].default_value = p["metallic"]
    bsdf.inputs["Roughness"].default_value = p["roughness"]
    bsdf.inputs["IOR"].default_value = p["ior"]
    bsdf.inputs["Specular IOR Level"].default_value = 0.5 * p["specular_weight"]
    bsdf.inputs["Specular Tint"].default_value = (*p["specular_color"], 1.0)
    bsdf.inputs["Transmission Weight"].default_value = p["transmission"]
    bsdf.inputs["Coat Weight"].default_value = p["coat"]
    bsdf.inputs["Coat Roughness"].default_value = p["coat_roughness"]
    bsdf.inputs["Coat IOR"].default_value = p["coat_ior"]
    bsdf.inputs["Sheen Weight"].default_value = p["fuzz"]
    bsdf.inputs["Sheen Tint"].default_value = (*p["fuzz_color"], 1.0)
    bsdf.inputs["Emission Color"].default_value = (*p["emission_color"], 1.0)
    bsdf.inputs["Subsurface Weight"].default_value = p["subsurface"]
    if p["subsurface"] > 0:
        # Blender's subsurface takes the base colour as its colour.
        w = p["subsurface"]
        bsdf.inputs["Base Color"].default_value = (
            *[(1 - w) * b + w * c for b, c in zip(p["base_color"], p["subsurface_color"])], 1.0)
    bsdf.inputs["Emission Strength"].default_value = p["emission"]
    if p["transmission"] > 0 and any(c < 1 for c in p["transmission_color"]):
        # OpenPBR's transmission colour without depth tints at the surface; the Principled
        # BSDF tints transmission by the base colour.
        bsdf.inputs["Base Color"].default_value = (*p["transmission_color"], 1.0)
    ball.data.materials.clear()
    ball.data.materials.append(mat)
scene.render.filepath = args["out"]
bpy.ops.render.render(write_still=True)
'''


def open_pbr_inputs(stage, material_path):
    """The ball's MaterialX surface inputs (open_pbr_surface or standard_surface; MaterialX
    defaults where unauthored), by the parts of the model lucerna's reader names."""
    from pxr import UsdShade
    from lucerna_usd import mtlx, surfaces

    material = UsdShade.Material(stage.GetPrimAtPath(material_path))
    out = material.GetSurfaceOutput("mtlx")
    source = out.GetValueProducingAttributes()[0]
    shader = UsdShade.Shader(source.GetPrim())
    node_id = shader.GetIdAttr().Get()
    values = dict(mtlx.defaults(node_id))
    for inp in shader.GetInputs():
        value = inp.Get()
        if value is not None:
            values[inp.GetBaseName()] = value

    roles = (surfaces._STANDARD_SURFACE_ROLES if mtlx.node_family(node_id) == "standard_surface"
             else surfaces._OPEN_PBR_ROLES)

    def number(role):
        return float(values[roles[role]])

    def color(role):
        return [float(x) for x in values[roles[role]]]

    return {"base_color": [number("base") * x for x in color("base_color")],
            "metallic": number("metalness"), "roughness": number("specular_roughness"),
            "ior": number("specular_ior"), "specular_weight": number("specular"),
            "specular_color": color("specular_color"), "transmission": number("transmission"),
            "transmission_color": color("transmission_color"), "coat": number("coat"),
            "coat_roughness": number("coat_roughness"), "coat_ior": number("coat_ior"),
            "fuzz": number("sheen"), "fuzz_color": color("sheen_color"),
            "emission": number("emission"), "emission_color": color("emission_color"),
            "subsurface": number("subsurface"), "subsurface_color": color("subsurface_color")}


def flatten(stage_path, variant, out):
    """The stage with `variant` selected and .mtlx documents substituted, flattened to
    `out`; returns the open_pbr inputs of the ball's material for MaterialX variants."""
    from pxr import Usd, UsdShade
    from lucerna_usd.mtlx import substitute_documents

    stage = Usd.Stage.Open(str(stage_path))
    root = stage.GetPrimAtPath("/standard_shader_ball_scene")
    root.GetVariantSets().GetVariantSet("example_material").SetVariantSelection(variant)
    keep = substitute_documents(stage, lambda *a: None)
    principled = None
    if variant.startswith("mtlx_"):
        ball = stage.GetPrimAtPath(BALL)
        material = UsdShade.MaterialBindingAPI(ball).ComputeBoundMaterial()[0]
        principled = open_pbr_inputs(stage, material.GetPath())
    # Asset paths absolute (on the session layer), so the flattened file finds them.
    from pxr import Sdf
    with Usd.EditContext(stage, stage.GetSessionLayer()):
        for prim in stage.Traverse():
            for attr in prim.GetAttributes():
                if attr.GetTypeName() == Sdf.ValueTypeNames.Asset:
                    value = attr.Get()
                    if value is not None and value.resolvedPath:
                        attr.Set(Sdf.AssetPath(value.resolvedPath))
    stage.Export(str(out))
    del keep
    return principled


def write_sheet(tiles, path):
    """Rows of display-encoded tiles, stacked, as an 8-bit PNG."""
    import OpenImageIO as oiio
    sheet = np.concatenate(tiles, 0).astype(np.float32)
    buf = oiio.ImageBuf(oiio.ImageSpec(sheet.shape[1], sheet.shape[0], 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(), sheet)
    buf.write(str(path))


def read_exr(path):
    import OpenImageIO as oiio
    return oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("stage")
    ap.add_argument("--blender", required=True, help="a Python with bpy 5.0 (pip install bpy)")
    ap.add_argument("--out", default=str(ROOT / "tools/compare/usd/results"))
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    args = ap.parse_args()
    out = Path(args.out)
    work = out / "work"
    work.mkdir(parents=True, exist_ok=True)
    lucerna = os.environ.get("LUCERNA_BIN", str(ROOT / "target/release/lucerna"))
    rows = []
    for variant in args.variants.split(","):
        flat = work / f"{variant}.usda"
        principled = flatten(args.stage, variant, flat)
        cycles_exr = work / f"{variant}.cycles.exr"
        lucerna_exr = work / f"{variant}.lucerna.exr"
        subprocess.run([lucerna, "render", args.stage, "--variant", f"example_material={variant}",
                        "--spp", str(args.spp), "--resolution", "320x240", "--aov", "beauty,position",
                        "--filter", "blackman-harris", "-o", str(lucerna_exr), "-q"], check=True)
        job = {"stage": str(flat), "out": str(cycles_exr), "spp": args.spp,
               "resolution": [320, 240], "principled": principled}
        subprocess.run([args.blender, "-c", BLENDER_SCRIPT, "--", json.dumps(job)], check=True,
                       capture_output=True)
        rows.append((variant, lucerna_exr, cycles_exr))
    report(rows, out)


def report(rows, out):
    lines = ["| variant | luminance lucerna/Cycles (image) | (ball) | relMSE (ball) |", "|---|---|---|---|"]
    tiles = []
    w = np.array([0.2126, 0.7152, 0.0722])
    for variant, lucerna_exr, cycles_exr in rows:
        a, b = read_exr(lucerna_exr), read_exr(cycles_exr)
        # The ball: the middle of the image, where the shader-ball surface is.
        h, wd = a.shape[:2]
        ball = (slice(int(h * 0.12), int(h * 0.75)), slice(int(wd * 0.3), int(wd * 0.7)))
        la, lb = (a @ w).mean(), (b @ w).mean()
        ba, bb = a[ball], b[ball]
        rel = float(np.mean((ba - bb) ** 2 / (bb ** 2 + 1e-2)))
        lines.append(f"| {variant} | {la / lb:.3f} | {(ba @ w).mean() / (bb @ w).mean():.3f} | {rel:.4f} |")
        tiles.append(np.concatenate([np.clip(a, 0, 1), np.clip(b, 0, 1)], 1) ** (1 / 2.2))
    write_sheet(tiles, out / "shaderball_contact_sheet.png")
    (out / "shaderball.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
