"""Surface shaders read into one description (`Surface`) of lucerna's material model.

lucerna's material is glTF's metallic-roughness model with its extensions: a base colour
that is diffuse for dielectrics and the reflectance of metals, a dielectric specular layer
(ior, specular weight and colour), transmission (thin wall or a volume with Beer-Lambert
absorption), clear coat, sheen, anisotropy, thin-film iridescence, emission, coverage.
Each reader maps one shading model onto it:

- UsdPreviewSurface (also as MaterialX's ND_UsdPreviewSurface_surfaceshader): its
  specification; opacity is transmission (opacityMode transparent) or coverage (presence,
  or opacityThreshold > 0).
- MaterialX standard_surface (Autodesk Standard Surface) and open_pbr_surface (OpenPBR):
  base weight x colour, metalness, specular weight / colour / roughness / ior / anisotropy,
  transmission with colour and depth (depth > 0: the colour is reached at that distance
  inside the volume; 0: a tint at the surface), coat, sheen / fuzz, thin film, emission
  (standard_surface: emission x colour; OpenPBR: luminance in nits x colour), opacity,
  thin walls, normal maps. Inputs the defaults come from MaterialX's own library.
- MaterialX gltf_pbr: glTF's model, field for field.
- MDL OmniPBR, OmniGlass and OmniSurface (Omniverse's materials, known by their module's
  subIdentifier) by their parameter names; their textures are asset-valued inputs. MDL
  emission is radiant exitance: radiance = colour x intensity / pi.
- RenderMan PxrSurface (diffuse and its roughness, specular face colour, roughness,
  refraction, glow, clearcoat, fuzz, presence) and PxrDisney (Burley's parameters).

Diffuse roughness (standard_surface, OpenPBR, OmniSurface, PxrSurface) becomes lucerna's
EON diffuse (OpenPBR's energy-preserving Oren-Nayar).

Subsurface scattering (standard_surface, OpenPBR, OmniSurface) is OpenPBR's subsurface
slab: the dielectric over a dense medium (mean free path radius x scale, single-scattering
albedo from the colour by van de Hulst's inversion) that paths random-walk through. On a
thin wall it is translucency, as MaterialX's graphs define it (Standard Surface: a
translucent BSDF of the subsurface colour; OpenPBR: half diffuse reflection, half
translucency, weighted by 1 -/+ the anisotropy), lucerna's diffuse transmission; with
transmission it stays approximated. Transmission scatter fills a
transmissive volume with OpenPBR's medium.

What does not map (subsurface with transmission, PxrSurface subsurface, coat colour and
ior other than 1.5, a metal's edge tint, ...) is approximated and warned about once per
material, naming the parameter."""

import math

import numpy as np

from . import mtlx
from .networks import NormalMap, as_array, as_value, fit

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


class Surface:
    """lucerna's material model with sources (see networks) where textures may feed it."""

    def __init__(self):
        self.base_color = ("value", (0.8, 0.8, 0.8))
        self.alpha = ("value", 1.0)       # coverage
        self.alpha_mode = None            # None (opaque), "blend" or ("mask", cutoff)
        self.metallic = ("value", 0.0)
        self.roughness = ("value", 0.5)
        self.emissive = ("value", (0.0, 0.0, 0.0))
        self.normal = None                # NormalMap (values in [-1, 1])
        self.ior = 1.5
        self.specular_f0 = None           # UsdPreviewSurface specular workflow colour
        self.specular_weight = 1.0
        self.specular_color = (1.0, 1.0, 1.0)
        self.transmission = ("value", 0.0)
        self.transmission_color = None    # None: the base colour tints (glTF's rule)
        self.absorption = None            # per unit length inside a volume
        self.scattering = None            # per unit length inside a volume (a medium)
        self.medium_anisotropy = 0.0      # its Henyey-Greenstein mean cosine
        self.thin_walled = False
        self.diffuse_transmission = None  # (share of the diffuse base, colour): translucency
        self.coat = 0.0
        self.coat_roughness = 0.0
        self.sheen_color = None
        self.sheen_roughness = 0.5
        self.diffuse_roughness = 0.0      # 0: Lambert; above: OpenPBR's EON
        self.anisotropy = None            # (strength, rotation in radians)
        self.iridescence = None           # (factor, ior, thickness in nm)
        self.unlit = False


