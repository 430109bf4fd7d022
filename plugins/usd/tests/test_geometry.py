"""Meshes, primvars, subsets, transforms, instancing, composition, cameras, units."""

import math
import subprocess

import numpy as np
import OpenImageIO as oiio
import pytest
from conftest import convert, lucerna_bin, write_image

QUAD = '''
    def Mesh "Quad" {{
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
        {extra}
    }}
'''


def world(body):
    return 'def Xform "World" {\n' + body + "\n}\n"


def normal_of(p, t):
    a, b, c = p[t[0]], p[t[1]], p[t[2]]
    n = np.cross(b - a, c - a)
    return n / np.linalg.norm(n)


def test_polygons_are_fan_triangulated_with_holes_and_degenerate_faces(stage_file, converted):
    s = converted(stage_file(world('''
    def Mesh "M" {
        int[] faceVertexCounts = [5, 4, 2, 3]
        int[] faceVertexIndices = [0, 1, 2, 3, 4,  0, 4, 5, 6,  1, 2,  0, 5, 6]
        int[] holeIndices = [3]
        point3f[] points = [(0,0,0), (2,0,0), (3,1,0), (1,2,0), (-1,1,0), (-1,-1,0), (0,-2,0)]
    }''')))
    m = s.mesh("/World/M")
    assert len(s.triangles(m)) == 3 + 2  # pentagon 3, quad 2; the 2-gon and the hole dropped
    assert s.warnings_about("1 faces with fewer than 3 vertices skipped")
    p = s.positions(m)
    for t in s.triangles(m):
        assert normal_of(p, t)[2] > 0.99  # counter-clockwise, facing +Z


def test_left_handed_orientation_flips_the_winding(stage_file, converted):
    s = converted(stage_file(world(QUAD.format(extra='uniform token orientation = "leftHanded"'))))
    m = s.mesh("/World/Quad")
    p = s.positions(m)
    assert all(normal_of(p, t)[2] < -0.99 for t in s.triangles(m))


def diffuse_texture_material(file, texture_inputs=""):
    """/World/Tex: a UsdPreviewSurface whose diffuseColor is the texture `file` read at
    primvar st."""
    return f'''
    def Material "Tex" {{
        token outputs:surface.connect = </World/Tex/S.outputs:surface>
        def Shader "S" {{
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor.connect = </World/Tex/T.outputs:rgb>
            token outputs:surface
        }}
        def Shader "T" {{
            uniform token info:id = "UsdUVTexture"
            asset inputs:file = @{file}@
            {texture_inputs}
            float2 inputs:st.connect = </World/Tex/R.outputs:result>
            float3 outputs:rgb
        }}
        def Shader "R" {{
            uniform token info:id = "UsdPrimvarReader_float2"
            string inputs:varname = "st"
            float2 outputs:result
        }}
    }}'''


def write_png(path, rgb):
    """A small 8-bit RGB image (H, W, 3) of values in 0..255."""
    rgb = np.asarray(rgb, dtype=np.uint8)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, oiio.UINT8))
    out.write_image(rgb)
    out.close()


