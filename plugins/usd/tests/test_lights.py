"""UsdLux lights: shapes, units (intensity, exposure, colour, temperature, normalize), the
dome's orientation (rendered)."""

import math
import subprocess

import numpy as np
import OpenImageIO as oiio
import pytest

from conftest import lucerna_bin


def world(body):
    return 'def Xform "World" {\n' + body + "\n}\n"


def emitter(s, material_index):
    m = s["materials"][material_index]
    assert m["model"] == "lambert" and m["base_color"][:3] == [0, 0, 0] and not m["double_sided"]
    return m["emissive"]


def mesh_area_and_normals(s, mesh):
    p = s.positions(mesh).astype(float)
    t = s.triangles(mesh)
    n = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    return 0.5 * np.linalg.norm(n, axis=1).sum(), n / np.linalg.norm(n, axis=1, keepdims=True), p[t].mean(axis=1)


def test_rect_light_units_and_orientation(stage_file, converted):
    s = converted(stage_file(world('''
    def RectLight "Plain" {
        float inputs:width = 2
        float inputs:height = 1
        float inputs:intensity = 3
        float inputs:exposure = 1
        color3f inputs:color = (1, 0.5, 0.25)
    }
    def RectLight "Normalized" {
        float inputs:width = 2
        float inputs:height = 1
        float inputs:intensity = 3
        bool inputs:normalize = 1
        double3 xformOp:scale = (2, 2, 2)
        uniform token[] xformOpOrder = ["xformOp:scale"]
    }''')))
    plain = s.mesh("/World/Plain")
    assert emitter(s, plain["material"]) == pytest.approx([6, 3, 1.5])
    area, normals, _ = mesh_area_and_normals(s, plain)
    assert area == pytest.approx(2.0) and np.allclose(normals, [0, 0, -1])  # emits along -Z
    # normalize divides by the world area: 2 x 1 scaled by 2 is 8.
    assert emitter(s, s.mesh("/World/Normalized")["material"]) == pytest.approx([3 / 8] * 3)


def test_disk_and_cylinder_lights_are_analytic_shapes(stage_file, converted):
    s = converted(stage_file(world('''
    def DiskLight "Disk" {
        float inputs:radius = 0.5
        float inputs:intensity = 2
        bool inputs:normalize = 1
        double3 xformOp:translate = (1, 2, 3)
        double3 xformOp:rotateXYZ = (90, 0, 0)
        double3 xformOp:scale = (2, 2, 1)
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ", "xformOp:scale"]
    }
    def CylinderLight "Tube" {
        float inputs:radius = 0.25
        float inputs:length = 2
        bool inputs:normalize = 1
        float inputs:intensity = 10
        double3 xformOp:rotateXYZ = (0, 0, 90)
        double3 xformOp:scale = (3, 1, 1)
        uniform token[] xformOpOrder = ["xformOp:rotateXYZ", "xformOp:scale"]
    }''')))
    assert not s["meshes"]
    (disk,), (tube,) = s["disks"], s["cylinders"]
    assert disk["centre"] == pytest.approx([1, 2, 3]) and disk["radius"] == pytest.approx(1.0)
    assert disk["normal"] == pytest.approx([0, 1, 0], abs=1e-9)  # local -Z turned by +90 about X
    assert emitter(s, disk["material"]) == pytest.approx([2 / math.pi] * 3)  # area pi * 1^2
    assert tube["axis"] == pytest.approx([0, 1, 0], abs=1e-9)  # local X turned by 90 about Z
    assert tube["radius"] == pytest.approx(0.25) and tube["length"] == pytest.approx(6.0)
    assert emitter(s, tube["material"]) == pytest.approx([10 / (2 * math.pi * 0.25 * 6)] * 3)


