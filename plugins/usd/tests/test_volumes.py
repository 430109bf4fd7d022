"""UsdVol Volume prims: the OpenVDB density field becomes a scene-file volume (read by the
renderer), the bound standard_volume shader its medium, in metres."""

import shutil
from pathlib import Path

import numpy as np
import pytest

PLUME = Path(__file__).resolve().parents[3] / "tests" / "assets" / "vdb" / "plume.vdb"
FIRE = PLUME.parent / "fire.vdb"

SHADED = '''
def Xform "World" {
    double3 xformOp:translate = (1, 2, 3)
    uniform token[] xformOpOrder = ["xformOp:translate"]
    def Volume "Smoke" (prepend apiSchemas = ["MaterialBindingAPI"]) {
        rel field:density = </World/Smoke/density>
        rel material:binding = </World/Looks/Smoke>
        def OpenVDBAsset "density" {
            asset filePath = @./smoke.vdb@
            token fieldName = "density"
        }
    }
    def Scope "Looks" {
        def Material "Smoke" {
            token outputs:arnold:volume.connect = </World/Looks/Smoke/standard_volume.outputs:out>
            def Shader "standard_volume" {
                uniform token info:id = "arnold:standard_volume"
                float inputs:density = 50
                float inputs:scatter = 0.8
                color3f inputs:scatter_color = (1, 0.5, 0.25)
                float inputs:scatter_anisotropy = 0.3
                float inputs:emission = 2
                color3f inputs:emission_color = (1, 0.5, 0)
                token inputs:emission_mode = "density"
                token outputs:out
            }
        }
    }
}
'''


def test_a_volume_reads_its_field_and_its_standard_volume_shader(stage_file, converted, tmp_path):
    shutil.copy(PLUME, tmp_path / "smoke.vdb")
    text = SHADED.replace("metersPerUnit = 1", "metersPerUnit = 0.01")
    s = converted(stage_file('#usda 1.0\n(\n    defaultPrim = "World"\n    metersPerUnit = 0.01\n'
                             '    upAxis = "Y"\n)\n' + text), no_validate=True)
    [volume] = s["volumes"]
    assert volume["name"] == "/World/Smoke"
    assert Path(volume["file"]) == tmp_path / "smoke.vdb"
    assert volume["grid"] == "density"
    # Stage units (centimetres) to metres, after the prim's translation.
    to_world = np.array(volume["to_world"]).reshape(4, 4)
    assert np.allclose(to_world, np.diag([0.01, 0.01, 0.01, 1.0]) + np.array(
        [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0.01, 0.02, 0.03, 0]]))
    material = s["materials"][volume["material"]]
    assert material["model"] == "interface"
    medium = material["volume"]
    extinction = 50 / 0.01
    albedo = np.array([0.8, 0.4, 0.2])
    assert np.allclose(medium["scattering"], extinction * albedo)
    assert np.allclose(medium["absorption"], extinction * (1 - albedo))
    assert medium["anisotropy"] == pytest.approx(0.3)
    assert np.allclose(medium["emission"], np.array([2.0, 1.0, 0.0]) / 0.01)
    assert not s.warnings_about("Smoke")


def test_an_unshaded_volume_is_standard_volume_with_its_defaults(stage_file, converted, tmp_path):
    shutil.copy(PLUME, tmp_path / "plume.vdb")
    s = converted(stage_file('''
def Volume "Fog" {
    rel field:smoke = </Fog/smoke>
    def OpenVDBAsset "smoke" {
        asset filePath = @./plume.vdb@
        token fieldName = "density"
    }
}
'''), no_validate=True)
    [volume] = s["volumes"]
    # The field is found by its grid's name, under another relationship name.
    assert volume["grid"] == "density"
    medium = s["materials"][volume["material"]]["volume"]
    assert medium["scattering"] == [0.5, 0.5, 0.5] and medium["absorption"] == [0.5, 0.5, 0.5]
    assert medium["anisotropy"] == 0.0 and medium["emission"] == [0.0, 0.0, 0.0]


