"""UsdLux lights to lucerna's scene.

Emission follows UsdLux's definition: L = intensity * 2^exposure * color, times the
blackbody colour of colorTemperature when enableColorTemperature is on (usd-core's
`UsdLux.BlackbodyTemperatureAsRgb`, divided by its value at 6500 K so that the fallback
temperature gives white, as the schema says); with normalize, area lights divide by their
surface area in stage units, and a distant light's intensity becomes the irradiance on a
surface facing it. Lights are visible to the camera, as in Karma and RenderMan.

- RectLight, DiskLight, CylinderLight: emissive surfaces (black, one-sided, emitting along
  -Z, resp. outwards; no end caps). The disk and the cylinder are the renderer's analytic
  disk and open cylinder; under a shear or an uneven scale that would make them elliptic,
  polygons of SEGMENTS sides whose radius keeps the true surface area, so their power is
  exact.
- SphereLight: an analytic emissive sphere (sampled by solid angle); with treatAsPoint a
  point light of the same radiant intensity L * pi * r^2.
- DistantLight: a directional light with its angular diameter (a cone of uniform radiance
  in the renderer; 0 is a parallel light) and the cone's irradiance.
- DomeLight, DomeLight_1: the environment, constant or a lat-long map (OpenEXR's
  convention: +Y pole, longitude 0 along +Z). Several domes add up: constants sum, a
  constant adds to a map's texels, maps of one orientation sum texel by texel (resampled
  to the first map's size); a map turned otherwise than the first is left out with a
  warning.

As written in the wild: an attribute authored without the `inputs:` prefix (UsdLux before
21.05, many DCC exporters) is read where `inputs:NAME` is not authored, as UsdLux's own
compatibility does. ShapingAPI: on a point-like light (a SphereLight with treatAsPoint, or
any SphereLight, whose size is then dropped with a warning) a cone of half-angle
`shaping:cone:angle` up to 90 degrees makes a spot light that fades from
angle x (1 - softness) to the angle (glTF's spot falloff: an approximation of UsdLux's
smoothstep); focus, IES profiles and cones on area lights are warned about and ignored.
Light linking (lightLink/shadowLink collections that exclude something) is not honoured:
a warning names the light.
"""

import math

import numpy as np
from pxr import UsdGeom, UsdLux

from . import images
from .scene_file import default_material, matrix, mean_scale

SEGMENTS = 64


def value(prim, name, time, fallback=None):
    """Light attribute `name`: `inputs:NAME` where authored, else `NAME` where authored
    (UsdLux before the inputs: prefix, as UsdLux's compatibility reads it), else the
    schema's fallback (that of `inputs:NAME`), else `fallback`."""
    new = prim.GetAttribute(f"inputs:{name}")
    if new and new.HasAuthoredValue():
        return new.Get(time)
    old = prim.GetAttribute(name)
    if old and old.HasAuthoredValue():
        return old.Get(time)
    if new:
        v = new.Get(time)
        if v is not None:
            return v
    return fallback


# The most radiance a light may have: sums of samples and pixels need headroom in 32-bit
# floats (the renderer's --env takes at most this too).
MAX_RADIANCE = 1e18


def emission(prim, time):
    """The light's scalar-times-colour emission before normalisation (RGB). A value that
    cannot render (not a number, infinite, negative, or so large that it overflows) is a
    `StageError` naming the prim and the attribute."""
    from . import StageError

    path = str(prim.GetPath())
    intensity = float(value(prim, "intensity", time, 1.0))
    exposure = float(value(prim, "exposure", time, 0.0))
    color = np.asarray(value(prim, "color", time, (1.0, 1.0, 1.0)), dtype=float)
    for name, v in (("intensity", intensity), ("exposure", exposure)):
        if not math.isfinite(v):
            raise StageError(path, f"inputs:{name} is {v}: a light's {name} must be a finite number")
    if intensity < 0.0:
        raise StageError(path, f"inputs:intensity is {intensity:g}: a light's intensity must be "
                               "at least 0 (lucerna has no negative lights)")
    if not (np.all(np.isfinite(color)) and np.all(color >= 0.0)):
        raise StageError(path, f"inputs:color is {tuple(float(c) for c in color)}: a light's colour "
                               "must be finite and not negative")
    if exposure > 1024.0:
        raise StageError(path, f"inputs:exposure is {exposure:g}: 2^exposure overflows")
    result = intensity * 2.0 ** exposure * color
    if value(prim, "enableColorTemperature", time, False):
        kelvin = float(value(prim, "colorTemperature", time, 6500.0))
        rgb = np.asarray(UsdLux.BlackbodyTemperatureAsRgb(kelvin), dtype=float)
        result = result * rgb / np.asarray(UsdLux.BlackbodyTemperatureAsRgb(6500.0), dtype=float)
    if not (np.all(np.isfinite(result)) and float(np.max(result, initial=0.0)) <= MAX_RADIANCE):
        raise StageError(path, f"intensity {intensity:g} x 2^exposure {exposure:g} x colour is "
                               f"{float(np.max(result)):.3g}, more than {MAX_RADIANCE:g}, the most a "
                               "light may emit")
    return result


