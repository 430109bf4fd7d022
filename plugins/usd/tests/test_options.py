"""Pipeline options: variant selections, purposes and payloads, as `lucerna render` passes
them (--variant, --purpose, --no-payloads)."""

import pytest

from conftest import run_plugin, Scene

QUAD = '''def Mesh "{name}" (
    {meta}
) {{
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0, 1, 2, 3]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    {body}
}}
'''


def mesh(name, meta="", body=""):
    return QUAD.format(name=name, meta=meta, body=body)


STAGE = '''def Xform "World" {
    def Xform "Asset" (
        variants = { string look = "plain" }
        prepend variantSets = "look"
    ) {
        variantSet "look" = {
            "plain" { ''' + mesh("Plain") + ''' }
            "fancy" { ''' + mesh("Fancy") + ''' }
        }
    }
    ''' + mesh("Proxy", body='uniform token purpose = "proxy"') + '''
    ''' + mesh("Guide", body='uniform token purpose = "guide"') + '''
    def Xform "Heavy" (
        prepend payload = @./heavy.usda@
    ) {}
}
'''

HEAVY = '#usda 1.0\n(\n defaultPrim = "Root"\n)\ndef Xform "Root" {\n' + mesh("Body") + "}\n"


def names(tmp_path, stage_file, *flags):
    (tmp_path / "heavy.usda").write_text(HEAVY)
    path = stage_file(STAGE)
    out = tmp_path / f"out{len(flags)}.lucerna"
    result = run_plugin("convert", path, "-o", out, *flags)
    assert result.returncode == 0, result.stderr
    scene = Scene(out)
    return sorted(i["name"] for i in scene["instances"]), scene


def test_defaults_render_the_default_variant_render_purpose_and_payloads(stage_file, tmp_path):
    got, _ = names(tmp_path, stage_file)
    assert got == ["/World/Asset/Plain", "/World/Heavy/Body"]


def test_variant_purpose_and_payload_options(stage_file, tmp_path):
    got, _ = names(tmp_path, stage_file, "--variant", "look=fancy", "--purpose", "render,proxy",
                   "--no-payloads")
    assert got == ["/World/Asset/Fancy", "/World/Proxy"]
    got, _ = names(tmp_path, stage_file, "--variant", "/World/Asset:look=fancy", "--purpose",
                   "guide")
    assert got == ["/World/Asset/Fancy", "/World/Guide", "/World/Heavy/Body"]


def test_unknown_variants_are_warned_about(stage_file, tmp_path):
    _, scene = names(tmp_path, stage_file, "--variant", "look=gold", "--variant", "size=big")
    assert scene.warnings_about("/World/Asset: --variant look=gold: no such variant (it has fancy, plain)")
    assert scene.warnings_about("--variant size=big: no prim has the variant set 'size'")


@pytest.mark.parametrize("flags", [["--variant", "look"], ["--purpose", "preview"]])
def test_malformed_options_are_refused(stage_file, tmp_path, flags):
    result = run_plugin("convert", stage_file(STAGE), "-o", tmp_path / "x.lucerna", *flags)
    assert result.returncode == 2 and "lucerna-usd: error:" in result.stderr, result.stderr


def test_the_renderer_passes_the_options_on(stage_file, tmp_path):
    import subprocess

    from conftest import lucerna_bin

    (tmp_path / "heavy.usda").write_text(HEAVY)
    out = tmp_path / "via-lucerna.lucerna"
    result = subprocess.run([lucerna_bin(), "convert", str(stage_file(STAGE)), "-o", str(out),
                             "--variant", "look=fancy", "--purpose", "proxy", "--no-payloads"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert sorted(i["name"] for i in Scene(out)["instances"]) == ["/World/Asset/Fancy", "/World/Proxy"]