def test_elliptic_disk_and_cylinder_lights_are_polygons_with_their_true_area(stage_file, converted):
    s = converted(stage_file(world('''
    def DiskLight "Disk" {
        float inputs:radius = 0.5
        double3 xformOp:scale = (1, 1.5, 1)
        uniform token[] xformOpOrder = ["xformOp:scale"]
    }
    def CylinderLight "Tube" {
        float inputs:radius = 0.25
        float inputs:length = 2
        bool inputs:normalize = 1
        float inputs:intensity = 10
        double3 xformOp:scale = (1, 1, 2)
        uniform token[] xformOpOrder = ["xformOp:scale"]
    }''')))
    assert not s["disks"] and not s["cylinders"]
    assert len(s.warnings_about("is rendered as a 64-sided polygon mesh")) == 2
    area, normals, _ = mesh_area_and_normals(s, s.mesh("/World/Disk"))
    assert area == pytest.approx(math.pi * 0.25, rel=1e-6) and np.allclose(normals, [0, 0, -1])  # object space
    tube = s.mesh("/World/Tube")
    _, normals, centres = mesh_area_and_normals(s, tube)
    assert np.abs(normals[:, 0]).max() < 1e-6  # no end caps
    radial = centres * [0, 1, 1]
    assert (np.einsum("ij,ij->i", normals, radial) > 0).all()  # outwards, along the X axis


def test_sphere_light_and_treat_as_point(stage_file, converted):
    s = converted(stage_file(world('''
    def SphereLight "Ball" {
        float inputs:radius = 0.5
        float inputs:intensity = 4
        bool inputs:normalize = 1
        double3 xformOp:translate = (1, 2, 3)
        double3 xformOp:scale = (2, 2, 2)
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:scale"]
    }
    def SphereLight "Bulb" {
        float inputs:radius = 0.1
        float inputs:intensity = 5
        bool treatAsPoint = 1
    }''')))
    (ball,) = s["spheres"]
    assert ball["centre"] == [1, 2, 3] and ball["radius"] == pytest.approx(1.0)
    assert emitter(s, ball["material"]) == pytest.approx([4 / (4 * math.pi)] * 3)
    (bulb,) = s["lights"]
    # Radiant intensity of the sphere it stands for: L * pi * r^2.
    assert bulb["kind"]["point"]["intensity"] == pytest.approx([5 * math.pi * 0.01] * 3)


def test_distant_light_direction_and_irradiance(stage_file, converted):
    s = converted(stage_file(world('''
    def DistantLight "Sun" {
        float inputs:intensity = 2
        float inputs:angle = 0.53
        double3 xformOp:rotateXYZ = (-90, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:rotateXYZ"]
    }
    def DistantLight "Normalized" {
        float inputs:intensity = 2
        bool inputs:normalize = 1
    }''')))
    sun, normalized = (l["kind"]["directional"] for l in s["lights"])
    assert sun["direction"] == pytest.approx([0, -1, 0], abs=1e-9)  # -Z turned to -Y: downwards
    half = math.radians(0.53) / 2
    assert sun["irradiance"] == pytest.approx([2 * math.pi * math.sin(half) ** 2] * 3)
    assert normalized["irradiance"] == pytest.approx([2, 2, 2])  # normalized: irradiance
    assert sun["angle"] == pytest.approx(math.radians(0.53))
    assert normalized["angle"] == pytest.approx(math.radians(0.53))  # the schema's default
    assert s["warnings"] == ["stage: no renderable geometry"]  # the angle is kept, not warned about


def test_color_temperature(stage_file, converted):
    s = converted(stage_file(world('''
    def DistantLight "White" {
        bool inputs:enableColorTemperature = 1
        float inputs:intensity = 1
        float inputs:colorTemperature = 6500
        bool inputs:normalize = 1
    }
    def DistantLight "Warm" {
        bool inputs:enableColorTemperature = 1
        float inputs:intensity = 1
        float inputs:colorTemperature = 3000
        bool inputs:normalize = 1
    }''')))
    white, warm = (l["kind"]["directional"]["irradiance"] for l in s["lights"])
    assert white == pytest.approx([1, 1, 1])
    assert warm[0] > warm[1] > warm[2]


