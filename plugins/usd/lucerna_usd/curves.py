"""UsdGeom.BasisCurves as round tubes: hair, fur, wires and cables.

Each curve is evaluated to a polyline (linear curves are their points; cubic bezier,
bspline and catmullRom curves are sampled SAMPLES times a segment with USD's basis
matrices, periodic wrap closing the loop), and a tube of SIDES sides is swept along it with
the curve's width (constant, uniform, varying or vertex `widths`; USD's fallback width is
1) as diameter, normals pointing radially so it shades round. Tubes are view-independent,
unlike camera-facing ribbons, so any camera sees the same hair. The whole prim is
vectorised: a million segments take seconds, not minutes.

Not supported (warned): hermite basis (a HermiteCurves prim is skipped by the converter),
`normals` (oriented ribbons: rendered as tubes), per-curve `type` changes."""

import numpy as np
from pxr import UsdGeom

#: Sides of a tube: a square section is enough for pixel-thin hair and keeps a million
#: segments at eight million triangles; wider curves (cables, wires: the widest at least
#: THICK of the prim's size) get a round section of ROUND_SIDES.
SIDES = 4
ROUND_SIDES = 12
THICK = 0.05
#: Polyline points a cubic segment is sampled at (its end is the next one's start).
SAMPLES = 4

#: Cubic bases as USD defines them (UsdGeomBasisCurves), rows = coefficients of
#: (1, t, t², t³) applied to the segment's four control points.
_BASES = {
    "bezier": np.array([[1, 0, 0, 0], [-3, 3, 0, 0], [3, -6, 3, 0], [-1, 3, -3, 1]], float),
    "bspline": np.array([[1, 4, 1, 0], [-3, 0, 3, 0], [3, -6, 3, 0], [-1, 3, -3, 1]], float) / 6.0,
    "catmullRom": np.array([[0, 2, 0, 0], [-1, 0, 1, 0], [2, -5, 4, -1], [-1, 3, -3, 1]], float) / 2.0,
}
#: Control points a segment steps over.
_STEP = {"bezier": 3, "bspline": 1, "catmullRom": 1}


def tessellate(curves, time, warn, colors=None):
    """(positions, triangles, normals, colors) of the tubes of a BasisCurves prim, or a
    reason it has none. `colors` (per control point, RGB) are carried along the curves."""
    path = str(curves.GetPath())
    points = np.asarray(curves.GetPointsAttr().Get(time) or [], np.float64).reshape(-1, 3)
    counts = np.asarray(curves.GetCurveVertexCountsAttr().Get(time) or [], np.int64)
    if not len(points) or not len(counts):
        return "no points or no curves"
    if (counts < 0).any() or counts.sum() != len(points):
        return f"curveVertexCounts sum to {int(counts.sum())} but there are {len(points)} points"
    if not np.isfinite(points).all():
        return "points are NaN or infinite"
    kind = curves.GetTypeAttr().Get(time) or "cubic"
    basis = curves.GetBasisAttr().Get(time) or "bezier"
    wrap = curves.GetWrapAttr().Get(time) or "nonperiodic"
    if kind == "cubic" and basis not in _BASES:
        warn(path, f"basis {basis!r} is not supported: the curves are drawn through their points")
        kind = "linear"
    if curves.GetNormalsAttr().HasAuthoredValue():
        warn(path, "curve normals (oriented ribbons) are not read: rendered as round tubes")
    widths = _widths(curves, time, counts, len(points), warn)
    # Values swept along with the points: width, then colour.
    values = widths[:, None] if colors is None else np.concatenate([widths[:, None], colors], 1)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    periodic = wrap == "periodic"
    if kind == "linear":
        line_points, line_values, line_counts = _linear(points, values, counts, starts, periodic)
    else:
        if wrap == "pinned" and basis != "bezier":
            warn(path, "pinned wrap is drawn as nonperiodic")
        line_points, line_values, line_counts = _cubic(points, values, counts, starts, basis, periodic)
    if not len(line_counts):
        return "no curve has enough points for a segment"
    sides = sides_for(widths, points)
    positions, triangles, normals = _tubes(line_points, np.maximum(line_values[:, 0], 0.0),
                                           line_counts, sides)
    tube_colors = None
    if colors is not None:
        tube_colors = np.concatenate([np.repeat(line_values[:, 1:4], sides, axis=0),
                                      np.ones((len(positions), 1))], 1)
    return positions, triangles, normals, tube_colors


