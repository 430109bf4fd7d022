"""UsdPreviewSurface networks: constants, textures, channel layouts, opacity, transforms,
and the approximations that are reported."""

import numpy as np
import OpenImageIO as oiio
import pytest

from conftest import texels, write_image

QUAD = '''
    def Mesh "Quad" (prepend apiSchemas = ["MaterialBindingAPI"]) {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
        texCoord2f[] primvars:st = [(0, 0), (1, 0), (1, 1), (0, 1)] (interpolation = "vertex")
        rel material:binding = </World/M>
    }
'''


def stage(inputs, nodes=""):
    return ('def Xform "World" {\n' + QUAD + '''
    def Material "M" {
        token outputs:surface.connect = </World/M/S.outputs:surface>
        def Shader "S" {
            uniform token info:id = "UsdPreviewSurface"
''' + inputs + '''
            token outputs:surface
        }
        def Shader "R" {
            uniform token info:id = "UsdPrimvarReader_float2"
            string inputs:varname = "st"
            float2 outputs:result
        }
''' + nodes + "\n    }\n}\n")


def texture(name, file, outputs, extra=""):
    return f'''
        def Shader "{name}" {{
            uniform token info:id = "UsdUVTexture"
            asset inputs:file = @{file}@
            float2 inputs:st.connect = </World/M/R.outputs:result>
            {extra}
            {outputs}
        }}'''



def material(s):
    return s["materials"][s.mesh("/World/Quad")["material"]]



def test_constants(stage_file, converted):
    s = converted(stage_file(stage('''
            color3f inputs:diffuseColor = (0.1, 0.2, 0.3)
            color3f inputs:emissiveColor = (4, 5, 6)
            float inputs:metallic = 0.25
            float inputs:roughness = 0.75
            float inputs:ior = 1.33''')))
    m = material(s)
    assert m["base_color"] == pytest.approx([0.1, 0.2, 0.3, 1.0])
    assert m["emissive"] == [4, 5, 6] and m["ior"] == pytest.approx(1.33)
    assert (m["metallic"], m["roughness"], m["alpha_mode"]) == (0.25, 0.75, "opaque")
    assert m["model"] == "gltf_pbr"


def test_diffuse_texture_passes_8_bit_srgb_through(stage_file, converted, tmp_path):
    write_image(tmp_path / "albedo.png", np.arange(2 * 2 * 3).reshape(2, 2, 3) * 10)
    s = converted(stage_file(stage(
        "color3f inputs:diffuseColor.connect = </World/M/T.outputs:rgb>",
        texture("T", "albedo.png", "float3 outputs:rgb", 'token inputs:wrapS = "mirror"'))))
    ref = material(s)["base_color_texture"]
    t = texels(s, ref)
    assert t.dtype == np.uint8 and t[0, 0].tolist() == [0, 10, 20, 255]
    assert s["textures"][ref["texture"]]["wrap_u"] == "mirrored_repeat"


def test_scaled_texture_is_baked_linear(stage_file, converted, tmp_path):
    write_image(tmp_path / "albedo.png", np.full((1, 1, 3), 255))
    s = converted(stage_file(stage(
        "color3f inputs:diffuseColor.connect = </World/M/T.outputs:rgb>",
        texture("T", "albedo.png", "float3 outputs:rgb", "float4 inputs:scale = (0.5, 0.25, 1, 1)"))))
    t = texels(s, material(s)["base_color_texture"])
    assert t.dtype == np.float32 and t[0, 0].tolist() == pytest.approx([0.5, 0.25, 1, 1])