def test_constant_dome(stage_file, converted):
    s = converted(stage_file(world('def DomeLight "Sky" {\n float inputs:intensity = 0.5\n'
                                   ' color3f inputs:color = (1, 0.5, 1)\n}')))
    assert s["environment"] == {"constant": [0.5, 0.25, 0.5]}


def render(path, out, *args):
    subprocess.run([lucerna_bin(), "render", str(path), "-o", str(out), "-q", *map(str, args)],
                   check=True, capture_output=True)
    return oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)[..., :3]


@pytest.mark.parametrize("up", ["Y", "Z"])
def test_dome_texture_orientation_follows_openexr_latlong(stage_file, tmp_path, up):
    # A black map with a bright band at longitude +pi/2, which OpenEXR's lat-long
    # convention (and USD's DomeLight) puts along +X: u = 0.5 - longitude / 2 pi = 0.25.
    w, h = 32, 16
    pixels = np.zeros((h, w, 3), np.float32)
    pixels[4:12, 6:10] = 50.0
    out = oiio.ImageOutput.create(str(tmp_path / "sky.exr"))
    out.open(str(tmp_path / "sky.exr"), oiio.ImageSpec(w, h, 3, oiio.FLOAT))
    out.write_image(pixels)
    out.close()
    # The camera looks along -Z from +Z (Y up): image right is +X. For a Z-up stage the
    # same view: a DomeLight_1 whose pole follows the stage's up axis, the camera looking
    # along +Y from -Y.
    if up == "Y":
        dome = 'def DomeLight "Sky" {\n asset inputs:texture:file = @./sky.exr@\n}'
        camera = 'double3 xformOp:translate = (0, 0, 5)\n uniform token[] xformOpOrder = ["xformOp:translate"]'
    else:
        dome = 'def DomeLight_1 "Sky" {\n asset inputs:texture:file = @./sky.exr@\n}'
        camera = ('double3 xformOp:translate = (0, -5, 0)\n double3 xformOp:rotateXYZ = (90, 0, 0)\n'
                  ' uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]')
    text = (f'#usda 1.0\n(\n defaultPrim = "World"\n metersPerUnit = 1\n upAxis = "{up}"\n)\n'
            + world(dome + f'\n def Camera "Cam" {{\n {camera}\n }}\n def Sphere "Ball" {{\n double radius = 1\n }}'))
    image = render(stage_file(text), tmp_path / "dome.exr", "--spp", "16", "--resolution", "32x32")
    ball = image[8:24]
    left, right = ball[:, 4:14].mean(), ball[:, 18:28].mean()
    assert right > 10 * left, (left, right)


def test_light_group_attribute_puts_lights_in_groups(stage_file, converted):
    s = converted(stage_file(world('''
    def SphereLight "Key" {
        float inputs:radius = 0.1
        string lucerna:lightGroup = "Warm"
    }
    def SphereLight "Fill" {
        float inputs:radius = 0.1
        string lucerna:lightGroup = "warm"
        double3 xformOp:translate = (1, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
    def DistantLight "Sun" {
        string lucerna:lightGroup = "bad name"
    }
    def Sphere "Ball" {
        double radius = 0.5
    }
    ''')))
    assert s["light_groups"] == [{"name": "warm", "members": ["/World/Key", "/World/Fill"]}]
    assert any("lucerna:lightGroup" in w and "/World/Sun" in w for w in s["warnings"])


def test_attributes_without_the_inputs_prefix_are_read(stage_file, converted):
    """UsdLux before 21.05 (and many exporters) wrote `intensity`, not `inputs:intensity`;
    where both are authored the prefixed one wins."""
    s = converted(stage_file(world(
        'def DistantLight "Old" {\n float intensity = 3\n color3f color = (1, 0.5, 0.25)\n'
        ' float exposure = 1\n float angle = 0\n}\n'
        'def DistantLight "Both" {\n float intensity = 100\n float inputs:intensity = 2\n'
        ' float inputs:angle = 0\n}')), no_validate=True)
    old, both = (l["kind"]["directional"] for l in s["lights"])
    assert old["irradiance"] == pytest.approx([6, 3, 1.5])
    assert both["irradiance"] == pytest.approx([2, 2, 2])