def test_primvar_interpolations_and_welding(stage_file, converted, tmp_path):
    write_png(tmp_path / "checker.png", [[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]])
    text = world('''
    def Mesh "M" (prepend apiSchemas = ["MaterialBindingAPI"]) {
        int[] faceVertexCounts = [4, 4]
        int[] faceVertexIndices = [0, 1, 2, 3, 1, 4, 5, 2]
        point3f[] points = [(0,0,0), (1,0,0), (1,1,0), (0,1,0), (2,0,0), (2,1,0)]
        normal3f[] primvars:normals = [(0,0,1), (0,1,0)] (interpolation = "uniform")
        texCoord2f[] primvars:st = [(0,0), (1,0), (1,1), (0,1)] (interpolation = "faceVarying")
        int[] primvars:st:indices = [0, 1, 2, 3, 0, 1, 2, 3]
        rel material:binding = </World/Tex>
        %s
    }
''' + diffuse_texture_material("checker.png"))
    # Without a scheme, USD's default catmullClark applies: the normals are ignored (warned).
    subdivided = converted(stage_file(text % ""))
    assert subdivided.warnings_about("subdivisionScheme is not authored")
    assert len(subdivided["subdivision_surfaces"]) == 1
    s = converted(stage_file(text % 'uniform token subdivisionScheme = "none"', "polygons.usda"))
    m = s.mesh("/World/M")
    # Uniform normals split the shared edge: 4 + 4 vertices, not 6.
    assert m["positions"]["count"] == 8
    normals = s.array(m["normals"], "<f4", 3)
    assert {tuple(n) for n in normals} == {(0, 0, 1), (0, 1, 0)}
    uvs = s.array(m["uvs"][0], "<f4", 2)
    positions = s.positions(m)
    # Indexed faceVarying st, with v flipped: the corner at (1, 1, 0) of face 0 has st (1, 1).
    k = next(i for i, (p, n) in enumerate(zip(positions, normals)) if tuple(p) == (1, 1, 0) and n[2] == 1)
    assert tuple(uvs[k]) == (1.0, 0.0)
    texture = s["textures"][s["materials"][m["material"]]["base_color_texture"]["texture"]]
    assert (texture["width"], texture["height"], texture["encoding"]) == (2, 2, "rgba8")


def test_missing_texture_is_a_validation_finding_and_the_fallback_renders(stage_file, converted, tmp_path):
    text = world(QUAD.format(extra='rel material:binding = </World/Tex>')
                 + diffuse_texture_material("missing.png", "float4 inputs:fallback = (0.5, 0.25, 0.125, 1)"))
    path = stage_file(text)
    assert convert(str(path), str(tmp_path / "x.lucerna"), quiet=True, strict=True) == 2
    s = converted(path)
    assert s.warnings_about("unresolvable external dependency 'missing.png'")
    assert s.warnings_about("texture 'missing.png' unreadable")
    material = s["materials"][s.mesh("/World/Quad")["material"]]
    assert material["base_color"] == [0.5, 0.25, 0.125, 1.0] and material["base_color_texture"] is None


def test_a_materialx_image_without_its_file_gives_its_default(stage_file, converted):
    """MaterialX: an image whose file is missing gives its `default` input, zero in every
    channel where none is authored (not the default of the input it feeds)."""
    def material(name, default):
        return f'''
    def Material "{name}" {{
        token outputs:mtlx:surface.connect = </World/{name}/S.outputs:out>
        def Shader "S" {{
            uniform token info:id = "ND_standard_surface_surfaceshader"
            color3f inputs:base_color.connect = </World/{name}/I.outputs:out>
            token outputs:out
        }}
        def Shader "I" {{
            uniform token info:id = "ND_image_color3"
            asset inputs:file = @missing.exr@
            {default}
            color3f outputs:out
        }}
    }}'''
    quads = (QUAD.format(extra="rel material:binding = </World/Plain>")
             + QUAD.replace('"Quad"', '"Other"').format(extra="rel material:binding = </World/Given>"))
    s = converted(stage_file(world(quads + material("Plain", "") + material("Given",
                                                                   "color3f inputs:default = (0.5, 0.25, 0.125)"))),
                  no_validate=True)
    colour = {name: s["materials"][s.mesh(f"/World/{name}")["material"]]["base_color"][:3]
              for name in ("Quad", "Other")}
    assert colour == {"Quad": [0.0, 0.0, 0.0], "Other": [0.5, 0.25, 0.125]}, colour


def test_vertex_primvars_keep_one_vertex_per_point(stage_file, converted):
    s = converted(stage_file(world(QUAD.format(extra='''
        normal3f[] normals = [(0,0,1), (0,0,1), (0,0,1), (0,0,1)] (interpolation = "vertex")
        color3f[] primvars:displayColor = [(1,0,0), (0,1,0), (0,0,1), (1,1,1)] (interpolation = "vertex")'''))))
    m = s.mesh("/World/Quad")
    assert m["positions"]["count"] == 4
    colors = s.array(m["colors"], "<f4", 4)
    assert colors[:, 3].tolist() == [1, 1, 1, 1]
    material = s["materials"][m["material"]]
    assert material["base_color"] == [1, 1, 1, 1]  # per-vertex displayColor: in the colours


