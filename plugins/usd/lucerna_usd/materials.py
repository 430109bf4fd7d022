"""UsdPreviewSurface networks to lucerna materials (glTF metallic-roughness).

Supported nodes: UsdPreviewSurface, UsdUVTexture (file, st, wrapS/T, scale, bias,
sourceColorSpace, fallback, outputs r g b a rgb), UsdPrimvarReader_float2 (texture
coordinates) and _float3 (vertex colours, e.g. displayColor), UsdTransform2d (texture
transform). Texture channels are combined into lucerna's layout where the layouts differ:
roughness in G and metallic in B of one texture, opacity in the base colour's alpha, normals
stored as (n + 1) / 2; an 8-bit image used exactly as stored is passed through, anything
scaled, biased, swizzled or decoded differently is baked to linear float texels.

clearcoat and clearcoatRoughness become the material's clear coat (ior 1.5, as both
UsdPreviewSurface and the renderer fix it); useSpecularWorkflow makes specularColor the
dielectric's reflectance at normal incidence (white at grazing), metallic unused; ior sets
the dielectric's reflectance otherwise.

opacity follows the specification's opacityMode: "transparent" (the default) makes
opacity < 1 transmission, 1 - opacity of the dielectric base, untinted (UsdPreviewSurface has
no transmission colour): a volume that refracts by `ior` (a thin wall when ior is 1);
"presence" makes it coverage (stochastic blending); opacityThreshold > 0 makes it a cut-out
in either mode. A gprim without a material shows displayColor, and displayOpacity as
coverage."""

import math

import numpy as np
from pxr import Sdf, UsdShade

from . import images
from .scene_file import default_material

# UsdPreviewSurface's fallback values (its specification, version 2.x).
PREVIEW_DEFAULTS = {
    "diffuseColor": (0.18, 0.18, 0.18),
    "emissiveColor": (0.0, 0.0, 0.0),
    "useSpecularWorkflow": 0,
    "specularColor": (0.0, 0.0, 0.0),
    "metallic": 0.0,
    "roughness": 0.5,
    "clearcoat": 0.0,
    "clearcoatRoughness": 0.01,
    "opacity": 1.0,
    "opacityThreshold": 0.0,
    "ior": 1.5,
    "normal": (0.0, 0.0, 1.0),
}

_CHANNELS = {"r": [0], "g": [1], "b": [2], "a": [3], "rgb": [0, 1, 2], "rgba": [0, 1, 2, 3]}
_WRAP = {"repeat": "repeat", "mirror": "mirrored_repeat", "clamp": "clamp_to_edge",
         "useMetadata": "repeat", "black": "clamp_to_edge"}


class TextureSource:
    """A UsdUVTexture output feeding a surface input."""

    def __init__(self, image, channels, scale, bias, color_space, wrap, st_name, transform,
                 element):
        self.image = image
        self.channels = channels
        self.scale = np.asarray(scale, dtype=np.float32)
        self.bias = np.asarray(bias, dtype=np.float32)
        self.color_space = color_space
        self.wrap = wrap
        self.st_name = st_name
        self.transform = transform
        self.element = element

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
        if self.plain:
            return px
        return px * self.scale + self.bias

    def values(self, count):
        """The selected output channels, (H, W, count): one channel is replicated."""
        lin = self.linear()[..., self.channels]
        if lin.shape[2] < count:
            lin = np.repeat(lin[..., :1], count, axis=2)
        return lin[..., :count]