class Reader:
    """Reads surface shaders with a `networks.Network`; warnings name the material."""

    def __init__(self, net, warn):
        self.net = net
        self.warn = warn

    # ---- helpers ----------------------------------------------------------------------
    def _inputs(self, shader, defaults):
        return {k: self.net.source(shader, k, v) for k, v in defaults.items()}

    def constant(self, source, name, material, what="the mean of its texture"):
        """A source where only a constant can be used: a texture's mean, with a warning."""
        kind, value = source
        if kind == "texture":
            self.warn(material, f"a texture on {name} is not supported: {what} is used")
            mean = value.mean()
            return mean[0] if len(mean) == 1 else mean
        if kind == "primvar":
            self.warn(material, f"a primvar on {name} is not supported: 1 is used")
            return 1.0
        return value

    def number(self, source, name, material):
        return float(as_array(self.constant(source, name, material))[0])

    def color(self, source, name, material):
        return tuple(float(x) for x in fit(self.constant(source, name, material), 3))

    def scaled(self, source, factor):
        """`source` times a constant factor (a float or an RGB triple)."""
        kind, value = source
        if kind == "value":
            return "value", tuple(fit(value, 3) * fit(factor, 3)) if as_array(value).size > 1 \
                or as_array(factor).size > 1 else float(as_array(value)[0] * as_array(factor)[0])
        if kind == "texture":
            n = len(value.channels)
            k = fit(factor, n) if as_array(factor).size > 1 else float(as_array(factor)[0])
            if np.allclose(k, 1.0):
                return source
            folded = value.affine(k, 0.0)
            if folded is not None:
                return "texture", folded
            return self.net.combine([source, ("value", as_value(fit(k, n)))], np.multiply, n,
                                    value.element)
        return source  # a primvar: the factor is lost (warned by the caller where it matters)

    def normal(self, source, material, name="normal"):
        kind, value = source
        if kind == "texture":
            if isinstance(value, NormalMap):
                return value
            # An image wired straight into the normal: MaterialX's world or tangent vector
            # in [-1, 1] is unusual; decode as a normal map.
            self.warn(material, f"{name} is fed by a texture without a normalmap node: "
                      "read as a tangent-space normal map")
            return NormalMap(value.affine(2.0, -1.0) or value, 1.0)
        return None

    def _transmission(self, surface, weight, color, depth, thin, material, scatter=None, anisotropy=0.0):
        """Transmission weight, colour, depth and interior scattering of the Standard Surface
        / OpenPBR kind: OpenPBR's medium (extinction -ln(colour) / depth, scattering
        scatter / depth, absorption the difference raised by grey until no channel is
        negative, Henyey-Greenstein anisotropy), which Standard Surface shares."""
        surface.transmission = weight
        surface.thin_walled = bool(thin)
        kind, w = weight
        if kind == "value" and float(as_array(w)[0]) <= 0.0:
            return
        color = self.color(color, "transmission_color", material)
        depth = float(depth)
        if thin or depth <= 0.0:
            surface.transmission_color = color
            surface.absorption = None if thin else (0.0, 0.0, 0.0)
        else:
            surface.transmission_color = (1.0, 1.0, 1.0)
            extinction = [-math.log(min(max(c, 1e-6), 1.0)) / depth for c in color]
            scattering = [max(float(c), 0.0) / depth for c in (scatter if scatter is not None else (0, 0, 0))]
            absorption = [t - s for t, s in zip(extinction, scattering)]
            lowest = min(absorption)
            surface.absorption = tuple(a - min(lowest, 0.0) for a in absorption)
            if max(scattering) > 0.0:
                surface.scattering = tuple(scattering)
                surface.medium_anisotropy = min(max(float(anisotropy), -0.99), 0.99)

    # ---- UsdPreviewSurface ------------------------------------------------------------
    def preview(self, shader, material):
        s = self._inputs(shader, PREVIEW_DEFAULTS)
        out = Surface()
        out.base_color = s["diffuseColor"]
        okind, opacity = s["opacity"]
        threshold = self.number(s["opacityThreshold"], "opacityThreshold", material)
        mode = self.net.value(shader, "opacityMode", "transparent")
        mode = {0: "transparent", 1: "presence"}.get(mode, str(mode))
        if mode not in ("transparent", "presence"):
            self.warn(material, f"unknown opacityMode {mode!r}: 'transparent' is used")
            mode = "transparent"
        see_through = okind == "texture" or (okind == "value" and float(as_array(opacity)[0]) < 1.0)
        coverage = see_through and (threshold > 0.0 or mode == "presence")
        if coverage:
            out.alpha = s["opacity"]
            out.alpha_mode = ("mask", threshold) if threshold > 0.0 else "blend"
        elif see_through:
            # 1 - opacity of the dielectric base transmits, untinted.
            if okind == "texture":
                out.transmission = ("texture", opacity.affine(-1.0, 1.0))
            else:
                out.transmission = ("value", 1.0 - min(max(float(as_array(opacity)[0]), 0.0), 1.0))
            out.transmission_color = (1.0, 1.0, 1.0)
        out.metallic = s["metallic"]
        out.roughness = s["roughness"]
        out.emissive = s["emissiveColor"]
        if s["normal"][0] == "texture":
            # The specification's normal map: a UsdUVTexture with scale 2 and bias -1
            # decodes to [-1, 1] itself.
            texture = s["normal"][1]
            out.normal = texture if isinstance(texture, NormalMap) else NormalMap(texture, 1.0)
        out.ior = self.number(s["ior"], "ior", material)
        if see_through and not coverage:
            out.absorption = (0.0, 0.0, 0.0) if out.ior != 1.0 else None
            out.thin_walled = out.ior == 1.0
        if int(self.number(s["useSpecularWorkflow"], "useSpecularWorkflow", material)) == 1:
            out.specular_f0 = tuple(min(max(c, 0.0), 1.0) for c in
                                    self.color(s["specularColor"], "specularColor", material))
            out.metallic = ("value", 0.0)
        out.coat = min(max(self.number(s["clearcoat"], "clearcoat", material), 0.0), 1.0)
        out.coat_roughness = min(max(self.number(s["clearcoatRoughness"], "clearcoatRoughness", material), 0.0), 1.0)
        return out

    # ---- MaterialX ----------------------------------------------------------------------
    def standard_surface(self, shader, material, node_id, rename=None):
        """Autodesk Standard Surface (`rename` maps its input names to another shader's,
        for OmniSurface)."""
        defaults = {**_STANDARD_SURFACE_DEFAULTS, **mtlx.defaults(node_id)}
        return self._layered(shader, material, defaults, _STANDARD_SURFACE_ROLES, rename or {}, 1.0)

    def open_pbr(self, shader, material, node_id):
        defaults = {**_OPEN_PBR_DEFAULTS, **mtlx.defaults(node_id)}
        return self._layered(shader, material, defaults, _OPEN_PBR_ROLES, {}, 1000.0)

    def _layered(self, shader, material, defaults, roles, rename, film_nm):
        """The layered uber-shaders (Standard Surface, OpenPBR, OmniSurface): `roles` maps
        each part of the model to the shader's input name, `defaults` holds the inputs'
        defaults, `rename` maps names to another shader's spelling of them; `film_nm` is
        nanometres per unit of thin-film thickness (Standard Surface nm, OpenPBR µm)."""
        def name(role):
            return rename.get(roles[role], roles[role])

        def source(role):
            return self.net.source(shader, name(role), defaults.get(roles[role]))

        def number(role):
            return self.number(source(role), name(role), material)

        def color(role):
            return self.color(source(role), name(role), material)

        out = Surface()
        base = self._product(source("base_color"), source("base"), name("base"), material)
        out.base_color = base
        out.metallic = source("metalness")
        out.roughness = source("specular_roughness")
        out.specular_weight = number("specular")
        out.specular_color = color("specular_color")
        out.ior = number("specular_ior")
        self._transmission(out, source("transmission"), source("transmission_color"),
                           number("transmission_depth"),
                           bool(self.net.value(shader, name("thin_walled"), False)), material,
                           scatter=fit(color("transmission_scatter"), 3),
                           anisotropy=number("transmission_scatter_anisotropy"))
        subsurface = min(number("subsurface"), 1.0)
        if subsurface > 0.0:
            if out.transmission == ("value", 0.0) and not out.thin_walled:
                # OpenPBR's subsurface slab: the dielectric over a dense medium, whose share
                # of the dielectric base is the weight (a random walk, as Cycles and Arnold).
                mfp = fit(color("subsurface_radius"), 3) * fit(color("subsurface_radius_scale"), 3)
                out.transmission = ("value", subsurface)
                out.transmission_color = (1.0, 1.0, 1.0)
                out.absorption, out.scattering, out.medium_anisotropy = subsurface_medium(
                    fit(color("subsurface_color"), 3), mfp, number("subsurface_anisotropy"),
                    number("specular_ior"))
            elif out.transmission == ("value", 0.0):
                # A thin wall's subsurface is translucency, as MaterialX's graphs define it:
                # Standard Surface's is a translucent BSDF of the subsurface colour; OpenPBR's
                # half a diffuse reflection (weighted 1 - g) and half a translucent BSDF
                # (weighted 1 + g) of it. Both mix with the diffuse base by the weight: the
                # diffuse transmission of glTF's extension, whose reflected part joins the
                # base colour.
                colour = np.clip(fit(color("subsurface_color"), 3), 0.0, 1.0)
                if roles is _OPEN_PBR_ROLES:
                    g = min(max(number("subsurface_anisotropy"), -1.0), 1.0)
                    reflected, transmitted = 0.5 * (1.0 - g), 0.5 * (1.0 + g)
                else:
                    reflected, transmitted = 0.0, 1.0
                share = subsurface * transmitted
                if share > 0.0:
                    out.diffuse_transmission = (share, tuple(float(c) for c in colour))
                if reflected > 0.0 and share < 1.0:
                    out.base_color = self._lerp_color(out.base_color, colour,
                                                      subsurface * reflected / (1.0 - share))
            else:
                self.warn(material, "subsurface scattering is approximated by diffuse reflection "
                          f"of {name('subsurface_color')} (transmission holds no subsurface medium)")
                out.base_color = self._lerp_color(out.base_color, fit(color("subsurface_color"), 3),
                                                  subsurface)
        self._coat(out, source("coat"), source("coat_roughness"), source("coat_color"),
                   source("coat_ior"), material)
        sheen = number("sheen")
        if sheen > 0.0:
            out.sheen_color = tuple(sheen * c for c in color("sheen_color"))
            out.sheen_roughness = number("sheen_roughness")
        out.emissive = self._product(source("emission_color"), source("emission"), name("emission"), material)
        self._opacity(out, source("opacity"), material)
        anisotropy = number("anisotropy")
        if anisotropy > 0.0:
            # Standard Surface's rotation: 0 to 1 is a full turn; OpenPBR has none.
            rotation = 2.0 * math.pi * number("rotation") if "rotation" in roles else 0.0
            out.anisotropy = (anisotropy, rotation)
        film = number("film_weight") if "film_weight" in roles else 1.0
        thickness = number("film_thickness") * film_nm
        if film > 0.0 and thickness > 0.0:
            out.iridescence = (film, number("film_ior"), thickness)
        out.diffuse_roughness = number("diffuse_roughness")
        out.normal = self.normal(self.net.source(shader, name("normal"), None), material, name("normal"))
        return out

    def gltf_pbr(self, shader, material, node_id):
        defaults = {**_GLTF_PBR_DEFAULTS, **mtlx.defaults(node_id)}
        s = {k: self.net.source(shader, k, v) for k, v in defaults.items()}
        out = Surface()
        out.base_color = s["base_color"]
        out.metallic = s["metallic"]
        out.roughness = s["roughness"]
        out.normal = self.normal(self.net.source(shader, "normal", None), material)
        out.transmission = s["transmission"]
        out.specular_weight = self.number(s["specular"], "specular", material)
        out.specular_color = self.color(s["specular_color"], "specular_color", material)
        out.ior = self.number(s["ior"], "ior", material)
        mode = int(self.number(s["alpha_mode"], "alpha_mode", material))
        if mode == 1:
            out.alpha, out.alpha_mode = s["alpha"], ("mask", self.number(s["alpha_cutoff"], "alpha_cutoff", material))
        elif mode == 2:
            out.alpha, out.alpha_mode = s["alpha"], "blend"
        sheen = self.color(s["sheen_color"], "sheen_color", material)
        if max(sheen) > 0.0:
            out.sheen_color = sheen
            out.sheen_roughness = self.number(s["sheen_roughness"], "sheen_roughness", material)
        out.coat = self.number(s["clearcoat"], "clearcoat", material)
        out.coat_roughness = self.number(s["clearcoat_roughness"], "clearcoat_roughness", material)
        out.emissive = self._product(s["emissive"], s["emissive_strength"], "emissive_strength", material)
        thickness = self.number(s["thickness"], "thickness", material)
        if thickness > 0.0:
            distance = self.number(s["attenuation_distance"], "attenuation_distance", material)
            color = self.color(s["attenuation_color"], "attenuation_color", material)
            out.absorption = tuple(-math.log(min(max(c, 1e-6), 1.0)) / distance
                                   if distance > 0.0 else 0.0 for c in color)
        else:
            out.thin_walled = True
        irid = self.number(s["iridescence"], "iridescence", material)
        if irid > 0.0:
            out.iridescence = (irid, self.number(s["iridescence_ior"], "iridescence_ior", material),
                               self.number(s["iridescence_thickness"], "iridescence_thickness", material))
        return out

    # ---- MDL (Omniverse) ----------------------------------------------------------------
    def omni_pbr(self, shader, material):
        net = self.net
        out = Surface()
        color = self._mdl_texture_or(shader, "diffuse_texture", "diffuse_color_constant",
                                     (0.2, 0.2, 0.2), [0, 1, 2], "sRGB")
        factor = fit(net.value(shader, "diffuse_tint", (1.0, 1.0, 1.0)), 3) * float(
            net.value(shader, "albedo_brightness", 1.0))
        out.base_color = self.scaled(color, tuple(factor))
        if bool(net.value(shader, "enable_ORM_texture", False)):
            orm = self._mdl_texture(shader, "ORM_texture", [0, 1, 2], "raw")
            if orm is not None:
                out.roughness = ("texture", orm.select([1]))
                out.metallic = ("texture", orm.select([2]))
        if out.roughness == ("value", 0.5):
            out.roughness = self._mdl_influenced(shader, "reflectionroughness_texture",
                                                 "reflection_roughness_texture_influence",
                                                 "reflection_roughness_constant", 0.5)
            out.metallic = self._mdl_influenced(shader, "metallic_texture",
                                                "metallic_texture_influence", "metallic_constant", 0.0)
        out.specular_weight = 2.0 * float(net.value(shader, "specular_level", 0.5))
        if bool(net.value(shader, "enable_emission", False)):
            emissive = self._mdl_texture_or(shader, "emissive_color_texture", "emissive_color",
                                            (1.0, 0.1, 0.1), [0, 1, 2], "sRGB")
            out.emissive = self.scaled(emissive, float(net.value(shader, "emissive_intensity", 40.0)) / math.pi)
            if self._mdl_texture(shader, "emissive_mask_texture", [0], "raw") is not None:
                self.warn(material, "emissive_mask_texture is not supported: the whole surface emits")
        normal = self._mdl_texture(shader, "normalmap_texture", [0, 1, 2], "raw")
        if normal is not None:
            out.normal = NormalMap(normal.affine(2.0, -1.0), float(net.value(shader, "bump_factor", 1.0)))
        if bool(net.value(shader, "enable_opacity", False)):
            alpha = ("value", float(net.value(shader, "opacity_constant", 1.0)))
            if bool(net.value(shader, "enable_opacity_texture", False)):
                tex = self._mdl_texture(shader, "opacity_texture", [3], "raw")
                if tex is not None:
                    alpha = ("texture", tex)
            threshold = float(net.value(shader, "opacity_threshold", 0.0))
            out.alpha = alpha
            out.alpha_mode = ("mask", threshold) if threshold > 0.0 else "blend"
        return out

    def omni_glass(self, shader, material):
        net = self.net
        out = Surface()
        color = self._mdl_texture_or(shader, "glass_color_texture", "glass_color",
                                     (1.0, 1.0, 1.0), [0, 1, 2], "sRGB")
        out.base_color = ("value", (1.0, 1.0, 1.0))
        out.metallic = ("value", 0.0)
        out.roughness = self._mdl_influenced(shader, "roughness_texture", "roughness_texture_influence",
                                             "frosting_roughness", 0.0)
        out.ior = float(net.value(shader, "glass_ior", 1.491))
        out.transmission = ("value", 1.0)
        out.thin_walled = bool(net.value(shader, "thin_walled", False))
        out.transmission_color = self.color(color, "glass_color", material)
        out.absorption = None if out.thin_walled else (0.0, 0.0, 0.0)
        normal = self._mdl_texture(shader, "normal_map_texture", [0, 1, 2], "raw")
        if normal is not None:
            out.normal = NormalMap(normal.affine(2.0, -1.0), float(net.value(shader, "normal_map_strength", 1.0)))
        return out

    def omni_surface(self, shader, material):
        out = self.standard_surface(shader, material, "ND_standard_surface_surfaceshader",
                                    _OMNI_SURFACE_NAMES)
        # OmniSurface's emission is MDL radiant exitance times its intensity.
        intensity = float(self.net.value(shader, "emission_intensity", 1.0))
        out.emissive = self.scaled(out.emissive, intensity / math.pi)
        if bool(self.net.value(shader, "enable_opacity", False)):
            self._opacity(out, self.net.source(shader, "geometry_opacity", 1.0), material)
        else:
            out.alpha, out.alpha_mode = ("value", 1.0), None
        return out

    def _mdl_texture(self, shader, name, channels, color_space):
        from pxr import Sdf
        from .networks import TextureSource
        attr = self.net.authored(shader, name)
        if attr is None:
            return None
        asset = attr.Get(self.net.time)
        if not isinstance(asset, Sdf.AssetPath) or not asset.path:
            return None
        image = self.net.image(asset, f"{shader.GetPath()}.inputs:{name}")
        if image is None:
            return None
        if attr.HasColorSpace():
            from .networks import color_space_kind
            color_space = color_space_kind(attr.GetColorSpace(), color_space == "sRGB") or color_space
        transform = None
        scale = fit(self.net.value(shader, "texture_scale", (1.0, 1.0)), 2)
        translate = fit(self.net.value(shader, "texture_translate", (0.0, 0.0)), 2)
        rotate = float(self.net.value(shader, "texture_rotate", 0.0))
        if not (np.allclose(scale, 1.0) and np.allclose(translate, 0.0) and rotate == 0.0):
            from .networks import _uv_transform
            transform = _uv_transform(scale, rotate, translate)
        return TextureSource(image, channels, (1.0,) * 4, (0.0,) * 4, color_space,
                             ("repeat", "repeat"), "st", transform, f"{shader.GetPath()}.inputs:{name}")

    def _mdl_texture_or(self, shader, texture, constant, default, channels, color_space):
        tex = self._mdl_texture(shader, texture, channels, color_space)
        if tex is not None:
            return "texture", tex
        return "value", tuple(fit(self.net.value(shader, constant, default), 3))

    def _mdl_influenced(self, shader, texture, influence, constant, default):
        """OmniPBR's lerp(constant, texture, influence)."""
        value = float(self.net.value(shader, constant, default))
        tex = self._mdl_texture(shader, texture, [0], "raw")
        weight = float(self.net.value(shader, influence, 0.0))
        if tex is None or weight <= 0.0:
            return "value", value
        return "texture", tex.affine(weight, (1.0 - weight) * value)

    # ---- RenderMan ----------------------------------------------------------------------
    def pxr_surface(self, shader, material):
        net = self.net
        out = Surface()
        out.base_color = self._product(net.source(shader, "diffuseColor", (0.18, 0.18, 0.18)),
                                       net.source(shader, "diffuseGain", 1.0), "diffuseGain", material)
        face = fit(self.color(net.source(shader, "specularFaceColor", (0.0, 0.0, 0.0)),
                              "specularFaceColor", material), 3)
        edge = fit(self.color(net.source(shader, "specularEdgeColor", (0.0, 0.0, 0.0)),
                              "specularEdgeColor", material), 3)
        mode = int(net.value(shader, "specularFresnelMode", 0))
        out.roughness = net.source(shader, "specularRoughness", 0.2)
        out.metallic = ("value", 0.0)
        if mode == 1:
            ior = fit(net.value(shader, "specularIor", (1.5, 1.5, 1.5)), 3)
            out.ior = float(ior.mean())
            out.specular_color = tuple(min(max(c, 0.0), 1.0) for c in face) if face.max() > 0 else (1.0, 1.0, 1.0)
        elif face.max() <= 0.0 and edge.max() <= 0.0:
            out.specular_weight = 0.0
        else:
            out.specular_f0 = tuple(min(max(c, 0.0), 1.0) for c in face)
            if not np.allclose(edge, 1.0) and edge.max() > 0.0:
                self.warn(material, "specularEdgeColor other than white is approximated (Schlick "
                          "to white at grazing angles)")
        refraction = float(net.value(shader, "refractionGain", 0.0))
        if refraction > 0.0:
            out.transmission = ("value", min(refraction, 1.0))
            out.transmission_color = self.color(net.source(shader, "refractionColor", (1.0, 1.0, 1.0)),
                                                "refractionColor", material)
            out.ior = float(net.value(shader, "glassIor", 1.5))
            out.roughness = net.source(shader, "glassRoughness", 0.1)
            out.thin_walled = bool(net.value(shader, "thinGlass", False))
            out.absorption = None if out.thin_walled else (0.0, 0.0, 0.0)
        coat = fit(self.color(net.source(shader, "clearcoatFaceColor", (0.0, 0.0, 0.0)),
                              "clearcoatFaceColor", material), 3)
        if coat.max() > 0.0:
            out.coat = 1.0
            out.coat_roughness = float(net.value(shader, "clearcoatRoughness", 0.0))
        out.diffuse_roughness = float(net.value(shader, "diffuseRoughness", 0.0))
        fuzz = float(net.value(shader, "fuzzGain", 0.0))
        if fuzz > 0.0:
            out.sheen_color = tuple(fuzz * c for c in self.color(
                net.source(shader, "fuzzColor", (1.0, 1.0, 1.0)), "fuzzColor", material))
            out.sheen_roughness = 0.5
        out.emissive = self._product(net.source(shader, "glowColor", (1.0, 1.0, 1.0)),
                                     net.source(shader, "glowGain", 0.0), "glowGain", material)
        if float(net.value(shader, "subsurfaceGain", 0.0)) > 0.0:
            self.warn(material, "subsurface scattering is approximated by diffuse reflection")
        self._opacity(out, net.source(shader, "presence", 1.0), material)
        out.normal = self.normal(net.source(shader, "bumpNormal", (0.0, 0.0, 1.0)), material, "bumpNormal")
        return out

    def pxr_disney(self, shader, material):
        net = self.net
        out = Surface()
        base = net.source(shader, "baseColor", (0.2, 0.5, 0.8))
        out.base_color = base
        out.metallic = net.source(shader, "metallic", 0.0)
        out.roughness = net.source(shader, "roughness", 0.25)
        out.specular_weight = 2.0 * float(net.value(shader, "specular", 0.5))
        tint = float(net.value(shader, "specularTint", 0.0))
        base_mean = fit(self.color(base, "baseColor", material), 3)
        tint_color = base_mean / max(float(base_mean @ [0.2126, 0.7152, 0.0722]), 1e-6)
        if tint > 0.0:
            out.specular_color = tuple((1.0 - tint) + tint * tint_color)
        out.emissive = net.source(shader, "emitColor", (0.0, 0.0, 0.0))
        sheen = float(net.value(shader, "sheen", 0.0))
        if sheen > 0.0:
            sheen_tint = float(net.value(shader, "sheenTint", 0.5))
            out.sheen_color = tuple(sheen * ((1.0 - sheen_tint) + sheen_tint * tint_color))
            out.sheen_roughness = 0.5
        coat = float(net.value(shader, "clearcoat", 0.0))
        if coat > 0.0:
            gloss = float(net.value(shader, "clearcoatGloss", 1.0))
            out.coat = 0.25 * coat
            out.coat_roughness = math.sqrt(0.1 + (0.001 - 0.1) * gloss)
        anisotropic = float(net.value(shader, "anisotropic", 0.0))
        if anisotropic > 0.0:
            out.anisotropy = (anisotropic, 0.0)
        if float(net.value(shader, "subsurface", 0.0)) > 0.0:
            self.warn(material, "subsurface is approximated by diffuse reflection")
        self._opacity(out, net.source(shader, "presence", 1.0), material)
        out.normal = self.normal(net.source(shader, "bumpNormal", (0.0, 0.0, 1.0)), material, "bumpNormal")
        return out

    # ---- shared pieces --------------------------------------------------------------------
    def _product(self, color, weight, weight_name, material):
        """colour x weight where either may be a texture."""
        if weight[0] == "value":
            return self.scaled(color, float(as_array(weight[1])[0]))
        if color[0] == "value":
            texture = weight[1]
            return self.scaled(("texture", texture.select([0, 0, 0])), tuple(fit(color[1], 3)))
        kind, value = self.net._combine([color, weight], lambda c, w: c * w[..., :1], 3, weight_name)
        return kind, value

    def _lerp_color(self, base, other, t):
        if base[0] == "value":
            return "value", tuple(fit(base[1], 3) * (1.0 - t) + other * t)
        if base[0] == "texture":
            return "texture", base[1].affine(1.0 - t, other * t) or base[1]
        return base

    def _coat(self, out, weight, roughness, color, ior, material):
        coat = self.number(weight, "coat", material)
        if coat <= 0.0:
            return
        out.coat = min(coat, 1.0)
        out.coat_roughness = self.number(roughness, "coat_roughness", material)
        tint = fit(self.color(color, "coat_color", material), 3)
        if not np.allclose(tint, 1.0):
            self.warn(material, "a coloured coat is not supported: the coat is clear")
        coat_ior = self.number(ior, "coat_IOR", material)
        if abs(coat_ior - 1.5) > 0.05:
            self.warn(material, f"coat ior {coat_ior:g} is approximated by 1.5")

    def _opacity(self, out, source, material):
        kind, value = source
        if kind == "texture":
            out.alpha = ("texture", value.select([0]) if len(value.channels) > 1 else value)
            out.alpha_mode = "blend"
        elif kind == "value":
            alpha = float(fit(value, 3).mean())
            if alpha < 1.0:
                out.alpha = ("value", alpha)
                out.alpha_mode = "blend"


