"""UsdRender: the render a stage declares, as lucerna's scene file states it.

Which settings: `--render-settings PATH`, else the stage's `renderSettingsPrimPath`
metadata, else the first RenderSettings prim of the stage (husk's order); a stage without
one renders as before. From the settings and each of its products (a product's own authored
camera, resolution, pixelAspectRatio, aspectRatioConformPolicy and dataWindowNDC override
the settings'):

- camera: the `camera` relationship (lucerna's cameras are named by prim path);
- resolution in pixels; dataWindowNDC (x0, y0, x1, y1, origin bottom-left) becomes the
  pixel window rendered, the EXR's data window: within 0..1 a crop, beyond it overscan
  (pixels past the image's edges; the display window stays the image);
- aspectRatioConformPolicy: expandAperture, the default, is every USD camera's own fit in
  lucerna (the whole aperture stays in view); cropAperture, adjustApertureWidth and
  adjustApertureHeight give a per-product camera with the field of view they imply;
  adjustPixelAspectRatio and pixel aspect ratios other than 1 are warned about (lucerna's
  pixels are square);
- productName is the output file, relative to the working directory as husk writes it,
  with frame tokens expanded ($F, $F4, <F>, <F4>, ####, %04d, {frame});
- orderedVars select lucerna's AOVs by each RenderVar's sourceName: lucerna's own layer
  names, and the names Karma, hdCycles and RenderMan use for the same quantities (see
  `AOV_NAMES` and docs/usd.md); a var without an equivalent is warned about and left out.

The beauty is always written; deepRaster and other product types are refused with a
warning (the product is skipped)."""

import math
import re

# The most pixels of overscan an edge may have (the renderer's limit).
MAX_OVERSCAN = 16384

from pxr import Sdf, Usd, UsdRender

#: RenderVar sourceName (lower case) -> lucerna AOV.
AOV_NAMES = {
    # lucerna's own names pass through (checked against LUCERNA_AOVS below).
    "c": "beauty", "ci": "beauty", "color": "beauty", "rgba": "beauty", "rgb": "beauty",
    "combined": "beauty", "beauty": "beauty", "lpe:c.*": "beauty", "lpe:c.*[<l.>o]": "beauty",
    "a": "beauty", "alpha": "beauty",
    "n": "normal", "normal": "normal", "nn": "normal",
    "p": "position", "position": "position",
    "pz": "depth", "z": "depth", "depth": "depth",
    "albedo": "albedo", "basecolor": "albedo", "diffusecolor": "diffuse_color",
    "diffuse_color": "diffuse_color", "glossy_color": "glossy_color",
    "transmission_color": "transmission_color",
    "emission": "emission", "emit": "emission", "lpe:c<l.>": "emission", "lpe:co": "emission",
    "lpe:ce": "emission", "directdiffuse": "diffuse_direct", "indirectdiffuse": "diffuse_indirect",
    "directspecular": "glossy_direct", "indirectspecular": "glossy_indirect",
    "directglossy": "glossy_direct", "indirectglossy": "glossy_indirect",
    "diffuse_direct": "diffuse_direct", "diffuse_indirect": "diffuse_indirect",
    "glossy_direct": "glossy_direct", "glossy_indirect": "glossy_indirect",
    "transmission_direct": "transmission_direct", "transmission_indirect": "transmission_indirect",
    "volume_direct": "volume_direct", "volume_indirect": "volume_indirect",
    "volumedirect": "volume_direct", "volumeindirect": "volume_indirect",
    "volumedir": "volume_direct", "volumeind": "volume_indirect",
    "lpe:cdl": "diffuse_direct", "lpe:cd.+l": "diffuse_indirect", "lpe:c<rd>l": "diffuse_direct",
    "lpe:c<rd>.+l": "diffuse_indirect", "lpe:c<rs>l": "glossy_direct", "lpe:c<rs>.+l": "glossy_indirect",
    "lpe:c<t.>.*l": "transmission_direct",
    "direct": "direct", "indirect": "indirect", "lpe:c.l": "direct", "lpe:c..+l": "indirect",
    "crypto_object": "crypto", "crypto_material": "crypto", "cryptomatte": "crypto",
    "cryptomatteobject": "crypto", "cryptomattematerial": "crypto",
    "variance": "variance", "spp": "spp", "samplecount": "spp",
}

#: lucerna's layer names (src/film/aov.rs).
LUCERNA_AOVS = {
    "beauty", "emission", "direct", "indirect", "nee", "bsdf", "direct_nee", "direct_bsdf",
    "indirect_nee", "indirect_bsdf", "direct_nee_unweighted", "direct_bsdf_unweighted", "albedo",
    "normal", "depth", "position", "spp", "variance", "diffuse_direct", "diffuse_indirect",
    "glossy_direct", "glossy_indirect", "transmission_direct", "transmission_indirect",
    "volume_direct", "volume_indirect",
    "diffuse_color", "glossy_color", "transmission_color", "crypto", "lightgroups",
}
_DEPTH_AOV = re.compile(r"^(nee|bsdf)_d([1-9]|1[0-6])$")


