"""One set of materials authored four ways renders alike where the models agree: MaterialX
open_pbr_surface (in a referenced .mtlx document), MaterialX standard_surface (inline in
USD), UsdPreviewSurface, and glTF (with its material extensions).

Six spheres: a rough red plastic, gold, clear glass (a volume of ior 1.5), an emitter, a
clear-coated blue and a textured one (an sRGB checker through each model's image node).
Every form states every input the others fix (ior 1.5, coat ior 1.5, specular weight 1), so
the models agree exactly. Lit by a structured sky (glass shows the refracted ground), the
block mean of each sphere must match the glTF render within 3 %, the issue's bound; two
seeds of the glTF render differ by at most 0.7 % per block channel (measured), so the bound
is about four times the noise, and the test checks that the noise stays below 1.5 %."""

import base64
import json
import math
import subprocess

import numpy as np
import OpenImageIO as oiio
import pytest

from conftest import lucerna_bin

WIDTH, HEIGHT, SPP = 384, 96, 128
CENTERS = [-2.5, -1.5, -0.5, 0.5, 1.5, 2.5]
RADIUS = 0.4
# Camera at (0, 0, 6) looking down -Z: focal length 50, apertures 80 x 20 (mm).
FOCAL, H_APERTURE, V_APERTURE, DISTANCE = 50.0, 80.0, 20.0, 6.0

MATERIALS = [
    ("plastic", {"base": (0.8, 0.1, 0.1), "metallic": 0.0, "roughness": 0.4}),
    ("gold", {"base": (1.0, 0.77, 0.33), "metallic": 1.0, "roughness": 0.3}),
    ("glass", {"base": (1.0, 1.0, 1.0), "metallic": 0.0, "roughness": 0.0, "transmission": 1.0}),
    ("emitter", {"base": (0.1, 0.1, 0.1), "metallic": 0.0, "roughness": 0.5,
                 "emission": (1.0, 0.5, 0.2)}),
    ("coated", {"base": (0.1, 0.2, 0.7), "metallic": 0.0, "roughness": 0.5, "coat": 1.0,
                "coat_roughness": 0.1}),
    ("textured", {"base": (1.0, 1.0, 1.0), "metallic": 0.0, "roughness": 0.6, "texture": True}),
]


def sphere(segments=48, rings=24):
    """A UV sphere: positions, normals, uvs (v down, glTF) and triangles."""
    pos, nrm, uv = [], [], []
    for r in range(rings + 1):
        theta = math.pi * r / rings
        for s in range(segments + 1):
            phi = 2 * math.pi * s / segments
            n = (math.sin(theta) * math.cos(phi), math.cos(theta), -math.sin(theta) * math.sin(phi))
            nrm.append(n)
            pos.append(tuple(RADIUS * c for c in n))
            uv.append((s / segments, r / rings))
    tris = []
    for r in range(rings):
        for s in range(segments):
            a = r * (segments + 1) + s
            b = a + segments + 1
            tris += [(a, b, a + 1), (a + 1, b, b + 1)]
    return (np.array(pos, np.float32), np.array(nrm, np.float32), np.array(uv, np.float32),
            np.array(tris, np.uint32))