def _diffuse_fresnel(eta):
    """The hemispherical average of the Fresnel reflectance seen from inside a medium of
    relative index eta (Egan and Hilgeman's fit, as Jensen et al. 2001 use it)."""
    return -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta


def _dipole_reflectance(reduced_albedo, eta):
    """The diffuse reflectance of a semi-infinite medium under a boundary of index eta by
    the dipole approximation (Jensen et al. 2001)."""
    fdr = _diffuse_fresnel(eta)
    a = (1.0 + fdr) / (1.0 - fdr)
    x = math.sqrt(3.0 * max(1.0 - reduced_albedo, 0.0))
    return 0.5 * reduced_albedo * (1.0 + math.exp(-4.0 / 3.0 * a * x)) * math.exp(-x)


def _multiple_scattering_albedo(albedo, g, eta):
    """The fraction of the light entering a semi-infinite medium of single-scattering
    albedo `albedo` that leaves it again: van de Hulst's index-matched formula (OpenPBR's
    subsurface section), times the dipole's ratio of what a boundary of index eta lets
    out against what an index-matched one does (light reflected back in at the boundary
    scatters further and is partly absorbed)."""
    s = math.sqrt((1.0 - albedo) / (1.0 - albedo * g))
    matched = (1.0 - s) * (1.0 - 0.139 * s) / (1.0 + 1.17 * s)
    reduced = albedo * (1.0 - g) / (1.0 - albedo * g)
    if reduced <= 0.0:
        return 0.0
    return matched * _dipole_reflectance(reduced, eta) / _dipole_reflectance(reduced, 1.0)


