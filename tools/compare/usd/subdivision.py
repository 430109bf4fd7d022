#!/usr/bin/env python3
"""lucerna against Cycles (Blender 5.0, pip `bpy`) on subdivision surfaces:

    .venv/bin/python tools/compare/usd/subdivision.py STAGE.usda [STAGE.usda ...] \
        --blender /path/to/bpy-venv/bin/python --out tools/compare/usd/results [--spp 64]

Each stage is wrapped in a stage that sublayers it and adds a camera looking at its
bounds, a distant light, a constant dome and a grey UsdPreviewSurface on every mesh, so
both renderers see the same shot. Blender
imports it with its USD importer with subdivision on (a Subdivision Surface modifier,
set here to 4 render levels on the limit surface); lucerna renders it with its default
screen-space refinement. Both 256x256, the same spp, box-free Blackman-Harris/Cycles'
1.5 px filter, no denoiser, Standard view. The report gives per stage the luminance ratio
lucerna/Cycles over the object's pixels and their relMSE, and writes a contact sheet
(lucerna left, Cycles right, a row per stage).
"""
import argparse
import json
import os
import subprocess
from pathlib import Path

import numpy as np
from shaderball import read_exr, write_sheet

ROOT = Path(__file__).resolve().parents[3]
RES = 256
#: The shot's lights: a sun of this irradiance (W/m²) and a constant sky of this radiance.
SUN, DOME = 4.0, 0.15

BLENDER_SCRIPT = r'''
import json, sys, bpy
args = json.loads(sys.argv[sys.argv.index("--") + 1])
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=args["stage"], import_subdivision=True, create_world_material=True)
scene = bpy.context.scene
for o in scene.objects:
    for m in o.modifiers:
        if m.type == "SUBSURF":
            m.render_levels = 4
            m.levels = 4
            m.use_limit_surface = True
cams = [o for o in scene.objects if o.type == "CAMERA"]
scene.camera = cams[0]
# The same lights as lucerna reads them (the importer scales UsdLux intensities its own way
# and makes no world of a dome without a texture).
for o in scene.objects:
    if o.type == "LIGHT" and o.data.type == "SUN":
        o.data.energy = args["sun"]
        o.data.angle = 2.0 * 3.141592653589793 / 180.0
world = bpy.data.worlds.new("dome")
world.use_nodes = True
world.node_tree.nodes["Background"].inputs["Color"].default_value = (args["dome"],) * 3 + (1.0,)
world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
scene.world = world
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = args["spp"]
scene.cycles.use_adaptive_sampling = False
scene.cycles.use_denoising = False
scene.cycles.filter_width = 1.5
scene.view_settings.view_transform = "Standard"
scene.render.resolution_x = scene.render.resolution_y = args["resolution"]
scene.render.resolution_percentage = 100
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.filepath = args["out"]
bpy.ops.render.render(write_still=True)
'''


