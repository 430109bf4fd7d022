"""Surface shaders other than UsdPreviewSurface: MaterialX node graphs, MDL (Omniverse),
RenderMan; render-context choice; what is approximated is warned about."""

import numpy as np
import pytest

from conftest import texels, write_image
from lucerna_usd import surfaces

QUAD = '''
    def Mesh "Quad" (prepend apiSchemas = ["MaterialBindingAPI"]) {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
        texCoord2f[] primvars:st = [(0, 0), (1, 0), (1, 1), (0, 1)] (interpolation = "vertex")
        color3f[] primvars:displayColor = [(0.25, 0.5, 0.75)]
        rel material:binding = </World/M>
    }
'''


def stage(material_body):
    return 'def Xform "World" {\n' + QUAD + '    def Material "M" {\n' + material_body + "\n    }\n}\n"


def material(s):
    return s["materials"][s.mesh("/World/Quad")["material"]]




def test_omni_pbr_by_parameter_names(stage_file, converted, tmp_path):
    write_image(tmp_path / "orm.png", np.dstack([np.full((2, 2), v, np.uint8) for v in (255, 128, 64)]))
    s = converted(stage_file(stage('''
        token outputs:mdl:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {
            uniform token info:implementationSource = "sourceAsset"
            uniform asset info:mdl:sourceAsset = @OmniPBR.mdl@
            uniform token info:mdl:sourceAsset:subIdentifier = "OmniPBR"
            color3f inputs:diffuse_color_constant = (0.5, 0.25, 0.125)
            float inputs:albedo_brightness = 0.8
            bool inputs:enable_ORM_texture = 1
            asset inputs:ORM_texture = @orm.png@
            bool inputs:enable_emission = 1
            color3f inputs:emissive_color = (1, 1, 1)
            float inputs:emissive_intensity = 31.4159265
            float inputs:specular_level = 0.25
            token outputs:out
        }''')), no_validate=True)
    m = material(s)
    assert m["base_color"][:3] == pytest.approx([0.4, 0.2, 0.1])
    # ORM: roughness in G, metallic in B, as glTF packs them: passed through as bytes.
    mr = texels(s, m["metallic_roughness_texture"])
    assert mr[0, 0, 1] == 128 and mr[0, 0, 2] == 64
    assert m["emissive"] == pytest.approx([10.0, 10.0, 10.0], rel=1e-5)  # MDL exitance / pi
    assert m["specular"]["weight"] == pytest.approx(0.5)


def test_omni_glass(stage_file, converted):
    s = converted(stage_file(stage('''
        token outputs:mdl:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {
            uniform token info:implementationSource = "sourceAsset"
            uniform asset info:mdl:sourceAsset = @OmniGlass.mdl@
            uniform token info:mdl:sourceAsset:subIdentifier = "OmniGlass"
            color3f inputs:glass_color = (0.9, 1, 0.95)
            float inputs:glass_ior = 1.33
            float inputs:frosting_roughness = 0.2
            token outputs:out
        }''')), no_validate=True)
    m = material(s)
    assert m["transmission"] == 1.0 and m["ior"] == pytest.approx(1.33)
    assert m["transmission_color"] == pytest.approx([0.9, 1.0, 0.95])
    assert m["roughness"] == pytest.approx(0.2) and m["volume"] is not None


def test_unknown_mdl_module_shows_display_color(stage_file, converted):
    s = converted(stage_file(stage('''
        token outputs:mdl:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {
            uniform token info:implementationSource = "sourceAsset"
            uniform asset info:mdl:sourceAsset = @studio.mdl@
            uniform token info:mdl:sourceAsset:subIdentifier = "car_paint"
            token outputs:out
        }''')), no_validate=True)
    assert material(s)["base_color"] == pytest.approx([0.25, 0.5, 0.75, 1.0])
    warning = s.warnings_about("unknown surface shader 'car_paint (MDL studio.mdl)'")
    assert warning and warning[0].startswith("/World/M/S")


