"""Broken stages give a clear error (exit status 2, the prim or file named) or a clear
warning, never a traceback; a missing package names the command that installs it."""

import subprocess
import sys

import pytest

from conftest import HEADER, PLUGIN, lucerna_bin, run_plugin

QUAD = '''def Mesh "Quad" {
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0, 1, 2, 3]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
}
'''


def convert(path, tmp_path, *flags):
    result = run_plugin("convert", path, "-o", tmp_path / "out.lucerna", *flags)
    assert "Traceback" not in result.stderr, result.stderr
    return result


def test_missing_reference(stage_file, tmp_path):
    path = stage_file('def Xform "World" {\n def "Ref" (\n references = @./nope.usda@\n ) {}\n' + QUAD + "}\n")
    # As husk and usdview: what composes renders; the finding is a warning naming the prim.
    result = convert(path, tmp_path)
    assert result.returncode == 0, result.stderr
    manifest = (tmp_path / "out.lucerna").read_text()
    assert "validation error: /World/Ref: Could not open asset" in manifest
    assert "[usdValidation:CompositionErrorTest]" in manifest
    result = convert(path, tmp_path, "--strict")
    assert result.returncode == 2
    assert "/World/Ref: Could not open asset" in result.stderr
    result = convert(path, tmp_path, "--no-validate")
    assert result.returncode == 0, result.stderr
    manifest = (tmp_path / "out.lucerna").read_text()
    assert "composition: Could not open asset" in manifest


def test_reference_cycle(tmp_path):
    (tmp_path / "a.usda").write_text(HEADER.replace("World", "A") + 'def Xform "A" (\n references = @./b.usda@</B>\n) {}\n')
    (tmp_path / "b.usda").write_text(HEADER.replace("World", "B") + 'def Xform "B" (\n references = @./a.usda@</A>\n) {}\n')
    result = convert(tmp_path / "a.usda", tmp_path)
    # Nothing renderable remains: refused, with the finding that explains why.
    assert result.returncode == 2 and "nothing to render" in result.stderr
    assert "Cycle detected" in result.stderr
    result = convert(tmp_path / "a.usda", tmp_path, "--strict")
    assert result.returncode == 2 and "Cycle detected" in result.stderr


def test_syntax_error_and_missing_file(stage_file, tmp_path):
    result = convert(stage_file('def Xform "World" {\n  this is not usd\n}\n'), tmp_path)
    assert result.returncode == 2 and "Expected" in result.stderr and "line" not in result.stderr.split(":")[0]
    result = convert(tmp_path / "absent.usda", tmp_path)
    assert result.returncode == 2 and "no such file" in result.stderr


def test_nan_points_and_non_manifold_edges_are_warnings(stage_file, converted):
    s = converted(stage_file('def Xform "World" {\ndef Mesh "M" {\n'
                             ' int[] faceVertexCounts = [3, 3, 3, 3]\n'
                             ' int[] faceVertexIndices = [0, 1, 2, 0, 1, 3, 0, 1, 4, 2, 3, 5]\n'
                             ' point3f[] points = [(0,0,0), (1,0,0), (0,1,0), (0,0,1), (0,-1,0), (nan,0,0)]\n}\n}\n'))
    assert s.warnings_about("1 points are NaN or infinite: 1 faces touching them skipped")
    assert s.warnings_about("non-manifold: 1 edges are shared by more than two faces")
    assert len(s.triangles(s["meshes"][0])) == 3


def test_broken_topology_skips_the_mesh(stage_file, converted):
    s = converted(stage_file('def Xform "World" {\ndef Mesh "Bad" {\n int[] faceVertexCounts = [4]\n'
                             ' int[] faceVertexIndices = [0, 1, 9, 3]\n'
                             ' point3f[] points = [(0,0,0), (1,0,0), (1,1,0), (0,1,0)]\n}\n' + QUAD + "}\n"),
                  no_validate=True)
    assert s.warnings_about("/World/Bad: 1 faceVertexIndices out of range")
    assert [m["name"] for m in s["meshes"]] == ["/World/Quad"]


def test_stage_without_metadata_takes_usds_fallbacks(tmp_path, converted):
    """No defaultPrim, upAxis or metersPerUnit: the validator's findings are warnings and
    USD's fallbacks apply (Y up, centimetres)."""
    path = tmp_path / "bare.usda"
    path.write_text('#usda 1.0\ndef Xform "World" {\n' + QUAD + "}\n")
    s = converted(path)
    assert s.warnings_about("defaultPrim"), s["warnings"]
    transform = next(i["transform"] for i in s["instances"] if i["name"] == "/World/Quad")
    assert 0.01 in [pytest.approx(abs(x)) for x in transform]  # 1 unit = 1 cm, Y up


def test_a_prim_whose_data_cannot_be_converted_is_skipped_alone(stage_file, converted, monkeypatch):
    """Whatever a malformed attribute makes the conversion of one prim raise, that prim is
    skipped with a warning naming it; the rest of the stage renders."""
    from lucerna_usd import convert as module

    read = module.MeshData.read

    def failing(mesh, *args):
        if str(mesh.GetPath()) == "/World/Bad":
            raise ValueError("cannot reshape array of size 3 into shape (4,3)")
        return read(mesh, *args)
    monkeypatch.setattr(module.MeshData, "read", staticmethod(failing))
    s = converted(stage_file('def Xform "World" {\ndef Mesh "Bad" {\n int[] faceVertexCounts = [4]\n'
                             ' int[] faceVertexIndices = [0, 1, 2, 3]\n'
                             ' point3f[] points = [(0,0,0), (1,0,0), (1,1,0), (0,1,0)]\n}\n'
                             + QUAD + "}\n"))
    assert [m["name"] for m in s["meshes"]] == ["/World/Quad"]
    assert s.warnings_about("/World/Bad: skipped: its data cannot be converted (ValueError")


def test_empty_stage(stage_file, tmp_path):
    result = convert(stage_file('def Xform "World" {}\n'), tmp_path)
    assert result.returncode == 2 and "nothing to render" in result.stderr


def test_missing_package_names_the_install_command(stage_file, tmp_path):
    code = ("import sys; sys.modules['pxr'] = None; sys.path.insert(0, %r); "
            "from lucerna_usd.__main__ import main; sys.exit(main(['convert', 'x.usda', '-o', 'y']))" % str(PLUGIN))
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 3
    assert f"-m pip install -r {PLUGIN / 'requirements.txt'}" in result.stderr


def test_renderer_reports_plugin_errors(stage_file, tmp_path):
    bad = stage_file('def Xform "World" {\n def "Ref" (\n references = @./nope.usda@\n ) {}\n}\n')
    for strict in ([], ["--strict"]):
        result = subprocess.run([lucerna_bin(), "render", str(bad), "-o", str(tmp_path / "x.exr"),
                                 *strict], capture_output=True, text=True)
        assert result.returncode == 2 and "error: " in result.stderr, result.stderr
        assert "nope.usda" in result.stderr, result.stderr
        assert not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("python", ["/nonexistent/python3"])
def test_renderer_without_python_says_how_to_install(stage_file, tmp_path, python):
    import os

    result = subprocess.run([lucerna_bin(), "inspect", str(stage_file('def Xform "World" {}\n'))],
                            capture_output=True, text=True, env=dict(os.environ, LUCERNA_PYTHON=python))
    assert result.returncode == 1
    assert "pip install -r" in result.stderr and "requirements.txt" in result.stderr