def test_constant_display_color_and_double_sided(stage_file, converted):
    s = converted(stage_file(world(QUAD.format(extra='''
        color3f[] primvars:displayColor = [(0.25, 0.5, 0.75)]
        uniform bool doubleSided = 1'''))))
    material = s["materials"][s.mesh("/World/Quad")["material"]]
    assert material["base_color"] == [0.25, 0.5, 0.75, 1.0]
    assert material["double_sided"] is True
    assert material["metallic"] == 0.0 and material["roughness"] == 0.5


MATERIALS = '''
    def Material "Red" {
        token outputs:surface.connect = </World/Red/S.outputs:surface>
        def Shader "S" {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor = (1, 0, 0)
            token outputs:surface
        }
    }
    def Material "Blue" {
        token outputs:surface.connect = </World/Blue/S.outputs:surface>
        def Shader "S" {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor = (0, 0, 1)
            token outputs:surface
        }
    }
'''


def test_geom_subsets_bind_materials_per_face(stage_file, converted):
    s = converted(stage_file(world(MATERIALS + '''
    def Mesh "M" (prepend apiSchemas = ["MaterialBindingAPI"]) {
        int[] faceVertexCounts = [3, 3, 3]
        int[] faceVertexIndices = [0, 1, 2, 0, 2, 3, 0, 3, 1]
        point3f[] points = [(0,0,0), (1,0,0), (0,1,0), (0,0,1)]
        rel material:binding = </World/Red>
        uniform token subsetFamily:materialBind:familyType = "nonOverlapping"
        def GeomSubset "blue" (prepend apiSchemas = ["MaterialBindingAPI"]) {
            uniform token elementType = "face"
            uniform token familyName = "materialBind"
            int[] indices = [1, 2]
            rel material:binding = </World/Blue>
        }
    }''')))
    red = s.mesh("/World/M")
    blue = s.mesh("/World/M:blue")
    assert len(s.triangles(red)) == 1 and len(s.triangles(blue)) == 2
    assert s["materials"][red["material"]]["base_color"][:3] == [1, 0, 0]
    assert s["materials"][blue["material"]]["base_color"][:3] == [0, 0, 1]


def test_time_sampled_transforms_follow_the_frame(stage_file, converted):
    path = stage_file('#usda 1.0\n(\n defaultPrim = "World"\n metersPerUnit = 1\n upAxis = "Y"\n'
                      ' startTimeCode = 1\n endTimeCode = 10\n)\n' + world('''
    def Xform "Moving" {
        double3 xformOp:translate.timeSamples = { 1: (0, 0, 0), 10: (9, 0, 0) }
        uniform token[] xformOpOrder = ["xformOp:translate"]
    ''' + QUAD.format(extra="") + "}"))
    def x_of(scene):
        return scene["instances"][0]["transform"][12]
    assert x_of(converted(path)) == 0.0  # the stage's start time code
    assert x_of(converted(path, frame=4.0)) == pytest.approx(3.0)
    assert x_of(converted(path, frame=10.0)) == pytest.approx(9.0)


def test_scene_graph_instances_share_one_mesh(stage_file, converted):
    s = converted(stage_file(world('''
    def Xform "A" (
        instanceable = true
        references = </Proto>
    ) {
        double3 xformOp:translate = (1, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
    def Xform "B" (
        instanceable = true
        references = </Proto>
    ) {
        double3 xformOp:translate = (2, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
    def Xform "C" (
        instanceable = true
        references = </Proto>
    ) {
        double3 xformOp:translate = (3, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
''') + 'class Xform "Proto" {' + QUAD.format(extra="") + "}\n"))
    assert len(s["meshes"]) == 1
    assert sorted(i["transform"][12] for i in s["instances"]) == [1, 2, 3]