#: The shortest mean free path of a subsurface channel, relative to the longest channel's.
SHORTEST_MFP = 0.05


def subsurface_medium(colour, mfp, anisotropy, ior=1.0):
    """(absorption, scattering, g) per unit length of OpenPBR's subsurface medium:
    extinction 1 / mean free path per channel, and the single-scattering albedo whose
    light transmitted back out through the dielectric boundary of index `ior` is the
    subsurface colour (OpenPBR's definition of it), found by bisection on
    [`_multiple_scattering_albedo`]; with `ior` 1 that is van de Hulst's inversion."""
    g = min(max(float(anisotropy), -0.99), 0.99)
    eta = max(float(ior), 1.0)
    absorption, scattering = [], []
    # A channel of (nearly) no mean free path scatters right at the surface, as a diffuse
    # reflection of its colour would (Cycles turns such channels into one): held at
    # SHORTEST_MFP of the longest channel's, dense enough to be that and long enough for a
    # walk to step through in single precision.
    longest = max(float(r) for r in mfp)
    mfp = [max(float(r), SHORTEST_MFP * longest) for r in mfp]
    for c, r in zip(colour, mfp):
        c = min(max(float(c), 0.0), 1.0)
        lo, hi = 0.0, 1.0
        for _ in range(48):
            mid = 0.5 * (lo + hi)
            if _multiple_scattering_albedo(mid, g, eta) < c:
                lo = mid
            else:
                hi = mid
        albedo = 1.0 if c >= 1.0 else 0.5 * (lo + hi)
        extinction = 1.0 / max(float(r), 1e-6)
        scattering.append(albedo * extinction)
        absorption.append((1.0 - albedo) * extinction)
    return tuple(absorption), tuple(scattering), g


