"""Motion blur: with the render camera's shutter open (or --shutter), transforms that move
while it is open are sampled at evenly spaced time codes over it, through the hierarchy,
for meshes (instances) and cameras; what does not move gets no keys."""

import numpy as np
import pytest

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


DEFORMING = '''def Xform "World" {
    def Mesh "Sampled" {
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points.timeSamples = {
            0: [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)],
            10: [(0, 0, 0), (11, 0, 0), (11, 1, 0), (0, 1, 0)],
        }
    }
    def Mesh "Flowing" {
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points.timeSamples = { 4: [(0, 0, 2), (1, 0, 2), (1, 1, 2), (0, 1, 2)] }
        vector3f[] velocities.timeSamples = { 4: [(0, 0, 0), (0, 0, 0), (0, 24, 0), (0, 24, 0)] }
        vector3f[] accelerations.timeSamples = { 4: [(0, 0, 0), (0, 0, 0), (0, 0, 0), (576, 0, 0)] }
    }
    def Mesh "Cage" {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points.timeSamples = {
            0: [(0, 0, 4), (1, 0, 4), (1, 1, 4), (0, 1, 4)],
            10: [(0, 0, 14), (1, 0, 14), (1, 1, 14), (0, 1, 14)],
        }
    }
    def Mesh "Growing" {
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts.timeSamples = { 0: [3], 4.25: [4] }
        int[] faceVertexIndices.timeSamples = { 0: [0, 1, 2], 4.25: [0, 1, 2, 3] }
        point3f[] points.timeSamples = {
            0: [(0, 0, 6), (1, 0, 6), (1, 1, 6)],
            4.25: [(0, 0, 6), (1, 0, 6), (1, 1, 6), (0, 1, 6)],
        }
    }
}
'''


def _keys(scene, mesh):
    return [scene.array(v, "<f4", 3) for v in mesh["deformation"]["positions"]]


def test_deforming_points_are_sampled_over_the_shutter(stage_file, converted):
    """Points time samples are interpolated at the shutter's keys, velocities and
    accelerations extrapolate from the frame's sample (UsdGeom: p + v dt + a dt^2 / 2, in
    seconds at 24 time codes a second), a subdivision cage carries its point keys, and a
    mesh whose point count changes over the shutter keeps the frame's shape with a
    warning."""
    scene = converted(stage_file(DEFORMING, name="deforming.usda"), frame=4, shutter=(-0.5, 0.5))
    times = [3.5 + k / (KEYS - 1) for k in range(KEYS)]
    sampled = scene.mesh("/World/Sampled")
    keys = _keys(scene, sampled)
    assert len(keys) == KEYS
    frame = scene.positions(sampled)
    for key, t in zip(keys, times):
        # The vertices sit where the frame's do, moved along x as the samples move them.
        moved = frame.copy()
        moved[frame[:, 0] > 0.5, 0] = 1 + t
        assert np.allclose(key, moved, atol=1e-5), (t, key)
    flowing = scene.mesh("/World/Flowing")
    frame = scene.positions(flowing)
    for key, t in zip(_keys(scene, flowing), times):
        dt = (t - 4) / 24
        top = frame[:, 1] > 0.5
        expected = frame.copy()
        expected[top, 1] += 24 * dt
        # Only the vertex at (0, 1) accelerates, along x.
        accelerated = top & (frame[:, 0] < 0.5)
        expected[accelerated, 0] += 0.5 * 576 * dt * dt
        assert np.allclose(key, expected, atol=1e-5), (t, key, expected)
    cage = next(s for s in scene["subdivision_surfaces"]
                if scene["meshes"][s["mesh"]]["name"] == "/World/Cage")
    cage_keys = [scene.array(v, "<f4", 3) for v in cage["point_keys"]]
    assert [round(float(k[0, 2]), 5) for k in cage_keys] == [round(4 + t, 5) for t in times]
    assert "deformation" not in scene.mesh("/World/Growing")
    assert scene.warnings_about("point count changes over the shutter")
    still = converted(stage_file(DEFORMING, name="still.usda"), frame=4, shutter=(0.0, 0.0))
    assert all("deformation" not in m for m in still["meshes"])