def point_instancer(n):
    side = int(math.ceil(math.sqrt(n)))
    positions = ", ".join(f"({i % side}, 0, {i // side})" for i in range(n))
    return world(f'''
    def PointInstancer "Field" {{
        point3f[] positions = [{positions}]
        int[] protoIndices = [{", ".join("0" for _ in range(n))}]
        rel prototypes = </World/Field/Prototypes/Ball>
        def Scope "Prototypes" {{
            def Xform "Ball" {{
                def Mesh "Tri" {{
                    int[] faceVertexCounts = [3, 3, 3, 3]
                    int[] faceVertexIndices = [0, 1, 2, 0, 3, 1, 0, 2, 3, 1, 3, 2]
                    point3f[] points = [(0, 0, 0), (0.4, 0, 0), (0, 0.4, 0), (0, 0, 0.4)]
                }}
            }}
        }}
    }}''')


def test_point_instancer_of_ten_thousand_stores_the_prototype_once(stage_file, converted, tmp_path):
    one = converted(stage_file(point_instancer(1), "one.usda"))
    many = converted(stage_file(point_instancer(10_000), "many.usda"))
    assert len(many["meshes"]) == 1 and len(many["instances"]) == 10_000
    assert len(many.buffer) == len(one.buffer)  # geometry bytes do not grow with the count
    xs = sorted({i["transform"][12] for i in many["instances"]})
    assert xs == list(range(100))
    # Prototypes under the instancer are not rendered on their own.
    assert all(i["mesh"] == 0 for i in many["instances"])


def test_point_instancer_mask(stage_file, converted):
    text = point_instancer(4).replace("int[] protoIndices", "int64[] invisibleIds = [1, 2]\n int[] protoIndices")
    s = converted(stage_file(text))
    assert sorted((i["transform"][12], i["transform"][14]) for i in s["instances"]) == [(0, 0), (1, 1)]


def test_point_instancer_with_bad_indices_is_skipped_with_a_warning(stage_file, converted):
    text = point_instancer(4).replace("int[] protoIndices = [0, 0, 0, 0]", "int[] protoIndices = [0, 0, 7, 0]")
    text += 'def Sphere "Keep" {}\n'
    s = converted(stage_file(text))
    assert not s["instances"]
    assert s.warnings_about("1 protoIndices out of range")


def test_reference_and_variant_set(stage_file, converted, tmp_path):
    (tmp_path / "asset.usda").write_text('#usda 1.0\n(\n defaultPrim = "Asset"\n metersPerUnit = 1\n upAxis = "Y"\n)\n'
                                         'def Xform "Asset" (\n variantSets = ["size"]\n variants = { string size = "small" }\n) {\n'
                                         ' variantSet "size" = {\n'
                                         '  "small" { double3 xformOp:scale = (1, 1, 1)\n uniform token[] xformOpOrder = ["xformOp:scale"]\n }\n'
                                         '  "large" { double3 xformOp:scale = (5, 5, 5)\n uniform token[] xformOpOrder = ["xformOp:scale"]\n }\n'
                                         ' }\n' + QUAD.format(extra="") + "}\n")
    s = converted(stage_file(world('''
    def "Small" (references = @./asset.usda@) {}
    def "Large" (
        references = @./asset.usda@
        variants = { string size = "large" }
    ) {}''')))
    scales = sorted(i["transform"][0] for i in s["instances"])
    assert scales == [1.0, 5.0]
    assert {i["name"] for i in s["instances"]} == {"/World/Small/Quad", "/World/Large/Quad"}


