"""BasisCurves: hair and wires as round tubes of the curves' widths."""

import subprocess

import numpy as np
import OpenImageIO as oiio
from conftest import lucerna_bin
from lucerna_usd import curves

HAIR = '''
def Xform "World" {
    def BasisCurves "Hair" {
        uniform token type = "cubic"
        uniform token basis = "bspline"
        int[] curveVertexCounts = [6, 6, 6]
        point3f[] points = [%s]
        float[] widths = [%s] (interpolation = "vertex")
        color3f[] primvars:displayColor = [(0.4, 0.2, 0.1)]
    }
    def BasisCurves "Wire" {
        uniform token type = "linear"
        uniform token wrap = "periodic"
        int[] curveVertexCounts = [4]
        point3f[] points = [(0, 0, 5), (1, 0, 5), (1, 1, 5), (0, 1, 5)]
        float[] widths = [0.2]
    }
    def NurbsCurves "Nurbs" {
        int[] curveVertexCounts = [4]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    }
}
'''


def hair_stage():
    points, widths = [], []
    for c in range(3):
        for k in range(6):
            points.append(f"({c}, {k * 0.5}, {0.1 * k * k})")
            widths.append(f"{0.1 - 0.015 * k}")
    return HAIR % (", ".join(points), ", ".join(widths))


def test_curves_become_tubes_of_their_widths(stage_file, converted):
    s = converted(stage_file(hair_stage()))
    hair = s.mesh("/World/Hair")
    tris = s.triangles(hair)
    # bspline: 6 points make 3 segments; each sampled SAMPLES times, SIDES sides (thin hair:
    # 0.1 wide across a 4.2 extent), 2 triangles.
    assert len(tris) == 3 * 3 * curves.SAMPLES * curves.SIDES * 2
    p = s.positions(hair).reshape(-1, curves.SIDES, 3)
    # The first ring sits at the bspline's start, B(0) = (P0 + 4 P1 + P2) / 6, with the
    # width interpolated alike: radius (0.1 + 4 * 0.085 + 0.07) / 12.
    ring = p[0]
    centre = ring.mean(axis=0)
    expected_centre = (np.array([0, 0, 0]) + 4 * np.array([0, 0.5, 0.1]) + np.array([0, 1.0, 0.4])) / 6
    assert np.allclose(centre, expected_centre, atol=1e-5)
    radius = np.linalg.norm(ring - centre, axis=1)
    assert np.allclose(radius, (0.1 + 4 * 0.085 + 0.07) / 12, rtol=1e-4)
    # Normals point radially outward.
    normals = s.array(hair["normals"], "<f4", 3).reshape(-1, curves.SIDES, 3)[0]
    assert np.allclose(normals, (ring - centre) / radius[:, None], atol=1e-4)
    # The periodic wire closes its square: 4 segments of radius 0.1; as thick as it is
    # (0.2 across a 1.4 square), its section is round.
    wire = s.mesh("/World/Wire")
    assert len(s.triangles(wire)) == 4 * curves.ROUND_SIDES * 2
    w = s.positions(wire).reshape(-1, curves.ROUND_SIDES, 3)
    assert np.allclose(np.linalg.norm(w[0] - w[0].mean(axis=0), axis=1), 0.1, rtol=1e-5)
    assert s.warnings_about("/World/Nurbs: NurbsCurves is not supported: skipped")


def test_a_curve_renders_with_its_width(stage_file, tmp_path):
    """A horizontal wire 0.3 wide seen through an orthographic camera 3 units tall at 90
    pixels: 9 pixel rows."""
    stage = stage_file('''
def BasisCurves "Wire" {
    uniform token type = "linear"
    int[] curveVertexCounts = [2]
    point3f[] points = [(-2, 0, 0), (2, 0, 0)]
    float[] widths = [0.3]
}
def Camera "Cam" {
    token projection = "orthographic"
    float horizontalAperture = 30
    float verticalAperture = 30
    double3 xformOp:translate = (0, 0, 10)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}
''')
    out = tmp_path / "wire.exr"
    result = subprocess.run([lucerna_bin(), "render", str(stage), "-o", str(out), "--spp", "4",
                             "--resolution", "90x90", "--aov", "beauty", "--env", "1,1,1", "-q"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    buf = oiio.ImageBuf(str(out))
    alpha = buf.get_pixels(oiio.FLOAT)[..., list(buf.spec().channelnames).index("A")]
    rows = (alpha[:, 45] > 0.5).sum()
    assert abs(rows - 9) <= 1, rows