def write_checker(path):
    texels = np.zeros((64, 64, 3), np.uint8)
    yy, xx = np.mgrid[0:64, 0:64]
    on = ((xx // 8) + (yy // 8)) % 2 == 0
    texels[on] = (230, 200, 40)
    texels[~on] = (30, 90, 200)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(64, 64, 3, oiio.UINT8))
    out.write_image(texels)
    out.close()


def write_gltf(path, mesh):
    pos, nrm, uv, tris = mesh
    blob = pos.tobytes() + nrm.tobytes() + uv.tobytes() + tris.tobytes()
    views, offset = [], 0
    for array, target in ((pos, 34962), (nrm, 34962), (uv, 34962), (tris, 34963)):
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": array.nbytes, "target": target})
        offset += array.nbytes
    accessors = [
        {"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3",
         "min": pos.min(0).tolist(), "max": pos.max(0).tolist()},
        {"bufferView": 1, "componentType": 5126, "count": len(nrm), "type": "VEC3"},
        {"bufferView": 2, "componentType": 5126, "count": len(uv), "type": "VEC2"},
        {"bufferView": 3, "componentType": 5125, "count": tris.size, "type": "SCALAR"},
    ]
    materials = []
    for name, m in MATERIALS:
        mat = {"name": name, "pbrMetallicRoughness": {
            "baseColorFactor": [*m["base"], 1.0], "metallicFactor": m["metallic"],
            "roughnessFactor": m["roughness"]}, "extensions": {"KHR_materials_ior": {"ior": 1.5}}}
        if m.get("texture"):
            mat["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
        if "emission" in m:
            mat["emissiveFactor"] = list(m["emission"])
        if "transmission" in m:
            mat["extensions"]["KHR_materials_transmission"] = {"transmissionFactor": m["transmission"]}
            mat["extensions"]["KHR_materials_volume"] = {"thicknessFactor": 1.0}
        if "coat" in m:
            mat["extensions"]["KHR_materials_clearcoat"] = {
                "clearcoatFactor": m["coat"], "clearcoatRoughnessFactor": m["coat_roughness"]}
        materials.append(mat)
    meshes = [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2},
                               "indices": 3, "material": i}]} for i in range(len(MATERIALS))]
    nodes = [{"mesh": i, "translation": [x, 0.0, 0.0]} for i, x in enumerate(CENTERS)]
    nodes.append({"camera": 0, "translation": [0.0, 0.0, DISTANCE]})
    gltf = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_materials_ior", "KHR_materials_transmission",
                           "KHR_materials_volume", "KHR_materials_clearcoat"],
        "scene": 0, "scenes": [{"nodes": list(range(len(nodes)))}], "nodes": nodes,
        "meshes": meshes, "materials": materials,
        "cameras": [{"type": "perspective", "perspective": {
            "yfov": 2 * math.atan(V_APERTURE / 2 / FOCAL), "aspectRatio": H_APERTURE / V_APERTURE,
            "znear": 0.1}}],
        "textures": [{"source": 0}], "images": [{"uri": "checker.png"}],
        "buffers": [{"byteLength": len(blob),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
        "bufferViews": views, "accessors": accessors,
    }
    path.write_text(json.dumps(gltf))


def usd_vec(values):
    return ", ".join("(" + ", ".join(f"{v:.7g}" for v in row) + ")" for row in values)


def usd_stage(mesh, material_prims, bindings):
    """A stage with the six spheres bound to `bindings[i]` and `material_prims` (text)."""
    pos, nrm, uv, tris = mesh
    st = uv.copy()
    st[:, 1] = 1.0 - st[:, 1]  # USD's st has v up
    spheres = []
    for i, x in enumerate(CENTERS):
        spheres.append(f'''
    def Mesh "Sphere{i}" (prepend apiSchemas = ["MaterialBindingAPI"]) {{
        double3 xformOp:translate = ({x}, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
        int[] faceVertexCounts = [{", ".join(["3"] * len(tris))}]
        int[] faceVertexIndices = [{", ".join(str(int(v)) for v in tris.reshape(-1))}]
        point3f[] points = [{usd_vec(pos)}]
        normal3f[] normals = [{usd_vec(nrm)}] (interpolation = "vertex")
        texCoord2f[] primvars:st = [{usd_vec(st)}] (interpolation = "vertex")
        uniform token subdivisionScheme = "none"
        rel material:binding = <{bindings[i]}>
    }}''')
    return ('#usda 1.0\n(\n    defaultPrim = "World"\n    metersPerUnit = 1\n    upAxis = "Y"\n)\n'
            'def Xform "World" {\n' + "".join(spheres) + f'''
    def Camera "Camera" {{
        float focalLength = {FOCAL}
        float horizontalAperture = {H_APERTURE}
        float verticalAperture = {V_APERTURE}
        double3 xformOp:translate = (0, 0, {DISTANCE})
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
''' + material_prims + "\n}\n")


def preview_materials():
    out = []
    for name, m in MATERIALS:
        inputs = [f"color3f inputs:diffuseColor = ({', '.join(map(str, m['base']))})",
                  f"float inputs:metallic = {m['metallic']}", f"float inputs:roughness = {m['roughness']}",
                  "float inputs:ior = 1.5"]
        nodes = ""
        if m.get("texture"):
            inputs[0] = f"color3f inputs:diffuseColor.connect = </World/Looks/{name}/Tex.outputs:rgb>"
            nodes = f'''
            def Shader "Tex" {{
                uniform token info:id = "UsdUVTexture"
                asset inputs:file = @checker.png@
                float2 inputs:st.connect = </World/Looks/{name}/St.outputs:result>
                float3 outputs:rgb
            }}
            def Shader "St" {{
                uniform token info:id = "UsdPrimvarReader_float2"
                string inputs:varname = "st"
                float2 outputs:result
            }}'''
        if "emission" in m:
            inputs.append(f"color3f inputs:emissiveColor = ({', '.join(map(str, m['emission']))})")
        if "transmission" in m:
            inputs.append("float inputs:opacity = 0")
        if "coat" in m:
            inputs += [f"float inputs:clearcoat = {m['coat']}",
                       f"float inputs:clearcoatRoughness = {m['coat_roughness']}"]
        body = "\n                ".join(inputs)
        out.append(f'''
        def Material "{name}" {{
            token outputs:surface.connect = </World/Looks/{name}/S.outputs:surface>
            def Shader "S" {{
                uniform token info:id = "UsdPreviewSurface"
                {body}
                token outputs:surface
            }}{nodes}
        }}''')
    return '    def Scope "Looks" {' + "".join(out) + "\n    }"


def standard_surface_materials():
    out = []
    for name, m in MATERIALS:
        inputs = ["float inputs:base = 1",
                  f"color3f inputs:base_color = ({', '.join(map(str, m['base']))})",
                  f"float inputs:metalness = {m['metallic']}", "float inputs:specular = 1",
                  "color3f inputs:specular_color = (1, 1, 1)",
                  f"float inputs:specular_roughness = {m['roughness']}",
                  "float inputs:specular_IOR = 1.5", "float inputs:coat_IOR = 1.5"]
        nodes = ""
        if m.get("texture"):
            inputs[1] = f"color3f inputs:base_color.connect = </World/Looks/{name}/Graph.outputs:color>"
            nodes = f'''
            def NodeGraph "Graph" {{
                color3f outputs:color.connect = </World/Looks/{name}/Graph/Image.outputs:out>
                def Shader "Image" {{
                    uniform token info:id = "ND_image_color3"
                    asset inputs:file = @checker.png@ (colorSpace = "srgb_texture")
                    float2 inputs:texcoord.connect = </World/Looks/{name}/Graph/Uv.outputs:out>
                    color3f outputs:out
                }}
                def Shader "Uv" {{
                    uniform token info:id = "ND_texcoord_vector2"
                    float2 outputs:out
                }}
            }}'''
        if "emission" in m:
            inputs += ["float inputs:emission = 1",
                       f"color3f inputs:emission_color = ({', '.join(map(str, m['emission']))})"]
        if "transmission" in m:
            inputs.append(f"float inputs:transmission = {m['transmission']}")
        if "coat" in m:
            inputs += [f"float inputs:coat = {m['coat']}",
                       f"float inputs:coat_roughness = {m['coat_roughness']}"]
        body = "\n                ".join(inputs)
        out.append(f'''
        def Material "{name}" {{
            token outputs:mtlx:surface.connect = </World/Looks/{name}/S.outputs:out>
            def Shader "S" {{
                uniform token info:id = "ND_standard_surface_surfaceshader"
                {body}
                token outputs:out
            }}{nodes}
        }}''')
    return '    def Scope "Looks" {' + "".join(out) + "\n    }"


def open_pbr_document():
    """A MaterialX document with the six materials as open_pbr_surface."""
    parts = ['<?xml version="1.0"?>\n<materialx version="1.39" colorspace="lin_rec709">']
    for name, m in MATERIALS:
        def inp(key, kind, value):
            text = ", ".join(map(str, value)) if isinstance(value, tuple) else str(value)
            return f'    <input name="{key}" type="{kind}" value="{text}" />'
        inputs = [inp("base_weight", "float", 1.0), inp("base_color", "color3", m["base"]),
                  inp("base_metalness", "float", m["metallic"]), inp("specular_weight", "float", 1.0),
                  inp("specular_roughness", "float", m["roughness"]), inp("specular_ior", "float", 1.5),
                  inp("coat_ior", "float", 1.5)]
        if m.get("texture"):
            parts.append(f'''  <nodegraph name="NG_{name}">
    <image name="image" type="color3">
      <input name="file" type="filename" value="checker.png" colorspace="srgb_texture" />
    </image>
    <output name="color" type="color3" nodename="image" />
  </nodegraph>''')
            inputs[1] = f'    <input name="base_color" type="color3" nodegraph="NG_{name}" output="color" />'
        if "emission" in m:
            inputs += [inp("emission_luminance", "float", 1.0), inp("emission_color", "color3", m["emission"])]
        if "transmission" in m:
            inputs.append(inp("transmission_weight", "float", m["transmission"]))
        if "coat" in m:
            inputs += [inp("coat_weight", "float", m["coat"]), inp("coat_roughness", "float", m["coat_roughness"])]
        parts.append(f'  <open_pbr_surface name="SR_{name}" type="surfaceshader">\n' + "\n".join(inputs)
                     + "\n  </open_pbr_surface>")
        parts.append(f'  <surfacematerial name="{name}" type="material">\n'
                     f'    <input name="surfaceshader" type="surfaceshader" nodename="SR_{name}" />\n'
                     '  </surfacematerial>')
    return "\n".join(parts) + "\n</materialx>\n"


def write_environment(path):
    """A lat-long sky: a blue gradient above, a warm checkered ground below and a bright
    sun patch, so that reflection and refraction show structure (a constant environment
    would hide clear glass entirely)."""
    h, w = 64, 128
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    sky = np.where(v[:, None, None] < 0.5,
                   np.array([0.3, 0.45, 0.9]) * (0.4 + 1.2 * v[:, None, None]),
                   np.where(((u[None, :, None] * 16).astype(int) + (v[:, None, None] * 8).astype(int)) % 2 == 0,
                            np.array([0.5, 0.35, 0.2]), np.array([0.08, 0.06, 0.05])))
    sky = np.broadcast_to(sky, (h, w, 3)).astype(np.float32).copy()
    sky[10:16, 70:78] = (40.0, 36.0, 30.0)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, 3, oiio.FLOAT))
    out.write_image(sky)
    out.close()


