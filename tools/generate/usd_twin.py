#!/usr/bin/env python3
"""Generate scenes/usd-twin/: one scene authored twice, as glTF (metres, Y up) and as USD
(centimetres, Z up: metersPerUnit 0.01), so that lucerna renders both to the same image
(tests/python/test_usd_twin.py). Both use what the two formats share: a textured floor
(faceVarying st on a quad polygon in USD), a wall, a GGX gold box placed twice (one glTF
mesh in two nodes; a USD scene-graph instance whose material is bound on the instance), a
smooth-shaded red dielectric icosphere, and a one-sided emissive panel (a USD RectLight
with normalize on, its intensity times the area in cm^2) seen by a camera with the same
field of view.

    .venv/bin/python tools/generate/usd_twin.py [output folder]
"""
import math
import struct
import sys
import zlib
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

from lucerna_tools.gltf_writer import GltfWriter, box, icosphere, look_rotation

EYE, TARGET, YFOV, ASPECT = [0.0, 1.4, 4.5], [0.0, 0.7, 0.0], 0.75, 1.5
LIGHT_RADIANCE, LIGHT_SIZE, LIGHT_HEIGHT = 12.0, (1.0, 0.6), 2.5
GOLD, RED, WALL = (1.0, 0.78, 0.34), (0.8, 0.1, 0.08), (0.6, 0.6, 0.6)
BOXES = [((-0.8, 0.3, -0.3), 0.0, 1.0), ((0.9, 0.24, 0.4), 30.0, 0.8)]  # centre, yaw, scale
SPHERE = ((-0.2, 0.45, 0.9), 0.45)
# glTF (x, y, z) metres -> USD (x, -z, y) centimetres.
TO_USD = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
CM = 100.0


def checker_png(path, size=64, squares=8):
    rows = []
    for y in range(size):
        row = bytearray([0])
        for x in range(size):
            light = ((x * squares // size) + (y * squares // size)) % 2 == 0
            row += bytes((200, 190, 170) if light else (60, 70, 90))
        rows.append(bytes(row))
    png = b"\x89PNG\r\n\x1a\n"
    for kind, data in ((b"IHDR", struct.pack(">IIBBBBB", size, size, 8, 2, 0, 0, 0)),
                       (b"IDAT", zlib.compress(b"".join(rows))), (b"IEND", b"")):
        png += struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    Path(path).write_bytes(png)


def floor():
    positions = [(-2, 0, 2), (2, 0, 2), (2, 0, -2), (-2, 0, -2)]
    uvs = [(0, 0), (2, 0), (2, 2), (0, 2)]  # glTF: v grows downwards in the image
    return positions, [(0, 1, 2), (0, 2, 3)], uvs


def wall():
    return [(-2, 0, -2), (2, 0, -2), (2, 3, -2), (-2, 3, -2)], [(0, 1, 2), (0, 2, 3)]


def light_quad():
    w, d = LIGHT_SIZE[0] / 2, LIGHT_SIZE[1] / 2
    y = LIGHT_HEIGHT
    # Counter-clockwise seen from below: the emitting side faces down.
    return [(-w, y, -d), (w, y, -d), (w, y, d), (-w, y, d)], [(0, 1, 2), (0, 2, 3)]


def box_transform(centre, yaw, scale):
    """Column-vector 4x4 (glTF)."""
    c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    m = np.identity(4)
    m[:3, :3] = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) * scale
    m[:3, 3] = centre
    return m


def write_gltf(out):
    w = GltfWriter("lucerna tools/generate/usd_twin.py")
    checker = w.texture("checker.png")
    lambert = {"lucerna": {"bsdf": "lambert"}}
    m_floor = w.material("floor", base=(1, 1, 1), roughness=0.7, base_texture=checker)
    m_wall = w.material("wall", base=WALL, roughness=1.0)
    m_gold = w.material("gold", base=GOLD, metallic=1.0, roughness=0.35)
    m_red = w.material("red", base=RED, roughness=0.25)
    m_light = w.material("light", base=(0, 0, 0), emissive=[LIGHT_RADIANCE] * 3, double_sided=False, extras=lambert)
    p, t, uv = floor()
    w.node(name="floor", mesh=w.mesh("floor", p, t, m_floor, uvs=uv))
    p, t = wall()
    w.node(name="wall", mesh=w.mesh("wall", p, t, m_wall))
    p, t = box((-0.3, -0.3, -0.3), (0.3, 0.3, 0.3))
    gold_box = w.mesh("box", p, t, m_gold)
    for k, (centre, yaw, scale) in enumerate(BOXES):
        m = box_transform(centre, yaw, scale)
        w.node(name=f"box{k}", mesh=gold_box, matrix=[float(x) for x in m.T.reshape(16)])
    verts, faces = icosphere(3)
    (cx, cy, cz), r = SPHERE
    w.node(name="sphere", mesh=w.mesh("sphere", [(cx + r * v[0], cy + r * v[1], cz + r * v[2]) for v in verts],
                                      faces, m_red, normals=verts))
    p, t = light_quad()
    w.node(name="light", mesh=w.mesh("light", p, t, m_light))
    w.camera("camera", YFOV, ASPECT, EYE, TARGET)
    w.write_gltf(out / "usd-twin.gltf")


def usd_points(points):
    return [Gf.Vec3f(*(TO_USD @ np.asarray(p, float) * CM)) for p in points]


def preview(stage, path, color, metallic, roughness, texture=None):
    material = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(metallic)
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(roughness)
    diffuse = shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f)
    if texture:
        reader = UsdShade.Shader.Define(stage, f"{path}/stReader")
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
        tex = UsdShade.Shader.Define(stage, f"{path}/Texture")
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(texture)
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
        tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("repeat")
        tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("repeat")
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
        diffuse.ConnectToSource(tex.ConnectableAPI(), "rgb")
    else:
        diffuse.Set(Gf.Vec3f(*color))
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material


