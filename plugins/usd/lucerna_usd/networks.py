"""Evaluating shader networks: what value, texture or primvar feeds a surface input.

A surface shader's input resolves, through material interface inputs and node-graph
outputs (`UsdShade.Input.GetValueProducingAttributes`), to an authored value or to the
output of an upstream node. Upstream nodes are evaluated into one of three sources:

- `("value", v)`: a constant (a float or a tuple of floats);
- `("texture", TextureSource)`: an image read through texture coordinates, with its
  channel selection, scale and bias; combinations of textures (MaterialX multiply, mix,
  extract, ...) are baked into a float image at the resolution of the largest input;
- `("primvar", name)`: a per-vertex primvar (vertex colours, or texture coordinates
  where the consumer is a texture's `st`).

Nodes understood: UsdPreviewSurface's UsdUVTexture, UsdPrimvarReader_*, UsdTransform2d;
their MaterialX twins (ND_UsdUVTexture_23, ND_UsdPrimvarReader_*, ND_UsdTransform2d);
MaterialX image, tiledimage, texcoord, geompropvalue, constant, convert, extract,
separate2/3/4, swizzle, combine2/3/4, multiply, add, subtract, divide, mix, normalmap,
place2d, dot (pass-through); RenderMan PxrTexture, PxrNormalMap and PxrManifold2D.
Anything else is warned about, naming the node and its id, and the input takes its
fallback value.

Colour spaces of images: UsdUVTexture's `sourceColorSpace` (auto: 8-bit files are sRGB);
for MaterialX images the file input's `colorSpace` metadata (srgb_texture, lin_rec709,
raw, acescg / lin_ap1, as MaterialX names them); without one, colour-typed images follow
`auto` (as Storm and Karma read 8-bit colour images) and float and vector images are raw.
ACEScg images are converted to lucerna's linear Rec.709 working space."""

import copy

import numpy as np
from pxr import Sdf, UsdShade

from . import images
from . import mtlx

_CHANNELS = {"r": [0], "g": [1], "b": [2], "a": [3], "rgb": [0, 1, 2], "rgba": [0, 1, 2, 3],
             "resultR": [0], "resultG": [1], "resultB": [2], "resultA": [3],
             "resultRGB": [0, 1, 2], "resultRGBA": [0, 1, 2, 3],
             "outr": [0], "outg": [1], "outb": [2], "outa": [3],
             "outx": [0], "outy": [1], "outz": [2], "outw": [3]}
_WRAP = {"repeat": "repeat", "periodic": "repeat", "mirror": "mirrored_repeat",
         "clamp": "clamp_to_edge", "useMetadata": "repeat", "black": "clamp_to_edge",
         "constant": "clamp_to_edge"}
_SWIZZLE = {"r": 0, "g": 1, "b": 2, "a": 3, "x": 0, "y": 1, "z": 2, "w": 3}

#: ACEScg (AP1 primaries, D60) to linear Rec.709 (D65), Bradford-adapted, as OCIO's
#: ACES configs and MaterialX's colour management use it.
ACESCG_TO_REC709 = np.array([[1.70505, -0.62179, -0.08326],
                             [-0.13026, 1.14080, -0.01055],
                             [-0.02400, -0.12897, 1.15297]], dtype=np.float32)

_LINEAR_8 = (np.arange(256, dtype=np.float32) / np.float32(255.0)).astype(np.float32)

_SRGB_NAMES = {"srgb", "srgb_texture", "srgb_rec709", "g22_rec709", "srgb_displayp3"}
_LINEAR_NAMES = {"raw", "linear", "lin_rec709", "lin_srgb", "scene_linear", "data",
                 "lin_rec709_scene", "srgb_linear", "linear rec.709 (srgb)"}
_ACESCG_NAMES = {"acescg", "lin_ap1", "aces - acescg", "acescg_linear", "lin_ap1_scene"}


