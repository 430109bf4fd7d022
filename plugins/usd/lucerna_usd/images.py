"""Texture images for the plugin, read with OpenImageIO (PNG, JPEG, OpenEXR, Radiance HDR,
TIFF, ...). Paths are resolved by USD's asset resolver, so images inside a .usdz package
are read too.

UDIM texture sets (a path with `<UDIM>`, `<UVTILE>` or `_MAPID_`) are read as a
[`TileSet`]: each tile whose file the resolver finds, among tiles 1001-1100 (the range
OpenUSD's UsdShadeUdimUtils searches). `<UDIM>` and RenderMan's `_MAPID_` stand for the
tile number 1001 + u + 10 v; `<UVTILE>` for `u<u+1>_v<v+1>` (Mudbox's one-based form, as
MaterialX defines it)."""

import os
import tempfile

import numpy as np
import OpenImageIO as oiio
from pxr import Ar


#: Most bytes decoding one image may take (lucerna passes its --max-memory); None: no limit.
MAX_BYTES = None


class Image:
    """A decoded image: `pixels` (H, W, 4) float32, with RGB replicated from a grey image
    and alpha 1 where the file has none; `eight_bit` tells whether the file stored 8-bit
    values (USD's `auto` colour space reads those as sRGB); `raw8` keeps the 8-bit values
    as stored, for textures passed through unchanged. An 8-bit image is decoded to bytes
    only; its float `pixels` are made the first time something asks for them (most
    8-bit textures are passed through or packed as bytes and never need them)."""

    def __init__(self, path, pixels, eight_bit, raw8):
        self.path = path
        self._pixels = pixels
        self.eight_bit = eight_bit
        self.raw8 = raw8

    @property
    def pixels(self):
        if self._pixels is None:
            self._pixels = self.raw8.astype(np.float32) * np.float32(1.0 / 255.0)
        return self._pixels

    @property
    def shape(self):
        return (self.raw8 if self._pixels is None else self._pixels).shape[:2]


def _rgba(pixels):
    h, w, c = pixels.shape
    if c >= 4:
        return np.ascontiguousarray(pixels[..., :4])
    out = np.empty((h, w, 4), pixels.dtype)
    if c >= 3:
        out[..., :3] = pixels[..., :3]
    else:
        out[..., :3] = pixels[..., :1]
    out[..., 3] = pixels[..., 1] if c == 2 else _one(pixels)
    return out


def _one(pixels):
    return 255 if pixels.dtype == np.uint8 else 1.0


class OverBudget(OSError):
    """An image that would take more memory to decode than the limit allows."""


def _read_file(path, limit):
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        raise OSError(buf.geterror().strip() or "cannot read the image")
    spec = buf.spec()  # the header only: ImageBuf reads pixels on demand
    if buf.has_error:
        raise OSError(buf.geterror().strip() or "cannot read the image")
    # Float pixels, RGBA floats, and the 8-bit copy: what decoding holds at its peak.
    need = spec.width * spec.height * (spec.nchannels * 4 + 16 + 4 + spec.nchannels)
    if limit is not None and need > limit:
        raise OverBudget(f"an image of {spec.width}x{spec.height} pixels would need "
                         f"{need / 2**20:.0f} MiB to decode, more than the "
                         f"{max(limit, 0) / 2**20:.0f} MiB left of the limit of "
                         f"{MAX_BYTES / 2**20:.0f} MiB (--max-memory)")
    eight_bit = spec.format == oiio.TypeDesc(oiio.UINT8)
    if eight_bit:
        raw = buf.get_pixels(oiio.UINT8)
        if raw is None or buf.has_error:
            raise OSError(buf.geterror().strip() or "cannot decode the image")
        return None, True, _rgba(np.asarray(raw, np.uint8).reshape(spec.height, spec.width, spec.nchannels))
    pixels = buf.get_pixels(oiio.FLOAT)
    if pixels is None or buf.has_error:
        raise OSError(buf.geterror().strip() or "cannot decode the image")
    pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    if not np.isfinite(pixels).all():
        bad = int((~np.isfinite(pixels)).sum())
        raise OSError(f"{bad} texel values are NaN or infinite")
    return _rgba(pixels), False, None


def read(asset_path):
    """Reads the image an `Sdf.AssetPath` names. Raises OSError with the reason."""
    resolved = asset_path.resolvedPath
    if not resolved:
        raise OSError(f"cannot resolve {asset_path.path!r}")
    return read_resolved(resolved)