def test_purpose_and_visibility(stage_file, converted):
    s = converted(stage_file(world('''
    def Xform "Guide" { uniform token purpose = "guide"''' + QUAD.format(extra="") + '''}
    def Xform "Proxy" { uniform token purpose = "proxy"''' + QUAD.format(extra="") + '''}
    def Xform "Render" { uniform token purpose = "render"''' + QUAD.format(extra="") + '''}
    def Xform "Hidden" { token visibility = "invisible"''' + QUAD.format(extra="") + '''}
    def Xform "Shown" {''' + QUAD.format(extra="") + "}")))
    assert sorted(i["name"] for i in s["instances"]) == ["/World/Render/Quad", "/World/Shown/Quad"]


def test_up_axis_and_meters_per_unit(stage_file, converted):
    s = converted(stage_file('#usda 1.0\n(\n defaultPrim = "World"\n metersPerUnit = 0.01\n upAxis = "Z"\n)\n'
                             + world(QUAD.format(extra=""))))
    t = np.array(s["instances"][0]["transform"]).reshape(4, 4)  # row-vector form, as stored
    p = np.array([0.0, 1.0, 0.0, 1.0]) @ t  # stage +Y (1 cm) ...
    assert np.allclose(p[:3], [0, 0, -0.01])  # ... is lucerna's -Z, in metres
    up = np.array([0.0, 0.0, 100.0, 1.0]) @ t  # stage +Z is up
    assert np.allclose(up[:3], [0, 1, 0])


def test_camera(stage_file, converted):
    s = converted(stage_file('#usda 1.0\n(\n defaultPrim = "World"\n metersPerUnit = 0.01\n upAxis = "Y"\n)\n' + world('''
    def Camera "Cam" {
        float focalLength = 35
        float horizontalAperture = 36
        float verticalAperture = 24
        float2 clippingRange = (10, 5000)
        float fStop = 2.8
        float focusDistance = 250
        double3 xformOp:translate = (0, 100, 500)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }''' + QUAD.format(extra=""))))
    cam = s["cameras"][0]
    assert cam["name"] == "/World/Cam"
    assert cam["projection"]["perspective"]["yfov"] == pytest.approx(2 * math.atan(12 / 35))
    assert cam["projection"]["perspective"]["aspect"] == pytest.approx(1.5)
    assert cam["clip_near"] == pytest.approx(0.1) and cam["clip_far"] == pytest.approx(50)
    # Aperture diameter focal length / f-stop, lens units tenths of a scene unit (cm here).
    assert cam["aperture_radius"] == pytest.approx(35 * 0.1 / 2.8 / 2 * 0.01)
    assert cam["focus_distance"] == pytest.approx(2.5)
    assert cam["transform"][12:15] == pytest.approx([0, 1, 5])
    assert cam["transform"][0] == pytest.approx(1)  # scale removed: an orthonormal frame


CUBE = '''def Mesh "Cube" {
        int[] faceVertexCounts = [4, 4, 4, 4, 4, 4]
        int[] faceVertexIndices = [0, 1, 3, 2, 4, 6, 7, 5, 0, 4, 5, 1, 2, 3, 7, 6, 0, 2, 6, 4, 1, 5, 7, 3]
        point3f[] points = [(-1, -1, -1), (1, -1, -1), (-1, 1, -1), (1, 1, -1), (-1, -1, 1), (1, -1, 1), (-1, 1, 1), (1, 1, 1)]
        %s
    }'''