class TextureSource:
    """An image read through texture coordinates `st_name` (with `transform`, lucerna's
    UvTransform or None): the image's linear RGBA after scale and bias, then `channels`."""

    def __init__(self, image, channels, scale, bias, color_space, wrap, st_name, transform,
                 element):
        self.image = image
        self.channels = list(channels)
        self.scale = np.asarray(scale, dtype=np.float32)
        self.bias = np.asarray(bias, dtype=np.float32)
        self.color_space = color_space
        self.wrap = wrap
        self.st_name = st_name
        self.transform = transform
        self.element = element

    @classmethod
    def baked(cls, values, like, element):
        """A texture of the float values (H, W, C) with `like`'s coordinates and wrap."""
        h, w, c = values.shape
        px = np.ones((h, w, 4), np.float32)
        px[..., :min(c, 4)] = values[..., :4]
        image = images.Image(f"{element} (baked)", px, False, None)
        return cls(image, range(min(c, 4)), (1.0,) * 4, (0.0,) * 4, "raw", like.wrap,
                   like.st_name, like.transform, element)

    @property
    def srgb(self):
        """Whether texel values are sRGB-encoded (USD's `auto`: 8-bit images are)."""
        if self.color_space == "sRGB":
            return True
        return self.color_space == "auto" and self.image.eight_bit

    @property
    def plain(self):
        """No scale and no bias: the values are used as decoded."""
        return bool(np.all(self.scale == 1.0) and np.all(self.bias == 0.0))

    def linear(self):
        """The texture's linear RGBA values after scale and bias, (H, W, 4) float32."""
        px = self.image.pixels
        if self.srgb:
            raw8 = self.image.raw8
            rgb = (images.SRGB_TO_LINEAR_8[raw8[..., :3]] if raw8 is not None
                   else images.srgb_to_linear(px[..., :3]))
            px = np.concatenate([rgb, px[..., 3:]], 2)
        elif self.color_space == "ACEScg":
            rgb = px[..., :3] @ ACESCG_TO_REC709.T
            px = np.concatenate([rgb, px[..., 3:]], 2)
        if self.plain:
            return px
        return px * self.scale + self.bias

    def values(self, count):
        """The selected output channels, (H, W, count) float32: one channel is replicated,
        missing ones are zero."""
        raw8 = self.image.raw8
        if raw8 is not None and self.color_space != "ACEScg":
            # 8-bit texels: each output channel by a 256-entry table that holds the colour
            # decoding, scale and bias, instead of arithmetic over every texel.
            out = np.empty((*raw8.shape[:2], len(self.channels)), np.float32)
            for i, c in enumerate(self.channels):
                table = images.SRGB_TO_LINEAR_8 if self.srgb and c < 3 else _LINEAR_8
                np.take(table * self.scale[c] + self.bias[c], raw8[..., c], out=out[..., i])
            lin = out
        else:
            lin = self.linear()[..., self.channels]
        if lin.shape[2] < count:
            lin = np.repeat(lin[..., :1], count, axis=2) if lin.shape[2] == 1 else np.concatenate(
                [lin, np.zeros((*lin.shape[:2], count - lin.shape[2]), np.float32)], 2)
        return lin[..., :count]

    def select(self, channels):
        """The same texture with output channels `channels` (indices into this one's)."""
        return TextureSource(self.image, [self.channels[min(c, len(self.channels) - 1)] for c in channels],
                             self.scale, self.bias, self.color_space, self.wrap, self.st_name,
                             self.transform, self.element)

    def affine(self, scale, bias):
        """The same texture times `scale` plus `bias` (scalars, or one per output channel)."""
        s = self.scale.copy()
        b = self.bias.copy()
        scale = np.broadcast_to(np.asarray(scale, np.float32), (len(self.channels),))
        bias = np.broadcast_to(np.asarray(bias, np.float32), (len(self.channels),))
        if len(set(self.channels)) != len(self.channels) and not (
                np.all(scale == scale[0]) and np.all(bias == bias[0])):
            return None  # one source channel read twice with different factors: bake
        for out, src in enumerate(self.channels):
            s[src] = s[src] * scale[out]
            b[src] = b[src] * scale[out] + bias[out]
        return TextureSource(self.image, self.channels, s, b, self.color_space, self.wrap,
                             self.st_name, self.transform, self.element)

    def mean(self):
        """The mean of each output channel (a texture where only a constant can be used);
        of a UDIM set, the mean of its tiles' means (each covers a unit square)."""
        if self.tiles is not None:
            means = [self.at_tile(n).mean() for n in self.tiles]
            return tuple(float(v) for v in np.mean(means, axis=0))
        values = self.values(len(self.channels))
        return tuple(float(v) for v in values.reshape(-1, values.shape[2]).mean(0))

    @property
    def tiles(self):
        """The tile numbers of a UDIM set, or None for one image."""
        return sorted(self.image.tiles) if isinstance(self.image, images.TileSet) else None

    def at_tile(self, number):
        """This texture of a UDIM set restricted to tile `number`'s image (None: the
        fallback, read as the linear value it is, through the same scale and bias), clamped
        at its edges so that no lookup blends two tiles."""
        tile = copy.copy(self)
        tile.image = self.image.image(number) if number is not None else self.image.fallback
        if tile.image is self.image.fallback:
            tile.color_space = "raw"
        tile.wrap = ("clamp_to_edge", "clamp_to_edge")
        return tile


