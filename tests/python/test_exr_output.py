"""The renderer's EXR as a compositor sees it, read with OpenImageIO (not with the Rust
`exr` crate that wrote it)."""
import os
import re
import subprocess
import tomllib
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("LUCERNA_BIN", str(ROOT / "target" / "release" / "lucerna"))

RGB_LAYERS = ["emission", "direct", "indirect", "nee", "bsdf", "direct_nee", "direct_bsdf",
              "indirect_nee", "indirect_bsdf", "direct_nee_unweighted", "direct_bsdf_unweighted",
              "albedo", "variance"]
CORE_CHANNELS = (["R", "G", "B", "A"] + [f"{l}.{c}" for l in RGB_LAYERS for c in "RGB"]
                 + ["normal.X", "normal.Y", "normal.Z", "depth.Z", "spp.Y"])


def read(path):
    inp = oiio.ImageInput.open(str(path))
    assert inp, oiio.geterror()
    try:
        spec = inp.spec()
        assert not inp.seek_subimage(1, 0), "the EXR must be single-part"
        inp.seek_subimage(0, 0)
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        channels = {name: pixels[:, :, i] for i, name in enumerate(spec.channelnames)}
        return spec, channels
    finally:
        inp.close()


@pytest.fixture(scope="module")
def default_render(tmp_path_factory):
    """The README's render command (`lucerna render`, no arguments) in an empty directory."""
    cwd = tmp_path_factory.mktemp("readme")
    subprocess.run([BIN, "render"], cwd=cwd, check=True)
    assert sorted(p.name for p in cwd.iterdir()) == ["render.exr"], "only render.exr is left"
    return read(cwd / "render.exr")


@pytest.fixture(scope="module")
def all_render(tmp_path_factory):
    """`lucerna render --aov all`: every core layer."""
    out = tmp_path_factory.mktemp("all") / "all.exr"
    subprocess.run([BIN, "render", "--aov", "all", "--spp", "16", "--resolution", "256x256",
                    "-o", str(out), "-q"], check=True)
    return read(out)


def assert_finite_float32(channels):
    for name, plane in channels.items():
        assert np.isfinite(plane).all(), name
        assert plane.dtype == np.float32


def test_readme_command_writes_the_beauty(default_render):
    """Without --aov a render writes the beauty only (RGBA), at the default 512x512."""
    spec, ch = default_render
    assert sorted(ch) == ["A", "B", "G", "R"]
    assert (spec.width, spec.height) == (512, 512)
    assert_finite_float32(ch)


def test_aov_all_writes_every_core_layer(all_render):
    spec, ch = all_render
    missing = [c for c in CORE_CHANNELS if c not in ch]
    assert not missing, f"missing channels: {missing}"
    assert (spec.width, spec.height) == (256, 256)
    assert_finite_float32(ch)


def test_header_metadata(default_render):
    spec, _ = default_render
    assert spec.getattribute("lucerna/renderer").startswith("lucerna ")
    assert spec.getattribute("lucerna/spp") == 64
    assert spec.getattribute("lucerna/nan_inf_discarded") == 0
    settings = tomllib.loads(spec.getattribute("lucerna/settings"))
    assert settings["mis"] == "power:2" and settings["spp"] == 64 and settings["rr"] == "throughput:0.1"
    assert spec.getattribute("lucerna/render_seconds") > 0
    for matrix in ("worldToCamera", "worldToNDC"):
        m = np.array(spec.getattribute(matrix), dtype=np.float64).reshape(4, 4)
        assert np.isfinite(m).all() and abs(np.linalg.det(m)) > 0


def test_world_to_ndc_projects_the_scene_into_the_frame(all_render):
    """Nuke's convention: row vector times matrix, divide by w, (0,0) top-left."""
    spec, ch = all_render
    to_ndc = np.array(spec.getattribute("worldToNDC"), dtype=np.float64).reshape(4, 4)
    # The world position of the centre pixel projects back onto the centre of the image.
    y, x = spec.height // 2, spec.width // 2
    p = np.array([ch["position.X"][y, x], ch["position.Y"][y, x], ch["position.Z"][y, x], 1.0])
    q = p @ to_ndc
    ndc = q[:2] / q[3]
    assert np.allclose(ndc, [(x + 0.5) / spec.width, (y + 0.5) / spec.height], atol=2.0 / spec.width)