def test_a_shaped_point_light_is_a_spot_light(stage_file, converted):
    s = converted(stage_file(world(
        'def SphereLight "Spot" (prepend apiSchemas = ["ShapingAPI"]) {\n'
        ' float inputs:intensity = 10\n float inputs:radius = 0.1\n bool treatAsPoint = 1\n'
        ' float inputs:shaping:cone:angle = 30\n float inputs:shaping:cone:softness = 0.5\n'
        ' float inputs:shaping:focus = 2\n}\n'
        'def RectLight "Panel" (prepend apiSchemas = ["ShapingAPI"]) {\n'
        ' float inputs:shaping:cone:angle = 20\n}')))
    spot = s["lights"][0]["kind"]["spot"]
    assert spot["outer_cone"] == pytest.approx(math.radians(30))
    assert spot["inner_cone"] == pytest.approx(math.radians(15))
    assert spot["direction"] == pytest.approx([0, 0, -1])
    assert spot["intensity"] == pytest.approx([10 * math.pi * 0.01] * 3)
    assert s.warnings_about("/World/Spot: shaping:focus 2.0 is not supported")
    assert s.warnings_about("/World/Panel: shaping:cone:angle on a RectLight is not supported")


def test_domes_add_up(stage_file, converted, tmp_path):
    s = converted(stage_file(world(
        'def DomeLight "A" {\n float inputs:intensity = 0.5\n}\n'
        'def DomeLight "B" {\n color3f inputs:color = (0.25, 0.5, 1)\n}')))
    assert s["environment"] == {"constant": pytest.approx([0.75, 1.0, 1.5])}
    pixels = np.zeros((8, 16, 3), np.float32)
    pixels[2:6, 4:8] = 2.0
    out = oiio.ImageOutput.create(str(tmp_path / "sky.exr"))
    out.open(str(tmp_path / "sky.exr"), oiio.ImageSpec(16, 8, 3, oiio.FLOAT))
    out.write_image(pixels)
    out.close()
    s = converted(stage_file(world(
        'def DomeLight "Map" {\n asset inputs:texture:file = @./sky.exr@\n float inputs:intensity = 2\n}\n'
        'def DomeLight "Map2" {\n asset inputs:texture:file = @./sky.exr@\n}\n'
        'def DomeLight "Fill" {\n float inputs:intensity = 0.1\n}'), name="maps.usda"))
    env = s["environment"]["lat_long"]
    assert env["scale"] == [1.0, 1.0, 1.0]
    t = s["textures"][env["texture"]]
    texels = s.array(t["texels"], "<f4", 4).reshape(t["height"], t["width"], 4)
    assert texels[3, 5, :3] == pytest.approx([2 * 2 + 2 + 0.1] * 3)
    assert texels[0, 0, :3] == pytest.approx([0.1] * 3)
    assert not s.warnings_about("dome")


def test_light_linking_is_warned_about(stage_file, converted):
    s = converted(stage_file(world(
        'def SphereLight "Key" (prepend apiSchemas = ["CollectionAPI:lightLink"]) {\n'
        ' uniform bool collection:lightLink:includeRoot = 0\n'
        ' rel collection:lightLink:includes = </World/Ball>\n}\n'
        'def Sphere "Ball" {\n}')))
    assert s.warnings_about("/World/Key: light linking (lightLink/shadowLink) is not honoured")