def as_array(value):
    """A value (float, Gf vector, tuple) as a 1-D float array."""
    return np.atleast_1d(np.asarray(value, dtype=np.float64)).astype(np.float64)


def as_value(array):
    array = np.atleast_1d(array)
    return float(array[0]) if array.size == 1 else tuple(float(x) for x in array)


def fit(value, count):
    """A value as `count` components: a scalar is replicated, extra components dropped."""
    a = as_array(value)
    if a.size == 1:
        return np.repeat(a, count)
    if a.size < count:
        return np.concatenate([a, np.zeros(count - a.size)])
    return a[:count]


def color_space_kind(name, typed_color):
    """lucerna's reading of a colour-space name: 'sRGB', 'raw', 'ACEScg' or 'auto'; None for
    a name it does not know."""
    if not name:
        return "auto" if typed_color else "raw"
    key = str(name).strip().lower()
    if key in ("auto",):
        return "auto"
    if key in _SRGB_NAMES or key == "srgb":
        return "sRGB"
    if key in _LINEAR_NAMES:
        return "raw"
    if key in _ACESCG_NAMES:
        return "ACEScg"
    return None


class Network:
    """Evaluates inputs of shader networks at `time`; `warn(element, message)` reports."""

    def __init__(self, time, warn):
        self.time = time
        self.warn = warn
        self._images = {}

    # ---- inputs ---------------------------------------------------------------------
    def source(self, shader, name, default):
        """What feeds input `name` of `shader`: a source tuple (see the module doc)."""
        inp = shader.GetInput(name)
        if not inp:
            return "value", default
        attrs = inp.GetValueProducingAttributes()
        if not attrs:
            return "value", default
        attr = attrs[0]
        if not UsdShade.Output.IsOutput(attr):
            value = attr.Get(self.time)
            return "value", default if value is None else value
        node = UsdShade.Shader(attr.GetPrim())
        element = f"{shader.GetPath()}.inputs:{name}"
        return self.output(node, UsdShade.Output(attr).GetBaseName(), element, default)

    def value(self, node, name, default):
        """The constant value input `name` of `node` gets, or `default` (also where a
        network feeds it)."""
        kind, value = self.source(node, name, default)
        return value if kind == "value" else default

    def authored(self, node, name):
        """The input's value-producing attribute, or None where nothing is authored."""
        inp = node.GetInput(name)
        attrs = inp.GetValueProducingAttributes() if inp else []
        if attrs and (UsdShade.Output.IsOutput(attrs[0]) or attrs[0].HasAuthoredValue()):
            return attrs[0]
        return None

    # ---- nodes ----------------------------------------------------------------------
    def output(self, node, output, element, default):
        node_id = node.GetIdAttr().Get() if node else None
        path = str(node.GetPath()) if node else element
        family = mtlx.node_family(node_id) if node_id else None
        handler = getattr(self, "_node_" + family, None) if family else None
        if handler is None:
            self.warn(path, f"unknown shader {node_id!r} feeding {element}: the input's "
                      "fallback value is used")
            return "value", default
        try:
            result = handler(node, output, element, default, node_id)
        except (ValueError, TypeError, IndexError) as e:
            self.warn(path, f"cannot evaluate {node_id!r} ({e}): the input's fallback value is used")
            return "value", default
        return result

    def _in(self, node, name, element, default):
        return self.source(node, name, default)

    def _node_UsdUVTexture(self, node, output, element, default, node_id):
        if output not in _CHANNELS:
            self.warn(str(node.GetPath()), f"unknown UsdUVTexture output {output!r}: fallback used")
            return "value", default
        fallback4 = fit(self.value(node, "fallback", (0.0, 0.0, 0.0, 1.0)), 4)
        fallback = as_value(fallback4[_CHANNELS[output]])
        color_space = str(self.value(node, "sourceColorSpace", "auto"))
        wraps = [str(self.value(node, axis, "useMetadata")) for axis in ("wrapS", "wrapT")]
        texture = self._image(node, "file", _CHANNELS[output], color_space, wraps, "st", element,
                              fallback4)
        if texture is None:
            return "value", fallback
        return "texture", texture.affine(
            fit(self.value(node, "scale", (1.0,) * 4), 4)[_CHANNELS[output]],
            fit(self.value(node, "bias", (0.0,) * 4), 4)[_CHANNELS[output]]) or texture

    def _node_image(self, node, output, element, default, node_id):
        count = mtlx.output_size(node_id, output)
        channels = list(range(count)) if output in ("out", "") else _CHANNELS.get(output, [0])
        attr = self.authored(node, "file")
        typed_color = mtlx.output_type(node_id, output).startswith("color")
        name = attr.GetColorSpace() if attr is not None and attr.HasColorSpace() else None
        if not name and attr is not None:
            name = _inherited_color_space(attr.GetPrim())
        color_space = color_space_kind(name, typed_color)
        if color_space is None:
            self.warn(str(node.GetPath()), f"unknown colour space {name!r}: the image is read as raw")
            color_space = "raw"
        wraps = [str(self.value(node, axis, "periodic")) for axis in ("uaddressmode", "vaddressmode")]
        fallback = self.value(node, "default", None)
        fallback4 = np.array([0.0, 0.0, 0.0, 1.0])
        if fallback is not None:
            fallback4[channels] = fit(fallback, len(channels))
        texture = self._image(node, "file", channels, color_space, wraps, "texcoord", element,
                              fallback4)
        if texture is None:
            # MaterialX: an image whose file is missing or unreadable gives its `default`,
            # zero where none is authored (not the default of the input it feeds).
            return "value", as_value(fallback4[channels])
        return "texture", texture

    def _node_tiledimage(self, node, output, element, default, node_id):
        kind, texture = self._node_image(node, output, element, default, node_id)
        if kind != "texture":
            return kind, texture
        tiling = fit(self.value(node, "uvtiling", (1.0, 1.0)), 2)
        offset = fit(self.value(node, "uvoffset", (0.0, 0.0)), 2)
        if not (np.allclose(tiling, 1.0) and np.allclose(offset, 0.0)):
            texture.transform = _compose(texture.transform, _uv_transform(tiling, 0.0, -offset / tiling))
        return kind, texture

    def _node_PxrTexture(self, node, output, element, default, node_id):
        channels = _CHANNELS.get(output, [0, 1, 2])
        linearize = int(self.value(node, "linearize", 0))
        missing = (*fit(self.value(node, "missingColor", (1.0, 0.0, 1.0)), 3),
                   float(as_array(self.value(node, "missingAlpha", 1.0))[0]))
        texture = self._image(node, "filename", channels, "sRGB" if linearize else "raw",
                              ["periodic", "periodic"], "manifold", element, missing)
        if texture is None:
            return "value", default
        return "texture", texture

    def _node_PxrNormalMap(self, node, output, element, default, node_id):
        texture = self._image(node, "filename", [0, 1, 2], "raw", ["periodic", "periodic"],
                              "manifold", element)
        if texture is None:
            return "value", default
        return "texture", NormalMap(texture.affine(2.0, -1.0),
                                    float(self.value(node, "bumpScale", 1.0)))

    def _node_constant(self, node, output, element, default, node_id):
        return self._in(node, "value", element, default)

    def _node_dot(self, node, output, element, default, node_id):
        return self._in(node, "in", element, default)

    def _node_convert(self, node, output, element, default, node_id):
        kind, value = self._in(node, "in", element, default)
        count = mtlx.output_size(node_id, output)
        if kind == "value":
            return "value", as_value(fit(value, count))
        if kind == "texture":
            n = len(value.channels)
            if n == 1:
                return "texture", value.select([0] * count)
            return "texture", value.select(list(range(min(n, count))))
        return kind, value

    def _node_extract(self, node, output, element, default, node_id):
        kind, value = self._in(node, "in", element, default)
        index = int(self.value(node, "index", 0))
        return self._channel(kind, value, [index])

    def _node_separate(self, node, output, element, default, node_id):
        kind, value = self._in(node, "in", element, default)
        return self._channel(kind, value, _CHANNELS.get(output, [0]))

    def _node_swizzle(self, node, output, element, default, node_id):
        kind, value = self._in(node, "in", element, default)
        spec = str(self.value(node, "channels", "rgb"))
        return self._channel(kind, value, [_SWIZZLE.get(c, 0) for c in spec])

    def _channel(self, kind, value, channels):
        if kind == "value":
            a = as_array(value)
            return "value", as_value(a[[min(c, a.size - 1) for c in channels]])
        if kind == "texture":
            return "texture", value.select(channels)
        return kind, value

    def _node_combine(self, node, output, element, default, node_id):
        count = mtlx.output_size(node_id, output)
        parts = [self._in(node, f"in{i + 1}", element, 0.0) for i in range(count)]
        return self.combine(parts, lambda *xs: np.concatenate([x[..., :1] for x in xs], -1), count, element)

    def _node_multiply(self, node, output, element, default, node_id):
        return self._binary(node, np.multiply, element, default, node_id, output)

    def _node_add(self, node, output, element, default, node_id):
        return self._binary(node, np.add, element, default, node_id, output)

    def _node_subtract(self, node, output, element, default, node_id):
        return self._binary(node, np.subtract, element, default, node_id, output)

    def _node_divide(self, node, output, element, default, node_id):
        def safe(a, b):
            return np.divide(a, np.where(b == 0, 1.0, b))
        return self._binary(node, safe, element, default, node_id, output)

    def _binary(self, node, op, element, default, node_id, output):
        count = mtlx.output_size(node_id, output)
        identity = 1.0 if op in (np.multiply,) else 0.0
        a = self._in(node, "in1", element, identity)
        b = self._in(node, "in2", element, 1.0 if op is not np.add and op is not np.subtract else 0.0)
        if a[0] == "texture" and b[0] == "value" and op in (np.multiply, np.add, np.subtract):
            k = fit(b[1], len(a[1].channels))
            folded = (a[1].affine(k, 0.0) if op is np.multiply
                      else a[1].affine(1.0, k if op is np.add else -k))
            if folded is not None:
                return "texture", folded
        if b[0] == "texture" and a[0] == "value" and op in (np.multiply, np.add):
            k = fit(a[1], len(b[1].channels))
            folded = b[1].affine(k, 0.0) if op is np.multiply else b[1].affine(1.0, k)
            if folded is not None:
                return "texture", folded
        return self.combine([a, b], op, count, element)

    def _node_mix(self, node, output, element, default, node_id):
        count = mtlx.output_size(node_id, output)
        fg = self._in(node, "fg", element, 0.0)
        bg = self._in(node, "bg", element, 0.0)
        mix = self._in(node, "mix", element, 0.0)
        return self.combine([fg, bg, mix], lambda f, b, m: b + (f - b) * m[..., :1], count, element)

    def combine(self, parts, op, count, element):
        """`op` over the parts: on values, or baked over the largest texture's texels (over
        each tile of UDIM sets, into a set of baked tiles)."""
        for kind, _ in parts:
            if kind == "primvar":
                self.warn(element, "a primvar combined with other inputs is not supported: "
                          "the input's fallback value is used")
                return "value", as_value(np.zeros(count))
        textures = [v for k, v in parts if k == "texture"]
        if not textures:
            arrays = [fit(v, count) if as_array(v).size != 1 else as_array(v) for _, v in parts]
            return "value", as_value(fit(op(*arrays), count))
        sets = [t for t in textures if t.tiles is not None]
        if sets:
            # UDIM sets: tile by tile (and the fallback), into a set of the baked tiles.
            def at(number):
                return [(k, v.at_tile(number) if k == "texture" and v.tiles is not None else v)
                        for k, v in parts]
            numbers = sorted(set().union(*(t.tiles for t in sets)))
            baked = {n: self.combine(at(n), op, count, element)[1] for n in numbers}
            fallback = self.combine(at(None), op, count, element)[1]
            tiles = images.TileSet(sets[0].image.path, {n: b.image for n, b in baked.items()},
                                   fallback.image)
            first = baked[numbers[0]]
            return "texture", TextureSource(tiles, first.channels, first.scale, first.bias, "raw",
                                            sets[0].wrap, first.st_name, first.transform, element)
        shape = max((t.image.shape for t in textures), key=lambda s: s[0] * s[1])
        if len({(t.st_name, str(t.transform)) for t in textures}) > 1:
            self.warn(element, "textures read through different coordinates are combined: "
                      "the first one's are used")
        arrays = []
        for kind, v in parts:
            if kind == "texture":
                n = len(v.channels)
                arrays.append(images.resample(v.values(count if n > 1 else 1), shape))
            else:
                a = as_array(v)
                arrays.append(np.broadcast_to(a.astype(np.float32) if a.size == 1 else fit(a, count).astype(np.float32),
                                              (*shape, 1 if a.size == 1 else count)))
        result = op(*[np.asarray(x, np.float32) for x in arrays])
        if result.shape[2] < count:
            result = np.repeat(result[..., :1], count, axis=2)
        return "texture", TextureSource.baked(np.ascontiguousarray(result[..., :count], np.float32),
                                              textures[0], element)

    def _node_normalmap(self, node, output, element, default, node_id):
        kind, value = self._in(node, "in", element, (0.5, 0.5, 1.0))
        if kind != "texture":
            return "value", (0.0, 0.0, 1.0)
        scale = self.value(node, "scale", 1.0)
        decoded = value.affine(2.0, -1.0)
        return "texture", NormalMap(decoded or value, float(as_array(scale)[0]))

    def _node_texcoord(self, node, output, element, default, node_id):
        index = int(self.value(node, "index", 0))
        return "primvar", "st" if index == 0 else f"st{index}"

    def _node_geompropvalue(self, node, output, element, default, node_id):
        return "primvar", str(self.value(node, "geomprop", "st"))

    def _node_UsdPrimvarReader(self, node, output, element, default, node_id):
        name = self.value(node, "varname", None)
        return "primvar", str(name) if name else "st"

    def _node_PxrManifold2D(self, node, output, element, default, node_id):
        return "primvar", str(self.value(node, "primvarName", "") or "st")

    # ---- images and coordinates -------------------------------------------------------
    def _image(self, node, file_input, channels, color_space, wraps, st_input, element,
               fallback=(0.0, 0.0, 0.0, 1.0)):
        """The texture a node's image input names, or None after a warning. `fallback`
        (linear RGBA) is what a UDIM set's coordinates without a tile read."""
        path = str(node.GetPath())
        asset = self.value(node, file_input, None)
        if isinstance(asset, str) and asset:
            asset = Sdf.AssetPath(asset)
        if not isinstance(asset, Sdf.AssetPath) or not asset.path:
            self.warn(path, "no texture file: fallback used")
            return None
        if images.udim_token(asset.path):
            image = self.tile_set(node, file_input, asset, fallback, path)
        else:
            image = self.image(asset, path)
        if image is None:
            return None
        wrap = []
        for axis, mode in zip(("S", "T"), wraps):
            if mode in ("black", "constant"):
                self.warn(path, f"wrap mode {mode!r} is not supported: clamped to the edge")
            wrap.append(_WRAP.get(mode, "repeat"))
        st_name, transform = self._st(node, st_input)
        return TextureSource(image, channels, (1.0,) * 4, (0.0,) * 4, color_space, tuple(wrap),
                             st_name, transform, element)

    def image(self, asset, element):
        """The decoded image an asset path names (cached), or None after a warning."""
        key = asset.resolvedPath or asset.path
        if key not in self._images:
            try:
                self._images[key] = images.read(asset)
            except OSError as e:
                self.warn(element, f"texture {asset.path!r} unreadable ({e}): fallback used")
                self._images[key] = None
        return self._images[key]

    def tile_set(self, node, file_input, asset, fallback, element):
        """The UDIM set (images.TileSet) an asset path names (cached), anchored at the layer
        that authored it, or None after a warning."""
        attrs = node.GetInput(file_input).GetValueProducingAttributes()
        specs = attrs[0].GetPropertyStack(self.time) if attrs else []
        layer = specs[0].layer if specs else node.GetPrim().GetStage().GetRootLayer()
        fallback = tuple(float(x) for x in fallback)
        key = (layer.identifier, asset.path, fallback)
        if key not in self._images:
            try:
                self._images[key] = images.read_tiles(asset.path, layer, fallback)
            except OSError as e:
                self.warn(element, f"UDIM texture {asset.path!r} unreadable ({e}): fallback used")
                self._images[key] = None
            for number, reason in getattr(self._images[key], "unreadable", {}).items():
                self.warn(element, f"UDIM texture {asset.path!r}: tile {number} unreadable "
                          f"({reason}): the fallback is read there")
        return self._images[key]

    def _st(self, node, name):
        """The texture-coordinate primvar feeding a texture and its transform."""
        inp = node.GetInput(name)
        attrs = inp.GetValueProducingAttributes() if inp else []
        transform = None
        while attrs and UsdShade.Output.IsOutput(attrs[0]):
            upstream = UsdShade.Shader(attrs[0].GetPrim())
            node_id = upstream.GetIdAttr().Get()
            family = mtlx.node_family(node_id) if node_id else None
            if family in ("UsdTransform2d", "place2d"):
                if family == "UsdTransform2d":
                    t = _uv_transform(fit(self.value(upstream, "scale", (1.0, 1.0)), 2),
                                      float(self.value(upstream, "rotation", 0.0)),
                                      fit(self.value(upstream, "translation", (0.0, 0.0)), 2))
                    src = upstream.GetInput("in")
                else:
                    t = _place2d(fit(self.value(upstream, "scale", (1.0, 1.0)), 2),
                                 float(self.value(upstream, "rotate", 0.0)),
                                 fit(self.value(upstream, "offset", (0.0, 0.0)), 2),
                                 fit(self.value(upstream, "pivot", (0.0, 0.0)), 2))
                    src = upstream.GetInput("texcoord")
                transform = _compose(transform, t)
                attrs = src.GetValueProducingAttributes() if src else []
                continue
            if family in ("UsdPrimvarReader", "geompropvalue"):
                key = "varname" if family == "UsdPrimvarReader" else "geomprop"
                return str(self.value(upstream, key, "st") or "st"), transform
            if family == "texcoord":
                index = int(self.value(upstream, "index", 0))
                return ("st" if index == 0 else f"st{index}"), transform
            if family == "PxrManifold2D":
                scale = (float(self.value(upstream, "scaleS", 1.0)), float(self.value(upstream, "scaleT", 1.0)))
                offset = (float(self.value(upstream, "offsetS", 0.0)), float(self.value(upstream, "offsetT", 0.0)))
                t = _uv_transform(scale, 0.0, offset)
                return str(self.value(upstream, "primvarName", "") or "st"), _compose(transform, t)
            self.warn(str(upstream.GetPath()),
                      f"unknown shader {node_id!r} feeding texture coordinates: 'st' used")
            break
        return "st", transform