def test_subdivision_cage_goes_to_the_renderer(stage_file, converted, tmp_path):
    """A catmullClark cube (USD's default scheme) passes its cage, creases, corners, boundary
    rule and face-varying texture coordinates to lucerna, which refines it; its placeholder
    is the cage shaded smooth. Left-handed faces are reversed; a scheme of none is a mesh."""
    write_image(tmp_path / "tex.png", np.full((2, 2, 3), 128))
    s = converted(stage_file(world(CUBE % '''
        int[] creaseIndices = [0, 1, 3]
        int[] creaseLengths = [3]
        float[] creaseSharpnesses = [2.5]
        int[] cornerIndices = [7]
        float[] cornerSharpnesses = [10]
        uniform token interpolateBoundary = "edgeOnly"
        uniform token orientation = "leftHanded"
        texCoord2f[] primvars:st = [(0, 0), (1, 0), (1, 1), (0, 1)] (interpolation = "faceVarying")
        int[] primvars:st:indices = [0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3]
        rel material:binding = </World/Tex>
    ''' + diffuse_texture_material("tex.png"))))
    mesh = s.mesh("/World/Cube")
    assert mesh["normals"] is not None  # the placeholder, shaded smooth
    (sub,) = s["subdivision_surfaces"]
    assert s["meshes"][sub["mesh"]] is mesh
    assert sub["scheme"] == "catmull_clark" and sub["boundary"] == "edge_only"
    assert s.array(sub["face_counts"], "<u4", 1).ravel().tolist() == [4] * 6
    # Left-handed: each face's corners reversed.
    assert s.array(sub["face_indices"], "<u4", 1).ravel()[:4].tolist() == [2, 3, 1, 0]
    creases = s.array(sub["creases"], "<u4", 3)
    assert creases[:, :2].tolist() == [[0, 1], [1, 3]]
    assert creases[:, 2].view("<f4").tolist() == [2.5, 2.5]
    corners = s.array(sub["corners"], "<u4", 2)
    assert corners[0, 0] == 7 and corners[:, 1].view("<f4")[0] == 10
    uvs = s.array(sub["uvs"], "<f4", 2)
    assert uvs.shape == (24, 2)
    assert uvs[:4].tolist() == [[0, 0], [1, 0], [1, 1], [0, 1]]  # (0,1),(1,1),(1,0),(0,0) flipped in v, reversed
    assert s.array(sub["keep"], "<u4", 1).ravel().tolist() == list(range(6))
    assert not s.warnings_about("control cage")
    flat = converted(stage_file(CUBE % 'uniform token subdivisionScheme = "none"', "flat.usda"))
    assert flat.mesh("/Cube")["normals"] is None
    assert flat["subdivision_surfaces"] == []


def test_subdivision_surface_renders_its_limit_shape(stage_file, tmp_path):
    """Seen head-on through an orthographic camera, the cube's cage covers its square. The
    Catmull-Clark limit surface of the cube reaches 68/81 of the half-size at the face
    centres (its widest points), so its silhouette lies between the circle and the square
    of that half-width: between 0.554 and 0.705 of the cage's square. --subdiv-level 4 and
    the default screen-space rule give the same shape."""
    stage = stage_file(CUBE % "" + '''
    def Camera "Cam" {
        token projection = "orthographic"
        float horizontalAperture = 30
        float verticalAperture = 30
        double3 xformOp:translate = (0, 0, 10)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
    def DomeLight "Sky" {
        float inputs:intensity = 1
    }''')
    coverage = {}
    for label, args in [("cage", ["--subdiv-level", "0"]), ("level4", ["--subdiv-level", "4"]),
                        ("auto", [])]:
        out = tmp_path / f"{label}.exr"
        result = subprocess.run([lucerna_bin(), "render", str(stage), "-o", str(out), "--spp", "1",
                                 "--resolution", "90x90", "--aov", "beauty", "-q", *args],
                                capture_output=True, text=True)
        assert result.returncode == 0, result.stderr
        buf = oiio.ImageBuf(str(out))
        alpha = buf.get_pixels(oiio.FLOAT)[..., list(buf.spec().channelnames).index("A")]
        hit = alpha > 0.5
        # The square spans 2 of the aperture's 3 units: 60 x 60 pixels.
        coverage[label] = hit.sum() / 3600.0
    assert coverage["cage"] == pytest.approx(1.0, abs=0.04)
    assert coverage["level4"] == pytest.approx(coverage["auto"], abs=0.02)
    r = 68 / 81
    assert math.pi * r * r / 4 < coverage["level4"] < r * r, coverage


