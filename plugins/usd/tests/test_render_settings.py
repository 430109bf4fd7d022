"""UsdRender: a stage's RenderSettings, products and vars decide the camera, size, data
window, files and layers of the render (render_settings.py, `lucerna render` without -o)."""

import subprocess

import numpy as np
import OpenImageIO as oiio
import pytest

from conftest import lucerna_bin

STAGE = '''#usda 1.0
(
    defaultPrim = "World"
    metersPerUnit = 1
    upAxis = "Y"
    renderSettingsPrimPath = "/Render/Settings"
    startTimeCode = 7
    endTimeCode = 7
)
def Xform "World" {
    def Sphere "Ball" {
        double radius = 1
    }
    def Camera "Front" {
        float focalLength = 35
        float horizontalAperture = 36
        float verticalAperture = 24
        double3 xformOp:translate = (0, 0, 10)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
    def Camera "Side" {
        float focalLength = 35
        float horizontalAperture = 24
        float verticalAperture = 24
        double3 xformOp:translate = (10, 0, 0)
        float3 xformOp:rotateXYZ = (0, 90, 0)
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]
    }
    def DomeLight "Sky" {
        float inputs:intensity = 1
    }
}
def Scope "Render" {
    def RenderSettings "Settings" {
        rel camera = </World/Front>
        int2 resolution = (60, 40)
        rel products = [</Render/Beauty>, </Render/Data>, </Render/Extra>]
    }
    def RenderSettings "OtherSettings" {
        rel camera = </World/Side>
        int2 resolution = (30, 30)
        rel products = [</Render/Other>]
    }
    def RenderProduct "Beauty" {
        token productName = "out/front.$F4.exr"
        rel orderedVars = [</Render/Vars/C>, </Render/Vars/Albedo>]
    }
    def RenderProduct "Extra" {
        token productName = "out/front_direct.<F>.exr"
        rel orderedVars = [</Render/Vars/Direct>]
    }
    def RenderProduct "Data" {
        token productName = "out/side.####.exr"
        rel camera = </World/Side>
        int2 resolution = (40, 40)
        float4 dataWindowNDC = (0, 0, 0.5, 1)
        rel orderedVars = [</Render/Vars/N>, </Render/Vars/Depth>, </Render/Vars/Custom>]
    }
    def RenderProduct "Other" {
        token productName = "out/other.exr"
    }
    def Scope "Vars" {
        def RenderVar "C" {
            string sourceName = "Ci"
        }
        def RenderVar "Albedo" {
            string sourceName = "albedo"
        }
        def RenderVar "Direct" {
            string sourceName = "direct"
        }
        def RenderVar "N" {
            string sourceName = "N"
        }
        def RenderVar "Depth" {
            string sourceName = "Pz"
        }
        def RenderVar "Custom" {
            string sourceName = "myStudioAOV"
        }
    }
}
'''


def spec(path):
    buf = oiio.ImageBuf(str(path))
    assert not buf.has_error, buf.geterror()
    return buf.spec()


def camera_position(s):
    """The camera's world position from the EXR's worldToCamera (Imath row vectors)."""
    m = np.array(s.getattribute("worldToCamera"), dtype=float).reshape(4, 4)
    return np.linalg.inv(m)[3, :3]


def run(tmp_path, *args):
    (tmp_path / "shot.usda").write_text(STAGE)
    return subprocess.run([lucerna_bin(), "render", "shot.usda", "--spp", "4", *args],
                          cwd=tmp_path, capture_output=True, text=True)


def test_products_decide_files_cameras_sizes_and_layers(tmp_path):
    done = run(tmp_path)
    assert done.returncode == 0, done.stderr
    out = tmp_path / "out"
    assert sorted(p.name for p in out.iterdir()) == [
        "front.0007.exr", "front_direct.7.exr", "side.0007.exr"]
    front = spec(out / "front.0007.exr")
    assert (front.full_width, front.full_height) == (60, 40)
    assert sorted(front.channelnames) == sorted(
        ["R", "G", "B", "A", "albedo.R", "albedo.G", "albedo.B"])
    assert camera_position(front) == pytest.approx([0, 0, 10], abs=1e-4)
    direct = spec(out / "front_direct.7.exr")
    assert sorted(direct.channelnames) == sorted(["R", "G", "B", "A", "direct.R", "direct.G", "direct.B"])
    side = spec(out / "side.0007.exr")
    assert (side.full_width, side.full_height) == (40, 40)
    # dataWindowNDC (0, 0, 0.5, 1): the left half is rendered, the EXR's data window.
    assert (side.x, side.y, side.width, side.height) == (0, 0, 20, 40)
    assert camera_position(side) == pytest.approx([10, 0, 0], abs=1e-4)
    assert {"normal.X", "depth.Z"} <= set(side.channelnames)
    assert "RenderVar 'myStudioAOV' (raw) has no lucerna equivalent" in done.stderr
    # Front's aperture is 3:2 and the image 3:2: one render for both front products.
    assert done.stderr.count("lucerna: wrote") == 2


