"""UsdGeom.Mesh to triangle meshes: fan triangulation of polygons (as Hydra does), holes,
orientation, and primvars of every interpolation (constant, uniform, vertex, varying,
faceVarying; indexed or not). Corners are welded where all their attributes agree, so a
mesh with only vertex primvars keeps one vertex per point.

A subdivision mesh (any subdivisionScheme but none) also gives its control cage with its
creases, corners and boundary rule (`Cage`): lucerna refines it to the limit surface when
it renders (src/geometry/subdivision.rs); the triangulated cage is its placeholder."""

import numpy as np
from pxr import UsdGeom

_ORDER = {UsdGeom.Tokens.constant: "constant", UsdGeom.Tokens.uniform: "uniform",
          UsdGeom.Tokens.vertex: "vertex", UsdGeom.Tokens.varying: "vertex",
          UsdGeom.Tokens.faceVarying: "faceVarying"}


_BOUNDARY = {"edgeAndCorner": "edge_and_corner", "edgeOnly": "edge_only"}


class Cage:
    """A subdivision surface's control cage, as the scene file carries it."""

    def __init__(self, scheme, boundary, points, counts, indices, keep):
        self.scheme = scheme
        self.boundary = boundary
        self.points = points
        self.counts = counts
        self.indices = indices
        self.keep = keep
        self.creases = np.zeros((0, 2), np.int64)
        self.crease_sharpness = np.zeros(0)
        self.corners = np.zeros(0, np.int64)
        self.corner_sharpness = np.zeros(0)
        self.uvs = None
        self.colors = None
        # The points at the shutter's keys, where the cage deforms over it.
        self.point_keys = None


