"""UDIM texture sets (`<UDIM>`, `<UVTILE>`, `_MAPID_`): tiles found through the asset
resolver, packed per tile into a UDIM texture of the scene file, rendered like the one
texture they were cut from; missing tiles read the fallback with one warning naming them."""

import json
import struct
import subprocess
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from conftest import lucerna_bin, texels, write_image

AVOCADO = Path(__file__).resolve().parents[3] / "tests" / "assets" / "gltf" / "Avocado"
#: The Avocado's 128-texel images, enlarged 5x (nearest) so that 10 tiles cut them evenly.
SIDE = 640
TILES = 10


def avocado_mesh():
    """Points, normals, st (USD: v up) and triangle indices of Khronos's Avocado."""
    gltf = json.loads((AVOCADO / "Avocado.gltf").read_text())
    data = (AVOCADO / "Avocado.bin").read_bytes()
    views = gltf["bufferViews"]

    def accessor(i, width, fmt):
        a = gltf["accessors"][i]
        view = views[a["bufferView"]]
        stride = view.get("byteStride", width * struct.calcsize(fmt))
        start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
        out = [struct.unpack_from(f"<{width}{fmt}", data, start + k * stride) for k in range(a["count"])]
        return np.array(out)

    prim = gltf["meshes"][0]["primitives"][0]
    attrs = prim["attributes"]
    uv = accessor(attrs["TEXCOORD_0"], 2, "f")
    st = np.stack([uv[:, 0], 1.0 - uv[:, 1]], 1)
    return (accessor(attrs["POSITION"], 3, "f"), accessor(attrs["NORMAL"], 3, "f"), st,
            accessor(prim["indices"], 1, "H")[:, 0])


def enlarged(name):
    """An Avocado image at SIDE x SIDE texels (each texel repeated 5x5), RGB 8-bit."""
    buf = oiio.ImageBuf(str(AVOCADO / f"Avocado_{name}.png"))
    px = np.asarray(buf.get_pixels(oiio.UINT8))[..., :3]
    k = SIDE // px.shape[0]
    return np.repeat(np.repeat(px, k, 0), k, 1)


def write_textures(folder, pattern):
    """The three images whole (`pattern` None) or cut into tiles 1001-1010 along u, named
    by `pattern` (a function of the tile number). Returns the file names by image."""
    folder.mkdir(parents=True, exist_ok=True)
    names = {}
    for image in ("baseColor", "roughnessMetallic", "normal"):
        px = enlarged(image)
        if pattern is None:
            write_image(folder / f"{image}.png", px)
            names[image] = f"tex/{image}.png"
            continue
        width = SIDE // TILES
        for k in range(TILES):
            write_image(folder / pattern(image, 1001 + k), px[:, k * width:(k + 1) * width])
        names[image] = "tex/" + pattern(image, "TOKEN")
    return names