#: The inputs of each part of the layered models (`_layered`).
_STANDARD_SURFACE_ROLES = {
    "base": "base", "base_color": "base_color", "diffuse_roughness": "diffuse_roughness",
    "metalness": "metalness", "specular": "specular", "specular_color": "specular_color",
    "specular_roughness": "specular_roughness", "specular_ior": "specular_IOR",
    "anisotropy": "specular_anisotropy", "rotation": "specular_rotation",
    "transmission": "transmission", "transmission_color": "transmission_color",
    "transmission_depth": "transmission_depth", "transmission_scatter": "transmission_scatter",
    "transmission_scatter_anisotropy": "transmission_scatter_anisotropy", "thin_walled": "thin_walled",
    "subsurface": "subsurface", "subsurface_color": "subsurface_color",
    "subsurface_radius": "subsurface_radius", "subsurface_radius_scale": "subsurface_scale",
    "subsurface_anisotropy": "subsurface_anisotropy",
    "coat": "coat", "coat_color": "coat_color", "coat_roughness": "coat_roughness",
    "coat_ior": "coat_IOR", "sheen": "sheen", "sheen_color": "sheen_color",
    "sheen_roughness": "sheen_roughness", "emission": "emission", "emission_color": "emission_color",
    "opacity": "opacity", "normal": "normal", "film_thickness": "thin_film_thickness",
    "film_ior": "thin_film_IOR",
}
_OPEN_PBR_ROLES = {
    "base": "base_weight", "base_color": "base_color", "diffuse_roughness": "base_diffuse_roughness",
    "metalness": "base_metalness", "specular": "specular_weight", "specular_color": "specular_color",
    "specular_roughness": "specular_roughness", "specular_ior": "specular_ior",
    "anisotropy": "specular_roughness_anisotropy", "transmission": "transmission_weight",
    "transmission_color": "transmission_color", "transmission_depth": "transmission_depth",
    "transmission_scatter": "transmission_scatter",
    "transmission_scatter_anisotropy": "transmission_scatter_anisotropy", "thin_walled": "geometry_thin_walled",
    "subsurface": "subsurface_weight", "subsurface_color": "subsurface_color",
    "subsurface_radius": "subsurface_radius", "subsurface_radius_scale": "subsurface_radius_scale",
    "subsurface_anisotropy": "subsurface_scatter_anisotropy",
    "coat": "coat_weight", "coat_color": "coat_color", "coat_roughness": "coat_roughness",
    "coat_ior": "coat_ior", "sheen": "fuzz_weight", "sheen_color": "fuzz_color",
    "sheen_roughness": "fuzz_roughness", "emission": "emission_luminance",
    "emission_color": "emission_color", "opacity": "geometry_opacity", "normal": "geometry_normal",
    "film_weight": "thin_film_weight", "film_thickness": "thin_film_thickness",
    "film_ior": "thin_film_ior",
}