def _normalize(prim, time):
    return bool(value(prim, "normalize", time, False))


def _links_something_out(prim):
    """Whether the light's lightLink or shadowLink collection excludes anything (UsdLux's
    default includes everything)."""
    from pxr import Usd

    for name in ("lightLink", "shadowLink"):
        collection = Usd.CollectionAPI(prim, name)
        root = prim.GetAttribute(f"collection:{name}:includeRoot")
        if root and root.HasAuthoredValue() and not root.Get():
            return True
        if collection.GetExcludesRel() and collection.GetExcludesRel().GetTargets():
            return True
        includes = collection.GetIncludesRel()
        if includes and includes.GetTargets() and not (root and root.Get()):
            return True
    return False


def _spot_cone(prim, time, warn, path, point_like):
    """(inner, outer) half-angles in radians of the ShapingAPI cone, or None (no cone)."""
    angle = value(prim, "shaping:cone:angle", time, 90.0)
    softness = value(prim, "shaping:cone:softness", time, 0.0)
    focus = value(prim, "shaping:focus", time, 0.0)
    ies = value(prim, "shaping:ies:file", time, None)
    if focus and float(focus) != 0.0:
        warn(path, f"shaping:focus {focus} is not supported and is ignored")
    if ies is not None and getattr(ies, "path", ""):
        warn(path, f"IES profile {ies.path!r} is not supported and is ignored")
    angle = float(angle) if angle is not None else 90.0
    if angle >= 180.0:
        return None
    if not point_like:
        warn(path, f"shaping:cone:angle on a {prim.GetTypeName()} is not supported: it emits "
             "over its whole hemisphere")
        return None
    if angle > 90.0:
        warn(path, f"shaping:cone:angle {angle} wider than 90 degrees is not supported: "
             "unshaped point light")
        return None
    outer = math.radians(max(angle, 0.0))
    softness = min(max(float(softness or 0.0), 0.0), 1.0)
    return outer * (1.0 - softness), outer


def _emitter(writer, name, radiance):
    return writer.add_material(default_material(
        name, model="lambert", base_color=[0.0, 0.0, 0.0, 1.0], metallic=0.0,
        emissive=[float(c) for c in radiance], double_sided=False))


def _face_outwards(positions, triangles, outward):
    """Orders each triangle counter-clockwise seen from `outward(centroid)`."""
    p = positions[triangles]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    flip = np.einsum("ij,ij->i", n, outward(p.mean(axis=1))) < 0
    triangles[flip] = triangles[flip][:, [0, 2, 1]]
    return triangles


def _world_area(linear, positions, triangles):
    p = positions[triangles] @ linear
    return float(0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum())


def _polygon_radius(radius, segments):
    """Radius of a regular polygon with the area of the circle of `radius`."""
    return radius * math.sqrt(2 * math.pi / (segments * math.sin(2 * math.pi / segments)))


def _rect(width, height):
    w, h = width / 2, height / 2
    positions = np.array([[-w, -h, 0], [w, -h, 0], [w, h, 0], [-w, h, 0]], float)
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    return positions, triangles, lambda c: np.tile([0.0, 0.0, -1.0], (len(c), 1))