class MaterialConverter:
    """Converts and caches materials; `warn(element, message)` reports problems."""

    def __init__(self, writer, time, warn):
        self.writer = writer
        self.time = time
        self.warn = warn
        self._cache = {}
        self._images = {}

    # ---- public -------------------------------------------------------------------
    def material(self, material, double_sided):
        """The lucerna material for a bound `UsdShade.Material` (or None: the preview
        surface's defaults). Returns (index, st primvar name or None, colour primvar name
        or None)."""
        key = (str(material.GetPath()) if material else None, double_sided)
        if key not in self._cache:
            self._cache[key] = self._convert(material, double_sided)
        return self._cache[key]

    def display_color(self, color, double_sided, opacity=None):
        """The material of a mesh without a bound material: UsdPreviewSurface defaults with
        `color` (a constant displayColor, or None for per-vertex colours) as diffuse, and a
        constant displayOpacity below 1 as coverage."""
        rgb = tuple(float(c) for c in color) if color is not None else (1.0, 1.0, 1.0)
        alpha = 1.0 if opacity is None else min(max(float(opacity), 0.0), 1.0)
        key = ("displayColor", rgb, alpha, double_sided)
        if key not in self._cache:
            fields = {"alpha_mode": "blend"} if alpha < 1.0 else {}
            index = self.writer.add_material(default_material(
                "displayColor", base_color=[*rgb, alpha], metallic=0.0, roughness=0.5,
                double_sided=double_sided, **fields))
            self._cache[key] = (index, None, None)
        return self._cache[key]

    # ---- network traversal ----------------------------------------------------------
    def _surface(self, material):
        shader = material.ComputeSurfaceSource()[0] if material else None
        if not shader or not shader.GetPrim().IsValid():
            if material:
                self.warn(str(material.GetPath()),
                          "no surface shader: rendered with UsdPreviewSurface defaults")
            return None
        shader_id = shader.GetIdAttr().Get()
        if shader_id != "UsdPreviewSurface":
            self.warn(str(shader.GetPath()),
                      f"unknown shader {shader_id!r} (only UsdPreviewSurface is supported): "
                      "rendered with UsdPreviewSurface defaults")
            return None
        return shader

    def _source(self, shader, name):
        """('value', v), ('texture', TextureSource) or ('primvar', name) for an input."""
        inp = shader.GetInput(name)
        default = PREVIEW_DEFAULTS[name]
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
        node_id = node.GetIdAttr().Get()
        output = UsdShade.Output(attr).GetBaseName()
        element = f"{shader.GetPath()}.inputs:{name}"
        if node_id == "UsdUVTexture":
            source = self._texture(node, output, element)
            return ("texture", source) if source else ("value", self._fallback(node, output, default))
        if node_id in ("UsdPrimvarReader_float3", "UsdPrimvarReader_float4") and name == "diffuseColor":
            return "primvar", self._string_input(node, "varname") or "displayColor"
        self.warn(str(node.GetPath()),
                  f"unknown shader {node_id!r} feeding {name}: the input's fallback is used")
        return "value", default

    def _string_input(self, node, name):
        value = self._value(node, name, None)
        return str(value) if value else None

    def _value(self, node, name, default):
        """The value an input of `node` gets (through material interface connections), or
        `default`."""
        inp = node.GetInput(name)
        attrs = inp.GetValueProducingAttributes() if inp else []
        if attrs and not UsdShade.Output.IsOutput(attrs[0]):
            value = attrs[0].Get(self.time)
            if value is not None:
                return value
        return default

    def _fallback(self, node, output, default):
        fallback = self._value(node, "fallback", (0.0, 0.0, 0.0, 1.0))
        chans = _CHANNELS.get(output, [0])
        values = [float(fallback[c]) for c in chans]
        return values[0] if len(values) == 1 else tuple(values)

    def _texture(self, node, output, element):
        path = str(node.GetPath())
        if output not in _CHANNELS:
            self.warn(path, f"unknown UsdUVTexture output {output!r}: fallback used")
            return None
        asset = self._value(node, "file", None)
        if not isinstance(asset, Sdf.AssetPath) or not asset.path:
            self.warn(path, "no texture file: fallback used")
            return None
        key = asset.resolvedPath or asset.path
        if key not in self._images:
            try:
                self._images[key] = images.read(asset)
            except OSError as e:
                self.warn(path, f"texture {asset.path!r} unreadable ({e}): fallback used")
                self._images[key] = None
        image = self._images[key]
        if image is None:
            return None
        wrap = []
        for axis in ("wrapS", "wrapT"):
            mode = str(self._value(node, axis, "useMetadata"))
            if mode == "black":
                self.warn(path, f"{axis} 'black' is not supported: clamped to the edge")
            wrap.append(_WRAP.get(mode, "repeat"))
        st_name, transform = self._st(node)
        return TextureSource(
            image, _CHANNELS[output],
            self._value(node, "scale", (1.0, 1.0, 1.0, 1.0)),
            self._value(node, "bias", (0.0, 0.0, 0.0, 0.0)),
            str(self._value(node, "sourceColorSpace", "auto")),
            tuple(wrap), st_name, transform, element)

    def _st(self, node):
        """The texture-coordinate primvar feeding a texture and its UsdTransform2d."""
        inp = node.GetInput("st")
        attrs = inp.GetValueProducingAttributes() if inp else []
        transform = None
        while attrs and UsdShade.Output.IsOutput(attrs[0]):
            upstream = UsdShade.Shader(attrs[0].GetPrim())
            node_id = upstream.GetIdAttr().Get()
            if node_id == "UsdTransform2d":
                transform = _uv_transform(
                    self._value(upstream, "scale", (1.0, 1.0)),
                    float(self._value(upstream, "rotation", 0.0)),
                    self._value(upstream, "translation", (0.0, 0.0)))
                src = upstream.GetInput("in")
                attrs = src.GetValueProducingAttributes() if src else []
                continue
            if node_id == "UsdPrimvarReader_float2":
                return self._string_input(upstream, "varname") or "st", transform
            self.warn(str(upstream.GetPath()),
                      f"unknown shader {node_id!r} feeding texture coordinates: 'st' used")
            break
        return "st", transform

    # ---- conversion ----------------------------------------------------------------
    def _convert(self, material, double_sided):
        name = str(material.GetPath()) if material else "UsdPreviewSurface"
        shader = self._surface(material)
        if shader is None:
            d = PREVIEW_DEFAULTS
            index = self.writer.add_material(default_material(
                name, base_color=[*d["diffuseColor"], 1.0], metallic=0.0, roughness=0.5,
                double_sided=double_sided))
            return index, None, None
        sources = {k: self._source(shader, k) for k in PREVIEW_DEFAULTS}
        out = default_material(name, double_sided=double_sided, metallic=0.0)
        st_names = []
        color_primvar = None

        def ref(texture_index, source):
            st_names.append(source.st_name)
            return {"texture": texture_index, "tex_coord": 0, "transform": source.transform}

        # Base colour and opacity: coverage (a cut-out, or presence), or transmission.
        kind, diffuse = sources["diffuseColor"]
        okind, opacity = sources["opacity"]
        threshold = float(sources["opacityThreshold"][1]) if sources["opacityThreshold"][0] == "value" else 0.0
        mode = str(self._value(shader, "opacityMode", "transparent"))
        if mode not in ("transparent", "presence"):
            self.warn(name, f"unknown opacityMode {mode!r}: 'transparent' is used")
            mode = "transparent"
        see_through = okind == "texture" or float(opacity if okind == "value" else 1.0) < 1.0
        coverage = see_through and (threshold > 0.0 or mode == "presence")
        transmits = see_through and not coverage
        rgb = [1.0, 1.0, 1.0] if kind != "value" else [float(c) for c in diffuse]
        alpha = float(opacity) if okind == "value" and coverage else 1.0
        if kind == "primvar":
            color_primvar = diffuse
        coverage_texture = okind == "texture" and coverage
        if kind == "texture" or coverage_texture:
            index, src = self._base_color_texture(
                diffuse if kind == "texture" else None,
                opacity if coverage_texture else None,
                None if kind == "texture" else rgb, name)
            out["base_color_texture"] = ref(index, src)
            if kind == "texture":
                rgb = [1.0, 1.0, 1.0]
        out["base_color"] = [*rgb, alpha]
        if coverage and threshold > 0.0:
            out["alpha_mode"] = {"mask": {"cutoff": threshold}}
        elif coverage:
            out["alpha_mode"] = "blend"
        if transmits:
            if okind == "texture":
                out["transmission"] = 1.0
                out["transmission_texture"] = ref(self._transmission_texture(opacity, name), opacity)
            else:
                out["transmission"] = 1.0 - min(max(float(opacity), 0.0), 1.0)
            out["transmission_color"] = [1.0, 1.0, 1.0]

        # Metallic and roughness: G and B of one texture.
        mk, metallic = sources["metallic"]
        rk, roughness = sources["roughness"]
        if mk == "texture" or rk == "texture":
            index, src = self._metal_rough_texture(metallic, roughness, name)
            out["metallic_roughness_texture"] = ref(index, src)
            out["metallic"] = 1.0 if mk == "texture" else float(metallic)
            out["roughness"] = 1.0 if rk == "texture" else float(roughness)
        else:
            out["metallic"] = float(metallic)
            out["roughness"] = float(roughness)

        ek, emissive = sources["emissiveColor"]
        if ek == "texture":
            index = self._color_texture(emissive, name + ":emissive")
            out["emissive_texture"] = ref(index, emissive)
            out["emissive"] = [1.0, 1.0, 1.0]
        else:
            out["emissive"] = [float(c) for c in emissive]

        nk, normal = sources["normal"]
        if nk == "texture":
            out["normal_texture"] = ref(self._normal_texture(normal, name), normal)

        ik, ior = sources["ior"]
        out["ior"] = float(ior) if ik == "value" else 1.5
        if transmits and out["ior"] != 1.0:
            out["volume"] = {"absorption": [0.0, 0.0, 0.0]}
        if sources["useSpecularWorkflow"][0] == "value" and int(sources["useSpecularWorkflow"][1]) == 1:
            sk, spec = sources["specularColor"]
            if sk != "value":
                self.warn(name, "a texture on specularColor is not supported: the fallback is used")
                spec = PREVIEW_DEFAULTS["specularColor"]
            out["specular_color"] = [min(max(float(c), 0.0), 1.0) for c in spec]
            out["metallic"] = 0.0  # also zeroes a metallic texture channel (factor x texel)
        for key in ("clearcoat", "clearcoatRoughness"):
            kind, value = sources[key]
            field = "clearcoat" if key == "clearcoat" else "clearcoat_roughness"
            if kind == "texture":
                self.warn(name, f"a texture on {key} is not supported: the fallback is used")
                value = PREVIEW_DEFAULTS[key]
            out[field] = min(max(float(value), 0.0), 1.0)
        for key in ("ior", "opacityThreshold"):
            if sources[key][0] == "texture":
                self.warn(name, f"a texture on {key} is not supported: the fallback is used")

        if len(set(st_names)) > 1:
            self.warn(name, f"textures read several primvars {sorted(set(st_names))}: "
                      f"{st_names[0]!r} is used for all")
        index = self.writer.add_material(out)
        return index, (st_names[0] if st_names else None), color_primvar

    # ---- textures ------------------------------------------------------------------
    def _base_color_texture(self, diffuse, opacity, rgb, name):
        src = diffuse or opacity
        if (diffuse is not None and diffuse.plain and diffuse.srgb and diffuse.image.raw8 is not None
                and diffuse.channels == [0, 1, 2]
                and (opacity is None or (opacity.image is diffuse.image and opacity.plain
                                         and opacity.channels == [3]))):
            texels = diffuse.image.raw8.copy()
            if opacity is None:
                texels[..., 3] = 255
            return self.writer.add_texture(name + ":base_color", texels, src.wrap), src
        shape = max((s.image.shape for s in (diffuse, opacity) if s is not None),
                    key=lambda s: s[0] * s[1])
        out = np.ones((*shape, 4), np.float32)
        if diffuse is not None:
            out[..., :3] = images.resample(diffuse.values(3), shape)
        else:
            out[..., :3] = rgb
        if opacity is not None:
            out[..., 3] = images.resample(opacity.values(1), shape)[..., 0]
        return self.writer.add_texture(name + ":base_color", out, src.wrap), src

    def _transmission_texture(self, source, name):
        """1 - opacity in R (the transmission texture's channel)."""
        out = np.ones((*source.image.shape, 4), np.float32)
        out[..., 0] = 1.0 - np.clip(source.values(1)[..., 0], 0.0, 1.0)
        return self.writer.add_texture(name + ":transmission", out, source.wrap)

    def _color_texture(self, source, name):
        if (source.plain and source.srgb and source.image.raw8 is not None
                and source.channels == [0, 1, 2]):
            return self.writer.add_texture(name, source.image.raw8, source.wrap)
        out = np.ones((*source.image.shape, 4), np.float32)
        out[..., :3] = source.values(3)
        return self.writer.add_texture(name, out, source.wrap)

    def _metal_rough_texture(self, metallic, roughness, name):
        textures = [s for s in (metallic, roughness) if isinstance(s, TextureSource)]
        src = textures[0]
        shape = max((t.image.shape for t in textures), key=lambda s: s[0] * s[1])
        out = np.ones((*shape, 4), np.float32)
        for channel, s in ((2, metallic), (1, roughness)):
            out[..., channel] = (images.resample(s.values(1), shape)[..., 0]
                                 if isinstance(s, TextureSource) else 1.0)
        out[..., 0] = 0.0
        return self.writer.add_texture(name + ":metallic_roughness", out, src.wrap), src

    def _normal_texture(self, source, name):
        standard = (np.allclose(source.scale[:3], 2.0) and np.allclose(source.bias[:3], -1.0))
        if standard and not source.srgb and source.image.raw8 is not None and source.channels == [0, 1, 2]:
            return self.writer.add_texture(name + ":normal", source.image.raw8, source.wrap)
        n = source.values(3)
        out = np.ones((*source.image.shape, 4), np.float32)
        out[..., :3] = (n + 1.0) * 0.5
        return self.writer.add_texture(name + ":normal", out, source.wrap)


def _uv_transform(scale, rotation_degrees, translation):
    """UsdTransform2d (st' = R(rotation) S st + translation, st with v up) as lucerna's
    UvTransform on uv = (s, 1 - t)."""
    r = math.radians(rotation_degrees)
    c, s = math.cos(r), math.sin(r)
    a = np.array([[c, -s], [s, c]]) @ np.diag([float(scale[0]), float(scale[1])])
    d = np.diag([1.0, -1.0])
    e = np.array([0.0, 1.0])
    linear = d @ a @ d
    offset = d @ (a @ e + np.asarray(translation, dtype=float)) + e
    return {"x": [float(linear[0, 0]), float(linear[1, 0])],
            "y": [float(linear[0, 1]), float(linear[1, 1])],
            "offset": [float(offset[0]), float(offset[1])]}
