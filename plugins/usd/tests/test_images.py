"""Texture images as the plugin decodes them: a band of rows (or of tiles) at a time into
RGBA, from scanline and tiled files alike, colour not premultiplied by alpha; images
dropped under the memory budget decode again to the same texels."""

import numpy as np
import OpenImageIO as oiio
import pytest

from lucerna_usd import images


def write(path, pixels, fmt, tile=None):
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], fmt)
    spec.attribute("oiio:UnassociatedAlpha", 1)  # the texels as given, alpha or not
    if tile:
        spec.tile_width = spec.tile_height = tile
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), oiio.geterror()
    assert out.write_image(pixels), out.geterror()
    out.close()


def expected_rgba(pixels, one):
    c = pixels.shape[2]
    out = np.empty((*pixels.shape[:2], 4), pixels.dtype)
    out[..., :3] = pixels[..., :3] if c >= 3 else pixels[..., :1]
    out[..., 3] = pixels[..., 3] if c >= 4 else (pixels[..., 1] if c == 2 else one)
    return out


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("tile", [None, 16])
@pytest.mark.parametrize("kind", ["uint8", "float"])
def test_bands_of_rows_or_tiles_give_the_whole_image(tmp_path, monkeypatch, channels, tile, kind):
    """37 x 23 texels (not a multiple of the tiles or bands), read 5 rows at a time."""
    monkeypatch.setattr(images, "BAND_BYTES", 37 * channels * (1 if kind == "uint8" else 4) * 5)
    rng = np.random.default_rng(channels)
    if kind == "uint8":
        pixels = rng.integers(0, 256, (23, 37, channels), dtype=np.uint8)
        fmt, path, one = oiio.UINT8, tmp_path / "i.tif", 255
    else:
        pixels = rng.random((23, 37, channels), dtype=np.float32) * 4
        fmt, path, one = oiio.FLOAT, tmp_path / "i.exr", 1.0
    write(path, pixels, fmt, tile)
    image = images.read_resolved(str(path))
    got = image.raw8 if kind == "uint8" else image.pixels
    assert image.shape == (23, 37) and image.eight_bit == (kind == "uint8")
    assert np.array_equal(got, expected_rgba(pixels, one))


def test_a_nan_texel_names_its_rows(tmp_path):
    pixels = np.ones((40, 8, 3), np.float32)
    pixels[33, 2, 1] = np.nan
    write(tmp_path / "nan.exr", pixels, oiio.FLOAT)
    with pytest.raises(OSError, match="1 texel values are NaN or infinite in rows"):
        images.read_resolved(str(tmp_path / "nan.exr"))


def test_dropped_images_decode_again_to_the_same_texels(tmp_path, monkeypatch):
    """A budget of one image: reading a second drops the first; the first's texels come
    back, equal, when asked for (and the second is dropped in turn)."""
    monkeypatch.setattr(images, "MAX_BYTES", 2 * 64 * 64 * 4)
    monkeypatch.setattr(images, "_BASELINE", 0)
    monkeypatch.setattr(images, "_RESIDENT", images._Resident())
    rng = np.random.default_rng(7)
    a_px, b_px = (rng.integers(0, 256, (64, 64, 4), dtype=np.uint8) for _ in range(2))
    write(tmp_path / "a.png", a_px, oiio.UINT8)
    write(tmp_path / "b.png", b_px, oiio.UINT8)
    a = images.read_resolved(str(tmp_path / "a.png"))
    b = images.read_resolved(str(tmp_path / "b.png"))
    assert a._raw8 is None and b._raw8 is not None  # a was dropped for b
    assert np.array_equal(a.raw8, a_px)
    assert b._raw8 is None
    assert np.array_equal(b.raw8, b_px)
    assert images._RESIDENT.bytes() == 64 * 64 * 4