def test_pxr_surface_and_disney(stage_file, converted):
    s = converted(stage_file(stage('''
        token outputs:ri:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {
            uniform token info:id = "PxrSurface"
            color3f inputs:diffuseColor = (0.5, 0.5, 0.25)
            float inputs:diffuseGain = 0.5
            color3f inputs:specularFaceColor = (0.04, 0.04, 0.04)
            color3f inputs:specularEdgeColor = (1, 1, 1)
            float inputs:specularRoughness = 0.3
            float inputs:glowGain = 2
            color3f inputs:glowColor = (1, 0.5, 0)
            float inputs:presence = 0.5
            token outputs:out
        }''')), no_validate=True)
    m = material(s)
    assert m["base_color"] == pytest.approx([0.25, 0.25, 0.125, 0.5])
    assert m["specular_color"] == pytest.approx([0.04] * 3) and m["roughness"] == pytest.approx(0.3)
    assert m["emissive"] == pytest.approx([2.0, 1.0, 0.0]) and m["alpha_mode"] == "blend"
    d = converted(stage_file(stage('''
        token outputs:ri:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {
            uniform token info:id = "PxrDisney"
            color3f inputs:baseColor = (0.8, 0.1, 0.1)
            float inputs:metallic = 1
            float inputs:roughness = 0.4
            float inputs:clearcoat = 1
            float inputs:clearcoatGloss = 1
            token outputs:out
        }'''), "disney.usda"), no_validate=True)
    m = material(d)
    assert m["base_color"][:3] == pytest.approx([0.8, 0.1, 0.1]) and m["metallic"] == 1.0
    assert m["clearcoat"] == pytest.approx(0.25)  # Burley's coat: a quarter of a full coat
    assert m["clearcoat_roughness"] == pytest.approx(np.sqrt(0.001), rel=1e-4)


def test_mtlx_context_is_preferred_and_unknown_contexts_fall_through(stage_file, converted):
    """A material with MaterialX and UsdPreviewSurface surfaces uses the MaterialX one; with
    an unknown MaterialX node it falls back to the preview surface."""
    body = '''
        token outputs:mtlx:surface.connect = </World/M/X.outputs:out>
        token outputs:surface.connect = </World/M/P.outputs:surface>
        def Shader "X" {
            uniform token info:id = "%s"
            color3f inputs:base_color = (0.1, 0.9, 0.1)
            token outputs:out
        }
        def Shader "P" {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor = (0.9, 0.1, 0.1)
            token outputs:surface
        }'''
    s = converted(stage_file(stage(body % "ND_standard_surface_surfaceshader")))
    assert material(s)["base_color"][:3] == pytest.approx([0.1, 0.9, 0.1])  # base 1 x colour
    s = converted(stage_file(stage(body % "ND_my_studio_surface"), "studio.usda"), no_validate=True)
    assert material(s)["base_color"][:3] == pytest.approx([0.9, 0.1, 0.1])


def test_materialx_graph_arithmetic_is_baked(stage_file, converted, tmp_path):
    """multiply (texture x constant folds into scale), extract and mix (baked texels)."""
    write_image(tmp_path / "ramp.png", np.dstack([np.array([[0, 255]], np.uint8)] * 3))
    s = converted(stage_file(stage('''
        token outputs:mtlx:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {
            uniform token info:id = "ND_open_pbr_surface_surfaceshader"
            color3f inputs:base_color.connect = </World/M/Mix.outputs:out>
            float inputs:specular_roughness.connect = </World/M/Half.outputs:out>
            token outputs:out
        }
        def Shader "Img" {
            uniform token info:id = "ND_image_color3"
            asset inputs:file = @ramp.png@ (colorSpace = "lin_rec709")
            color3f outputs:out
        }
        def Shader "R" {
            uniform token info:id = "ND_extract_color3"
            color3f inputs:in.connect = </World/M/Img.outputs:out>
            int inputs:index = 0
            float outputs:out
        }
        def Shader "Half" {
            uniform token info:id = "ND_multiply_float"
            float inputs:in1.connect = </World/M/R.outputs:out>
            float inputs:in2 = 0.5
            float outputs:out
        }
        def Shader "Mix" {
            uniform token info:id = "ND_mix_color3"
            color3f inputs:fg = (1, 0, 0)
            color3f inputs:bg = (0, 0, 1)
            float inputs:mix.connect = </World/M/R.outputs:out>
            color3f outputs:out
        }''')))
    m = material(s)
    rough = texels(s, m["metallic_roughness_texture"])[..., 1].astype(float)
    rough = rough / 255.0 if rough.max() > 1.0 else rough
    assert rough[0, 0] == pytest.approx(0.0, abs=1e-6) and rough[0, 1] == pytest.approx(0.5, abs=1e-6)
    base = texels(s, m["base_color_texture"])
    assert base[0, 0, :3] == pytest.approx([0, 0, 1]) and base[0, 1, :3] == pytest.approx([1, 0, 0])
    assert not s.warnings_about("unknown shader")


