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
    result = convert(path, tmp_path)
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
    result = subprocess.run([lucerna_bin(), "render", str(bad), "-o", str(tmp_path / "x.exr")],
                            capture_output=True, text=True)
    assert result.returncode == 2 and "error: " in result.stderr and "nope.usda" in result.stderr
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("python", ["/nonexistent/python3"])
def test_renderer_without_python_says_how_to_install(stage_file, tmp_path, python):
    import os

    result = subprocess.run([lucerna_bin(), "inspect", str(stage_file('def Xform "World" {}\n'))],
                            capture_output=True, text=True, env=dict(os.environ, LUCERNA_PYTHON=python))
    assert result.returncode == 1
    assert "pip install -r" in result.stderr and "requirements.txt" in result.stderr