def aov_of(source_name):
    """lucerna's AOV for a RenderVar sourceName, or None."""
    name = str(source_name).strip()
    key = name.lower().replace(" ", "")
    if name in LUCERNA_AOVS or _DEPTH_AOV.match(name):
        return name
    return AOV_NAMES.get(key)


def expand_frame(name, frame):
    """Expands the frame tokens of a product name for `frame` (a number, or None)."""
    if frame is None:
        return name
    whole = int(math.floor(frame + 0.5)) if abs(frame - round(frame)) < 1e-6 else None
    number = str(whole) if whole is not None else f"{frame:g}"

    def padded(width):
        if whole is None:
            return number
        return f"{whole:0{width}d}" if whole >= 0 else "-" + f"{-whole:0{width}d}"

    name = re.sub(r"\$F(\d)?", lambda m: padded(int(m.group(1) or 1)), name)
    name = re.sub(r"<F(\d)?>", lambda m: padded(int(m.group(1) or 1)), name)
    name = re.sub(r"%0?(\d)d", lambda m: padded(int(m.group(1))), name)
    name = name.replace("{frame}", padded(4))
    return re.sub(r"#+", lambda m: padded(len(m.group(0))), name)


def find(stage, explicit):
    """The UsdRender.Settings to use, or None; raises ValueError for an explicit path that
    names no RenderSettings prim."""
    if explicit:
        prim = stage.GetPrimAtPath(Sdf.Path(explicit)) if Sdf.Path.IsValidPathString(explicit) else None
        if not prim or not prim.IsA(UsdRender.Settings):
            raise ValueError(f"--render-settings {explicit}: no RenderSettings prim there")
        return UsdRender.Settings(prim)
    metadata = stage.GetMetadata("renderSettingsPrimPath")
    if metadata:
        prim = stage.GetPrimAtPath(Sdf.Path(metadata))
        if prim and prim.IsA(UsdRender.Settings):
            return UsdRender.Settings(prim)
    for prim in stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)):
        if prim.IsA(UsdRender.Settings):
            return UsdRender.Settings(prim)
    return None


def _authored(attr):
    return attr and attr.HasAuthoredValue()


def _base(prim_api, inherited, time):
    """Camera, resolution, pixel aspect, conform policy and data window of a SettingsBase,
    each from `inherited` unless authored here."""
    out = dict(inherited)
    targets = prim_api.GetCameraRel().GetForwardedTargets()
    if targets:
        out["camera"] = str(targets[0])
    for key, attr in (("resolution", prim_api.GetResolutionAttr()),
                      ("pixel_aspect", prim_api.GetPixelAspectRatioAttr()),
                      ("conform", prim_api.GetAspectRatioConformPolicyAttr()),
                      ("window", prim_api.GetDataWindowNDCAttr())):
        if _authored(attr) or key not in out:
            value = attr.Get(time)
            if value is not None:
                out[key] = value
    return out


def convert(stage, writer, time, frame, explicit, warn):
    """Reads the settings into `writer.render_settings` (and per-product cameras into
    `writer.cameras`)."""
    settings = find(stage, explicit)
    if settings is None:
        return
    path = str(settings.GetPath())
    base = _base(settings, {}, time)
    products = []
    for target in settings.GetProductsRel().GetForwardedTargets():
        prim = stage.GetPrimAtPath(target)
        if not prim or not prim.IsA(UsdRender.Product):
            warn(str(target), "not a RenderProduct: skipped")
            continue
        product = UsdRender.Product(prim)
        kind = product.GetProductTypeAttr().Get(time) or "raster"
        if kind != "raster":
            warn(str(target), f"productType {kind!r} is not supported (raster only): skipped")
            continue
        name = product.GetProductNameAttr().Get(time)
        if not name:
            warn(str(target), "no productName: skipped")
            continue
        fields = _base(product, base, time)
        aovs = []
        for var_path in product.GetOrderedVarsRel().GetForwardedTargets():
            var_prim = stage.GetPrimAtPath(var_path)
            if not var_prim or not var_prim.IsA(UsdRender.Var):
                warn(str(var_path), "not a RenderVar: skipped")
                continue
            var = UsdRender.Var(var_prim)
            source = var.GetSourceNameAttr().Get(time) or var_prim.GetName()
            source_type = var.GetSourceTypeAttr().Get(time) or "raw"
            key = f"lpe:{source}" if source_type == "lpe" and not str(source).startswith("lpe:") else source
            aov = aov_of(key) or aov_of(var_prim.GetName())
            if aov is None:
                warn(str(var_path), f"RenderVar {source!r} ({source_type}) has no lucerna equivalent: "
                     "left out (lucerna's layer names and their Karma/Cycles names are listed "
                     "in docs/usd.md)")
                continue
            if aov not in aovs:
                aovs.append(aov)
        products.append(_product(writer, stage, fields, expand_frame(str(name), frame), aovs,
                                 str(target), warn, time))
    fields = base
    settings_product = _product(writer, stage, fields, "", [], path, warn, time)
    writer.render_settings = {
        "path": path,
        "camera": settings_product["camera"],
        "resolution": settings_product["resolution"],
        "crop": settings_product["crop"],
        "products": products,
    }
    if "overscan" in settings_product:
        writer.render_settings["overscan"] = settings_product["overscan"]