def test_volumes_that_cannot_render_are_skipped_with_the_reason(stage_file, converted):
    s = converted(stage_file('''
def Xform "World" {
    def Volume "Missing" {
        rel field:density = </World/Missing/density>
        def OpenVDBAsset "density" {
            asset filePath = @./nowhere.vdb@
        }
    }
    def Volume "Field3D" {
        rel field:density = </World/Field3D/density>
        def Field3DAsset "density" {
            asset filePath = @./smoke.f3d@
        }
    }
    def Volume "Empty" {
    }
    def Sphere "Ball" {
    }
}
'''), no_validate=True)
    assert "volumes" not in s.manifest
    assert s.warnings_about("/World/Missing: Volume skipped: its field 'density': the file ./nowhere.vdb "
                            "cannot be found")
    assert s.warnings_about("/World/Field3D: Volume skipped: its field 'density' (/World/Field3D/density) "
                            "is Field3DAsset, not an OpenVDBAsset")
    assert s.warnings_about("/World/Empty: Volume skipped: it has no field 'density' (fields: none)")


def test_blackbody_emission_reads_the_temperature_field(stage_file, converted, tmp_path):
    """standard_volume's default emission_mode is blackbody: the field temperature_channel
    names glows, at temperature x blackbody_kelvin kelvin per unit, scaled by emission x
    emission_color x blackbody_intensity per stage unit."""
    shutil.copy(PLUME, tmp_path / "smoke.vdb")
    text = SHADED.replace('                token inputs:emission_mode = "density"\n',
                          '                float inputs:temperature = 0.5\n'
                          '                float inputs:blackbody_kelvin = 4000\n'
                          '                float inputs:blackbody_intensity = 3\n')
    text = text.replace('        rel field:density = </World/Smoke/density>\n',
                        '        rel field:density = </World/Smoke/density>\n'
                        '        rel field:temperature = </World/Smoke/heat>\n'
                        '        def OpenVDBAsset "heat" {\n'
                        '            asset filePath = @./smoke.vdb@\n'
                        '            token fieldName = "temperature"\n'
                        '        }\n')
    s = converted(stage_file('#usda 1.0\n(\n    defaultPrim = "World"\n    metersPerUnit = 0.01\n'
                             '    upAxis = "Y"\n)\n' + text), no_validate=True)
    [volume] = s["volumes"]
    assert volume["temperature"] == {"file": str(tmp_path / "smoke.vdb"), "grid": "temperature"}
    medium = s["materials"][volume["material"]]["volume"]
    assert medium["emission"] == [0.0, 0.0, 0.0]
    blackbody = medium["blackbody"]
    assert blackbody["kelvin"] == pytest.approx(2000.0) and blackbody["intensity"] == pytest.approx(3.0)
    assert np.allclose(blackbody["tint"], np.array([2.0, 1.0, 0.0]) / 0.01)
    assert not s.warnings_about("Smoke")


def test_blackbody_without_a_temperature_field_is_reported(stage_file, converted, tmp_path):
    shutil.copy(PLUME, tmp_path / "smoke.vdb")
    text = SHADED.replace('token inputs:emission_mode = "density"', 'token inputs:emission_mode = "blackbody"')
    s = converted(stage_file(text), no_validate=True)
    [volume] = s["volumes"]
    assert "temperature" not in volume
    medium = s["materials"][volume["material"]]["volume"]
    assert "blackbody" not in medium and medium["emission"] == [0.0, 0.0, 0.0]
    assert s.warnings_about("/World/Smoke: blackbody emission needs a temperature field: it has no field "
                            "'temperature'")


def test_emission_channel_reads_its_field(stage_file, converted, tmp_path):
    """emission_mode "channel": the field emission_channel names glows at its value x
    emission x emission_color per stage unit, not scaled by the density."""
    shutil.copy(FIRE, tmp_path / "smoke.vdb")
    text = SHADED.replace('token inputs:emission_mode = "density"',
                          'token inputs:emission_mode = "channel"\n'
                          '                string inputs:emission_channel = "temperature"')
    text = text.replace('        rel field:density = </World/Smoke/density>\n',
                        '        rel field:density = </World/Smoke/density>\n'
                        '        rel field:glow = </World/Smoke/glow>\n'
                        '        def OpenVDBAsset "glow" {\n'
                        '            asset filePath = @./smoke.vdb@\n'
                        '            token fieldName = "temperature"\n'
                        '        }\n')
    s = converted(stage_file('#usda 1.0\n(\n    defaultPrim = "World"\n    metersPerUnit = 0.01\n'
                             '    upAxis = "Y"\n)\n' + text), no_validate=True)
    [volume] = s["volumes"]
    assert volume["emission"] == {"file": str(tmp_path / "smoke.vdb"), "grid": "temperature"}
    assert "temperature" not in volume
    medium = s["materials"][volume["material"]]["volume"]
    assert medium["emission"] == [0.0, 0.0, 0.0] and "blackbody" not in medium
    assert np.allclose(medium["emission_field"]["tint"], np.array([2.0, 1.0, 0.0]) / 0.01)
    assert not s.warnings_about("Smoke")