def sides_for(widths, points):
    """The sides of a prim's tubes: SIDES for hair-thin curves, ROUND_SIDES for thick ones."""
    size = np.linalg.norm(points.max(axis=0) - points.min(axis=0))
    return ROUND_SIDES if widths.max(initial=0.0) >= THICK * size else SIDES


def _widths(curves, time, counts, n, warn):
    """Per-control-point widths (uniform values repeated over their curve's points)."""
    path = str(curves.GetPath())
    w = np.asarray(curves.GetWidthsAttr().Get(time) or [], np.float64)
    interpolation = curves.GetWidthsInterpolation()
    pv = UsdGeom.PrimvarsAPI(curves).GetPrimvar("widths")
    if pv and pv.HasAuthoredValue():
        w = np.asarray(pv.ComputeFlattened(time), np.float64)
        interpolation = pv.GetInterpolation()
    if not len(w):
        return np.ones(n)
    if interpolation == UsdGeom.Tokens.constant or len(w) == 1:
        return np.full(n, w[0])
    if interpolation == UsdGeom.Tokens.uniform and len(w) >= len(counts):
        return np.repeat(w[:len(counts)], counts)
    if len(w) >= n:
        return w[:n]
    if interpolation == UsdGeom.Tokens.varying:
        # One width per segment end (fewer than the control points of cubic curves):
        # spread each curve's values over its points.
        out = np.empty(n)
        at, start = 0, 0
        for c in counts:
            k = max(min(len(w) - at, c), 1)
            values = w[at:at + k] if at < len(w) else np.ones(1)
            out[start:start + c] = np.interp(np.linspace(0, 1, c), np.linspace(0, 1, len(values)), values)
            at += k
            start += c
        return out
    warn(path, f"{len(w)} widths are too few for {interpolation} interpolation: width 1 is used")
    return np.ones(n)


def _linear(points, values, counts, starts, periodic):
    keep = counts >= 2
    index = np.concatenate([np.arange(s, s + c) for s, c in zip(starts[keep], counts[keep])]) \
        if keep.any() else np.zeros(0, np.int64)
    line_counts = counts[keep]
    if periodic and keep.any():
        # Close each loop by repeating its first point.
        ends = np.cumsum(line_counts)
        index = np.insert(index, ends, index[ends - line_counts])
        line_counts = line_counts + 1
    return points[index], values[index], line_counts