class NormalMap(TextureSource):
    """A tangent-space normal map: values decoded to [-1, 1], and the strength (MaterialX
    normalmap's scale, PxrNormalMap's bumpScale) lucerna's normal_scale takes."""

    def __init__(self, texture, strength):
        super().__init__(texture.image, texture.channels, texture.scale, texture.bias,
                         texture.color_space, texture.wrap, texture.st_name, texture.transform,
                         texture.element)
        self.strength = strength


def _inherited_color_space(prim):
    """The colorSpace metadata of the nearest ancestor that authors one (MaterialX
    documents' colorspace as usdMtlx writes it), or None."""
    while prim and prim.IsValid():
        if prim.HasMetadata("colorSpace"):
            return prim.GetMetadata("colorSpace")
        prim = prim.GetParent()
    return None


def _uv_transform(scale, rotation_degrees, translation):
    """UsdTransform2d (st' = R(rotation) S st + translation, st with v up) as lucerna's
    UvTransform on uv = (s, 1 - t)."""
    r = np.radians(rotation_degrees)
    c, s = np.cos(r), np.sin(r)
    a = np.array([[c, -s], [s, c]]) @ np.diag([float(scale[0]), float(scale[1])])
    return _from_st_affine(a, np.asarray(translation, dtype=float))


