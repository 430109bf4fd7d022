"""Bound USD materials to lucerna materials.

A material's surface is looked up in the render contexts lucerna understands, richest
first: MaterialX (`outputs:mtlx:surface`), the universal one (UsdPreviewSurface), MDL
(`outputs:mdl:surface`: Omniverse's OmniPBR, OmniGlass, OmniSurface) and RenderMan
(`outputs:ri:surface`: PxrSurface, PxrDisney); the first context whose shader lucerna
knows is used. `surfaces` reads the shader into lucerna's model, `networks` evaluates what
feeds its inputs, and this module writes the material and packs textures into lucerna's
slots: roughness in G and metallic in B of one texture, coverage in the base colour's
alpha, normals stored as (n + 1) / 2, transmission in R. An 8-bit image used exactly as
stored is passed through; anything scaled, biased, swizzled, combined or decoded
differently is baked to linear float texels.

A material whose surface shader lucerna does not know is warned about, naming the shader
prim and its id, and the gprim shows its displayColor instead (as usdview's fallback
does). A gprim without a material shows displayColor, and displayOpacity as coverage."""

import math
import numpy as np
from pxr import UsdShade

from . import images
from . import mtlx
from .networks import Network, TextureSource
from .scene_file import default_material
from .surfaces import PREVIEW_DEFAULTS, Reader

__all__ = ["MaterialConverter", "PREVIEW_DEFAULTS", "TextureSource"]

def _shared(pack):
    """Packs a texture once per distinct set of sources: materials that read the same
    images the same way share the packed texture (the name is the first material's)."""
    def signature(x):
        if isinstance(x, TextureSource):
            return (id(x.image), tuple(x.channels), x.scale.tobytes(), x.bias.tobytes(),
                    x.color_space, x.wrap)
        return repr(x)

    def wrapper(self, *args):
        key = (pack.__name__, tuple(signature(a) for a in args[:-1]))
        cache = self.__dict__.setdefault("_packed", {})
        if key not in cache:
            cache[key] = (_by_tile(self, pack, args), args)  # the sources stay alive with the key
        return cache[key][0]
    return wrapper


def _by_tile(self, pack, args):
    """`pack` of the sources `args` (the last is the name). Where some are UDIM sets, the
    slot's texture is a UDIM set too: packed once per tile that any of them has (the
    others read as they are) and once for the fallback, whose texture becomes the set."""
    udim = [isinstance(a, TextureSource) and a.tiles is not None for a in args[:-1]]
    if not any(udim):
        return pack(self, *args)

    def at(number):
        return [a.at_tile(number) if u else a for a, u in zip(args[:-1], udim)]

    def index(packed):
        return packed[0] if isinstance(packed, tuple) else packed

    sets = [a.image for a, u in zip(args[:-1], udim) if u]
    numbers = sorted(set().union(*(s.tiles for s in sets)))
    tiles = [(n, index(pack(self, *at(n), args[-1]))) for n in numbers]
    packed = pack(self, *at(None), args[-1])
    self.writer.set_tiles(index(packed), tiles, sets[0].path)
    return packed


#: Render contexts in the order they are tried.
_CONTEXTS = ("mtlx", "", "mdl", "ri")
#: Surface readers by shader family.
_READERS = {
    "UsdPreviewSurface": "preview", "standard_surface": "standard_surface",
    "open_pbr_surface": "open_pbr", "gltf_pbr": "gltf_pbr", "PxrSurface": "pxr_surface",
    "PxrDisney": "pxr_disney",
}
#: MDL materials by module subIdentifier (or the module's file name).
_MDL_READERS = {"OmniPBR": "omni_pbr", "OmniPBR_ClearCoat": "omni_pbr",
                "OmniPBR_Opacity": "omni_pbr", "OmniGlass": "omni_glass",
                "OmniGlass_Opacity": "omni_glass", "OmniSurface": "omni_surface",
                "OmniSurfaceBase": "omni_surface", "OmniSurfaceLite": "omni_surface"}