@pytest.mark.parametrize("scheme", ["none", "catmullClark"])
def test_lucerna_renders_deforming_points_as_moving_xforms(stage_file, tmp_path, scheme):
    """End to end: a quad whose points slide over the shutter renders the image of the same
    quad slid by its transform (both keyed at 9 time codes, the same linear motion), and
    not the frame's sharp one; as a polygon mesh and as a subdivision surface (whose point
    keys lucerna refines)."""
    import subprocess

    import OpenImageIO as oiio

    from conftest import lucerna_bin

    camera = '''    def Camera "Shot" {
        double shutter:open = -0.5
        double shutter:close = 0.5
        double3 xformOp:translate = (0.5, 0.5, 6)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
'''
    quad = "int[] faceVertexCounts = [4]\n        int[] faceVertexIndices = [0, 1, 2, 3]"
    by_points = f'''def Xform "World" {{
    def Mesh "Quad" {{
        uniform token subdivisionScheme = "{scheme}"
        {quad}
        point3f[] points.timeSamples = {{
            0: [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)],
            10: [(2, 0, 0), (3, 0, 0), (3, 1, 0), (2, 1, 0)],
        }}
    }}
{camera}}}
'''
    by_xform = f'''def Xform "World" {{
    def Mesh "Quad" {{
        uniform token subdivisionScheme = "{scheme}"
        {quad}
        point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
        double3 xformOp:translate.timeSamples = {{ 0: (0, 0, 0), 10: (2, 0, 0) }}
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
{camera}}}
'''

    def render(text, name, *flags):
        path = stage_file(text, name=f"{name}-{scheme}.usda")
        out = tmp_path / f"{name}-{scheme}.exr"
        subprocess.run([lucerna_bin(), "render", str(path), "--frame", "4", "--resolution", "48x48",
                        "--spp", "16", "--env", "1,1,1", "-q", "-o", str(out), *flags],
                       check=True, capture_output=True)
        return oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)[:, :, :3]

    points = render(by_points, "points")
    xform = render(by_xform, "xform")
    sharp = render(by_points, "sharp", "--shutter", "0,0")
    assert np.abs(points - xform).max() < 1e-3, np.abs(points - xform).max()
    assert np.abs(points - sharp).max() > 0.1


def test_points_that_are_not_finite_over_the_shutter_keep_the_frame(stage_file, converted):
    """Velocities of NaN (or infinite accelerations) would put points nowhere over the
    shutter: the mesh keeps the frame's shape, with a warning naming it."""
    text = '''def Mesh "Broken" {
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points.timeSamples = { 4: [(0, 0, 0), (1, 0, 0), (0, 1, 0)] }
    vector3f[] velocities.timeSamples = { 4: [(0, 0, 0), (nan, 0, 0), (0, 0, 0)] }
}
def Mesh "Flung" {
    uniform token subdivisionScheme = "none"
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]
    point3f[] points.timeSamples = { 4: [(0, 0, 2), (1, 0, 2), (0, 1, 2)] }
    vector3f[] velocities.timeSamples = { 4: [(0, 0, 0), (1, 0, 0), (0, 0, 0)] }
    vector3f[] accelerations.timeSamples = { 4: [(0, 0, 0), (inf, 0, 0), (0, 0, 0)] }
}
'''
    scene = converted(stage_file(text, name="broken.usda"), frame=4, shutter=(-0.5, 0.5))
    for name in ("/Broken", "/Flung"):
        assert "deformation" not in scene.mesh(name)
    warned = scene.warnings_about("not finite")
    assert any("/Broken" in w for w in warned) and any("/Flung" in w for w in warned), warned