@pytest.mark.parametrize("shape,extent", [
    ('Cylinder "S" {\n        double radius = 0.5\n        double height = 2\n        uniform token axis = "X"\n    }',
     [(-1, -0.5, -0.5), (1, 0.5, 0.5)]),
    ('Cone "S" {\n        double radius = 1\n        double height = 2\n    }', [(-1, -1, -1), (1, 1, 1)]),
    ('Capsule "S" {\n        double radius = 0.5\n        double height = 1\n        uniform token axis = "Y"\n    }',
     [(-0.5, -1, -0.5), (0.5, 1, 0.5)]),
    ('Plane "S" {\n        double width = 2\n        double length = 4\n        uniform token axis = "Y"\n    }',
     [(-1, 0, -2), (1, 0, 2)]),
])
def test_implicit_gprims_are_tessellated_with_outward_normals(stage_file, converted, shape, extent):
    """Cylinder, Cone, Capsule and Plane: their extent along the authored axis, unit
    normals, and triangles wound counter-clockwise seen from where their normals point."""
    s = converted(stage_file("def " + shape + "\n"))
    mesh = s.mesh("/S")
    p = s.positions(mesh).astype(float)
    n = s.array(mesh["normals"], "<f4", 3).astype(float)
    t = s.triangles(mesh)
    assert np.allclose(p.min(0), extent[0], atol=1e-6) and np.allclose(p.max(0), extent[1], atol=1e-6)
    assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-5)
    face = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    area = np.linalg.norm(face, axis=1)
    real = area > 1e-9
    mean_normal = n[t].mean(axis=1)
    assert np.all(np.sum(face[real] * mean_normal[real], axis=1) > 0)
    assert not s.warnings_about("skipped")


def test_points_are_spheres_of_their_widths(stage_file, converted):
    s = converted(stage_file('''def Points "P" {
        point3f[] points = [(0, 0, 0), (2, 0, 0), (4, 0, 0)]
        float[] widths = [0.5, 1, 2] (interpolation = "vertex")
        color3f[] primvars:displayColor = [(1, 0, 0)]
        double3 xformOp:translate = (0, 1, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
'''))
    spheres = s["spheres"]
    assert [sp["radius"] for sp in spheres] == pytest.approx([0.25, 0.5, 1.0])
    assert [sp["centre"] for sp in spheres] == [pytest.approx([x, 1, 0]) for x in (0, 2, 4)]
    assert s["materials"][spheres[0]["material"]]["base_color"] == pytest.approx([1, 0, 0, 1])


def test_subdivision_mesh_with_a_nan_point_still_renders(stage_file):
    """Faces on a NaN point leave the cage (warned); the point itself must not reach the
    renderer, which refuses non-finite cage points."""
    stage = stage_file(world('''
    def Mesh "M" {
        int[] faceVertexCounts = [4, 4]
        int[] faceVertexIndices = [0, 1, 2, 3, 1, 4, 5, 2]
        point3f[] points = [(0,0,0), (1,0,0), (1,1,0), (0,1,0), (2,0,0), (inf,1,0)]
    }'''))
    result = subprocess.run([lucerna_bin(), "inspect", str(stage)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "NaN or infinite" in result.stderr + result.stdout


def test_a_volume_is_skipped_with_its_fields_named(stage_file, converted):
    """A UsdVol.Volume whose density file is missing is skipped: the conversion says so on
    the prim, naming each field's OpenVDB file and grid, and renders the rest of the stage."""
    s = converted(stage_file('''
def Xform "World" {
    def Volume "Smoke" {
        rel field:density = </World/Smoke/density>
        rel field:temperature = </World/Smoke/heat>
        def OpenVDBAsset "density" {
            asset filePath = @./smoke.vdb@
            token fieldName = "density"
        }
        def OpenVDBAsset "heat" {
            asset filePath = @./smoke.vdb@
            token fieldName = "temperature"
        }
    }
    def Sphere "Ball" {
    }
}
'''), no_validate=True)
    assert s.warnings_about("/World/Smoke: Volume skipped: its field 'density': the file ./smoke.vdb cannot be "
                            "found (fields density: ./smoke.vdb[density], temperature: ./smoke.vdb[temperature])")
    assert len(s.manifest["spheres"]) == 1