def _cubic(points, values, counts, starts, basis, periodic):
    """Samples cubic segments: each curve's segments (every _STEP points, four control
    points each, wrapping around when periodic) at SAMPLES parameters, plus its end."""
    step = _STEP[basis]
    if periodic:
        segments = np.where(counts >= 4, counts // step, 0)
    else:
        segments = np.where(counts >= 4, (counts - 4) // step + 1, 0)
    keep = segments > 0
    if not keep.any():
        return np.zeros((0, 3)), np.zeros((0, values.shape[1])), np.zeros(0, np.int64)
    counts, starts, segments = counts[keep], starts[keep], segments[keep]
    curve_of_segment = np.repeat(np.arange(len(counts)), segments)
    k = np.arange(segments.sum()) - np.repeat(np.cumsum(segments) - segments, segments)
    local = k[:, None] * step + np.arange(4)[None, :]
    local = local % counts[curve_of_segment][:, None]  # periodic wrap (no-op otherwise)
    control = starts[curve_of_segment][:, None] + local  # (S, 4)
    t = np.arange(SAMPLES) / SAMPLES
    powers = np.stack([np.ones_like(t), t, t * t, t * t * t], 1)  # (K, 4)
    weights = powers @ _BASES[basis]  # (K, 4): weight of each control point
    sampled = np.einsum("kc,scd->skd", weights, points[control])  # (S, K, 3)
    sampled_v = np.einsum("kc,scv->skv", weights, values[control])
    # Each curve's end: t = 1 of its last segment.
    end_weights = np.array([1.0, 1.0, 1.0, 1.0]) @ _BASES[basis]
    last = np.cumsum(segments) - 1
    end_points = np.einsum("c,scd->sd", end_weights, points[control[last]])
    end_v = np.einsum("c,scv->sv", end_weights, values[control[last]])
    per_curve = segments * SAMPLES
    line_points = np.empty((per_curve.sum() + len(counts), 3))
    line_values = np.empty((len(line_points), values.shape[1]))
    line_counts = per_curve + 1
    offsets = np.concatenate([[0], np.cumsum(line_counts)[:-1]])
    body = np.delete(np.arange(len(line_points)), offsets + per_curve)
    line_points[body] = sampled.reshape(-1, 3)
    line_values[body] = sampled_v.reshape(-1, values.shape[1])
    line_points[offsets + per_curve] = end_points
    line_values[offsets + per_curve] = end_v
    return line_points, line_values, line_counts


def _tubes(points, widths, counts, sides):
    """Tubes of `sides` sides along polylines (`counts` points each)."""
    n = len(points)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    curve = np.repeat(np.arange(len(counts)), counts)
    # Tangents: central differences inside a curve, one-sided at its ends.
    nxt = np.minimum(np.arange(n) + 1, np.repeat(starts + counts - 1, counts))
    prv = np.maximum(np.arange(n) - 1, np.repeat(starts, counts))
    tangent = points[nxt] - points[prv]
    length = np.linalg.norm(tangent, axis=1, keepdims=True)
    overall = points[starts + counts - 1] - points[starts]
    tangent = np.where(length > 0, tangent / np.maximum(length, 1e-30), overall[curve])
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-30)
    # One reference axis per curve (the one least along it): frames that do not flip.
    direction = np.abs(overall) / np.maximum(np.linalg.norm(overall, axis=1, keepdims=True), 1e-30)
    axis = np.eye(3)[np.argmin(direction, axis=1)][curve]
    u = np.cross(tangent, axis)
    u_len = np.linalg.norm(u, axis=1, keepdims=True)
    fallback = np.cross(tangent, np.eye(3)[np.argmin(np.abs(tangent), axis=1)])
    u = np.where(u_len > 1e-6, u / np.maximum(u_len, 1e-30), fallback)
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-30)
    v = np.cross(tangent, u)
    # The rings in single precision (what the scene file stores): half the memory.
    angles = 2 * np.pi * np.arange(sides) / sides
    cos, sin = np.cos(angles).astype(np.float32), np.sin(angles).astype(np.float32)
    u, v = u.astype(np.float32), v.astype(np.float32)
    radial = cos[None, :, None] * u[:, None, :] + sin[None, :, None] * v[:, None, :]
    positions = points.astype(np.float32)[:, None, :] + radial * (widths.astype(np.float32)[:, None, None] / 2)
    # Two triangles per side per segment (counter-clockwise seen from outside).
    segment = np.ones(n, bool)
    segment[starts + counts - 1] = False
    a = np.flatnonzero(segment).astype(np.uint32)
    s = np.arange(sides, dtype=np.uint32)
    s1 = (s + 1) % sides
    i00 = a[:, None] * sides + s[None, :]
    i01 = a[:, None] * sides + s1[None, :]
    i10 = (a + 1)[:, None] * sides + s[None, :]
    i11 = (a + 1)[:, None] * sides + s1[None, :]
    triangles = np.concatenate([np.stack([i00, i01, i11], -1).reshape(-1, 3),
                                np.stack([i00, i11, i10], -1).reshape(-1, 3)]).astype(np.uint32)
    return positions.reshape(-1, 3), triangles, radial.reshape(-1, 3)