def test_metallic_and_roughness_from_two_images_share_one_texture(stage_file, converted, tmp_path):
    write_image(tmp_path / "metal.png", np.full((2, 2, 1), 255))
    write_image(tmp_path / "rough.exr", np.full((4, 4, 3), [0.0, 0.3, 0.0], np.float32), oiio.FLOAT)
    s = converted(stage_file(stage('''
            float inputs:metallic.connect = </World/M/Metal.outputs:r>
            float inputs:roughness.connect = </World/M/Rough.outputs:g>''',
        texture("Metal", "metal.png", "float outputs:r", 'token inputs:sourceColorSpace = "raw"')
        + texture("Rough", "rough.exr", "float outputs:g"))))
    m = material(s)
    t = texels(s, m["metallic_roughness_texture"])
    assert t.shape == (4, 4, 4)  # the larger image's size
    assert t[..., 1] == pytest.approx(0.3) and t[..., 2] == pytest.approx(1.0)
    assert (m["metallic"], m["roughness"]) == (1.0, 1.0)


def test_opacity_threshold_masks_and_presence_blends(stage_file, converted, tmp_path):
    s = converted(stage_file(stage("float inputs:opacity = 0.3\n float inputs:opacityThreshold = 0.5")))
    assert material(s)["alpha_mode"] == {"mask": {"cutoff": 0.5}}
    assert material(s)["base_color"][3] == pytest.approx(0.3)
    assert material(s).get("transmission", 0.0) == 0.0
    s = converted(stage_file(stage('float inputs:opacity = 0.3\n uniform token inputs:opacityMode = "presence"'),
                             "blend.usda"))
    assert material(s)["alpha_mode"] == "blend"
    assert material(s)["base_color"][3] == pytest.approx(0.3)


def test_transparent_opacity_is_glass(stage_file, converted, tmp_path):
    """opacity < 1 in the default opacityMode is transmission (the specification's glass):
    untinted, refracting by the ior."""
    s = converted(stage_file(stage("float inputs:opacity = 0.2\n float inputs:ior = 1.33\n"
                                   " color3f inputs:diffuseColor = (0.8, 0.1, 0.1)")))
    m = material(s)
    assert m["alpha_mode"] == "opaque" and m["base_color"][3] == 1.0
    assert m["transmission"] == pytest.approx(0.8)
    assert m["transmission_color"] == [1.0, 1.0, 1.0]
    assert m["volume"] == {"absorption": [0.0, 0.0, 0.0]} and m["ior"] == pytest.approx(1.33)
    # ior 1: a thin wall, which does not bend light.
    s = converted(stage_file(stage("float inputs:opacity = 0.0\n float inputs:ior = 1.0"), "thin.usda"))
    assert material(s)["transmission"] == 1.0 and material(s).get("volume") is None
    # A texture on opacity: transmission 1 - opacity in the R channel.
    write_image(tmp_path / "mask.png", np.array([[[51], [255]]]))
    s = converted(stage_file(stage(
        "float inputs:opacity.connect = </World/M/T.outputs:r>",
        texture("T", "mask.png", "float outputs:r", 'token inputs:sourceColorSpace = "raw"')), "tex.usda"))
    m = material(s)
    assert m["transmission"] == 1.0 and m["alpha_mode"] == "opaque"
    t = texels(s, m["transmission_texture"])
    assert t[0, :, 0] == pytest.approx([0.8, 0.0], abs=1e-3)


DISPLAY_OPACITY = '''def Xform "World" {
    def Mesh "Quad" {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
        color3f[] primvars:displayColor = [(0.2, 0.4, 0.6)] (interpolation = "constant")
        float[] primvars:displayOpacity = [0.25] (interpolation = "constant")
    }
}
'''


def test_display_opacity_is_coverage(stage_file, converted):
    s = converted(stage_file(DISPLAY_OPACITY))
    m = s["materials"][s.mesh("/World/Quad")["material"]]
    assert m["alpha_mode"] == "blend" and m["base_color"] == pytest.approx([0.2, 0.4, 0.6, 0.25])


def test_opacity_from_the_diffuse_texture_alpha(stage_file, converted, tmp_path):
    write_image(tmp_path / "leaf.png", np.array([[[10, 20, 30, 0], [10, 20, 30, 255]]]))
    s = converted(stage_file(stage('''
            color3f inputs:diffuseColor.connect = </World/M/T.outputs:rgb>
            float inputs:opacity.connect = </World/M/T.outputs:a>
            float inputs:opacityThreshold = 0.5''',
        texture("T", "leaf.png", "float3 outputs:rgb\n float outputs:a"))))
    t = texels(s, material(s)["base_color_texture"])
    assert t.dtype == np.uint8 and t[0, :, 3].tolist() == [0, 255]