def test_standard_surface_approximations_are_warned(stage_file, converted):
    s = converted(stage_file(stage('''
        token outputs:mtlx:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {
            uniform token info:id = "ND_standard_surface_surfaceshader"
            float inputs:subsurface = 0.5
            color3f inputs:subsurface_color = (1, 0, 0)
            float inputs:coat = 1
            color3f inputs:coat_color = (1, 0.5, 0.5)
            float inputs:sheen = 1
            color3f inputs:sheen_color = (0.5, 0.5, 1)
            float inputs:thin_film_thickness = 400
            float inputs:transmission = 0.5
            float inputs:transmission_depth = 2
            color3f inputs:transmission_color = (0.5, 1, 1)
            token outputs:out
        }''')))
    m = material(s)
    assert m["base_color"][:3] == pytest.approx([0.9, 0.4, 0.4])  # lerp(0.8 x 1, sss, 0.5)
    assert s.warnings_about("subsurface scattering is approximated")
    assert s.warnings_about("a coloured coat is not supported")
    assert m["sheen"]["color"] == pytest.approx([0.5, 0.5, 1.0])
    assert m["iridescence"]["thickness_max"] == pytest.approx(400)
    # Depth 2: the colour is what survives 2 units inside the volume.
    assert m["volume"]["absorption"] == pytest.approx([np.log(2) / 2, 0, 0], abs=1e-6)
    assert m["transmission"] == pytest.approx(0.5)


def van_de_hulst_albedo(c, g):
    s = 4.09712 + 4.20863 * c - np.sqrt(9.59217 + 41.6808 * c + 17.7126 * c * c)
    return (1 - s * s) / (1 - g * s * s)


@pytest.mark.parametrize("node, inputs", [
    ("ND_standard_surface_surfaceshader", """float inputs:subsurface = 1
            color3f inputs:subsurface_radius = (0.1, 0.05, 0.02)
            float inputs:subsurface_scale = 2
            float inputs:subsurface_anisotropy = 0.3"""),
    ("ND_open_pbr_surface_surfaceshader", """float inputs:subsurface_weight = 1
            float inputs:subsurface_radius = 0.2
            color3f inputs:subsurface_radius_scale = (1, 0.5, 0.2)
            float inputs:subsurface_scatter_anisotropy = 0.3""")])
def test_subsurface_is_a_random_walk_in_openpbrs_medium(stage_file, converted, node, inputs):
    """Subsurface becomes OpenPBR's subsurface slab: the dielectric (transmission of the
    subsurface weight, untinted) over a medium of extinction 1 / (radius x scale) whose
    single-scattering albedo inverts van de Hulst's formula for the colour; no warning."""
    s = converted(stage_file(stage(f'''
        token outputs:mtlx:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {{
            uniform token info:id = "{node}"
            {inputs}
            color3f inputs:subsurface_color = (0.8, 0.5, 0.2)
            token outputs:out
        }}'''), name=f"sss-{node}.usda"))
    m = material(s)
    assert m["transmission"] == pytest.approx(1.0)
    assert m["transmission_color"] == pytest.approx([1, 1, 1])
    extinction = 1 / np.array([0.2, 0.1, 0.04])
    volume = m["volume"]
    assert np.array(volume["scattering"]) + volume["absorption"] == pytest.approx(extinction, rel=1e-5)
    albedo = np.array(volume["scattering"]) / extinction
    # Both families' default specular ior is 1.5.
    _, expected, _ = surfaces.subsurface_medium((0.8, 0.5, 0.2), (1, 1, 1), 0.3, 1.5)
    assert albedo == pytest.approx(expected, rel=1e-5)
    assert volume["anisotropy"] == pytest.approx(0.3)
    assert not s.warnings_about("subsurface")