#: OmniSurface's parameter names for Standard Surface's (its base).
_OMNI_SURFACE_NAMES = {
    "base": "diffuse_reflection_weight", "base_color": "diffuse_reflection_color",
    "diffuse_roughness": "diffuse_reflection_roughness", "metalness": "metalness",
    "specular": "specular_reflection_weight", "specular_color": "specular_reflection_color",
    "specular_roughness": "specular_reflection_roughness", "specular_IOR": "specular_reflection_ior",
    "specular_anisotropy": "specular_reflection_anisotropy",
    "specular_rotation": "specular_reflection_anisotropy_rotation",
    "transmission": "specular_transmission_weight", "transmission_color": "specular_transmission_color",
    "transmission_depth": "specular_transmission_scatter_depth",
    "transmission_scatter": "specular_transmission_scatter",
    "transmission_scatter_anisotropy": "specular_transmission_scatter_anisotropy",
    "subsurface": "subsurface_weight", "subsurface_color": "subsurface_color",
    "sheen": "sheen_weight", "sheen_color": "sheen_color", "sheen_roughness": "sheen_roughness",
    "coat": "coat_weight", "coat_color": "coat_color", "coat_roughness": "coat_roughness",
    "coat_IOR": "coat_ior", "emission": "emission_weight", "emission_color": "emission_color",
    "thin_film_thickness": "thin_film_thickness", "thin_film_IOR": "thin_film_ior",
    "thin_walled": "thin_walled", "opacity": "geometry_opacity", "normal": "geometry_normal",
}