def test_layer_sums(all_render):
    _, ch = all_render
    for c in "RGB":
        beauty = ch[c]
        parts = ch[f"emission.{c}"] + ch[f"direct.{c}"] + ch[f"indirect.{c}"]
        assert np.allclose(beauty, parts, rtol=1e-4, atol=1e-5)
        assert np.allclose(ch[f"direct.{c}"], ch[f"direct_nee.{c}"] + ch[f"direct_bsdf.{c}"], rtol=1e-4, atol=1e-5)


def test_aov_selection_writes_only_what_was_asked(tmp_path):
    out = tmp_path / "few.exr"
    subprocess.run([BIN, "render", "--spp", "2", "--resolution", "32x24", "--aov", "direct,albedo",
                    "-o", str(out), "-q"], check=True)
    spec, ch = read(out)
    assert sorted(ch) == sorted(["R", "G", "B", "A", "direct.R", "direct.G", "direct.B",
                                 "albedo.R", "albedo.G", "albedo.B"])
    assert (spec.width, spec.height) == (32, 24)


def test_storage_options_and_colour_space(tmp_path):
    """--exr-half stores light layers as half floats and keeps data layers and Cryptomatte
    float; --exr-compression sets the compression (lossy ones refused with data layers);
    every file states its colour space (Rec.709 primaries, D65; colorInteropID) and carries
    owner, capDate, a one-line summary in comments, the rays traced and the host, and, for a
    frame, framesPerSecond."""
    out = tmp_path / "half.exr"
    env = dict(os.environ, USER="artist")
    subprocess.run([BIN, "render", "-o", str(out), "--spp", "2", "--resolution", "64x64",
                    "--aov", "beauty,direct,albedo,normal,depth,crypto", "--exr-half",
                    "--exr-compression", "piz", "--frame", "3", "--fps", "25", "-q"],
                   check=True, env=env)
    inp = oiio.ImageInput.open(str(out))
    spec = inp.spec()
    inp.close()
    formats = {name: str(spec.channelformat(k)) for k, name in enumerate(spec.channelnames)}
    assert all(formats[c] == "half" for c in ["R", "G", "B", "A", "direct.R", "direct.B"])
    assert all(formats[c] == "float" for c in ["albedo.R", "normal.X", "depth.Z", "CryptoObject00.R"])
    assert spec.getattribute("compression") == "piz"
    chroma = np.array(spec.getattribute("chromaticities"))
    assert np.allclose(chroma, [0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290], atol=1e-6)
    assert spec.getattribute("colorInteropID") == "lin_rec709_scene"
    assert spec.getattribute("Copyright") == "artist"  # OpenEXR owner, as OpenImageIO names it
    assert len(spec.getattribute("DateTime")) == 19  # capDate "YYYY:MM:DD hh:mm:ss"
    # OpenEXR comments, as OpenImageIO names it.
    assert re.fullmatch(r"lucerna [\d.]+: <default: cornell-box>, 2 spp, 8192 samples, [\d.]+e\d+ rays "
                        r"in [\d.]+ s( on .+)?", spec.getattribute("ImageDescription")), \
        spec.getattribute("ImageDescription")
    assert spec.getattribute("lucerna/rays") > 8192
    assert tuple(spec.getattribute("framesPerSecond")) == (25000, 1000)
    # Half and float agree to half's precision.
    full = tmp_path / "full.exr"
    subprocess.run([BIN, "render", "-o", str(full), "--spp", "2", "--resolution", "64x64",
                    "--aov", "beauty", "-q"], check=True)
    a, b = read(out)[1], read(full)[1]
    assert np.allclose(a["R"], b["R"], rtol=2e-3, atol=1e-4)
    assert os.path.getsize(out) > 0
    # Lossy compression: refused with data layers, accepted without.
    bad = subprocess.run([BIN, "render", "-o", str(tmp_path / "bad.exr"), "--spp", "1",
                          "--resolution", "32x32", "--aov", "beauty,normal", "--exr-compression",
                          "dwaa:45", "-q"], capture_output=True, text=True)
    assert bad.returncode == 2 and "normal holds data" in bad.stderr, bad.stderr
    assert not (tmp_path / "bad.exr").exists()
    dwa = tmp_path / "dwa.exr"
    subprocess.run([BIN, "render", "-o", str(dwa), "--spp", "1", "--resolution", "32x32",
                    "--aov", "beauty", "--exr-compression", "dwaa:60", "-q"], check=True)
    inp = oiio.ImageInput.open(str(dwa))
    assert inp.spec().getattribute("compression") == "dwaa"
    assert inp.spec().getattribute("openexr:dwaCompressionLevel") == 60
    inp.close()