def test_a_mesh_light_emits_its_radiance(stage_file, converted):
    s = converted(stage_file(world(
        'def Mesh "Panel" (prepend apiSchemas = ["MeshLightAPI"]) {\n'
        ' int[] faceVertexCounts = [4]\n int[] faceVertexIndices = [0, 1, 2, 3]\n'
        ' point3f[] points = [(0, 0, 0), (2, 0, 0), (2, 2, 0), (0, 2, 0)]\n'
        ' float inputs:intensity = 8\n bool inputs:normalize = 1\n}')))
    material = s["materials"][s.mesh("/World/Panel")["material"]]
    assert material["emissive"] == pytest.approx([2, 2, 2])  # 8 over 4 square units


def test_a_shaped_spot_renders_its_analytic_falloff(stage_file, converted, tmp_path):
    """A ShapingAPI spot 1 m above a white Lambertian floor (ior 1: no specular), seen by
    an orthographic camera from above: each pixel of the direct light is
    I falloff(theta) cos^3(theta) / (pi h^2), falloff the squared ramp in cos theta between
    the cone angle and angle (1 - softness) (docs: lights.py), averaged over the pixel."""
    stage = stage_file(world('''
    def SphereLight "Spot" (prepend apiSchemas = ["ShapingAPI"]) {
        float inputs:intensity = 10
        float inputs:radius = 0.1
        bool treatAsPoint = 1
        float inputs:shaping:cone:angle = 30
        float inputs:shaping:cone:softness = 0.5
        double3 xformOp:translate = (0, 1, 0)
        float3 xformOp:rotateXYZ = (-90, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]
    }
    def Mesh "Floor" (prepend apiSchemas = ["MaterialBindingAPI"]) {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(-3, 0, -3), (-3, 0, 3), (3, 0, 3), (3, 0, -3)]
        uniform token subdivisionScheme = "none"
        rel material:binding = </World/White>
    }
    def Material "White" {
        token outputs:surface.connect = </World/White/S.outputs:surface>
        def Shader "S" {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor = (1, 1, 1)
            float inputs:roughness = 1
            float inputs:ior = 1
            token outputs:surface
        }
    }
    def Camera "Top" {
        token projection = "orthographic"
        float horizontalAperture = 20
        float verticalAperture = 20
        double3 xformOp:translate = (0, 5, 0)
        float3 xformOp:rotateXYZ = (-90, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]
    }'''))
    s = converted(stage)
    spot = s["lights"][0]["kind"]["spot"]
    intensity = spot["intensity"][0]
    size = 64
    out = tmp_path / "spot.exr"
    done = subprocess.run([lucerna_bin(), "render", str(stage), "-o", str(out), "--spp", "16",
                           "--resolution", f"{size}x{size}", "--filter", "box", "--aov", "direct",
                           "--max-depth", "1", "--rr", "off", "-q"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    buf = oiio.ImageBuf(str(out))
    names = list(buf.spec().channelnames)
    image = buf.get_pixels(oiio.FLOAT)[..., names.index("direct.G")]

    cos_outer, cos_inner = math.cos(math.radians(30)), math.cos(math.radians(15))
    sub = (np.arange(8) + 0.5) / 8

    def expected(i, j):
        """The analytic radiance averaged over pixel (row i, column j) of the 2 m view."""
        x = -1 + (j + sub[None, :]) * 2 / size
        z = -1 + (i + sub[:, None]) * 2 / size
        cos_t = 1 / np.sqrt(1 + x * x + z * z)
        ramp = np.clip((cos_t - cos_outer) / (cos_inner - cos_outer), 0, 1) ** 2
        return float(np.mean(intensity * ramp * cos_t ** 3 / math.pi))

    row = size // 2
    want = np.array([expected(row, j) for j in range(size)])
    got = image[row].astype(float)
    # The peak, the ramp and the dark outside: within 2 % of the peak everywhere.
    assert want.max() > 0 and np.abs(got - want).max() < 0.02 * want.max(), (got, want)
    ramp = (want > 0.05 * want.max()) & (want < 0.95 * want.max())
    assert ramp.sum() >= 6  # the test sees the falloff, not just the core