def _disk(radius):
    r = _polygon_radius(radius, SEGMENTS)
    angles = 2 * math.pi * np.arange(SEGMENTS) / SEGMENTS
    ring = np.stack([r * np.cos(angles), r * np.sin(angles), np.zeros(SEGMENTS)], 1)
    positions = np.vstack([[0.0, 0.0, 0.0], ring])
    k = np.arange(SEGMENTS)
    triangles = np.stack([np.zeros(SEGMENTS, int), 1 + k, 1 + (k + 1) % SEGMENTS], 1)
    return positions, triangles, lambda c: np.tile([0.0, 0.0, -1.0], (len(c), 1))


def _cylinder(radius, length):
    # Same lateral area: the polygon's perimeter equals the circle's.
    r = radius * math.pi / (SEGMENTS * math.sin(math.pi / SEGMENTS))
    angles = 2 * math.pi * np.arange(SEGMENTS) / SEGMENTS
    ring = np.stack([np.zeros(SEGMENTS), r * np.cos(angles), r * np.sin(angles)], 1)
    positions = np.vstack([ring + [-length / 2, 0, 0], ring + [length / 2, 0, 0]])
    k = np.arange(SEGMENTS)
    k1 = (k + 1) % SEGMENTS
    triangles = np.vstack([np.stack([k, k1, SEGMENTS + k1], 1), np.stack([k, SEGMENTS + k1, SEGMENTS + k], 1)])
    return positions, triangles, lambda c: c * [0.0, 1.0, 1.0]


def _similar(a, b, tolerance=1e-5):
    """Whether row vectors `a` and `b` are perpendicular and of equal length: the
    in-plane axes of a transform that keeps circles circular."""
    la, lb = np.linalg.norm(a), np.linalg.norm(b)
    return la > 0 and abs(la - lb) <= tolerance * la and abs(a @ b) <= tolerance * la * lb


def _analytic_disk(writer, name, material, world, radius):
    """Adds the disk light's exact disk if `world` keeps it circular; False otherwise."""
    ex, ey, ez = world[0, :3], world[1, :3], world[2, :3]
    if not _similar(ex, ey):
        return False
    normal = np.cross(ex, ey)
    normal /= np.linalg.norm(normal)
    if normal @ -ez < 0:  # mirrored: the light still emits where local -Z goes
        normal = -normal
    writer.disks.append({"name": name, "centre": [float(x) for x in world[3, :3]],
                         "normal": [float(x) for x in normal],
                         "radius": float(radius * np.linalg.norm(ex)), "material": material})
    return True


def _analytic_cylinder(writer, name, material, world, radius, length):
    """Adds the cylinder light's exact cylinder if `world` keeps its cross-section circular
    and its axis perpendicular to it; False otherwise."""
    ex, ey, ez = world[0, :3], world[1, :3], world[2, :3]
    lx = np.linalg.norm(ex)
    if not (_similar(ey, ez) and lx > 0 and abs(ex @ ey) <= 1e-5 * lx * np.linalg.norm(ey)
            and abs(ex @ ez) <= 1e-5 * lx * np.linalg.norm(ez)):
        return False
    writer.cylinders.append({"name": name, "centre": [float(x) for x in world[3, :3]],
                             "axis": [float(x) for x in ex / lx],
                             "radius": float(radius * np.linalg.norm(ey)),
                             "length": float(length * lx), "material": material})
    return True


LIGHT_GROUP_ATTRIBUTE = "lucerna:lightGroup"


def _light_group(prim, time, warn):
    """The light group of a light prim: its `string lucerna:lightGroup` attribute (letters,
    digits and _, lower-cased), or None."""
    attr = prim.GetAttribute(LIGHT_GROUP_ATTRIBUTE)
    value = attr.Get(time) if attr and attr.HasAuthoredValue() else None
    if value is None:
        return None
    group = str(value).lower()
    if not group or not all(c.isascii() and (c.isalnum() or c == "_") for c in group):
        warn(str(prim.GetPath()), f"{LIGHT_GROUP_ATTRIBUTE} {value!r} is not a group name "
             "(letters, digits and _); ignored")
        return None
    return group


