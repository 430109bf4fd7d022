"""UsdVol `Volume` prims: the OpenVDB density field they bind and the medium their material
describes, as a scene file's `volumes` entry (the renderer reads the grid itself and
encloses it in an interface box: docs/media.md).

The field: the Volume's `field:density` relationship (or the field its shader's
`density_channel` names), an `OpenVDBAsset` whose `filePath` (time-sampled paths give a
file per frame) and `fieldName` (default: the relationship's name) choose the file and
grid. Other field types (Field3D) are reported and skipped.

The medium: the surface-less shader connected to the bound material's `volume` output (of
any render context: `outputs:volume`, `outputs:arnold:volume`, ...), read with the inputs of
Arnold's `standard_volume`, the volume shader that Houdini, Maya and MtoA users write:
`density` (extinction per stage unit at grid density 1), `scatter` and `scatter_color`
(the single-scattering albedo is their product), `scatter_anisotropy` (Henyey-Greenstein
g), and emission by `emission_mode`: "density" (`emission` x `emission_color`, radiance per
stage unit at density 1), "channel" (the field `emission_channel` names, default `heat`:
radiance per stage unit = its value x `emission` x `emission_color`, not scaled by the
density) or "blackbody" (the default): the field `temperature_channel` names (default
`temperature`) read as kelvin = value x `temperature` x `blackbody_kelvin`, glowing as
Cycles' Principled Volume does (radiance per stage unit sigma T^4 / pi x 1e-6 in Planck's
colour: docs/media.md), times `blackbody_intensity` x `emission` x `emission_color`. The
renderer reads scalar (float or double) grids: a vector emission field is an error naming
the volume and its field. `scatter_color_channel` names a colour field (a vector grid such
as Houdini's `Cd`, or a scalar one read as grey) that multiplies the albedo point by point
(at most 1; the extinction is the density's alone), as Arnold does. A transparency field
(`transparent_channel`) and a `transparent` colour are not read and are reported. Arnold
does not publish its blackbody's brightness, so a fire tuned in
Arnold may render brighter or darker; `blackbody_intensity` scales it. A Volume without
such a shader renders as standard_volume with its defaults (density 1, albedo 0.5 grey,
g 0; blackbody emission where it has a temperature field), as Arnold and Karma render an
unshaded volume.
"""

from pxr import Sdf, UsdShade, UsdVol

from .scene_file import default_material

# Arnold standard_volume's defaults, for the inputs lucerna reads.
DEFAULTS = {"density": 1.0, "scatter": 1.0, "scatter_color": (0.5, 0.5, 0.5), "scatter_anisotropy": 0.0,
            "emission": 1.0, "emission_color": (1.0, 1.0, 1.0), "emission_mode": "blackbody",
            "density_channel": "density", "temperature": 1.0, "temperature_channel": "temperature",
            "emission_channel": "heat", "scatter_color_channel": "",
            "blackbody_kelvin": 5000.0, "blackbody_intensity": 1.0}


# standard_volume inputs that lucerna does not read: a transparency field and colour.
# Authored, they are reported.
UNREAD = ("transparent", "transparent_channel")


def unread_inputs(shader, time):
    """The authored standard_volume inputs of `shader` that the medium ignores, with their
    values: a transparency channel naming a field, a transparency other than black."""
    unread = []
    for name in UNREAD:
        shader_input = shader.GetInput(name) if shader is not None else None
        if not shader_input or not shader_input.GetAttr().HasAuthoredValue():
            continue
        value = shader_input.Get(time)
        if name.endswith("_channel") and not value:
            continue
        if name == "transparent" and value is not None and not any(float(c) for c in value):
            continue
        if isinstance(value, str):
            unread.append(f"{name} = {value!r}")
        else:
            unread.append(f"{name} = ({', '.join(f'{float(c):g}' for c in value)})")
    return unread


def volume_shader(material):
    """The shader connected to a `volume` output of `material` (a UsdShade.Material), or None."""
    if not material:
        return None
    for output in material.GetOutputs():
        name = output.GetBaseName()
        if name == "volume" or name.endswith(":volume"):
            for source in output.GetConnectedSources()[0]:
                shader = UsdShade.Shader(source.source.GetPrim())
                if shader:
                    return shader
    return None


def shader_inputs(shader, time):
    """The standard_volume inputs of `shader` (authored values, else defaults)."""
    values = dict(DEFAULTS)
    if shader is None:
        return values
    for name in DEFAULTS:
        shader_input = shader.GetInput(name)
        if shader_input:
            value = shader_input.Get(time)
            if value is not None:
                values[name] = tuple(float(c) for c in value) if hasattr(value, "__len__") and not isinstance(value, str) else value
    return values