def test_normal_map_and_uv_transform(stage_file, converted, tmp_path):
    write_image(tmp_path / "normal.png", np.full((2, 2, 3), [128, 128, 255]))
    s = converted(stage_file(stage(
        "normal3f inputs:normal.connect = </World/M/N.outputs:rgb>",
        texture("N", "normal.png", "float3 outputs:rgb",
                'token inputs:sourceColorSpace = "raw"\n float4 inputs:scale = (2, 2, 2, 1)\n'
                ' float4 inputs:bias = (-1, -1, -1, 0)').replace(
            "</World/M/R.outputs:result>", "</World/M/X.outputs:result>") + '''
        def Shader "X" {
            uniform token info:id = "UsdTransform2d"
            float2 inputs:in.connect = </World/M/R.outputs:result>
            float2 inputs:scale = (2, 2)
            float2 inputs:translation = (0.5, 0)
            float2 outputs:result
        }''')))
    ref = material(s)["normal_texture"]
    assert texels(s, ref).dtype == np.uint8  # the standard encoding is passed through
    # st (0.25, 0.25) -> st' = (1.0, 0.5); in lucerna's uv (v = 1 - t): (0.25, 0.75) -> (1.0, 0.5).
    tr = ref["transform"]
    uv = np.array(tr["x"]) * 0.25 + np.array(tr["y"]) * 0.75 + np.array(tr["offset"])
    assert uv == pytest.approx([1.0, 0.5])


def test_specular_workflow_and_clearcoat(stage_file, converted):
    s = converted(stage_file(stage('''
            int inputs:useSpecularWorkflow = 1
            color3f inputs:specularColor = (0.9, 0.5, 0.1)
            float inputs:metallic = 1
            float inputs:clearcoat = 0.75
            float inputs:clearcoatRoughness = 0.2''')))
    m = material(s)
    assert m["specular_color"] == pytest.approx([0.9, 0.5, 0.1]) and m["metallic"] == 0.0
    assert not s.warnings_about("specular")
    assert m["clearcoat"] == pytest.approx(0.75) and m["clearcoat_roughness"] == pytest.approx(0.2)
    plain = material(converted(stage_file(stage(""), "plain.usda")))
    assert plain.get("specular_color") is None  # the metallic workflow: from ior
    assert plain["clearcoat"] == 0.0 and plain["clearcoat_roughness"] == pytest.approx(0.01)


def test_unknown_shader_is_a_warning_and_shows_the_display_color(stage_file, converted):
    """As usdview does: a surface shader lucerna does not know falls back to the gprim's
    displayColor; the warning names the shader prim and its id."""
    text = stage("").replace('"UsdPreviewSurface"', '"MySurface"').replace(
        'rel material:binding', 'color3f[] primvars:displayColor = [(0.2, 0.4, 0.6)]\n        rel material:binding')
    s = converted(stage_file(text), no_validate=True)
    warning = s.warnings_about("unknown surface shader 'MySurface'")
    assert warning and "/World/M/S" in warning[0]
    assert material(s)["base_color"] == pytest.approx([0.2, 0.4, 0.6, 1])


def test_an_image_beyond_the_memory_limit_is_not_decoded(stage_file, converted, tmp_path,
                                                          monkeypatch):
    """lucerna passes --max-memory: an image whose header needs more is refused unread
    (OpenImageIO already refuses headers far larger than their file)."""
    from lucerna_usd import images

    write_image(tmp_path / "huge.png", np.zeros((512, 512, 4)))
    monkeypatch.setattr(images, "MAX_BYTES", 1 << 20)
    s = converted(stage_file(stage(
        "color3f inputs:diffuseColor.connect = </World/M/T.outputs:rgb>",
        texture("T", "huge.png", "float3 outputs:rgb"))))
    assert s.warnings_about("--max-memory"), s["warnings"]
    assert material(s)["base_color_texture"] is None