def convert(writer, prim, usd_worlds, to_lucerna, time, warn):
    """Adds the light `prim` placed by each row-vector matrix of `usd_worlds` (stage
    space); `to_lucerna` maps stage space to lucerna's (Y up, metres)."""
    path = str(prim.GetPath())
    radiance = emission(prim, time)
    normalize = _normalize(prim, time)
    shaped = prim.HasAPI(UsdLux.ShapingAPI) or any(
        prim.GetAttribute(n).HasAuthoredValue() for n in (
            "inputs:shaping:cone:angle", "shaping:cone:angle", "inputs:shaping:focus"))
    if _links_something_out(prim):
        warn(path, "light linking (lightLink/shadowLink) is not honoured: the light "
             "illuminates and shadows everything")
    group = _light_group(prim, time, warn)
    for k, usd_world in enumerate(usd_worlds):
        name = path if len(usd_worlds) == 1 else f"{path}[{k}]"
        if group:
            writer.add_to_light_group(group, name)
        world = usd_world @ to_lucerna
        if prim.IsA(UsdLux.RectLight) or prim.IsA(UsdLux.DiskLight) or prim.IsA(UsdLux.CylinderLight):
            analytic = None
            if shaped:
                _spot_cone(prim, time, warn, path, point_like=False)
            if prim.IsA(UsdLux.RectLight):
                shape = _rect(float(value(prim, "width", time, 1.0)),
                              float(value(prim, "height", time, 1.0)))
                texture = value(prim, "texture:file", time, None)
                if texture is not None and getattr(texture, "path", ""):
                    warn(path, "texture:file on a RectLight is not supported: uniform emission")
            elif prim.IsA(UsdLux.DiskLight):
                radius = float(value(prim, "radius", time, 0.5))
                shape = _disk(radius)
                analytic = (_analytic_disk, (radius,))
            else:
                if value(prim, "treatAsLine", time, False):
                    warn(path, "treatAsLine is ignored: the cylinder is rendered")
                radius = float(value(prim, "radius", time, 0.5))
                length = float(value(prim, "length", time, 1.0))
                shape = _cylinder(radius, length)
                analytic = (_analytic_cylinder, (radius, length))
            positions, triangles, outward = shape
            triangles = _face_outwards(positions, triangles.copy(), outward)
            # The polygons have exactly the true area, so normalisation divides by it
            # whichever shape is written.
            area = _world_area(np.asarray(usd_world)[:3, :3], positions, triangles)
            if area <= 0.0:
                warn(path, "light has no area: skipped")
                continue
            L = radiance / area if normalize else radiance
            material = _emitter(writer, name, L)
            if analytic is not None:
                add, dimensions = analytic
                if add(writer, name, material, world, *dimensions):
                    continue
                warn(name, f"a sheared or unevenly scaled {prim.GetTypeName()} is rendered as a "
                     f"{SEGMENTS}-sided polygon mesh with the true area")
            mesh = writer.add_mesh(name, material, positions, triangles)
            writer.add_instances(name, mesh, world[None])
        elif prim.IsA(UsdLux.SphereLight):
            radius = float(value(prim, "radius", time, 0.5))
            scale, uniform = mean_scale(world[:3, :3])
            if not uniform:
                warn(name, "non-uniform scale on a SphereLight: the mean scale is used")
            usd_scale = mean_scale(np.asarray(usd_world)[:3, :3])[0]
            r_world = radius * scale
            centre = [float(x) for x in world[3, :3]]
            L = radiance
            if normalize and radius > 0:
                L = radiance / (4 * math.pi * (radius * usd_scale) ** 2)
            point = bool(value(prim, "treatAsPoint", time, False)) or radius <= 0.0
            cone = _spot_cone(prim, time, warn, path, point_like=True) if shaped else None
            if cone is not None and not point:
                warn(name, "a shaped SphereLight is rendered as a spot light at its centre "
                     "(its size, and so the softness of its shadows, is dropped)")
            if point or cone is not None:
                intensity = L * math.pi * r_world ** 2 if radius > 0 else L
                if cone is None:
                    writer.lights.append({"name": name, "kind": {"point": {
                        "position": centre, "intensity": [float(c) for c in intensity]}}})
                else:
                    axis = np.array([0.0, 0.0, -1.0]) @ world[:3, :3]
                    axis /= np.linalg.norm(axis)
                    writer.lights.append({"name": name, "kind": {"spot": {
                        "position": centre, "direction": [float(x) for x in axis],
                        "intensity": [float(c) for c in intensity],
                        "inner_cone": float(cone[0]), "outer_cone": float(cone[1])}}})
            else:
                writer.spheres.append({"name": name, "centre": centre, "radius": r_world,
                                       "material": _emitter(writer, name, L)})
        elif prim.IsA(UsdLux.DistantLight):
            angle = math.radians(min(max(float(value(prim, "angle", time, 0.53)), 0.0), 180.0))
            if normalize or angle == 0.0:
                irradiance = radiance
            else:
                irradiance = radiance * math.pi * math.sin(angle / 2) ** 2
            direction = np.array([0.0, 0.0, -1.0]) @ world[:3, :3]
            direction /= np.linalg.norm(direction)
            writer.lights.append({"name": name, "kind": {"directional": {
                "direction": [float(x) for x in direction],
                "irradiance": [float(c) for c in irradiance], "angle": angle}}})
        elif prim.IsA(UsdLux.DomeLight) or prim.IsA(UsdLux.DomeLight_1):
            _dome(writer, prim, world, radiance, time, warn, name)
        else:
            warn(path, f"light type {prim.GetTypeName()!r} is not supported: skipped")