def test_emission_channel_without_its_field_is_reported(stage_file, converted, tmp_path):
    shutil.copy(PLUME, tmp_path / "smoke.vdb")
    text = SHADED.replace('token inputs:emission_mode = "density"', 'token inputs:emission_mode = "channel"')
    s = converted(stage_file(text), no_validate=True)
    [volume] = s["volumes"]
    assert "emission" not in volume
    medium = s["materials"][volume["material"]]["volume"]
    assert "emission_field" not in medium and medium["emission"] == [0.0, 0.0, 0.0]
    assert s.warnings_about("/World/Smoke: the emission channel needs its field: it has no field 'heat'")


def test_scatter_color_channel_reads_its_field(stage_file, converted, tmp_path):
    """scatter_color_channel names the colour field that tints the scattering: the volume
    entry carries it; a transparency colour is still reported, an empty transparency
    channel and a black transparency say nothing."""
    shutil.copy(PLUME, tmp_path / "smoke.vdb")
    text = SHADED.replace('token inputs:emission_mode = "density"',
                          'token inputs:emission_mode = "density"\n'
                          '                string inputs:scatter_color_channel = "Cd"\n'
                          '                string inputs:transparent_channel = ""\n'
                          '                color3f inputs:transparent = (0.1, 0.1, 0.1)')
    text = text.replace('        rel field:density = </World/Smoke/density>\n',
                        '        rel field:density = </World/Smoke/density>\n'
                        '        rel field:Cd = </World/Smoke/colour>\n'
                        '        def OpenVDBAsset "colour" {\n'
                        '            asset filePath = @./smoke.vdb@\n'
                        '            token fieldName = "velocity"\n'
                        '        }\n')
    s = converted(stage_file(text), no_validate=True)
    [volume] = s["volumes"]
    assert volume["scatter_color"] == {"file": str(tmp_path / "smoke.vdb"), "grid": "velocity"}
    assert s.warnings_about("/World/Smoke: standard_volume inputs not read (lucerna reads no "
                            "transparency): transparent = (0.1, 0.1, 0.1)")
    assert not s.warnings_about("scatter_color") and not s.warnings_about("transparent_channel")


def test_scatter_color_channel_without_its_field_is_reported(stage_file, converted, tmp_path):
    shutil.copy(PLUME, tmp_path / "smoke.vdb")
    text = SHADED.replace('token inputs:emission_mode = "density"',
                          'token inputs:emission_mode = "density"\n'
                          '                string inputs:scatter_color_channel = "Cd"')
    s = converted(stage_file(text), no_validate=True)
    [volume] = s["volumes"]
    assert "scatter_color" not in volume
    assert s.warnings_about("/World/Smoke: scatter_color_channel is not read: it has no field 'Cd'")


def _render(scene, out, *args, env="1,1,1"):
    import subprocess
    import OpenImageIO as oiio
    from conftest import lucerna_bin
    result = subprocess.run([lucerna_bin(), "render", str(scene), "-o", str(out), "--resolution", "48x48",
                             "--spp", "64", "--env", env, *args], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)[:, :, :3]


def _box_twin(folder, lo, hi, camera, medium):
    """Writes folder/twin.gltf: an interface box from `lo` to `hi` holding `medium`
    (extras.lucerna.medium), seen by the 50 mm camera of the stages here at `camera`."""
    import json
    corners = [[(lo, hi)[i & 1][0], (lo, hi)[i >> 1 & 1][1], (lo, hi)[i >> 2 & 1][2]] for i in range(8)]
    triangles = [0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6, 0, 1, 5, 0, 5, 4, 2, 6, 7, 2, 7, 3, 0, 4, 6, 0, 6, 2,
                 1, 3, 7, 1, 7, 5]
    positions = np.asarray(corners, dtype="<f4").tobytes()
    indices = np.asarray(triangles, dtype="<u4").tobytes()
    (folder / "box.bin").write_bytes(positions + indices)
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"mesh": 0}, {"camera": 0, "translation": list(camera)}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": float(2 * np.arctan(20.955 / 100)),
                                                              "aspectRatio": 1.0, "znear": 0.01}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [{"extras": {"lucerna": {"bsdf": "interface", "medium": medium}}}],
        "buffers": [{"uri": "box.bin", "byteLength": len(positions) + len(indices)}],
        "bufferViews": [{"buffer": 0, "byteLength": len(positions)},
                        {"buffer": 0, "byteOffset": len(positions), "byteLength": len(indices)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3",
                       "min": [float(v) for v in lo], "max": [float(v) for v in hi]},
                      {"bufferView": 1, "componentType": 5125, "count": 36, "type": "SCALAR"}],
    }
    (folder / "twin.gltf").write_text(json.dumps(doc))