def density_field(volume, channel, time):
    """(file, grid name) of the OpenVDB field `channel` of `volume` (a Usd.Prim), or
    (None, reason)."""
    fields = UsdVol.Volume(volume).GetFieldPaths()
    target = fields.get(channel)
    if target is None:
        # A field whose grid is named `channel` under another relationship name.
        for path in fields.values():
            field = volume.GetStage().GetPrimAtPath(path)
            if field and field.IsA(UsdVol.OpenVDBAsset) and UsdVol.OpenVDBAsset(field).GetFieldNameAttr().Get(time) == channel:
                target = path
                break
    if target is None:
        return None, f"it has no field {channel!r} (fields: {', '.join(sorted(fields)) or 'none'})"
    field = volume.GetStage().GetPrimAtPath(target)
    if not field or not field.IsA(UsdVol.OpenVDBAsset):
        kind = field.GetTypeName() if field else "missing"
        return None, f"its field {channel!r} ({target}) is {kind}, not an OpenVDBAsset"
    asset = UsdVol.OpenVDBAsset(field)
    path = asset.GetFilePathAttr().Get(time)
    if not isinstance(path, Sdf.AssetPath) or not path.path:
        return None, f"its field {channel!r} ({target}) has no filePath"
    if not path.resolvedPath:
        return None, f"its field {channel!r}: the file {path.path} cannot be found"
    grid = asset.GetFieldNameAttr().Get(time) or channel
    return (path.resolvedPath, str(grid)), None


def glow_channel(inputs):
    """The field that makes the medium `inputs` describe glow, by its emission mode:
    ("temperature", channel) for blackbody emission, ("emission", channel) for an emission
    channel, or None."""
    mode = inputs["emission_mode"]
    if mode == "blackbody":
        return "temperature", str(inputs["temperature_channel"])
    if mode == "channel":
        return "emission", str(inputs["emission_channel"])
    return None


def medium_material(name, inputs, per_metre, warn, glowing=False):
    """The scene-file material of an interface around the medium `inputs` describe;
    `glowing`: the volume has the field that its emission mode reads (`glow_channel`)."""
    density = float(inputs["density"])
    albedo = [min(max(float(inputs["scatter"]) * float(c), 0.0), 1.0) for c in inputs["scatter_color"]]
    g = float(inputs["scatter_anisotropy"])
    if not -1.0 < g < 1.0:
        warn(name, f"scatter_anisotropy {g} is outside (-1, 1): clamped")
        g = min(max(g, -0.99), 0.99)
    if density < 0.0:
        warn(name, f"density {density} is negative: 0 is used")
        density = 0.0
    extinction = density * per_metre
    emission = [0.0, 0.0, 0.0]
    blackbody = None
    emission_field = None
    strength = float(inputs["emission"])
    weight = [max(strength * float(c), 0.0) for c in inputs["emission_color"]]
    mode = inputs["emission_mode"]
    if mode in ("density", "constant"):
        emission = [w * per_metre for w in weight]
        if mode == "constant" and strength > 0.0:
            warn(name, "emission_mode 'constant' is rendered scaled by the density, as 'density'")
    elif mode == "blackbody":
        kelvin = float(inputs["temperature"]) * float(inputs["blackbody_kelvin"])
        intensity = float(inputs["blackbody_intensity"])
        if glowing and kelvin > 0.0 and intensity > 0.0 and max(weight) > 0.0:
            blackbody = {"kelvin": kelvin, "intensity": intensity, "tint": [w * per_metre for w in weight]}
        elif glowing:
            warn(name, f"blackbody emission is off (temperature x blackbody_kelvin {kelvin}, "
                       f"blackbody_intensity {intensity}, emission {strength})")
    elif mode == "channel":
        if glowing and max(weight) > 0.0:
            emission_field = {"tint": [w * per_metre for w in weight]}
        elif glowing:
            warn(name, f"the emission channel is off (emission {strength}, emission_color "
                       f"{tuple(inputs['emission_color'])})")
    elif mode != "none":
        warn(name, f"emission_mode {mode!r} is not read: the volume does not glow")
    volume = {"absorption": [extinction * (1.0 - a) for a in albedo],
              "scattering": [extinction * a for a in albedo],
              "anisotropy": g, "emission": emission}
    if blackbody is not None:
        volume["blackbody"] = blackbody
    if emission_field is not None:
        volume["emission_field"] = emission_field
    return default_material(name, model="interface", metallic=0.0, ior=1.0, volume=volume)