def _dome(writer, prim, world, radiance, time, warn, name):
    """Records the dome for [`finish_domes`]: its scale and, if it has a readable lat-long
    map, the map's linear texels and orientation."""
    dome = UsdLux.DomeLight_1(prim) if prim.IsA(UsdLux.DomeLight_1) else UsdLux.DomeLight(prim)
    fmt = value(prim, "texture:format", time, "automatic")
    asset = value(prim, "texture:file", time, None)
    entry = {"name": name, "scale": np.asarray(radiance, dtype=float), "pixels": None}
    writer.domes.append(entry)
    if asset is None or not asset.path:
        return
    if fmt not in ("automatic", "latlong"):
        warn(name, f"texture:format {fmt!r} is not supported (latlong is): constant dome")
        return
    try:
        image = images.read(asset)
    except OSError as e:
        warn(name, f"dome texture {asset.path!r} unreadable ({e}): constant dome")
        return
    pixels = image.pixels.copy()
    if image.eight_bit:
        pixels[..., :3] = images.srgb_to_linear(pixels[..., :3])
    rotation = np.asarray(world, dtype=float)[:3, :3].copy()
    rotation /= np.linalg.norm(rotation, axis=1, keepdims=True)
    pole_z = prim.IsA(UsdLux.DomeLight_1) and (
        dome.GetPoleAxisAttr().Get(time) == "Z"
        or (dome.GetPoleAxisAttr().Get(time) == "scene"
            and UsdGeom.GetStageUpAxis(prim.GetStage()) == UsdGeom.Tokens.z))
    if pole_z:
        # The map's +Y pole onto the dome's +Z (row vectors: y -> z, z -> -y).
        rotation = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]) @ rotation
    # lucerna's lat-long map looks along -Z at its centre, OpenEXR's along +Z: a half turn
    # about the pole.
    rotation = np.diag([-1.0, 1.0, -1.0]) @ rotation
    entry["pixels"] = pixels
    entry["rotation"] = rotation


def finish_domes(writer, warn):
    """The environment of every dome met: the sum of their light (see the module doc)."""
    domes = writer.domes
    if not domes:
        return
    maps = [d for d in domes if d["pixels"] is not None]
    constant = sum((d["scale"] for d in domes if d["pixels"] is None), np.zeros(3))
    if not maps:
        writer.environment = {"constant": [float(c) for c in constant]}
        return
    first = maps[0]
    h, w = first["pixels"].shape[:2]
    texels = first["pixels"][..., :3] * first["scale"]
    for d in maps[1:]:
        if not np.allclose(d["rotation"], first["rotation"], atol=1e-6):
            warn(d["name"], f"a dome turned otherwise than {first['name']} is not added "
                 "(one environment map per scene; domes of one orientation add up)")
            continue
        texels = texels + images.resample(d["pixels"], (h, w))[..., :3] * d["scale"]
    texels = texels + constant
    rgba = np.concatenate([texels, np.ones((h, w, 1))], axis=2).astype(np.float32)
    texture = writer.add_texture(first["name"], rgba, ("repeat", "clamp_to_edge"))
    m = np.identity(4)
    m[:3, :3] = first["rotation"]
    writer.environment = {"lat_long": {"texture": texture, "scale": [1.0, 1.0, 1.0],
                                       "rotation": matrix(m)}}