def _place2d(scale, rotate_degrees, offset, pivot):
    """MaterialX place2d: st' = R^-1 S^-1 (st - pivot) ... per its nodegraph: subtract the
    pivot, scale by 1/scale, rotate by -rotate, subtract the offset, add the pivot."""
    r = np.radians(-rotate_degrees)
    c, s = np.cos(r), np.sin(r)
    inv_scale = np.diag([1.0 / scale[0] if scale[0] else 1.0, 1.0 / scale[1] if scale[1] else 1.0])
    a = np.array([[c, -s], [s, c]]) @ inv_scale
    pivot = np.asarray(pivot, float)
    translation = -a @ pivot - np.asarray(offset, float) + pivot
    return _from_st_affine(a, translation)


def _from_st_affine(a, translation):
    d = np.diag([1.0, -1.0])
    e = np.array([0.0, 1.0])
    linear = d @ a @ d
    offset = d @ (a @ e + translation) + e
    return {"x": [float(linear[0, 0]), float(linear[1, 0])],
            "y": [float(linear[0, 1]), float(linear[1, 1])],
            "offset": [float(offset[0]), float(offset[1])]}


def _compose(outer, inner):
    """The transform applying `inner` first, then `outer` (None is the identity)."""
    if outer is None:
        return inner
    if inner is None:
        return outer

    def m(t):
        return np.array([[t["x"][0], t["y"][0], t["offset"][0]],
                         [t["x"][1], t["y"][1], t["offset"][1]], [0.0, 0.0, 1.0]])
    r = m(outer) @ m(inner)
    return {"x": [float(r[0, 0]), float(r[1, 0])], "y": [float(r[0, 1]), float(r[1, 1])],
            "offset": [float(r[0, 2]), float(r[1, 2])]}