class MaterialConverter:
    """Converts and caches materials; `warn(element, message)` reports problems."""

    def __init__(self, writer, time, warn, meters_per_unit=1.0):
        self.writer = writer
        self.time = time
        self.warn = warn
        # Media coefficients are per stage unit; the scene file's lengths are metres.
        self.per_metre = 1.0 / meters_per_unit
        self._cache = {}
        self.net = Network(time, warn)

    # ---- public -------------------------------------------------------------------
    def material(self, material, double_sided):
        """The lucerna material for a bound `UsdShade.Material`: (index, st primvar name or
        None, colour primvar name or None), or None where lucerna knows none of its surface
        shaders (the caller shows displayColor)."""
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

    # ---- surfaces -----------------------------------------------------------------------
    def _surface(self, material):
        """(reader method, shader, family) of the first render context lucerna knows, or
        None after a warning."""
        if not material:
            return None
        seen = []
        for context in _CONTEXTS:
            output = material.GetSurfaceOutput(context)
            if not output:
                continue
            sources = output.GetValueProducingAttributes()
            if not sources or not UsdShade.Output.IsOutput(sources[0]):
                continue
            shader = UsdShade.Shader(sources[0].GetPrim())
            if not shader:
                continue
            family, method = self._family(shader)
            if method is not None:
                return method, shader, family
            seen.append((shader, family))
        path = str(material.GetPath())
        if not seen:
            self.warn(path, "no surface shader: the gprim's displayColor is shown")
        else:
            shader, family = seen[0]
            self.warn(str(shader.GetPath()), f"unknown surface shader {family!r}: the gprim's "
                      "displayColor is shown")
        return None

    def _family(self, shader):
        """(family name, reader method or None) of a surface shader."""
        node_id = shader.GetIdAttr().Get()
        if node_id:
            family = mtlx.node_family(node_id) or str(node_id)
            return family, _READERS.get(family)
        source = shader.GetImplementationSource()
        if source == "sourceAsset":
            asset = shader.GetSourceAsset("mdl")
            sub = shader.GetSourceAssetSubIdentifier("mdl")
            name = sub or (asset.path.rsplit("/", 1)[-1].rsplit(".", 1)[0] if asset else "")
            module = asset.path if asset else "?"
            return f"{name} (MDL {module})", _MDL_READERS.get(name)
        return "(no info:id)", None

    # ---- conversion ----------------------------------------------------------------
    def _convert(self, material, double_sided):
        name = str(material.GetPath()) if material else "UsdPreviewSurface"
        found = self._surface(material)
        if found is None:
            return None
        method, shader, family = found
        reader = Reader(self.net, self.warn)
        if method in ("standard_surface", "open_pbr", "gltf_pbr"):
            surface = getattr(reader, method)(shader, name, shader.GetIdAttr().Get())
        else:
            surface = getattr(reader, method)(shader, name)
        return self._build(name, surface, double_sided)

    def _build(self, name, surface, double_sided):
        """The lucerna material of a `surfaces.Surface`: (index, st primvar, colour
        primvar)."""
        out = default_material(name, double_sided=double_sided, metallic=0.0)
        st_names = []
        color_primvar = None

        def ref(texture_index, source):
            st_names.append(source.st_name)
            return {"texture": texture_index, "tex_coord": 0, "transform": source.transform}

        def scalar(pair, what, default):
            """A scalar input read from a primvar (per gprim) is not supported: its default,
            warned about."""
            kind, value = pair
            if kind == "primvar":
                self.warn(name, f"{what} read from primvar {value!r} is not supported: "
                          f"{default} is used")
                return "value", default
            return kind, value

        # Base colour and coverage.
        kind, base = surface.base_color
        akind, alpha = scalar(surface.alpha, "opacity", 1.0)
        rgb = [1.0, 1.0, 1.0] if kind != "value" else [float(c) for c in _fit3(base)]
        if kind == "primvar":
            color_primvar = base
        coverage_texture = surface.alpha_mode is not None and akind == "texture"
        a = float(np.atleast_1d(alpha)[0]) if akind == "value" and surface.alpha_mode else 1.0
        if kind == "texture" or coverage_texture:
            index, src = self._base_color_texture(
                base if kind == "texture" else None, alpha if coverage_texture else None,
                None if kind == "texture" else rgb, name)
            out["base_color_texture"] = ref(index, src)
            if kind == "texture":
                rgb = [1.0, 1.0, 1.0]
        out["base_color"] = [*rgb, a]
        if isinstance(surface.alpha_mode, tuple):
            out["alpha_mode"] = {"mask": {"cutoff": float(surface.alpha_mode[1])}}
        elif surface.alpha_mode == "blend":
            out["alpha_mode"] = "blend"

        # Transmission.
        tkind, transmission = scalar(surface.transmission, "transmission", 0.0)
        transmits = tkind == "texture" or (tkind == "value" and float(np.atleast_1d(transmission)[0]) > 0.0)
        if transmits:
            if tkind == "texture":
                out["transmission"] = 1.0
                out["transmission_texture"] = ref(self._transmission_texture(transmission, name), transmission)
            else:
                out["transmission"] = min(max(float(np.atleast_1d(transmission)[0]), 0.0), 1.0)
            if surface.transmission_color is not None:
                out["transmission_color"] = [min(max(float(c), 0.0), 1.0) for c in surface.transmission_color]
            if not surface.thin_walled and surface.absorption is not None:
                per_metre = self.per_metre
                out["volume"] = {"absorption": [max(float(c), 0.0) * per_metre for c in surface.absorption]}
                if surface.scattering is not None:
                    out["volume"]["scattering"] = [max(float(c), 0.0) * per_metre for c in surface.scattering]
                    out["volume"]["anisotropy"] = float(surface.medium_anisotropy)

        if surface.diffuse_transmission is not None:
            share, colour = surface.diffuse_transmission
            out["diffuse_transmission"] = {"factor": _clamp01(share),
                                           "color": [_clamp01(c) for c in colour]}

        # Metallic and roughness: G and B of one texture.
        mk, metallic = scalar(surface.metallic, "metallic", 0.0)
        rk, roughness = scalar(surface.roughness, "roughness", 0.5)
        if mk == "texture" or rk == "texture":
            index, src = self._metal_rough_texture(metallic, roughness, name)
            out["metallic_roughness_texture"] = ref(index, src)
            out["metallic"] = 1.0 if mk == "texture" else _clamp01(metallic)
            out["roughness"] = 1.0 if rk == "texture" else _clamp01(roughness)
        else:
            out["metallic"] = _clamp01(metallic)
            out["roughness"] = _clamp01(roughness)

        ek, emissive = surface.emissive
        if ek == "texture":
            index = self._color_texture(emissive, name + ":emissive")
            out["emissive_texture"] = ref(index, emissive)
            out["emissive"] = [1.0, 1.0, 1.0]
        elif ek == "value":
            out["emissive"] = [max(float(c), 0.0) for c in _fit3(emissive)]
        else:
            self.warn(name, "a primvar as emission is not supported: no emission")

        if surface.normal is not None:
            out["normal_texture"] = ref(self._normal_texture(surface.normal, name), surface.normal)
            out["normal_scale"] = float(getattr(surface.normal, "strength", 1.0))

        out["ior"] = max(float(surface.ior), 1.0)
        if surface.specular_f0 is not None:
            out["specular_color"] = [float(c) for c in surface.specular_f0]
        if surface.specular_weight != 1.0 or tuple(surface.specular_color) != (1.0, 1.0, 1.0):
            out["specular"] = {"weight": max(float(surface.specular_weight), 0.0), "weight_texture": None,
                               "color": [max(float(c), 0.0) for c in surface.specular_color],
                               "color_texture": None}
        roughness = float(surface.diffuse_roughness)
        if math.isfinite(roughness) and roughness > 0.0:
            out["diffuse_roughness"] = min(roughness, 1.0)
        out["clearcoat"] = min(max(float(surface.coat), 0.0), 1.0)
        out["clearcoat_roughness"] = min(max(float(surface.coat_roughness), 0.0), 1.0)
        if surface.sheen_color is not None and max(surface.sheen_color) > 0.0:
            out["sheen"] = {"color": [min(max(float(c), 0.0), 1.0) for c in surface.sheen_color],
                            "color_texture": None,
                            "roughness": min(max(float(surface.sheen_roughness), 0.0), 1.0),
                            "roughness_texture": None}
        if surface.anisotropy is not None:
            strength, rotation = surface.anisotropy
            out["anisotropy"] = {"strength": min(max(float(strength), 0.0), 1.0),
                                 "rotation": float(rotation), "texture": None}
        if surface.iridescence is not None:
            factor, ior, thickness = surface.iridescence
            out["iridescence"] = {"factor": min(max(float(factor), 0.0), 1.0), "texture": None,
                                  "ior": max(float(ior), 1.0), "thickness_min": float(thickness),
                                  "thickness_max": float(thickness), "thickness_texture": None}

        if len(set(st_names)) > 1:
            self.warn(name, f"textures read several primvars {sorted(set(st_names))}: "
                      f"{st_names[0]!r} is used for all")
        index = self.writer.add_material(out)
        return index, (st_names[0] if st_names else None), color_primvar

    # ---- textures ------------------------------------------------------------------
    @_shared
    def _base_color_texture(self, diffuse, opacity, rgb, name):
        src = diffuse or opacity
        if (diffuse is not None and diffuse.plain and diffuse.srgb and diffuse.image.raw8 is not None
                and diffuse.channels == [0, 1, 2]
                and (opacity is None or (opacity.image is diffuse.image and opacity.plain
                                         and opacity.channels == [3]))):
            texels, key = diffuse.image.raw8, ("as stored", diffuse.image.path)
            if opacity is None and not np.all(texels[..., 3] == 255):
                texels, key = texels.copy(), None  # alpha that is not coverage: opaque
                texels[..., 3] = 255
            return self.writer.add_texture(name + ":base_color", texels, src.wrap, key=key), src
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

    @_shared
    def _transmission_texture(self, source, name):
        """The transmission weight in R (the transmission texture's channel)."""
        raw = _raw_channel(source)
        if raw is not None:
            out = np.full((*source.image.shape, 4), 255, np.uint8)
            out[..., 0] = raw
            return self.writer.add_texture(name + ":transmission", out, source.wrap)
        out = np.ones((*source.image.shape, 4), np.float32)
        out[..., 0] = np.clip(source.values(1)[..., 0], 0.0, 1.0)
        return self.writer.add_texture(name + ":transmission", out, source.wrap)

    @_shared
    def _color_texture(self, source, name):
        if (source.plain and source.srgb and source.image.raw8 is not None
                and source.channels == [0, 1, 2]):
            return self.writer.add_texture(name, source.image.raw8, source.wrap,
                                           key=("as stored", source.image.path))
        out = np.ones((*source.image.shape, 4), np.float32)
        out[..., :3] = source.values(3)
        return self.writer.add_texture(name, out, source.wrap)

    @_shared
    def _metal_rough_texture(self, metallic, roughness, name):
        textures = [s for s in (metallic, roughness) if isinstance(s, TextureSource)]
        src = textures[0]
        shape = max((t.image.shape for t in textures), key=lambda s: s[0] * s[1])
        raw = {c: _raw_channel(s) for c, s in ((2, metallic), (1, roughness))
               if isinstance(s, TextureSource)}
        if all(r is not None and r.shape == tuple(shape) for r in raw.values()):
            # 8-bit data used as stored: packed as bytes, a quarter of float texels.
            out = np.full((*shape, 4), 255, np.uint8)
            out[..., 0] = 0
            for channel, r in raw.items():
                out[..., channel] = r
            return self.writer.add_texture(name + ":metallic_roughness", out, src.wrap), src
        out = np.ones((*shape, 4), np.float32)
        for channel, s in ((2, metallic), (1, roughness)):
            out[..., channel] = (images.resample(s.values(1), shape)[..., 0]
                                 if isinstance(s, TextureSource) else 1.0)
        out[..., 0] = 0.0
        return self.writer.add_texture(name + ":metallic_roughness", out, src.wrap), src

    @_shared
    def _normal_texture(self, source, name):
        standard = (np.allclose(source.scale[:3], 2.0) and np.allclose(source.bias[:3], -1.0))
        if standard and not source.srgb and source.image.raw8 is not None and source.channels == [0, 1, 2]:
            return self.writer.add_texture(name + ":normal", source.image.raw8, source.wrap,
                                           key=("as stored", source.image.path))
        n = source.values(3)
        out = np.ones((*source.image.shape, 4), np.float32)
        out[..., :3] = (n + 1.0) * 0.5
        return self.writer.add_texture(name + ":normal", out, source.wrap)


def _raw_channel(source):
    """The 8-bit values of a one-channel texture used exactly as stored (no colour
    decoding, scale or bias), or None."""
    if (len(source.channels) == 1 and source.plain and source.image.raw8 is not None
            and not source.srgb and source.color_space in ("raw", "auto")):
        return source.image.raw8[..., source.channels[0]]
    return None


def _fit3(value):
    a = np.atleast_1d(np.asarray(value, dtype=np.float64))
    return np.repeat(a, 3) if a.size == 1 else a[:3]


def _clamp01(value):
    return min(max(float(np.atleast_1d(value)[0]), 0.0), 1.0)