def read_resolved(resolved, limit=None):
    """Reads the image at a path the asset resolver returned, refusing one that would take
    more than `limit` bytes to decode (default: the whole MAX_BYTES). Raises OSError."""
    from . import heartbeat

    heartbeat()
    limit = MAX_BYTES if limit is None else limit
    if "[" in resolved and resolved.endswith("]"):
        # Inside a package (.usdz): copy the bytes out for OpenImageIO.
        asset = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
        if asset is None:
            raise OSError(f"cannot open {resolved}")
        data = bytes(asset.GetBuffer())
        suffix = os.path.splitext(resolved[:-1])[1]
        with tempfile.NamedTemporaryFile(suffix=suffix) as f:
            f.write(data)
            f.flush()
            pixels, eight_bit, raw8 = _read_file(f.name, limit)
    else:
        pixels, eight_bit, raw8 = _read_file(resolved, limit)
    return Image(resolved, pixels, eight_bit, raw8)


#: The tokens that make a path a UDIM texture set.
UDIM_TOKENS = ("<UDIM>", "<UVTILE>", "_MAPID_")
#: Tiles searched: OpenUSD's range (ten rows of ten).
UDIM_SEARCH = range(1001, 1101)


def udim_token(path):
    """The UDIM token in `path`, or None."""
    return next((t for t in UDIM_TOKENS if t in path), None)


def udim_tile_path(path, number):
    """`path` with its UDIM token replaced by tile `number`'s name."""
    token = udim_token(path)
    if token == "<UVTILE>":
        u, v = (number - 1001) % 10, (number - 1001) // 10
        return path.replace(token, f"u{u + 1}_v{v + 1}")
    return path.replace(token, str(number))


class TileSet:
    """A UDIM texture set: `tiles`, {tile number: Image}, and `fallback`, the Image read
    where the set has no tile (given as an Image, or as a linear RGBA value: a 1x1 image)."""

    def __init__(self, path, tiles, fallback, unreadable=None):
        self.path = path
        self.tiles = tiles
        #: Tiles whose files were found but could not be read: {number: reason}.
        self.unreadable = unreadable or {}
        if not isinstance(fallback, Image):
            fallback = Image(f"{path} (fallback)",
                             np.asarray(fallback, np.float32).reshape(1, 1, 4), False, None)
        self.fallback = fallback

    @property
    def eight_bit(self):
        return all(t.eight_bit for t in self.tiles.values())

    def image(self, number):
        """Tile `number`'s image, or the fallback where the set has none."""
        return self.tiles.get(number, self.fallback)


def read_tiles(path, layer, fallback):
    """The UDIM set `path` names, anchored at `layer` (the layer that authored it), with
    `fallback` (linear RGBA). A tile whose file cannot be read is left out (it reads the
    fallback) and named in the set's `unreadable`. The tiles together stay within
    MAX_BYTES (--max-memory): a tile that would pass it refuses the whole set, as an image
    beyond it is refused. Raises OSError where no tile is read."""
    resolver = Ar.GetResolver()
    tiles, unreadable = {}, {}
    held = 0
    for number in UDIM_SEARCH:
        candidate = udim_tile_path(path, number)
        anchored = layer.ComputeAbsolutePath(candidate) if layer else candidate
        resolved = str(resolver.Resolve(anchored))
        if not resolved:
            continue
        try:
            tile = read_resolved(resolved, None if MAX_BYTES is None else MAX_BYTES - held)
        except OverBudget as e:
            raise OverBudget(f"tile {number} after {len(tiles)} tiles of {held / 2**20:.0f} MiB: "
                             f"{e}") from None
        except OSError as e:
            unreadable[number] = f"{os.path.basename(resolved)}: {e}"
            continue
        tiles[number] = tile
        held += (tile.raw8 if tile.raw8 is not None else tile.pixels).nbytes
    if not tiles:
        found = "; ".join(f"tile {n} ({r})" for n, r in unreadable.items())
        raise OSError(f"no tile of {path!r} read among {UDIM_SEARCH.start}-{UDIM_SEARCH.stop - 1}"
                      + (f": {found}" if found else ""))
    return TileSet(path, tiles, fallback, unreadable)


def srgb_to_linear(x):
    """The sRGB transfer function's inverse (IEC 61966-2-1)."""
    x = np.asarray(x, dtype=np.float32)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


#: srgb_to_linear of the 256 8-bit values: decoding an 8-bit image by table lookup is an
#: order of magnitude faster than the power function over every texel.
SRGB_TO_LINEAR_8 = srgb_to_linear(np.arange(256, dtype=np.float32) / np.float32(255.0))


def resample(pixels, shape):
    """Nearest-texel resampling of (H, W, C) to `shape` (H', W'), for combining channels
    of images of different sizes into one texture."""
    h, w = pixels.shape[:2]
    if (h, w) == tuple(shape):
        return pixels
    ys = np.minimum(((np.arange(shape[0]) + 0.5) * h / shape[0]).astype(int), h - 1)
    xs = np.minimum(((np.arange(shape[1]) + 0.5) * w / shape[1]).astype(int), w - 1)
    return pixels[ys][:, xs]