def test_subsurface_albedo_inverts_the_colour_through_the_boundary():
    """The single-scattering albedo is found so that the medium gives back the colour:
    index-matched (ior 1) that is van de Hulst's closed-form inversion (OpenPBR's formula);
    behind a denser boundary light reflected back in is partly absorbed, so the albedo must
    be higher for the same colour; the forward model at the albedo found is the colour; a
    white colour scatters without absorbing (the furnace's case)."""
    for g in (0.0, 0.3, -0.3):
        for c in (0.1, 0.3, 0.5, 0.8, 0.95):
            _, matched, _ = surfaces.subsurface_medium((c,) * 3, (1, 1, 1), g, 1.0)
            # (OpenPBR's closed form is a fitted inverse of the forward formula: 1e-5 apart.)
            assert matched[0] == pytest.approx(van_de_hulst_albedo(c, g), abs=1e-4)
            _, bounded, _ = surfaces.subsurface_medium((c,) * 3, (1, 1, 1), g, 1.5)
            assert bounded[0] > matched[0]
            assert surfaces._multiple_scattering_albedo(bounded[0], g, 1.5) == pytest.approx(c, abs=1e-6)
        _, white, _ = surfaces.subsurface_medium((1.0,) * 3, (1, 1, 1), g, 1.5)
        assert white == pytest.approx((1.0, 1.0, 1.0))


@pytest.mark.parametrize("node, weight", [("ND_standard_surface_surfaceshader", "transmission"),
                                           ("ND_open_pbr_surface_surfaceshader", "transmission_weight")])
def test_transmission_scatter_is_the_medium_inside(stage_file, converted, node, weight):
    """OpenPBR's interior medium (Standard Surface's alike): extinction -ln(colour) / depth,
    scattering scatter / depth, absorption the difference raised by grey until no channel
    is negative, the anisotropy as the phase function's; no warning."""
    text = stage(f'''
        token outputs:mtlx:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {{
            uniform token info:id = "{node}"
            float inputs:{weight} = 1
            color3f inputs:transmission_color = (0.5, 0.5, 0.5)
            float inputs:transmission_depth = 0.1
            color3f inputs:transmission_scatter = (0.2, 0.4, 0.8)
            float inputs:transmission_scatter_anisotropy = 0.3
            token outputs:out
        }}''')
    s = converted(stage_file(text, name=f"scatter-{weight}.usda"))
    volume = material(s)["volume"]
    extinction = np.log(2) / 0.1
    assert volume["scattering"] == pytest.approx([2, 4, 8], rel=1e-5)
    # 6.93 - (2, 4, 8) = (4.93, 2.93, -1.07): raised by 1.07.
    raised = 8 - extinction
    assert volume["absorption"] == pytest.approx([extinction - 2 + raised, extinction - 4 + raised, 0],
                                                 abs=1e-4)
    assert volume["anisotropy"] == pytest.approx(0.3)
    assert not s.warnings_about("scatter")
    # In a centimetre stage the depth is centimetres: the coefficients per metre are 100x.
    centimetres = stage_file(text, name=f"scatter-cm-{weight}.usda")
    centimetres.write_text(centimetres.read_text().replace("metersPerUnit = 1", "metersPerUnit = 0.01"))
    assert material(converted(centimetres))["volume"]["scattering"] == pytest.approx([200, 400, 800], rel=1e-5)

@pytest.mark.parametrize("node, name", [("ND_standard_surface_surfaceshader", "diffuse_roughness"),
                                         ("ND_open_pbr_surface_surfaceshader", "base_diffuse_roughness")])