def _agree_within_noise(usd, gltf):
    """The box is placed by an instance's transform in one and baked into the positions in
    the other, so hit points differ in their last bits, and with them the seeds of the
    walks through the grid: the renders differ by noise, and the mean difference stays
    within 4 standard errors of the pixels'."""
    difference = (usd - gltf).mean(axis=2).ravel()
    error = difference.std() / np.sqrt(difference.size)
    assert abs(difference.mean()) < 4 * error, (difference.mean(), error)


def test_a_volume_renders_as_its_gltf_twin(stage_file, tmp_path):
    """The plume as a USD Volume (standard_volume: density 90, albedo (0.9, 0.8, 0.65),
    g 0.3) renders as the same grid inside the same box in glTF: the box the renderer puts
    around a Volume is the grid's padded box, so both follow the same paths."""
    shutil.copy(PLUME, tmp_path / "plume.vdb")
    camera = '''
def Camera "Camera" {
    float focalLength = 50
    float horizontalAperture = 20.955
    float verticalAperture = 20.955
    float2 clippingRange = (0.01, 100)
    double3 xformOp:translate = (0.28, 0.18, 1.2)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}
'''
    volume = '''
def Volume "Plume" (prepend apiSchemas = ["MaterialBindingAPI"]) {
    rel field:density = </Plume/density>
    rel material:binding = </Smoke>
    def OpenVDBAsset "density" {
        asset filePath = @./plume.vdb@
    }
}
def Material "Smoke" {
    token outputs:volume.connect = </Smoke/V.outputs:out>
    def Shader "V" {
        uniform token info:id = "arnold:standard_volume"
        float inputs:density = 90
        color3f inputs:scatter_color = (0.9, 0.8, 0.65)
        float inputs:scatter_anisotropy = 0.3
        token outputs:out
    }
}
'''
    stage = stage_file(camera + volume)
    # The grid's padded box: index points 0 to 36 (active 2..35, 0..35, 3..33, one voxel of
    # background around), half a voxel beyond, placed by the grid's transform.
    lo_index, hi_index = np.array([1, -1, 2]) - 0.5, np.array([36, 36, 34]) + 0.5
    voxel, origin = 0.009, np.array([0.1045, 0.0045, 0.1245])
    lo, hi = origin + voxel * lo_index, origin + voxel * hi_index
    extinction, albedo = 90.0, np.array([0.9, 0.8, 0.65])
    _box_twin(tmp_path, lo, hi, (0.28, 0.18, 1.2), {
        "scattering": list(extinction * albedo), "absorption": list(extinction * (1 - albedo)),
        "anisotropy": 0.3, "density": "plume.vdb"})
    usd = _render(stage, tmp_path / "usd.exr", "--no-validate")
    gltf = _render(tmp_path / "twin.gltf", tmp_path / "gltf.exr")
    # The plume is there: its pixels are darker than the white environment behind it.
    assert usd.min() < 0.5 and usd.max() > 0.9
    _agree_within_noise(usd, gltf)


FIRE_STAGE = '''
def Camera "Camera" {
    float focalLength = 50
    float horizontalAperture = 20.955
    float verticalAperture = 20.955
    float2 clippingRange = (0.01, 100)
    double3 xformOp:translate = (0, 0.2, 1.0)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}
def Volume "Fire" (prepend apiSchemas = ["MaterialBindingAPI"]) {
    rel field:density = </Fire/density>
    rel field:temperature = </Fire/temperature>
    rel material:binding = </Flame>
    def OpenVDBAsset "density" {
        asset filePath = @./fire.vdb@
        token fieldName = "density"
    }
    def OpenVDBAsset "temperature" {
        asset filePath = @./fire.vdb@
        token fieldName = "temperature"
    }
}
def Material "Flame" {
    token outputs:volume.connect = </Flame/V.outputs:out>
    def Shader "V" {
        uniform token info:id = "arnold:standard_volume"
        float inputs:density = 20
        color3f inputs:scatter_color = (0.3, 0.3, 0.3)
        float inputs:blackbody_kelvin = 3000
        token outputs:out
    }
}
'''