def test_render_settings_option_and_output_override(tmp_path):
    done = run(tmp_path, "--render-settings", "/Render/OtherSettings")
    assert done.returncode == 0, done.stderr
    other = spec(tmp_path / "out" / "other.exr")
    assert (other.full_width, other.full_height) == (30, 30)
    assert camera_position(other) == pytest.approx([10, 0, 0], abs=1e-4)
    # -o names the file: the settings' camera and size still apply, the products do not.
    done = run(tmp_path, "-o", "mine.exr")
    assert done.returncode == 0, done.stderr
    mine = spec(tmp_path / "mine.exr")
    assert (mine.full_width, mine.full_height) == (60, 40)
    assert camera_position(mine) == pytest.approx([0, 0, 10], abs=1e-4)
    bad = run(tmp_path, "--render-settings", "/World/Ball")
    assert bad.returncode == 2
    assert "--render-settings /World/Ball: no RenderSettings prim there" in bad.stderr


def test_conform_policies(tmp_path):
    """A 1:1 image through a 3:2 aperture. expandAperture (USD's default, every USD camera's
    fit in lucerna) keeps the aperture's width in view, so the height's field of view grows;
    cropAperture keeps the height's and loses the sides."""
    from lucerna_usd.render_settings import _fitted_camera

    writer = type("W", (), {})()
    yfov = 2 * np.arctan(12 / 35)
    writer.cameras = [{"name": "/C", "projection": {"perspective": {"yfov": yfov, "aspect": 1.5}},
                       "fit": "expand_aperture"}]
    warnings = []
    expanded = _fitted_camera(writer, "/C", 100, 100, 1.0, "expandAperture", "p", lambda *a: warnings.append(a))
    cropped = _fitted_camera(writer, "/C", 100, 100, 1.0, "cropAperture", "p", lambda *a: warnings.append(a))
    by_name = {c["name"]: c for c in writer.cameras}
    assert expanded == "/C"
    assert by_name[cropped]["fit"] == "vertical"
    assert by_name[cropped]["projection"]["perspective"]["yfov"] == pytest.approx(yfov)
    assert not warnings
    # The renderer's side: a square render of the stage's 3:2 Front camera sees the whole
    # 36 mm width: the ball (radius 1 at distance 10, focal 35) spans 2 tan(asin(1/10)) of
    # the 2 x 18/35 the image's width sees, 14.1 pixels (keeping the height's 24 mm would
    # make it 21.1).
    (tmp_path / "shot.usda").write_text(STAGE)
    done = subprocess.run([lucerna_bin(), "render", "shot.usda", "--spp", "16", "-o", "sq.exr",
                           "--resolution", "72x72", "--camera", "/World/Front", "--aov", "beauty,depth"],
                          cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    depth = oiio.ImageBuf(str(tmp_path / "sq.exr")).get_pixels(oiio.FLOAT)
    names = spec(tmp_path / "sq.exr").channelnames
    z = depth[..., names.index("depth.Z")]
    row = z[36]
    hit = np.where((row > 0) & (row < 100))[0]
    width = 72 * (2 / np.sqrt(99)) / (2 * 18 / 35)
    assert abs(len(hit) - width) <= 1.5, (len(hit), width)


def test_frame_tokens():
    from lucerna_usd.render_settings import expand_frame

    assert expand_frame("a.$F4.exr", 12) == "a.0012.exr"
    assert expand_frame("a.$F.exr", 12) == "a.12.exr"
    assert expand_frame("a.<F3>.exr", 5) == "a.005.exr"
    assert expand_frame("a.####.exr", 5) == "a.0005.exr"
    assert expand_frame("a.%04d.exr", 5) == "a.0005.exr"
    assert expand_frame("a.{frame}.exr", 5) == "a.0005.exr"
    assert expand_frame("a.$F4.exr", 1.5) == "a.1.5.exr"


def test_a_data_window_beyond_the_image_is_overscan(tmp_path):
    """dataWindowNDC beyond 0..1 renders past the image's edges: the EXR's display window is
    the image, its data window reaches out by the overscan (here 10 % of 40 pixels left and
    right, 5 % of 40 at the bottom), and the image inside is the render's without it."""
    stage = STAGE.replace("float4 dataWindowNDC = (0, 0, 0.5, 1)", "float4 dataWindowNDC = (-0.1, -0.05, 1.1, 1)")
    (tmp_path / "shot.usda").write_text(stage)
    done = subprocess.run([lucerna_bin(), "render", "shot.usda", "--spp", "4"], cwd=tmp_path,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    side = spec(tmp_path / "out" / "side.0007.exr")
    assert (side.full_x, side.full_y, side.full_width, side.full_height) == (0, 0, 40, 40)
    assert (side.x, side.y, side.width, side.height) == (-4, 0, 48, 42)
    plain = tmp_path / "plain.exr"
    done = subprocess.run([lucerna_bin(), "render", "shot.usda", "--spp", "4", "--camera", "/World/Side",
                           "--resolution", "40x40", "--aov", "normal,depth", "-o", str(plain)],
                          cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    wide = oiio.ImageBuf(str(tmp_path / "out" / "side.0007.exr")).get_pixels(oiio.FLOAT)
    reference = oiio.ImageBuf(str(plain)).get_pixels(oiio.FLOAT)
    assert np.array_equal(wide[0:40, 4:44, :4], reference[:, :, :4])