def test_diffuse_roughness_is_the_rough_diffuse_lobe(stage_file, converted, node, name):
    """MaterialX diffuse roughness becomes lucerna's EON diffuse, without a warning; none
    leaves the Lambertian base (no field written)."""
    s = converted(stage_file(stage(f'''
        token outputs:mtlx:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {{
            uniform token info:id = "{node}"
            float inputs:{name} = 0.6
            token outputs:out
        }}''')))
    assert material(s)["diffuse_roughness"] == pytest.approx(0.6)
    assert not s.warnings_about("Oren-Nayar") and not s.warnings_about("diffuse")
    s = converted(stage_file(stage(f'''
        token outputs:mtlx:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {{
            uniform token info:id = "{node}"
            token outputs:out
        }}'''), name="lambert.usda"))
    assert "diffuse_roughness" not in material(s)


def test_scalar_input_from_a_primvar_falls_back_with_a_warning(stage_file, converted):
    """OpenUSD's testPreviewSurfaceConnectedScalar: roughness read per gprim through a
    UsdPrimvarReader_float. lucerna holds roughness per material: the input's default is
    used, with a warning, and the gprims render (they were skipped before)."""
    s = converted(stage_file('''
def Material "M" {
    token outputs:surface.connect = </M/S.outputs:surface>
    def Shader "S" {
        uniform token info:id = "UsdPreviewSurface"
        float inputs:roughness.connect = </M/R.outputs:result>
        token outputs:surface
    }
    def Shader "R" {
        uniform token info:id = "UsdPrimvarReader_float"
        string inputs:varname = "roughness"
        float outputs:result
    }
}
def Sphere "Ball" (prepend apiSchemas = ["MaterialBindingAPI"]) {
    rel material:binding = </M>
    float primvars:roughness = 0.2
}'''))
    assert len(s["spheres"]) == 1
    assert s.warnings_about("roughness read from primvar 'roughness' is not supported: 0.5 is used")
    assert s["materials"][s["spheres"][0]["material"]]["roughness"] == 0.5


@pytest.mark.parametrize("node, inputs, base, share", [
    # Standard Surface: a translucent BSDF of the subsurface colour, mixed by the weight.
    ("ND_standard_surface_surfaceshader", """float inputs:subsurface = 0.6
            float inputs:subsurface_anisotropy = 0.5
            bool inputs:thin_walled = 1""", [0.8, 0.8, 0.8], 0.6),
    # OpenPBR: half diffuse reflection (1 - g), half translucency (1 + g): g = 0.5 transmits
    # 0.6 x 0.75 = 0.45 and reflects 0.6 x 0.25 = 0.15 of the colour, which joins the base:
    # (0.4 x 0.8 + 0.15 x colour) / (1 - 0.45).
    ("ND_open_pbr_surface_surfaceshader", """float inputs:subsurface_weight = 0.6
            float inputs:subsurface_scatter_anisotropy = 0.5
            bool inputs:geometry_thin_walled = 1""",
     list((0.4 * 0.8 + 0.15 * np.array([0.9, 0.6, 0.2])) / 0.55), 0.45)])
def test_thin_walled_subsurface_is_diffuse_transmission(stage_file, converted, node, inputs, base, share):
    """On a thin wall, subsurface is translucency as MaterialX's graphs define it: lucerna's
    diffuse transmission (KHR_materials_diffuse_transmission) of the subsurface colour; no
    medium, no warning."""
    s = converted(stage_file(stage(f'''
        token outputs:mtlx:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {{
            uniform token info:id = "{node}"
            {inputs}
            color3f inputs:base_color = (0.8, 0.8, 0.8)
            float inputs:base = 1
            float inputs:base_weight = 1
            color3f inputs:subsurface_color = (0.9, 0.6, 0.2)
            token outputs:out
        }}'''), name=f"thin-{node}.usda"), no_validate=True)
    m = material(s)
    assert m["diffuse_transmission"]["factor"] == pytest.approx(share)
    assert m["diffuse_transmission"]["color"] == pytest.approx([0.9, 0.6, 0.2])
    assert m["base_color"][:3] == pytest.approx(base)
    assert "volume" not in m and m.get("transmission", 0.0) == 0.0
    assert not s.warnings_about("subsurface")