def _product(writer, stage, fields, output, aovs, element, warn, time):
    resolution = fields.get("resolution")
    width, height = (int(resolution[0]), int(resolution[1])) if resolution is not None else (None, None)
    if width is not None and not (1 <= width <= 65536 and 1 <= height <= 65536):
        warn(element, f"resolution {width}x{height} is out of range: the camera's is used")
        width = height = None
    pixel_aspect = float(fields.get("pixel_aspect", 1.0) or 1.0)
    if abs(pixel_aspect - 1.0) > 1e-6:
        warn(element, f"pixelAspectRatio {pixel_aspect:g}: lucerna renders square pixels")
    camera = fields.get("camera")
    if camera is not None:
        camera = _fitted_camera(writer, camera, width, height, pixel_aspect,
                                str(fields.get("conform", "expandAperture")), element, warn)
    crop = overscan = None
    window = fields.get("window")
    if window is not None and width is not None:
        x0, y0, x1, y1 = (float(v) for v in window)
        if (x0, y0, x1, y1) != (0.0, 0.0, 1.0, 1.0):
            # Beyond 0..1 the window is overscan: pixels past the image's edges (at most
            # MAX_OVERSCAN an edge); within, it crops the image.
            # Edges a hair off a pixel boundary (a float4's -0.1 is -0.100000001) snap to it.
            def snap(v):
                return round(v) if abs(v - round(v)) < 1e-3 else v
            px0, px1 = math.floor(snap(x0 * width)), math.ceil(snap(x1 * width))
            py0, py1 = math.floor(snap((1.0 - y1) * height)), math.ceil(snap((1.0 - y0) * height))
            edges = [max(0, -px0), max(0, -py0), max(0, px1 - width), max(0, py1 - height)]
            if any(e > MAX_OVERSCAN for e in edges):
                warn(element, f"dataWindowNDC {tuple(window)} reaches more than {MAX_OVERSCAN} pixels "
                              "beyond the image: the overscan is limited to that")
                edges = [min(e, MAX_OVERSCAN) for e in edges]
            if any(edges):
                overscan = edges
            px0, px1 = max(0, px0), min(width, px1)
            py0, py1 = max(0, py0), min(height, py1)
            if px0 < px1 and py0 < py1:
                if (px0, py0, px1, py1) != (0, 0, width, height):
                    crop = [px0, py0, px1, py1]
            else:
                warn(element, f"dataWindowNDC {tuple(window)} holds no pixel: the whole image is rendered")
                overscan = None
    elif window is not None and tuple(float(v) for v in window) != (0.0, 0.0, 1.0, 1.0):
        warn(element, "dataWindowNDC needs a resolution: the whole image is rendered")
    product = {"output": output, "camera": camera,
               "resolution": [width, height] if width is not None else None,
               "crop": crop, "aovs": ",".join(aovs) if aovs else "beauty"}
    if overscan:
        product["overscan"] = overscan
    return product


_POLICIES = {"expandAperture", "cropAperture", "adjustApertureWidth", "adjustApertureHeight",
             "adjustPixelAspectRatio"}


def _fitted_camera(writer, name, width, height, pixel_aspect, policy, element, warn):
    """The camera to render `name` through at width x height: itself where its aperture
    fits the image, else a copy whose field of view follows the conform policy."""
    camera = next((c for c in writer.cameras if c["name"] == name), None)
    if camera is None:
        warn(element, f"camera {name} is not a camera of the stage: the first camera is used")
        return None
    if width is None or "perspective" not in camera["projection"]:
        return name
    if policy in ("expandAperture", "adjustPixelAspectRatio") or policy not in _POLICIES:
        if policy == "adjustPixelAspectRatio":
            warn(element, "aspectRatioConformPolicy adjustPixelAspectRatio: lucerna renders "
                 "square pixels; the aperture is expanded instead")
        elif policy != "expandAperture":
            warn(element, f"unknown aspectRatioConformPolicy {policy!r}: expandAperture is used")
        return name  # the renderer keeps the whole aperture in view (the camera's fit)
    persp = camera["projection"]["perspective"]
    aperture_aspect = persp["aspect"]
    image_aspect = width * pixel_aspect / height
    tan_v = math.tan(persp["yfov"] / 2)
    tan_h = tan_v * aperture_aspect
    if policy == "cropAperture":
        tan_v = min(tan_v, tan_h / image_aspect)
    elif policy == "adjustApertureHeight":
        tan_v = tan_h / image_aspect
    # adjustApertureWidth keeps the vertical field of view.
    yfov = 2 * math.atan(tan_v)
    fitted = f"{name} ({width}x{height}, {policy})"
    if not any(c["name"] == fitted for c in writer.cameras):
        copy = dict(camera)
        copy["name"] = fitted
        copy["projection"] = {"perspective": {"yfov": yfov, "aspect": image_aspect}}
        copy["fit"] = "vertical"
        writer.cameras.append(copy)
    return fitted