def test_a_fire_renders_as_its_gltf_twin(stage_file, tmp_path):
    """A fire (tests/assets/vdb/fire.vdb: smoke, and a temperature grid reaching below it)
    as a USD Volume with standard_volume blackbody emission renders as its glTF twin, whose
    interface box holds both grids: the box the renderer puts around a Volume covers the
    temperature grid too, so the flame's foot is not cut off."""
    shutil.copy(FIRE, tmp_path / "fire.vdb")
    stage = stage_file(FIRE_STAGE)
    # The union of the grids' padded boxes (index -1.5 to 32.5, 56.5 in y: the density's
    # active voxels 0..31, 11..55, 0..31, the temperature's 8..23, 0..39, 8..23), 1 cm voxels.
    origin = np.array([-0.16, 0.0, -0.16])
    lo, hi = origin + 0.01 * np.array([-1.5, -1.5, -1.5]), origin + 0.01 * np.array([32.5, 56.5, 32.5])
    _box_twin(tmp_path, lo, hi, (0.0, 0.2, 1.0), {
        "scattering": [6.0, 6.0, 6.0], "absorption": [14.0, 14.0, 14.0], "density": "fire.vdb",
        "density_grid": "density", "blackbody": {"temperature": "fire.vdb", "kelvin": 3000.0}})
    usd = _render(stage, tmp_path / "usd.exr", "--no-validate", env="0.02,0.02,0.02")
    gltf = _render(tmp_path / "twin.gltf", tmp_path / "gltf.exr", env="0.02,0.02,0.02")
    # The flame glows orange against the dim sky, down to its foot below the smoke.
    assert usd.max() > 0.2 and (usd[..., 0] > 2 * usd[..., 2]).any()
    foot = usd[34:44, 20:28].mean(axis=(0, 1))
    assert foot[0] > 0.05, foot
    _agree_within_noise(usd, gltf)


def test_an_emission_channel_renders_as_its_gltf_twin(stage_file, tmp_path):
    """The fire's `temperature` grid read as an emission channel (standard_volume
    emission_mode "channel": radiance per metre = value x emission x emission_color) renders
    as its glTF twin's emission field, and glows where the grid does, below the smoke too."""
    shutil.copy(FIRE, tmp_path / "fire.vdb")
    text = FIRE_STAGE.replace('        float inputs:blackbody_kelvin = 3000\n',
                              '        token inputs:emission_mode = "channel"\n'
                              '        string inputs:emission_channel = "temperature"\n'
                              '        float inputs:emission = 2\n'
                              '        color3f inputs:emission_color = (1, 0.5, 0.2)\n')
    stage = stage_file(text)
    origin = np.array([-0.16, 0.0, -0.16])
    lo, hi = origin + 0.01 * np.array([-1.5, -1.5, -1.5]), origin + 0.01 * np.array([32.5, 56.5, 32.5])
    _box_twin(tmp_path, lo, hi, (0.0, 0.2, 1.0), {
        "scattering": [6.0, 6.0, 6.0], "absorption": [14.0, 14.0, 14.0], "density": "fire.vdb",
        "density_grid": "density",
        "emission_field": {"file": "fire.vdb", "grid": "temperature", "tint": [2.0, 1.0, 0.4]}})
    usd = _render(stage, tmp_path / "usd.exr", "--no-validate", env="0.02,0.02,0.02")
    gltf = _render(tmp_path / "twin.gltf", tmp_path / "gltf.exr", env="0.02,0.02,0.02")
    # The glow has the emission colour's hue (red twice green, five times blue) where it is
    # bright, down to the foot below the smoke.
    bright = usd[..., 0] > 0.1
    assert bright.any()
    ratio = usd[bright].mean(axis=0)
    assert 1.7 < ratio[0] / ratio[1] < 2.3 and ratio[0] / ratio[2] > 3.0, ratio
    foot = usd[34:44, 20:28].mean(axis=(0, 1))
    assert foot[0] > 0.05, foot
    _agree_within_noise(usd, gltf)