def avocado_stage(path, files, token=None):
    """A stage of the Avocado with UsdPreviewSurface reading `files`; with `token`, the
    paths hold it in place of TOKEN and the texture coordinates s are spread over ten
    tiles (s' = 10 s)."""
    points, normals, st, indices = avocado_mesh()
    if token is not None:
        st = st * np.array([TILES, 1.0])
        files = {k: v.replace("TOKEN", token) for k, v in files.items()}

    def arr(a, fmt):
        return "[" + ", ".join("(" + ", ".join(fmt % x for x in row) + ")" for row in a) + "]"

    def texture(name, image, color_space, extra=""):
        return f'''
        def Shader "{name}" {{
            uniform token info:id = "UsdUVTexture"
            asset inputs:file = @{files[image]}@
            token inputs:sourceColorSpace = "{color_space}"
            float2 inputs:st.connect = </World/M/St.outputs:result>
            {extra}
            float3 outputs:rgb
            float outputs:g
            float outputs:b
        }}'''

    decode = "float4 inputs:scale = (2, 2, 2, 1)\n            float4 inputs:bias = (-1, -1, -1, 0)"
    shaders = (texture("B", "baseColor", "sRGB") + texture("R", "roughnessMetallic", "raw")
               + texture("N", "normal", "raw", decode))
    counts = ", ".join(["3"] * (len(indices) // 3))
    path.write_text(f'''#usda 1.0
(
    defaultPrim = "World"
    metersPerUnit = 1
    upAxis = "Y"
)
def Xform "World" {{
    def Mesh "Avocado" (prepend apiSchemas = ["MaterialBindingAPI"]) {{
        int[] faceVertexCounts = [{counts}]
        int[] faceVertexIndices = [{", ".join(str(int(i)) for i in indices)}]
        point3f[] points = {arr(points, "%.7g")}
        normal3f[] normals = {arr(normals, "%.7g")} (interpolation = "vertex")
        texCoord2f[] primvars:st = {arr(st, "%.7g")} (interpolation = "vertex")
        uniform token subdivisionScheme = "none"
        rel material:binding = </World/M>
    }}
    def Material "M" {{
        token outputs:surface.connect = </World/M/S.outputs:surface>
        def Shader "S" {{
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor.connect = </World/M/B.outputs:rgb>
            float inputs:roughness.connect = </World/M/R.outputs:g>
            float inputs:metallic.connect = </World/M/R.outputs:b>
            normal3f inputs:normal.connect = </World/M/N.outputs:rgb>
            token outputs:surface
        }}
        def Shader "St" {{
            uniform token info:id = "UsdPrimvarReader_float2"
            string inputs:varname = "st"
            float2 outputs:result
        }}{shaders}
    }}
    def Camera "Camera" {{
        double3 xformOp:translate = (0.068, 0.032, 0.113)
        float3 xformOp:rotateXYZ = (0, 31, 0)
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]
        float focalLength = 35
        float horizontalAperture = 20.955
        float2 clippingRange = (0.001, 10)
    }}
    def DomeLight "Sky" {{
        float inputs:intensity = 0.6
    }}
    def DistantLight "Sun" {{
        float3 xformOp:rotateXYZ = (-40, 50, 0)
        uniform token[] xformOpOrder = ["xformOp:rotateXYZ"]
        float inputs:intensity = 3
        float inputs:angle = 2
    }}
}}
''')
    return path


def render(scene, out, seed, spp=64):
    run = subprocess.run([lucerna_bin(), "render", str(scene), "-o", str(out), "--spp", str(spp),
                          "--resolution", "96x96", "--seed", str(seed)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    px = oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)
    return px, run.stderr


def rel_mse(a, b):
    return float(np.mean((a - b) ** 2 / (b ** 2 + 0.01)))


def udim_name(image, number):
    return f"{image}.{number}.png"


def test_a_udim_avocado_renders_as_the_texture_it_was_cut_from(tmp_path):
    whole = avocado_stage(tmp_path / "whole.usda", write_textures(tmp_path / "tex", None))
    tiled = avocado_stage(tmp_path / "tiled.usda", write_textures(tmp_path / "tex", udim_name),
                          "<UDIM>")
    a, _ = render(whole, tmp_path / "a.exr", 1)
    b, _ = render(whole, tmp_path / "b.exr", 2)
    u, log = render(tiled, tmp_path / "u.exr", 3)
    same_seed, _ = render(tiled, tmp_path / "s.exr", 2)
    assert "UDIM" not in log and "fallback" not in log, log
    assert (a > 0).any() and a.mean() > 0.02, "the avocado is lit and in view"
    noise = rel_mse(a, b)
    # Independent renders: E[relMSE] is the same for both pairs (see test_twin); a tile read
    # at the wrong place, flipped, or one channel of the packing lost moves it far more.
    assert rel_mse(u, b) < 1.35 * noise, (rel_mse(u, b), noise)
    # With the same seed only the texels next to tile borders (clamped, not blended with
    # the neighbour tile) and rounding differ: far below the noise.
    assert rel_mse(same_seed, b) < 0.05 * noise, (rel_mse(same_seed, b), noise)


def test_uvtile_and_mapid_name_the_same_tiles(stage_file, converted, tmp_path):
    names = {
        "<UVTILE>": lambda image, n: f"{image}_u{(int(n) - 1001) % 10 + 1}_v1.png"
        if n != "TOKEN" else f"{image}_TOKEN.png",
        "_MAPID_": lambda image, n: f"{image}.{n}.png",
    }
    for token, pattern in names.items():
        folder = tmp_path / token.strip("<>_")
        files = write_textures(folder / "tex", pattern)
        scene = converted(avocado_stage(folder / "s.usda", files, token))
        m = scene["materials"][0]
        udim = scene["textures"][m["base_color_texture"]["texture"]]
        assert [n for n, _ in udim["tiles"]] == list(range(1001, 1011)), token
        # Tile 1003 is the third tenth of the image, clamped at its edges.
        tile = scene["textures"][dict(udim["tiles"])[1003]]
        assert (tile["width"], tile["height"]) == (SIDE // TILES, SIDE)
        assert (tile["wrap_u"], tile["wrap_v"]) == ("clamp_to_edge", "clamp_to_edge")
        expected = enlarged("baseColor")[:, 2 * SIDE // TILES:3 * SIDE // TILES]
        got = texels(scene, {"texture": dict(udim["tiles"])[1003]})
        assert np.array_equal(got[..., :3], expected), token
        # The metallic-roughness packing is done tile by tile too.
        mr = scene["textures"][m["metallic_roughness_texture"]["texture"]]
        assert len(mr["tiles"]) == TILES
        assert not scene.warnings_about("UDIM"), scene["warnings"]


def test_missing_tiles_read_the_fallback_and_are_named_once(tmp_path):
    files = write_textures(tmp_path / "tex", udim_name)
    for image in ("baseColor", "roughnessMetallic", "normal"):
        for n in (1004, 1007):
            (tmp_path / "tex" / udim_name(image, n)).unlink()
    stage = avocado_stage(tmp_path / "holes.usda", files, "<UDIM>")
    px, log = render(stage, tmp_path / "h.exr", 1, spp=4)
    warnings = [line for line in log.splitlines() if "UDIM texture" in line]
    assert warnings and all("tiles 1004, 1007 that meshes reach" in w for w in warnings), log
    # One warning per texture of the material (base colour, metallic-roughness, normal),
    # naming the material's slot and the asset.
    assert len(warnings) == 3, warnings
    assert any("/World/M:base_color (tex/baseColor.<UDIM>.png)" in w for w in warnings), warnings
    assert np.isfinite(px).all()


def test_unreadable_or_absent_tile_sets_warn_and_use_the_fallback(stage_file, converted, tmp_path):
    files = write_textures(tmp_path / "tex", udim_name)
    (tmp_path / "tex" / udim_name("baseColor", 1002)).write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    files["normal"] = "tex/nothing.<UDIM>.png"
    scene = converted(avocado_stage(tmp_path / "bad.usda", files, "<UDIM>"))
    bad = scene.warnings_about("UDIM texture")
    assert any("tile 1002 unreadable (baseColor.1002.png" in w and "fallback is read there" in w
               for w in bad), bad
    assert any("no tile of 'tex/nothing.<UDIM>.png' read among 1001-1100" in w for w in bad), bad
    m = scene["materials"][0]
    assert m["normal_texture"] is None
    base = scene["textures"][m["base_color_texture"]["texture"]]
    assert [n for n, _ in base["tiles"]] == [n for n in range(1001, 1011) if n != 1002]
    assert len(scene["textures"][m["metallic_roughness_texture"]["texture"]]["tiles"]) == TILES


@pytest.mark.parametrize("tiles, reason", [
    ([[1000, 1]], "outside 1001..=9999"),
    ([[1001, 1], [1001, 1]], "given twice"),
    ([[1001, 7]], "out of range"),
    ([[1001, 1], [4294967295, 2]], "outside 1001..=9999"),
    ([[1001, 0]], "texture 0 is itself a UDIM set"),
])
def test_bad_tile_lists_in_a_scene_file_are_refused(tmp_path, converted, stage_file, tiles, reason):
    files = write_textures(tmp_path / "tex", None)
    converted(avocado_stage(tmp_path / "ok.usda", files))
    path = tmp_path / "ok.lucerna"
    manifest = json.loads(path.read_text())
    manifest["textures"][0]["tiles"] = tiles
    path.write_text(json.dumps(manifest))
    run = subprocess.run([lucerna_bin(), "render", str(path), "-o", str(tmp_path / "x.exr"),
                          "--spp", "1", "--resolution", "8x8"], capture_output=True, text=True)
    assert run.returncode == 2, run.stderr
    assert "textures[0].tiles" in run.stderr and reason in run.stderr, run.stderr
    assert not (tmp_path / "x.exr").exists()


def test_materialx_graphs_over_a_udim_set_are_baked_tile_by_tile(stage_file, converted, tmp_path):
    """mix(fg, bg, image.r) over a set of tiles 1001 (r = 0) and 1012 (r = 1): one baked
    tile each, and the fallback (the image node's `default`) baked through the same mix."""
    write_image(tmp_path / "m.1001.png", np.zeros((2, 2, 3), np.uint8))
    write_image(tmp_path / "m.1012.png", np.full((2, 2, 3), 255, np.uint8))
    s = converted(stage_file('''def Xform "World" {
    def Mesh "Quad" (prepend apiSchemas = ["MaterialBindingAPI"]) {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
        texCoord2f[] primvars:st = [(0, 0), (3, 0), (3, 2), (0, 2)] (interpolation = "vertex")
        uniform token subdivisionScheme = "none"
        rel material:binding = </World/M>
    }
    def Material "M" {
        token outputs:mtlx:surface.connect = </World/M/S.outputs:out>
        def Shader "S" {
            uniform token info:id = "ND_open_pbr_surface_surfaceshader"
            color3f inputs:base_color.connect = </World/M/Mix.outputs:out>
            token outputs:out
        }
        def Shader "Img" {
            uniform token info:id = "ND_image_color3"
            asset inputs:file = @m.<UDIM>.png@ (colorSpace = "lin_rec709")
            color3f inputs:default = (0.5, 0.5, 0.5)
            color3f outputs:out
        }
        def Shader "R" {
            uniform token info:id = "ND_extract_color3"
            color3f inputs:in.connect = </World/M/Img.outputs:out>
            int inputs:index = 0
            float outputs:out
        }
        def Shader "Mix" {
            uniform token info:id = "ND_mix_color3"
            color3f inputs:fg = (1, 0, 0)
            color3f inputs:bg = (0, 0, 1)
            float inputs:mix.connect = </World/M/R.outputs:out>
            color3f outputs:out
        }
    }
}
'''))
    m = s["materials"][s.mesh("/World/Quad")["material"]]
    udim = s["textures"][m["base_color_texture"]["texture"]]
    tiles = dict(udim["tiles"])
    assert sorted(tiles) == [1001, 1012]
    assert texels(s, {"texture": tiles[1001]})[0, 0, :3] == pytest.approx([0, 0, 1])
    assert texels(s, {"texture": tiles[1012]})[0, 0, :3] == pytest.approx([1, 0, 0])
    fallback = texels(s, m["base_color_texture"])
    assert fallback.shape[:2] == (1, 1) and fallback[0, 0, :3] == pytest.approx([0.5, 0, 0.5])


def test_a_set_beyond_the_memory_limit_is_converted_a_part_at_a_time(converted, tmp_path,
                                                                     monkeypatch):
    """Thirty tiles of 64x640 RGBA bytes (160 KiB each, 4.7 MiB in all) under a limit of
    2 MiB: the plugin keeps at most half the limit of decoded images (and the one in use;
    here the limit is taken as all the plugin's, its own footprint not counted),
    decoding again those it dropped when they are packed, and writes every tile with the
    texels of a conversion without a limit."""
    from lucerna_usd import images

    files = write_textures(tmp_path / "tex", udim_name)
    stage = avocado_stage(tmp_path / "big.usda", files, "<UDIM>")
    free = converted(stage)
    held = []
    hold = images._Resident.hold

    def measured(self, image):
        hold(self, image)
        held.append(self.bytes())

    monkeypatch.setattr(images._Resident, "hold", measured)
    monkeypatch.setattr(images, "MAX_BYTES", 2 << 20)
    monkeypatch.setattr(images, "_BASELINE", 0)  # the budget is then half the limit
    limited = converted(stage)
    assert not limited["warnings"], limited["warnings"]
    assert held and max(held) <= (1 << 20) + 64 * 640 * 4 * 5, max(held)
    for slot in ("base_color_texture", "metallic_roughness_texture", "normal_texture"):
        a, b = (s["textures"][s["materials"][0][slot]["texture"]] for s in (free, limited))
        assert len(a["tiles"]) == len(b["tiles"]) == TILES
        for (n, i), (m, j) in zip(a["tiles"], b["tiles"]):
            assert n == m
            assert np.array_equal(texels(free, {"texture": i}), texels(limited, {"texture": j}))


def test_a_tile_beyond_the_memory_limit_refuses_the_set(converted, tmp_path, monkeypatch):
    """Decoding one 64x640 RGB tile needs 280 KiB (the bytes read and their RGBA copy): a
    limit of 256 KiB refuses the set at its first tile, naming it and --max-memory; the
    fallback is used."""
    from lucerna_usd import images

    files = write_textures(tmp_path / "tex", udim_name)
    monkeypatch.setattr(images, "MAX_BYTES", 256 << 10)
    scene = converted(avocado_stage(tmp_path / "big.usda", files, "<UDIM>"))
    refused = scene.warnings_about("--max-memory")
    assert any("tile 1001: an image of 64x640" in w and "fallback used" in w for w in refused), \
        scene["warnings"]
    assert scene["materials"][0]["base_color_texture"] is None


def test_inspect_counts_the_sets_and_their_tiles(tmp_path):
    stage = avocado_stage(tmp_path / "s.usda", write_textures(tmp_path / "tex", udim_name), "<UDIM>")
    run = subprocess.run([lucerna_bin(), "inspect", str(stage)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "textures: 33, 3 of them UDIM sets of 30 tiles in all" in run.stdout, run.stdout