def mesh(stage, path, points, counts, indices, material=None, double_sided=True):
    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(usd_points(points))
    m.CreateFaceVertexCountsAttr(counts)
    m.CreateFaceVertexIndicesAttr(indices)
    m.CreateDoubleSidedAttr(double_sided)
    m.CreateSubdivisionSchemeAttr("none")
    m.CreateExtentAttr(UsdGeom.Boundable.ComputeExtentFromPlugins(m, Usd.TimeCode.Default()))
    if material is not None:
        UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(material)
    return m


def row_matrix(m):
    """Column-vector 4x4 to Gf.Matrix4d (row vectors)."""
    return Gf.Matrix4d(*[float(x) for x in m.T.reshape(16)])


def write_usd(out):
    stage = Usd.Stage.CreateNew(str(out / "usd-twin.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    looks = "/World/Looks"
    m_floor = preview(stage, f"{looks}/Floor", None, 0.0, 0.7, texture="./checker.png")
    m_wall = preview(stage, f"{looks}/Wall", WALL, 0.0, 1.0)
    m_gold = preview(stage, f"{looks}/Gold", GOLD, 1.0, 0.35)
    m_red = preview(stage, f"{looks}/Red", RED, 0.0, 0.25)

    p, _, uv = floor()
    f = mesh(stage, "/World/Floor", p, [4], [0, 1, 2, 3], m_floor)
    # USD's t grows upwards in the image: t = 1 - v.
    st = UsdGeom.PrimvarsAPI(f).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    st.Set([Gf.Vec2f(u, 1 - v) for u, v in uv])
    p, _ = wall()
    mesh(stage, "/World/Wall", p, [4], [0, 1, 2, 3], m_wall)

    # The box prototype: a class, referenced by two instanceable prims.
    proto = stage.CreateClassPrim("/BoxPrototype")
    p, t = box((-0.3, -0.3, -0.3), (0.3, 0.3, 0.3))
    mesh(stage, "/BoxPrototype/Box", p, [3] * len(t), [i for tri in t for i in tri])
    proto.SetTypeName("Xform")
    for k, (centre, yaw, scale) in enumerate(BOXES):
        inst = UsdGeom.Xform.Define(stage, f"/World/Box{k}")
        inst.GetPrim().GetReferences().AddInternalReference("/BoxPrototype")
        inst.GetPrim().SetInstanceable(True)
        to_usd = np.identity(4)
        to_usd[:3, :3] = TO_USD
        scale_cm = np.diag([CM, CM, CM, 1.0])
        m = to_usd @ scale_cm @ box_transform(centre, yaw, scale) @ np.linalg.inv(scale_cm) @ np.linalg.inv(to_usd)
        inst.AddTransformOp().Set(row_matrix(m))
        UsdShade.MaterialBindingAPI.Apply(inst.GetPrim()).Bind(m_gold)

    verts, faces = icosphere(3)
    (cx, cy, cz), r = SPHERE
    s = mesh(stage, "/World/Sphere", [(cx + r * v[0], cy + r * v[1], cz + r * v[2]) for v in verts],
             [3] * len(faces), [i for tri in faces for i in tri], m_red)
    s.CreateNormalsAttr([Gf.Vec3f(*(TO_USD @ np.asarray(v, float))) for v in verts])
    s.SetNormalsInterpolation(UsdGeom.Tokens.vertex)

    light = UsdLux.RectLight.Define(stage, "/World/Light")
    light.CreateWidthAttr(LIGHT_SIZE[0] * CM)
    light.CreateHeightAttr(LIGHT_SIZE[1] * CM)
    light.CreateNormalizeAttr(True)
    light.CreateIntensityAttr(LIGHT_RADIANCE * LIGHT_SIZE[0] * LIGHT_SIZE[1] * CM * CM)
    # Local -Z (the emitting side) points down (USD -Z); local X, Y along glTF X, Z.
    light.AddTranslateOp().Set(Gf.Vec3d(0, 0, LIGHT_HEIGHT * CM))

    cam = UsdGeom.Camera.Define(stage, "/World/Camera")
    focal = 50.0
    vertical = 2 * focal * math.tan(YFOV / 2)
    cam.CreateFocalLengthAttr(focal)
    cam.CreateVerticalApertureAttr(vertical)
    cam.CreateHorizontalApertureAttr(vertical * ASPECT)
    cam.CreateClippingRangeAttr(Gf.Vec2f(1.0, 1.0e6))
    q = look_rotation([t - e for t, e in zip(TARGET, EYE)])
    rot = np.array(Gf.Matrix3d(Gf.Rotation(Gf.Quatd(q[3], q[0], q[1], q[2]))).GetTranspose())
    m = np.identity(4)
    m[:3, :3] = TO_USD @ rot
    m[:3, 3] = TO_USD @ np.asarray(EYE) * CM
    cam.AddTransformOp().Set(row_matrix(m))
    stage.GetRootLayer().Save()


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[2] / "scenes" / "usd-twin"
    out.mkdir(parents=True, exist_ok=True)
    checker_png(out / "checker.png")
    write_gltf(out)
    write_usd(out)
    print(f"wrote {out}/usd-twin.gltf, usd-twin.usda, checker.png")


if __name__ == "__main__":
    main()
