"""Texture images for the plugin, read with OpenImageIO (PNG, JPEG, OpenEXR, Radiance HDR,
TIFF, ...). Paths are resolved by USD's asset resolver, so images inside a .usdz package
are read too.

UDIM texture sets (a path with `<UDIM>`, `<UVTILE>` or `_MAPID_`) are read as a
[`TileSet`]: each tile whose file the resolver finds, among tiles 1001-1100 (the range
OpenUSD's UsdShadeUdimUtils searches). `<UDIM>` and RenderMan's `_MAPID_` stand for the
tile number 1001 + u + 10 v; `<UVTILE>` for `u<u+1>_v<v+1>` (Mudbox's one-based form, as
MaterialX defines it)."""

import os
import resource
import tempfile

import numpy as np
import OpenImageIO as oiio
from pxr import Ar


#: Most bytes decoding one image may take (lucerna passes its --max-memory); None: no limit.
MAX_BYTES = None


#: The plugin's own peak memory before it decodes images (the interpreter, usd-core,
#: OpenImageIO, the stage), measured when first needed.
_BASELINE = None


def resident_budget():
    """Bytes of decoded images kept for reuse: half of what MAX_BYTES leaves beside the
    plugin's own footprint (None: no limit). Beyond it the least recently used images read
    from files are dropped and decoded again when something asks for them, so a conversion
    holds a bounded part of a texture set larger than memory, not all of it."""
    global _BASELINE
    if MAX_BYTES is None:
        return None
    if _BASELINE is None:
        _BASELINE = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    return max(0, MAX_BYTES - _BASELINE) // 2


class Image:
    """A decoded image: `pixels` (H, W, 4) float32, with RGB replicated from a grey image
    and alpha 1 where the file has none; `eight_bit` tells whether the file stored 8-bit
    values (USD's `auto` colour space reads those as sRGB); `raw8` keeps the 8-bit values
    as stored, for textures passed through unchanged (None for other images). An 8-bit
    image is decoded to bytes only; its float `pixels` are made the first time something
    asks for them (most 8-bit textures are passed through or packed as bytes and never
    need them).

    An image read from a file (`source`, the resolved path) is one of the resident images
    (`_Resident`): its texels may be dropped when others are decoded and are then decoded
    again, transparently, on the next use; shape and bit depth stay known. Images made in
    memory (baked, fallbacks) always keep their texels."""

    def __init__(self, path, pixels, eight_bit, raw8, source=None):
        self.path = path
        self._pixels = pixels
        self.eight_bit = eight_bit
        self._raw8 = raw8
        self._shape = (raw8 if raw8 is not None else pixels).shape[:2]
        self._source = source
        if source is not None:
            _RESIDENT.hold(self)

    def _texels(self):
        """Decodes the image again if its texels were dropped; marks it as just used."""
        if self._source is None:
            return
        if self._raw8 is None and self._pixels is None:
            pixels, _, raw8 = _decode(self._source)
            self._pixels, self._raw8 = pixels, raw8
        _RESIDENT.hold(self)

    def _drop(self):
        self._pixels = self._raw8 = None

    def _bytes(self):
        return sum(a.nbytes for a in (self._pixels, self._raw8) if a is not None)

    @property
    def raw8(self):
        if not self.eight_bit:
            return None
        self._texels()
        return self._raw8

    @property
    def pixels(self):
        self._texels()
        if self._pixels is None:
            self._pixels = self._raw8.astype(np.float32) * np.float32(1.0 / 255.0)
            if self._source is not None:
                _RESIDENT.hold(self)
        return self._pixels

    @property
    def shape(self):
        return self._shape


class _Resident:
    """The images read from files whose texels are in memory, least recently used first,
    kept within `resident_budget()` bytes (the image just used always stays)."""

    def __init__(self):
        self._images = {}  # id -> (image, bytes), in order of use

    def hold(self, image):
        """Marks `image` as just used, counting its texels, and drops others beyond the
        budget."""
        self._images.pop(id(image), None)
        self._images[id(image)] = (image, image._bytes())
        self.make_room(0, keep=id(image))

    def make_room(self, incoming, keep=None):
        """Drops the least recently used images (not `keep`) until `incoming` more bytes
        fit in the budget: called before an image is decoded, so that it never sits in
        memory beside those it will displace."""
        budget = resident_budget()
        if budget is None:
            return
        total = sum(b for _, b in self._images.values())
        for key in list(self._images):
            if total + incoming <= budget:
                break
            if key == keep:
                continue
            old, held = self._images.pop(key)
            old._drop()
            total -= held

    def bytes(self):
        """Bytes of texels held now."""
        return sum(image._bytes() for image, _ in self._images.values())


_RESIDENT = _Resident()


def _one(pixels):
    return 255 if pixels.dtype == np.uint8 else 1.0


class OverBudget(OSError):
    """An image that would take more memory to decode than the limit allows."""


#: Bytes of file texels decoded at a time (the band of rows read into the RGBA array).
BAND_BYTES = 1 << 22


