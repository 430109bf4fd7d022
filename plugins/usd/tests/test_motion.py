"""Motion blur: with the render camera's shutter open (or --shutter), transforms that move
while it is open are sampled at evenly spaced time codes over it, through the hierarchy,
for meshes (instances) and cameras; what does not move gets no keys."""

import numpy as np

from lucerna_usd.motion import KEYS

STAGE = '''def Xform "World" {
    def Xform "Rig" {
        double3 xformOp:translate.timeSamples = { 0: (0, 0, 0), 10: (10, 0, 0) }
        uniform token[] xformOpOrder = ["xformOp:translate"]
        def Xform "Spinner" {
            float xformOp:rotateY.timeSamples = { 0: 0, 10: 90 }
            uniform token[] xformOpOrder = ["xformOp:rotateY"]
            def Mesh "Blade" {
                int[] faceVertexCounts = [4]
                int[] faceVertexIndices = [0, 1, 2, 3]
                point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
            }
        }
    }
    def Mesh "Floor" {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)]
    }
    def Camera "Shot" {
        double shutter:open = -0.25
        double shutter:close = 0.25
        double3 xformOp:translate.timeSamples = { 0: (0, 1, 5), 10: (0, 1, 15) }
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
}
'''


def _matrix(numbers):
    """A scene file's 16 numbers as the row-vector matrix they were written from."""
    return np.asarray(numbers, dtype=np.float64).reshape(4, 4)


def _instance(scene, name):
    return next(i for i in scene["instances"] if i["name"] == name)


def test_the_camera_shutter_samples_moving_transforms(stage_file, converted):
    scene = converted(stage_file(STAGE), frame=4)
    blade = _instance(scene, "/World/Rig/Spinner/Blade")
    assert len(blade["motion"]) == KEYS
    for k, key in enumerate(blade["motion"]):
        time = 4 - 0.25 + 0.5 * k / (KEYS - 1)
        angle = np.radians(9 * time)
        expected = np.identity(4)
        expected[0, 0], expected[0, 2] = np.cos(angle), -np.sin(angle)
        expected[2, 0], expected[2, 2] = np.sin(angle), np.cos(angle)
        expected[3, 0] = time
        assert np.allclose(_matrix(key), expected, atol=1e-9), (k, _matrix(key), expected)
    # The frame's transform is kept; what does not move gets no keys.
    assert np.allclose(_matrix(blade["transform"]), _matrix(blade["motion"][KEYS // 2]), atol=1e-9)
    assert "motion" not in _instance(scene, "/World/Floor")
    assert scene["shutter"] == {"open": -0.25, "close": 0.25}
    camera = scene["cameras"][0]
    assert [_matrix(k)[3, 2] for k in camera["motion"]] == [
        5 + 4 - 0.25 + 0.5 * k / (KEYS - 1) for k in range(KEYS)]


def test_shutter_option_overrides_and_render_settings_close_it(stage_file, converted):
    moving = converted(stage_file(STAGE), frame=4, shutter=(0.0, 1.0))
    keys = _instance(moving, "/World/Rig/Spinner/Blade")["motion"]
    assert np.isclose(_matrix(keys[-1])[3, 0], 5.0)
    closed = converted(stage_file(STAGE), frame=4, shutter=(0.0, 0.0))
    assert "motion" not in _instance(closed, "/World/Rig/Spinner/Blade")
    assert "motion" not in closed["cameras"][0]
    disabled = STAGE + '''
def "Render" {
    def RenderSettings "Settings" {
        rel camera = </World/Shot>
        uniform bool disableMotionBlur = true
    }
}
'''
    scene = converted(stage_file(disabled, name="disabled.usda"), frame=4)
    assert "motion" not in _instance(scene, "/World/Rig/Spinner/Blade")


INSTANCER = '''def Xform "World" {
    def PointInstancer "Crowd" {
        rel prototypes = [</World/Crowd/Protos/Quad>]
        int[] protoIndices = [0, 0]
        point3f[] positions.timeSamples = { 0: [(0, 0, 0), (0, 5, 0)], 10: [(10, 0, 0), (0, 5, 0)] }
        def Scope "Protos" {
            def Mesh "Quad" {
                int[] faceVertexCounts = [4]
                int[] faceVertexIndices = [0, 1, 2, 3]
                point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
            }
        }
    }
    def PointInstancer "Fliers" {
        rel prototypes = [</World/Fliers/Protos/Quad>]
        int[] protoIndices = [0]
        point3f[] positions.timeSamples = { 0: [(0, 0, 0)] }
        vector3f[] velocities.timeSamples = { 0: [(0, 24, 0)] }
        def Scope "Protos" {
            def Mesh "Quad" {
                int[] faceVertexCounts = [4]
                int[] faceVertexIndices = [0, 1, 2, 3]
                point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
            }
        }
    }
}
'''


def test_point_instancers_move_by_position_samples_and_velocities(stage_file, converted):
    scene = converted(stage_file(INSTANCER, name="instancer.usda"), frame=4, shutter=(-0.5, 0.5))
    crowd = [i for i in scene["instances"] if i["name"].startswith("/World/Crowd")]
    moving, still = crowd
    assert len(moving["motion"]) == KEYS and "motion" not in still
    # Position samples interpolated: x = t at time code t.
    assert [round(_matrix(k)[3, 0], 9) for k in moving["motion"]] == [
        round(3.5 + k / (KEYS - 1), 9) for k in range(KEYS)]
    flier = next(i for i in scene["instances"] if i["name"].startswith("/World/Fliers"))
    # 24 units a second at 24 time codes a second from the sample at 0: y = t at time code t.
    assert np.allclose([_matrix(k)[3, 1] for k in flier["motion"]],
                       [3.5 + k / (KEYS - 1) for k in range(KEYS)], atol=1e-6)


def test_lucerna_renders_the_stage_blurred_with_its_vectors(stage_file, tmp_path):
    """End to end: `lucerna render` of a stage whose camera's shutter is open blurs the
    moving blade and writes its motion (the rig's 1 unit a frame to the right: u > 0); with
    the shutter closed (--shutter 0,0) the image is sharp and the motion layer still holds
    the motion, taken over half a frame each way (`--vectors`)."""
    import subprocess

    import OpenImageIO as oiio

    from conftest import lucerna_bin

    text = STAGE.replace("double3 xformOp:translate.timeSamples = { 0: (0, 1, 5), 10: (0, 1, 15) }",
                         "double3 xformOp:translate = (4.5, 0.5, 4)")
    path = stage_file(text, name="shot.usda")

    def render(name, *flags):
        out = tmp_path / name
        subprocess.run([lucerna_bin(), "render", str(path), "--frame", "4", "--resolution", "64x48",
                        "--spp", "8", "--env", "0.2,0.2,0.2", "--aov", "motion", "-q", "-o", str(out),
                        *flags], check=True, capture_output=True)
        image = oiio.ImageBuf(str(out))
        names = list(image.spec().channelnames)
        pixels = image.get_pixels(oiio.FLOAT)
        return image.spec().getattribute("lucerna/shutter"), pixels[:, :, names.index("motion.u")]

    shutter, blurred_u = render("blurred.exr")
    assert shutter == "-0.25,0.25" and blurred_u.max() > 1.0, (shutter, blurred_u.max())
    shutter, sharp_u = render("closed.exr", "--shutter", "0,0")
    assert shutter == "-0.5,0.5 without blur" and sharp_u.max() > 1.0, (shutter, sharp_u.max())