def wrap(stage_path, out):
    """A stage sublayering `stage_path` with a camera, a distant light and a dome."""
    from pxr import Gf, Usd, UsdGeom, UsdLux

    source = Usd.Stage.Open(str(stage_path))
    bounds = UsdGeom.BBoxCache(Usd.TimeCode.Default(), ["default", "render"]).ComputeWorldBound(
        source.GetPseudoRoot()).ComputeAlignedRange()
    centre = (bounds.GetMin() + bounds.GetMax()) / 2
    size = (bounds.GetMax() - bounds.GetMin()).GetLength()
    stage = Usd.Stage.CreateNew(str(out))
    stage.GetRootLayer().subLayerPaths.append(str(Path(stage_path).resolve()))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.GetStageUpAxis(source))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)  # the shot in metres in both renderers
    up = Gf.Vec3d(0, 0, 1) if UsdGeom.GetStageUpAxis(source) == "Z" else Gf.Vec3d(0, 1, 0)
    side = Gf.Vec3d(1, 0, 0)
    depth = Gf.Cross(side, up)  # towards the viewer
    eye = centre + (side * 0.55 + up * 0.45 + depth * 1.0).GetNormalized() * size * 1.6
    look = Gf.Matrix4d().SetLookAt(eye, centre, up).GetInverse()
    cam = UsdGeom.Camera.Define(stage, "/CompareCamera")
    cam.AddTransformOp().Set(look)
    cam.CreateFocalLengthAttr(50.0)
    cam.CreateHorizontalApertureAttr(24.0)
    cam.CreateVerticalApertureAttr(24.0)
    sun = UsdLux.DistantLight.Define(stage, "/CompareSun")
    sun.CreateIntensityAttr(SUN)
    sun.CreateAngleAttr(2.0)
    sun.CreateNormalizeAttr(True)  # intensity = irradiance, as Blender's sun strength
    sun_dir = Gf.Matrix4d().SetLookAt(centre + (side * -0.6 + up * 1.0 + depth * 0.7) * size, centre, up)
    sun.AddTransformOp().Set(sun_dir.GetInverse())
    dome = UsdLux.DomeLight.Define(stage, "/CompareDome")
    dome.CreateIntensityAttr(DOME)
    # One grey UsdPreviewSurface on every mesh, which both renderers read alike.
    from pxr import Sdf, UsdShade
    material = UsdShade.Material.Define(stage, "/CompareMaterial")
    shader = UsdShade.Shader.Define(stage, "/CompareMaterial/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.5, 0.5, 0.5))
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.5)
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    for prim in source.Traverse():
        if prim.IsA(UsdGeom.Mesh):
            over = stage.OverridePrim(prim.GetPath())
            UsdShade.MaterialBindingAPI.Apply(over).Bind(material)
    stage.GetRootLayer().Save()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("stages", nargs="+")
    ap.add_argument("--blender", required=True, help="a Python with bpy 5.0 (pip install bpy)")
    ap.add_argument("--out", default=str(ROOT / "tools/compare/usd/results"))
    ap.add_argument("--spp", type=int, default=64)
    args = ap.parse_args()
    out = Path(args.out)
    work = out / "work"
    work.mkdir(parents=True, exist_ok=True)
    lucerna = os.environ.get("LUCERNA_BIN", str(ROOT / "target/release/lucerna"))
    rows = []
    for stage in args.stages:
        name = Path(stage).stem
        wrapped = work / f"{name}.compare.usda"
        if wrapped.exists():
            wrapped.unlink()
        wrap(stage, wrapped)
        lucerna_exr = work / f"{name}.lucerna.exr"
        cycles_exr = work / f"{name}.cycles.exr"
        subprocess.run([lucerna, "render", str(wrapped), "--spp", str(args.spp), "--resolution",
                        f"{RES}x{RES}", "--aov", "beauty", "--filter", "blackman-harris",
                        "-o", str(lucerna_exr), "-q"], check=True)
        job = {"stage": str(wrapped), "out": str(cycles_exr), "spp": args.spp, "resolution": RES,
               "sun": SUN, "dome": DOME}
        subprocess.run([args.blender, "-c", BLENDER_SCRIPT, "--", json.dumps(job)], check=True,
                       capture_output=True)
        rows.append((name, lucerna_exr, cycles_exr))
    report(rows, out)


def object_mask(exr):
    """The object's pixels: lucerna's beauty alpha."""
    import OpenImageIO as oiio
    buf = oiio.ImageBuf(str(exr))
    return buf.get_pixels(oiio.FLOAT)[..., list(buf.spec().channelnames).index("A")] > 0.5


def report(rows, out):
    lines = ["| stage | luminance lucerna/Cycles (object) | relMSE (object) |", "|---|---|---|"]
    tiles = []
    w = np.array([0.2126, 0.7152, 0.0722])
    for name, lucerna_exr, cycles_exr in rows:
        a, b = read_exr(lucerna_exr), read_exr(cycles_exr)
        mask = object_mask(lucerna_exr)
        oa, ob = a[mask], b[mask]
        rel = float(np.mean((oa - ob) ** 2 / (ob ** 2 + 1e-2)))
        lines.append(f"| {name} | {(oa @ w).mean() / (ob @ w).mean():.3f} | {rel:.4f} |")
        tiles.append(np.concatenate([np.clip(a, 0, 1), np.clip(b, 0, 1)], 1) ** (1 / 2.2))
    write_sheet(tiles, out / "subdivision_contact_sheet.png")
    (out / "subdivision.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
