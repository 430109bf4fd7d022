"""Motion blur: the shutter a stage is rendered with and the time codes within it at which
moving transforms are sampled.

The shutter is `--shutter OPEN,CLOSE` when given, else the render camera's (UsdGeom.Camera
`shutter:open` and `shutter:close`, in frames relative to the frame; their defaults 0 and 0
leave it closed): the camera of the render settings (`--render-settings`, the stage's
`renderSettingsPrimPath`, its first RenderSettings prim), else the stage's first camera.
RenderSettings' `disableMotionBlur` (and the older `instantaneousShutter`) close it.

Transforms are sampled at `KEYS` evenly spaced time codes from the shutter's opening to its
closing; lucerna interpolates between them (translation and stretch linearly, rotation by
slerp). A mesh's points are sampled at the same time codes where they change (points time
samples, `velocities` and `accelerations` by UsdGeom's rules, skinning) and interpolated
linearly (deformation blur).
"""

import numpy as np
from pxr import Usd, UsdGeom

from . import render_settings as usd_render

#: Time codes a moving transform is sampled at over the shutter.
KEYS = 9

#: Where the shutter is closed and the motion layers are asked for (`--vectors`): the
#: interval, frames around the frame, that motion is taken over without blur (lucerna's
#: VECTOR_INTERVAL).
VECTOR_INTERVAL = (-0.5, 0.5)


def parse(text):
    """`OPEN,CLOSE` as two floats (argparse's type)."""
    parts = text.split(",")
    if len(parts) != 2:
        raise ValueError(f"OPEN,CLOSE in frames relative to the frame, got {text!r}")
    return float(parts[0]), float(parts[1])


def shutter(stage, explicit_settings, override):
    """The open shutter (open, close) in frames relative to the frame, or None where it is
    closed."""
    if override is not None:
        open_, close = override
        return (open_, close) if close > open_ else None
    settings = usd_render.find(stage, explicit_settings)
    camera = None
    if settings is not None:
        if settings.GetDisableMotionBlurAttr().Get() or settings.GetInstantaneousShutterAttr().Get():
            return None
        targets = settings.GetCameraRel().GetForwardedTargets()
        if targets:
            camera = stage.GetPrimAtPath(targets[0])
    if not camera or not camera.IsA(UsdGeom.Camera):
        camera = next((p for p in stage.Traverse() if p.IsA(UsdGeom.Camera)), None)
    if camera is None:
        return None
    cam = UsdGeom.Camera(camera)
    open_ = cam.GetShutterOpenAttr().Get()
    close = cam.GetShutterCloseAttr().Get()
    if open_ is None or close is None or not close > open_:
        return None
    return float(open_), float(close)


def times(time, open_close):
    """The time codes at which moving transforms are sampled for the frame at `time`, or
    None for a closed shutter (or a frame that is not a number: the earliest time)."""
    if open_close is None or time.IsEarliestTime() or time.IsDefault():
        return None
    open_, close = open_close
    base = time.GetValue()
    return [Usd.TimeCode(base + open_ + (close - open_) * k / (KEYS - 1)) for k in range(KEYS)]


def point_keys(mesh, times, base, skinned_points):
    """The points of UsdGeom.Mesh `mesh` at the shutter's time codes `times`, in its own space
    ((N, 3) float64 arrays), or None where they do not move. A skinned mesh's are
    `skinned_points(time, rest)` of its points at each time; others' follow their time
    samples, or their `velocities` and `accelerations` from the frame's sample at `base`
    (UsdGeom.PointBased.ComputePointsAtTimes). Returns (keys, reason): keys None and a reason
    where they change their count (the topology changes), which is not blurred."""
    attr = mesh.GetPointsAttr()
    if skinned_points is not None:
        keys = [skinned_points(t, np.asarray(attr.Get(t) or [], np.float64).reshape(-1, 3))
                for t in times]
    elif attr.ValueMightBeTimeVarying() or mesh.GetVelocitiesAttr().HasAuthoredValue():
        # UsdGeom holds the frame's points where the samples' counts differ: say so.
        counts = {len(attr.Get(t) or []) for t in times}
        if len(counts) != 1:
            return None, f"its point count changes over the shutter ({min(counts)} to {max(counts)})"
        computed = mesh.ComputePointsAtTimes(times, base)
        if not computed or len(computed) != len(times):
            return None, "its points cannot be computed over the shutter"
        keys = [np.asarray(k, np.float64).reshape(-1, 3) for k in computed]
    else:
        return None, None
    counts = {len(k) for k in keys}
    if len(counts) != 1:
        return None, f"its point count changes over the shutter ({min(counts)} to {max(counts)})"
    if any(not np.isfinite(k).all() for k in keys):
        return None, "its points over the shutter are not finite"
    if all(np.array_equal(k, keys[0]) for k in keys[1:]):
        return None, None
    return keys, None