# Fallbacks where the MaterialX package is missing (its library gives the real defaults).
_STANDARD_SURFACE_DEFAULTS = {
    "base": 1.0, "base_color": (0.8, 0.8, 0.8), "diffuse_roughness": 0.0, "metalness": 0.0,
    "specular": 1.0, "specular_color": (1.0, 1.0, 1.0), "specular_roughness": 0.2,
    "specular_IOR": 1.5, "specular_anisotropy": 0.0, "specular_rotation": 0.0,
    "transmission": 0.0, "transmission_color": (1.0, 1.0, 1.0), "transmission_depth": 0.0,
    "transmission_scatter": (0.0, 0.0, 0.0), "transmission_scatter_anisotropy": 0.0, "subsurface": 0.0,
    "subsurface_color": (1.0, 1.0, 1.0), "subsurface_radius": (1.0, 1.0, 1.0), "subsurface_scale": 1.0,
    "subsurface_anisotropy": 0.0, "sheen": 0.0, "sheen_color": (1.0, 1.0, 1.0),
    "sheen_roughness": 0.3, "coat": 0.0, "coat_color": (1.0, 1.0, 1.0), "coat_roughness": 0.1,
    "coat_IOR": 1.5, "thin_film_thickness": 0.0, "thin_film_IOR": 1.5, "emission": 0.0,
    "emission_color": (1.0, 1.0, 1.0), "opacity": (1.0, 1.0, 1.0), "thin_walled": False,
}
_OPEN_PBR_DEFAULTS = {
    "base_weight": 1.0, "base_color": (0.8, 0.8, 0.8), "base_diffuse_roughness": 0.0,
    "base_metalness": 0.0, "specular_weight": 1.0, "specular_color": (1.0, 1.0, 1.0),
    "specular_roughness": 0.3, "specular_ior": 1.5, "specular_roughness_anisotropy": 0.0,
    "transmission_weight": 0.0, "transmission_color": (1.0, 1.0, 1.0), "transmission_depth": 0.0,
    "transmission_scatter": (0.0, 0.0, 0.0), "transmission_scatter_anisotropy": 0.0,
    "subsurface_weight": 0.0,
    "subsurface_color": (0.8, 0.8, 0.8), "subsurface_radius": 1.0,
    "subsurface_radius_scale": (1.0, 0.5, 0.25), "subsurface_scatter_anisotropy": 0.0,
    "coat_weight": 0.0, "coat_color": (1.0, 1.0, 1.0),
    "coat_roughness": 0.0, "coat_ior": 1.6, "fuzz_weight": 0.0, "fuzz_color": (1.0, 1.0, 1.0),
    "fuzz_roughness": 0.5, "thin_film_weight": 0.0, "thin_film_thickness": 0.5,
    "thin_film_ior": 1.4, "emission_luminance": 0.0, "emission_color": (1.0, 1.0, 1.0),
    "geometry_opacity": 1.0, "geometry_thin_walled": False,
}
_GLTF_PBR_DEFAULTS = {
    "base_color": (1.0, 1.0, 1.0), "metallic": 1.0, "roughness": 1.0, "transmission": 0.0,
    "specular": 1.0, "specular_color": (1.0, 1.0, 1.0), "ior": 1.5, "alpha": 1.0,
    "alpha_mode": 0, "alpha_cutoff": 0.5, "sheen_color": (0.0, 0.0, 0.0), "sheen_roughness": 0.0,
    "clearcoat": 0.0, "clearcoat_roughness": 0.0, "emissive": (0.0, 0.0, 0.0),
    "emissive_strength": 1.0, "thickness": 0.0, "attenuation_distance": 0.0,
    "attenuation_color": (1.0, 1.0, 1.0), "iridescence": 0.0, "iridescence_ior": 1.3,
    "iridescence_thickness": 100.0,
}