class MeshData:
    """A mesh's topology, triangulated, with its primvars read on demand."""

    def __init__(self, mesh, time, warn, points, counts, indices, face_keep, deformed=False):
        self.mesh = mesh
        self.deformed = deformed
        self.counts = counts
        self.face_keep = face_keep
        self.time = time
        self.warn = warn
        self.path = str(mesh.GetPath())
        self.points = points
        self.indices = indices
        self.face_count = len(counts)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        self.face_of_corner = np.repeat(np.arange(len(counts)), counts)
        # Fan triangulation in corner space: (s, s + k + 1, s + k + 2), k = 0 .. n - 3.
        ntri = np.where(face_keep, np.maximum(counts - 2, 0), 0)
        self.face_of_triangle = np.repeat(np.arange(len(counts)), ntri)
        first = np.repeat(starts, ntri)
        k = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri)
        self.corner_triangles = np.stack([first, first + k + 1, first + k + 2], 1)
        if mesh.GetOrientationAttr().Get(time) == UsdGeom.Tokens.leftHanded:
            self.corner_triangles = self.corner_triangles[:, [0, 2, 1]]

    @classmethod
    def read(cls, mesh, time, warn, deform=None):
        """The mesh's topology, or None (with a warning) if it cannot be used. `deform(prim,
        points)` gives the points at the time when something deforms them (UsdSkel)."""
        path = str(mesh.GetPath())
        points = np.asarray(mesh.GetPointsAttr().Get(time) or [], dtype=np.float64).reshape(-1, 3)
        rest = points
        if deform is not None and len(points):
            points = deform(mesh.GetPrim(), points)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(time) or [], dtype=np.int64)
        indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(time) or [], dtype=np.int64)
        if not len(points) or not len(counts):
            warn(path, "mesh has no points or no faces: skipped")
            return None
        if (counts < 0).any() or counts.sum() != len(indices):
            warn(path, f"faceVertexCounts sum to {int(counts[counts > 0].sum())} but there are "
                 f"{len(indices)} faceVertexIndices: mesh skipped")
            return None
        if ((indices < 0) | (indices >= len(points))).any():
            bad = int(((indices < 0) | (indices >= len(points))).sum())
            warn(path, f"{bad} faceVertexIndices out of range (the mesh has {len(points)} "
                 "points): mesh skipped")
            return None
        keep = counts >= 3
        if not keep.all():
            warn(path, f"{int((~keep).sum())} faces with fewer than 3 vertices skipped")
        holes = np.asarray(mesh.GetHoleIndicesAttr().Get(time) or [], dtype=np.int64)
        holes = holes[(holes >= 0) & (holes < len(counts))]
        keep[holes] = False
        face_of_corner = np.repeat(np.arange(len(counts)), counts)
        finite = np.isfinite(points).all(axis=1)
        if not finite.all():
            broken = np.zeros(len(counts), bool)
            broken[face_of_corner[~finite[indices]]] = True
            warn(path, f"{int((~finite).sum())} points are NaN or infinite: "
                 f"{int((broken & keep).sum())} faces touching them skipped")
            keep &= ~broken
        _check_manifold(path, counts, indices, warn)
        if not keep.any():
            warn(path, "mesh has no usable faces: skipped")
            return None
        return cls(mesh, time, warn, points, counts, indices, keep, deformed=points is not rest)

    def _primvar(self, name, width):
        """A primvar's values per corner, (corners, width) float64, or None."""
        api = UsdGeom.PrimvarsAPI(self.mesh)
        pv = api.GetPrimvar(name)
        if pv and pv.HasAuthoredValue():
            values = pv.ComputeFlattened(self.time)
            interpolation = pv.GetInterpolation()
        elif name == "normals" and self.mesh.GetNormalsAttr().HasAuthoredValue():
            values = self.mesh.GetNormalsAttr().Get(self.time)
            interpolation = self.mesh.GetNormalsInterpolation()
        else:
            return None
        if values is None or not len(values):
            return None
        values = np.asarray(values, dtype=np.float64).reshape(len(values), -1)[:, :width]
        n = len(values)
        mode = _ORDER.get(interpolation, "vertex")
        corners = len(self.indices)
        if mode == "constant":
            per_corner = np.broadcast_to(values[0], (corners, values.shape[1]))
        elif mode == "uniform" and n >= self.face_count:
            per_corner = values[self.face_of_corner]
        elif mode == "vertex" and n >= len(self.points):
            per_corner = values[self.indices]
        elif mode == "faceVarying" and n >= corners:
            per_corner = values[:corners]
        else:
            self.warn(self.path, f"primvar {name!r} has {n} values, too few for "
                      f"{interpolation} interpolation: ignored")
            return None
        if not np.isfinite(per_corner).all():
            self.warn(self.path, f"primvar {name!r} has NaN or infinite values: ignored")
            return None
        return per_corner

    def subdivided(self):
        """Whether the mesh is a subdivision surface (any subdivisionScheme but none;
        catmullClark is USD's default)."""
        scheme = self.mesh.GetSubdivisionSchemeAttr().Get(self.time) or "catmullClark"
        return scheme != "none"

    def _smooth_normals(self, points=None):
        """Per-corner smooth normals: the area-weighted mean of the faces around each point
        (a subdivision cage's placeholder, whose authored normals USD ignores, and a
        deformed mesh, whose authored normals are the rest pose's), of the mesh's points or
        of `points` (the same count). None for flat shading."""
        points = self.points if points is None else points
        tri_points = self.indices[self.corner_triangles]
        p = points[tri_points]
        # Each polygon's area vector (the sum over its fan, outward: corner_triangles are
        # wound counter-clockwise already) goes once to every point it has; faces on NaN
        # points (skipped by read) weigh nothing.
        tri = np.nan_to_num(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), nan=0.0, posinf=0.0, neginf=0.0)
        faces = np.stack([np.bincount(self.face_of_triangle, tri[:, k], self.face_count)
                          for k in range(3)], 1)
        per_corner = faces[self.face_of_corner]
        normals = np.stack([np.bincount(self.indices, per_corner[:, k], len(points))
                            for k in range(3)], 1)
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        if (length[self.indices] == 0).any():
            return None  # a corner with no area around its point: flat shading
        return normals[self.indices] / length[self.indices]

    def cage(self, face_mask, st_name, color_primvar, name, keys=None):
        """The subdivision cage (Cage) whose faces in `face_mask` this part renders: faces of
        fewer than 3 points and faces on NaN points leave the topology; holes and the other
        parts' faces stay in it (they shape the surface) but are not rendered. `keys`: the
        points at the shutter's keys, where they move."""
        mesh, time = self.mesh, self.time
        scheme = mesh.GetSubdivisionSchemeAttr().Get(time) or "catmullClark"
        counts = self.counts
        finite = np.isfinite(self.points).all(axis=1)
        usable = counts >= 3
        if not finite.all():
            usable &= np.bincount(self.face_of_corner, ~finite[self.indices], len(counts)) == 0
        corner_usable = usable[self.face_of_corner]
        scheme = {"catmullClark": "catmull_clark", "loop": "loop", "bilinear": "bilinear"}.get(scheme)
        if scheme is None:
            self.warn(name, f"subdivisionScheme {mesh.GetSubdivisionSchemeAttr().Get(time)!r} "
                      "is unknown: catmullClark is used")
            scheme = "catmull_clark"
        if scheme == "loop" and (counts[usable] != 3).any():
            self.warn(name, "loop subdivision needs triangles: catmullClark is used")
            scheme = "catmull_clark"
        boundary = str(mesh.GetInterpolateBoundaryAttr().Get(time) or "edgeAndCorner")
        if boundary not in _BOUNDARY:
            self.warn(name, f"interpolateBoundary {boundary!r} is rendered as edgeAndCorner")
        fvli = mesh.GetFaceVaryingLinearInterpolationAttr().Get(time) or "cornersPlus1"
        indices = self.indices[corner_usable]
        face_counts = counts[usable]
        left = mesh.GetOrientationAttr().Get(time) == UsdGeom.Tokens.leftHanded
        # Corner order: each face's corners, reversed for a left-handed mesh (lucerna's
        # faces are counter-clockwise).
        order = np.flatnonzero(corner_usable)
        if left:
            starts = np.concatenate([[0], np.cumsum(face_counts)[:-1]])
            within = np.arange(len(order)) - np.repeat(starts, face_counts)
            flipped = np.repeat(starts + face_counts - 1, face_counts) - within
            order = order[flipped]
            indices = self.indices[order]
        # Points no usable face uses may be NaN (read() warned): zero them for the file.
        points = np.where(finite[:, None], self.points, 0.0)
        c = Cage(scheme, _BOUNDARY.get(boundary, "edge_and_corner"), points, face_counts,
                 indices, (face_mask & self.face_keep)[usable])
        c.point_keys = keys
        crease_indices = np.asarray(mesh.GetCreaseIndicesAttr().Get(time) or [], np.int64)
        lengths = np.asarray(mesh.GetCreaseLengthsAttr().Get(time) or [], np.int64)
        sharpness = np.asarray(mesh.GetCreaseSharpnessesAttr().Get(time) or [], np.float64)
        if len(lengths) and lengths.sum() == len(crease_indices) and (lengths >= 2).all():
            starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
            a = np.concatenate([crease_indices[s:s + n - 1] for s, n in zip(starts, lengths)])
            b = np.concatenate([crease_indices[s + 1:s + n] for s, n in zip(starts, lengths)])
            if len(sharpness) == len(lengths):
                per_edge = np.repeat(sharpness, lengths - 1)
            elif len(sharpness) == len(a):
                per_edge = sharpness
            else:
                per_edge = None
                self.warn(name, f"{len(sharpness)} creaseSharpnesses for {len(lengths)} creases: "
                          "creases ignored")
            if per_edge is not None:
                ok = (a < len(self.points)) & (b < len(self.points)) & (a >= 0) & (b >= 0)
                c.creases = np.stack([a[ok], b[ok]], 1)
                c.crease_sharpness = np.clip(np.nan_to_num(per_edge[ok]), 0.0, None)
        elif len(crease_indices):
            self.warn(name, "creaseLengths do not match creaseIndices: creases ignored")
        corners = np.asarray(mesh.GetCornerIndicesAttr().Get(time) or [], np.int64)
        corner_sharpness = np.asarray(mesh.GetCornerSharpnessesAttr().Get(time) or [], np.float64)
        if len(corners) and len(corner_sharpness) == len(corners):
            ok = (corners >= 0) & (corners < len(self.points))
            c.corners = corners[ok]
            c.corner_sharpness = np.clip(np.nan_to_num(corner_sharpness[ok]), 0.0, None)
        uvs = self._primvar(st_name, 2) if st_name else None
        if uvs is not None:
            uvs = uvs[order]
            c.uvs = np.stack([uvs[:, 0], 1.0 - uvs[:, 1]], 1)
            if fvli not in ("all", "none"):
                self.warn(name, f"faceVaryingLinearInterpolation {fvli!r}: texture coordinates "
                          "are interpolated linearly within each face (as 'all')")
        colors = self._primvar(color_primvar, 3) if color_primvar else None
        if colors is not None:
            c.colors = np.concatenate([colors[order], np.ones((len(order), 1))], 1)
        return c

    def build(self, face_mask, st_name, color_primvar, name, keys=None):
        """(positions, triangles, normals, uvs, colors, deformation) of the faces in
        `face_mask`, welded, or None when no triangle is left. With `keys` (the points at the
        shutter's keys), the deformation is (positions, normals) at each key, normals None
        where the mesh keeps its authored ones; else None."""
        tri = self.corner_triangles[face_mask[self.face_of_triangle]]
        if not len(tri):
            return None
        normals = None if self.deformed or self.subdivided() else self._primvar("normals", 3)
        smooth = normals is None and (self.deformed or self.subdivided())
        if smooth:
            normals = self._smooth_normals()
        uvs = self._primvar(st_name, 2) if st_name else None
        if st_name and uvs is None:
            self.warn(name, f"the material reads primvar {st_name!r}, which the mesh lacks: "
                      "textures are sampled at (0, 0)")
        colors = self._primvar(color_primvar, 3) if color_primvar else None
        columns = [self.indices[:, None].astype(np.float64)]
        columns += [a for a in (normals, uvs, colors) if a is not None]
        key = np.ascontiguousarray(np.concatenate(columns, 1))
        used = _sorted_unique(tri.ravel())
        corners, remap = self._weld_by_point(used, key)
        if corners is None:
            # Some point has corners that differ (a UV seam, split normals): weld equal rows.
            rows = key[used]
            unique, first, inverse = np.unique(
                rows.view(np.dtype((np.void, rows.dtype.itemsize * rows.shape[1]))).ravel(),
                return_index=True, return_inverse=True)
            remap = np.empty(len(key), np.int64)
            remap[used] = inverse.ravel()
            corners = used[first]
        triangles = remap[tri].astype(np.uint32)
        positions = self.points[self.indices[corners]]
        out_normals = None
        if normals is not None:
            n = normals[corners]
            length = np.linalg.norm(n, axis=1, keepdims=True)
            zero = int((length == 0).sum())
            if zero:
                self.warn(name, f"{zero} zero-length normals: the mesh is flat-shaded")
            else:
                out_normals = n / length
        out_uvs = None
        if uvs is not None:
            out_uvs = np.stack([uvs[corners, 0], 1.0 - uvs[corners, 1]], 1)
        out_colors = None
        if colors is not None:
            out_colors = np.concatenate([colors[corners], np.ones((len(corners), 1))], 1)
        deformation = None
        if keys is not None:
            point_of_vertex = self.indices[corners]
            key_normals = None
            if out_normals is not None and smooth:
                key_normals = []
                for k in keys:
                    n = self._smooth_normals(k)
                    if n is None:
                        key_normals = None
                        break
                    key_normals.append(n[corners])
            deformation = ([k[point_of_vertex] for k in keys], key_normals)
        return positions, triangles, out_normals, out_uvs, out_colors, deformation


    def _weld_by_point(self, used, key):
        """When every point's corners carry equal attributes (per-vertex data, or face-
        varying data indexed like the points), one vertex per point: (representative corner
        per vertex, corner -> vertex), found by integer sorts alone. (None, None) otherwise."""
        points = self.indices[used]
        first_corner = np.empty(len(self.points), np.int64)
        first_corner[points[::-1]] = used[::-1]
        if not np.array_equal(key[used], key[first_corner[points]]):
            return None, None
        unique_points = _sorted_unique(points)
        vertex_of_point = np.empty(len(self.points), np.int64)
        vertex_of_point[unique_points] = np.arange(len(unique_points))
        remap = np.empty(len(key), np.int64)
        remap[used] = vertex_of_point[points]
        return first_corner[unique_points], remap


def _sorted_unique(values):
    """np.unique of integers by one sort (numpy's hashing unique is several times slower on
    millions of indices)."""
    s = np.sort(values)
    return s[np.concatenate([[True], s[1:] != s[:-1]])] if len(s) else s


def _check_manifold(path, counts, indices, warn):
    """Warns about edges shared by more than two faces (the renderer does not need a
    manifold, but such meshes are usually broken exports)."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    nxt = np.arange(len(indices)) + 1
    ends = np.repeat(starts + counts, counts)
    nxt = np.where(nxt == ends, np.repeat(starts, counts), nxt)
    a, b = indices.astype(np.int64), indices[nxt].astype(np.int64)
    # One integer per undirected edge; an edge in more than two faces repeats 3+ times.
    edges = np.sort(np.minimum(a, b) * (int(indices.max(initial=0)) + 1) + np.maximum(a, b))
    over = len(_sorted_unique(edges[2:][edges[2:] == edges[:-2]]))
    if over:
        warn(path, f"non-manifold: {over} edges are shared by more than two faces")