def parts_of(path):
    """(part name, channel names) of every part of an EXR, in file order."""
    inp = oiio.ImageInput.open(str(path))
    parts, index = [], 0
    while inp.seek_subimage(index, 0):
        spec = inp.spec()
        parts.append((spec.getattribute("name"), list(spec.channelnames)))
        index += 1
    inp.close()
    return parts


def test_multi_part_output(tmp_path):
    """--exr-parts layer writes a part per layer (`rgba` for the beauty) and group the parts
    light, data and cryptomatte; every channel keeps its name and value, each part carries
    the header, and lucerna reads such files back (two crop windows written in parts merge
    into the render, Cryptomatte included)."""
    aovs = ["--aov", "beauty,direct,indirect,albedo,normal,depth,crypto", "--spp", "4",
            "--resolution", "48x32", "-q"]
    single = tmp_path / "single.exr"
    subprocess.run([BIN, "render", "-o", str(single), *aovs], check=True)
    reference = read(single)[1]
    for split, names in [("layer", None), ("group", ["light", "data", "cryptomatte"])]:
        out = tmp_path / f"{split}.exr"
        subprocess.run([BIN, "render", "-o", str(out), "--exr-parts", split, *aovs], check=True)
        parts = parts_of(out)
        if names:
            assert [p for p, _ in parts] == names, parts
        else:
            assert parts[0] == ("rgba", ["R", "G", "B", "A"]), parts
            assert all(all(c.startswith(part + ".") for c in channels) for part, channels in parts[1:]), parts
        channels = [c for _, cs in parts for c in cs]
        assert sorted(channels) == sorted(reference), (split, channels)
        # Every part has the header; the pixels are the single part's.
        for index in range(len(parts)):
            inp = oiio.ImageInput.open(str(out))
            inp.seek_subimage(index, 0)
            assert inp.spec().getattribute("lucerna/spp") == 4
            inp.close()
        merged = tmp_path / f"{split}-merged.exr"
        passes = []
        for k, crop in enumerate(["0,0,24,32", "24,0,48,32"]):
            part = tmp_path / f"{split}-crop{k}.exr"
            subprocess.run([BIN, "render", "-o", str(part), "--exr-parts", split, "--crop", crop, *aovs],
                           check=True)
            passes.append(str(part))
        subprocess.run([BIN, "merge", *passes, "-o", str(merged)], check=True, capture_output=True)
        got = read(merged)[1]
        for name in ["R", "direct.G", "depth.Z", "CryptoObject00.R"]:
            assert np.array_equal(got[name], reference[name]), (split, name)
    bad = subprocess.run([BIN, "render", "-o", str(tmp_path / "bad.exr"), "--exr-parts", "views", "-q"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "unknown split \"views\"" in bad.stderr, bad.stderr


def windows(path, index=0):
    """(data window, display window) of part `index` as (x, y, width, height)."""
    inp = oiio.ImageInput.open(str(path))
    try:
        inp.seek_subimage(index, 0)
        s = inp.spec()
        return (s.x, s.y, s.width, s.height), (s.full_x, s.full_y, s.full_width, s.full_height)
    finally:
        inp.close()


def test_overscan(tmp_path):
    """--overscan renders beyond the image's edges: the data window reaches past the display
    window by the overscan (in every part of a multi-part file), and the pixels of the image
    itself are the render's without overscan, to the bit, in every layer. A crop of an
    overscanned render resumes and merges with the rest into the whole."""
    view = ["--aov", "beauty,direct,albedo,normal,depth,crypto", "--resolution", "48x32",
            "--env", "0.3,0.3,0.3", "-q"]
    aovs = [*view, "--spp", "4"]
    plain = tmp_path / "plain.exr"
    subprocess.run([BIN, "render", "-o", str(plain), *aovs], check=True)
    reference = read(plain)[1]
    wide = tmp_path / "wide.exr"
    subprocess.run([BIN, "render", "-o", str(wide), "--overscan", "8,4,6,2", *aovs], check=True)
    assert windows(wide) == ((-8, -4, 62, 38), (0, 0, 48, 32))
    got = read(wide)[1]
    for name, plane in reference.items():
        assert np.array_equal(got[name][4:36, 8:56], plane), name
    # Beyond the frame the render goes on: the environment around the box is there.
    assert got["R"][:, :8].min() > 0.1
    parts = tmp_path / "parts.exr"
    subprocess.run([BIN, "render", "-o", str(parts), "--overscan", "16", "--exr-parts", "layer", *aovs], check=True)
    for index in range(len(parts_of(parts))):
        assert windows(parts, index) == ((-16, -16, 80, 64), (0, 0, 48, 32)), index
    # A crop inside the image, resumed with more samples, then merged with the rest.
    left, right = tmp_path / "left.exr", tmp_path / "right.exr"
    split = ["--aov", "beauty,direct,depth,spp", "--resolution", "48x32", "--env", "0.3,0.3,0.3", "-q",
             "--overscan", "8,4,6,2"]
    subprocess.run([BIN, "render", "-o", str(left), "--crop", "0,0,24,32", *split, "--spp", "2"], check=True)
    subprocess.run([BIN, "render", "-o", str(left), "--crop", "0,0,24,32", "--resume", *split, "--spp", "4"],
                   check=True)
    assert windows(left) == ((0, 0, 24, 32), (0, 0, 48, 32))
    subprocess.run([BIN, "render", "-o", str(right), "--crop", "24,0,48,32", *split, "--spp", "4"], check=True)
    merged = tmp_path / "merged.exr"
    subprocess.run([BIN, "merge", str(left), str(right), "-o", str(merged)], check=True, capture_output=True)
    assert windows(merged) == ((0, 0, 48, 32), (0, 0, 48, 32))
    got = read(merged)[1]
    for name in ["R", "direct.G", "depth.Z"]:
        # A resumed render sums its samples in another order: equal to float rounding.
        assert np.allclose(got[name], reference[name], rtol=1e-5, atol=1e-6), name
    bad = subprocess.run([BIN, "render", "-o", str(tmp_path / "bad.exr"), "--overscan", "1,2", "-q"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "expected PIXELS or LEFT,TOP,RIGHT,BOTTOM" in bad.stderr, bad.stderr


def test_channel_aliases(tmp_path):
    """--exr-aliases writes the normal, position and depth again as N, P and Z (Karma's and
    RenderMan's names), as data (32-bit with --exr-half), in every split of parts; lucerna's
    own reading (resume, merge) leaves them out."""
    args = ["--aov", "normal,position,depth,spp", "--resolution", "24x16", "--spp", "2", "-q"]
    out = tmp_path / "aliases.exr"
    subprocess.run([BIN, "render", "-o", str(out), "--exr-aliases", "--exr-half", *args], check=True)
    spec, channels = read(out)
    for layer, alias in [("normal", "N"), ("position", "P")]:
        for c in "XYZ":
            assert np.array_equal(channels[f"{alias}.{c}"], channels[f"{layer}.{c}"]), (alias, c)
    assert np.array_equal(channels["Z"], channels["depth.Z"])
    types = dict(zip(spec.channelnames, spec.channelformats or [spec.format] * spec.nchannels))
    assert str(types["Z"]) == "float" and str(types["N.X"]) == "float" and str(types["R"]) == "half", types
    parts = tmp_path / "parts.exr"
    subprocess.run([BIN, "render", "-o", str(parts), "--exr-aliases", "--exr-parts", "layer", *args], check=True)
    names = dict(parts_of(parts))
    assert names["N"] == ["N.X", "N.Y", "N.Z"] and names["P"] == ["P.X", "P.Y", "P.Z"], names
    assert sorted(names["depth"]) == ["Z", "depth.Z"], names
    # Crops written with aliases, one file single-part and one split by layer, merge.
    left, right, merged = tmp_path / "left.exr", tmp_path / "right.exr", tmp_path / "merged.exr"
    subprocess.run([BIN, "render", "-o", str(left), "--exr-aliases", "--crop", "0,0,12,16", *args], check=True)
    subprocess.run([BIN, "render", "-o", str(right), "--exr-aliases", "--exr-parts", "layer", "--crop",
                    "12,0,24,16", *args], check=True)
    subprocess.run([BIN, "merge", str(left), str(right), "-o", str(merged)], check=True, capture_output=True)
    spec, got = read(merged)
    assert not {"Z", "N.X", "P.X"} & set(spec.channelnames)
    whole = tmp_path / "whole.exr"
    subprocess.run([BIN, "render", "-o", str(whole), *args], check=True)
    assert np.array_equal(got["depth.Z"], read(whole)[1]["depth.Z"])