def render(scene, out, seed):
    environment = scene.parent / "sky.exr"
    if not environment.exists():
        write_environment(environment)
    subprocess.run([lucerna_bin(), "render", str(scene), "-o", str(out), "--spp", str(SPP),
                    "--resolution", f"{WIDTH}x{HEIGHT}", "--seed", str(seed), "--aov", "beauty",
                    "--env-map", str(environment), "-q"], check=True, capture_output=True, text=True)
    return oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)


def block_means(image):
    """The mean RGB of the central 12 x 12 pixels of each sphere."""
    scale = WIDTH / 2 / (DISTANCE * H_APERTURE / 2 / FOCAL)
    means = []
    for x in CENTERS:
        cx = int(round(WIDTH / 2 + x * scale))
        cy = HEIGHT // 2
        means.append(image[cy - 6:cy + 6, cx - 6:cx + 6].reshape(-1, 3).mean(0))
    return np.array(means)


@pytest.fixture(scope="module")
def twins(tmp_path_factory):
    d = tmp_path_factory.mktemp("twins")
    mesh = sphere()
    write_checker(d / "checker.png")
    write_gltf(d / "twin.gltf", mesh)
    names = [n for n, _ in MATERIALS]
    (d / "preview.usda").write_text(usd_stage(mesh, preview_materials(),
                                              [f"/World/Looks/{n}" for n in names]))
    (d / "standard.usda").write_text(usd_stage(mesh, standard_surface_materials(),
                                               [f"/World/Looks/{n}" for n in names]))
    (d / "openpbr.mtlx").write_text(open_pbr_document())
    (d / "openpbr.usda").write_text(usd_stage(
        mesh, '    def Scope "Looks" (references = @openpbr.mtlx@</MaterialX/Materials>) {}',
        [f"/World/Looks/{n}" for n in names]))
    images = {form: render(d / f"{form}", d / f"{form}.exr", seed)
              for seed, form in enumerate(["twin.gltf", "preview.usda", "standard.usda", "openpbr.usda"])}
    images["twin.gltf#2"] = render(d / "twin.gltf", d / "twin2.exr", 17)
    return images


@pytest.mark.parametrize("form", ["preview.usda", "standard.usda", "openpbr.usda"])
def test_material_models_render_alike(twins, form):
    reference = block_means(twins["twin.gltf"])
    other = block_means(twins[form])
    noise = np.abs(block_means(twins["twin.gltf#2"]) / reference - 1).max()
    assert noise < 0.015, f"the comparison is too noisy to be meaningful: {noise:.4f}"
    ratio = other / reference
    for (name, _), r in zip(MATERIALS, ratio):
        assert np.all(np.abs(r - 1) < 0.03), f"{form}: {name}: {r} (noise between seeds {noise:.4f})"