def _decode(path):
    """(float RGBA pixels or None, whether 8-bit, 8-bit RGBA or None) of the image file at
    `path`, refusing one whose decoding would take more than MAX_BYTES (None: any).
    Read with ImageInput, not ImageBuf, so that OpenImageIO's image cache keeps no copy,
    and a band of rows at a time into the RGBA array, so that decoding needs little more
    than the array."""
    # Texels as stored: OpenImageIO would premultiply a PNG's colour by its alpha, which
    # texture files (glTF's, USD's: OpenUSD's Hio reads them so too) do not mean.
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(path, config)
    if inp is None:
        raise OSError(oiio.geterror().strip() or "cannot read the image")
    try:
        spec = inp.spec()  # the header only
        width, height, channels = spec.width, spec.height, spec.nchannels
        eight_bit = spec.format == oiio.TypeDesc(oiio.UINT8)
        dtype = np.uint8 if eight_bit else np.float32
        itemsize = np.dtype(dtype).itemsize
        tiled = spec.tile_width > 0
        rows = spec.tile_height if tiled else BAND_BYTES // max(1, width * channels * itemsize)
        rows = min(max(rows, 1), max(height, 1))
        # The RGBA array, and what the decoder holds: a band of tiles, or for scanline
        # files the whole image (OpenImageIO's PNG reader decodes it at once).
        held = (rows if tiled else height) * width * channels * itemsize
        need = width * height * 4 * itemsize + held
        if MAX_BYTES is not None and need > MAX_BYTES:
            raise OverBudget(f"an image of {width}x{height} pixels would need "
                             f"{need / 2**20:.0f} MiB to decode, more than the limit "
                             f"of {MAX_BYTES / 2**20:.0f} MiB (--max-memory)")
        _RESIDENT.make_room(need)
        out = np.empty((height, width, 4), dtype)
        fmt = oiio.UINT8 if eight_bit else oiio.FLOAT
        for y in range(0, height, rows):
            end = min(y + rows, height)
            if tiled:
                raw = inp.read_tiles(0, 0, spec.x, spec.x + width, spec.y + y, spec.y + end,
                                     spec.z, spec.z + max(spec.depth, 1), 0, channels, fmt)
            else:
                raw = inp.read_scanlines(0, 0, spec.y + y, spec.y + end, spec.z, 0, channels, fmt)
            if raw is None or inp.has_error:
                raise OSError(inp.geterror().strip() or "cannot decode the image")
            band = np.asarray(raw, dtype).reshape(end - y, width, channels)
            if not eight_bit and not np.isfinite(band).all():
                bad = int((~np.isfinite(band)).sum())
                raise OSError(f"{bad} texel values are NaN or infinite in rows {y}-{end - 1}")
            _fill_rgba(out[y:end], band)
    finally:
        inp.close()
    return (None, True, out) if eight_bit else (out, False, None)


def _fill_rgba(out, band):
    """`band` (rows, W, C) into `out` (rows, W, 4): RGB replicated from grey, alpha from
    a second channel of two, else 1 where the file has none."""
    c = band.shape[2]
    if c >= 3:
        out[..., :3] = band[..., :3]
    else:
        out[..., :3] = band[..., :1]
    if c >= 4:
        out[..., 3] = band[..., 3]
    else:
        out[..., 3] = band[..., 1] if c == 2 else _one(band)


def read(asset_path):
    """Reads the image an `Sdf.AssetPath` names. Raises OSError with the reason."""
    resolved = asset_path.resolvedPath
    if not resolved:
        raise OSError(f"cannot resolve {asset_path.path!r}")
    return read_resolved(resolved)


def read_resolved(resolved):
    """Reads the image at a path the asset resolver returned, refusing one that would take
    more than MAX_BYTES to decode. Raises OSError."""
    from . import heartbeat

    heartbeat()
    resident_budget()  # the plugin's footprint is measured before the first image
    if "[" in resolved and resolved.endswith("]"):
        # Inside a package (.usdz): copy the bytes out for OpenImageIO (the copy stays
        # while the conversion runs, for decoding again an image that was dropped).
        asset = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
        if asset is None:
            raise OSError(f"cannot open {resolved}")
        data = bytes(asset.GetBuffer())
        suffix = os.path.splitext(resolved[:-1])[1]
        f = tempfile.NamedTemporaryFile(suffix=suffix)
        f.write(data)
        f.flush()
        _PACKAGED.append(f)
        source = f.name
    else:
        source = resolved
    pixels, eight_bit, raw8 = _decode(source)
    return Image(resolved, pixels, eight_bit, raw8, source=source)


#: Copies of images read out of packages, removed when the plugin ends.
_PACKAGED = []


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
    fallback) and named in the set's `unreadable`; a tile beyond MAX_BYTES (--max-memory)
    refuses the whole set, as an image beyond it is refused. The tiles are resident
    images: a set larger than the plugin's budget is decoded a part at a time. Raises
    OSError where no tile is read."""
    resolver = Ar.GetResolver()
    tiles, unreadable = {}, {}
    for number in UDIM_SEARCH:
        candidate = udim_tile_path(path, number)
        anchored = layer.ComputeAbsolutePath(candidate) if layer else candidate
        resolved = str(resolver.Resolve(anchored))
        if not resolved:
            continue
        try:
            tile = read_resolved(resolved)
        except OverBudget as e:
            raise OverBudget(f"tile {number}: {e}") from None
        except OSError as e:
            unreadable[number] = f"{os.path.basename(resolved)}: {e}"
            continue
        tiles[number] = tile
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
