"""The composed stage to lucerna's scene.

Traversal: active, loaded, defined prims (usd-core's default predicate); `visibility`
invisible prunes a subtree; `purpose` default is rendered, and of render, proxy and guide
those asked for (render by default; `--purpose`). Every prim yields *groups*: what it contains (meshes, spheres, lights, cameras)
with one transform per placement, relative to the prim. A parent applies its children's
local transforms (time-sampled, at the frame) to their groups, so a prototype (a
scene-graph instance's, or a PointInstancer's) is converted once and placed many times:
its meshes are stored once and instanced.

Stage space to lucerna's: Z-up stages are turned to Y up, and metersPerUnit scales to
metres (lucerna's world unit, as glTF's). Texture coordinates flip v (USD's t grows
upwards, glTF's v downwards).
"""

import math

import numpy as np
from pxr import Usd, UsdGeom, UsdLux, UsdShade, UsdSkel, UsdVol

from . import curves, lights, motion, volumes
from .materials import MaterialConverter
from .mesh import MeshData
from .skel import Skinning
from .scene_file import SceneWriter, matrix, mean_scale

# Implicit gprims rendered as meshes or spheres; other gprims are reported and skipped.
def _authored(shader, name):
    """True where UsdShade.Shader `shader` authors input `name`."""
    shader_input = shader.GetInput(name)
    return bool(shader_input) and shader_input.GetAttr().HasAuthoredValue()


def _fields(volume):
    """The fields of UsdVol.Volume `volume` as `name: file[field]` for a message."""
    described = []
    for name, target in sorted(UsdVol.Volume(volume).GetFieldPaths().items()):
        field = volume.GetStage().GetPrimAtPath(target)
        asset = UsdVol.OpenVDBAsset(field) if field and field.IsA(UsdVol.OpenVDBAsset) else None
        if asset:
            path = asset.GetFilePathAttr().Get()
            grid = asset.GetFieldNameAttr().Get()
            described.append(f"{name}: {path.path if path else '?'}[{grid or name}]")
        else:
            described.append(f"{name}: {target}")
    return "fields " + ", ".join(described) if described else "no fields"


_SKIPPED_GPRIMS = (UsdGeom.NurbsCurves, UsdGeom.NurbsPatch, UsdGeom.HermiteCurves, UsdGeom.TetMesh)
#: Implicit gprims tessellated into meshes (Sphere stays analytic, Points become spheres).
_TESSELLATED = (UsdGeom.Cube, UsdGeom.Cylinder, UsdGeom.Cone, UsdGeom.Capsule, UsdGeom.Plane)
#: Segments around the axis of a tessellated cylinder, cone or capsule.
SEGMENTS = 64


class Group:
    """Something a prim contributes, placed by row-vector matrices `mats` (K, 4, 4)
    relative to the prim (or to the world when `absolute`, after a resetXformStack)."""

    __slots__ = ("kind", "payload", "mats", "absolute", "motion")

    def __init__(self, kind, payload, mats=None, absolute=False, motion=None):
        self.kind = kind
        self.payload = payload
        self.mats = np.identity(4)[None] if mats is None else mats
        self.absolute = absolute
        # Where something above moves while the shutter is open: the matrices at each of
        # the shutter's time codes, (S, K, 4, 4).
        self.motion = motion

    def placed(self, local, resets, local_motion=None):
        """This group seen from the parent whose child has `local` transform (and
        `local_motion`, (S, 4, 4), over the shutter where it may move)."""
        if self.absolute:
            return self
        motion = None
        if self.motion is not None or local_motion is not None:
            own = self.motion if self.motion is not None else self.mats[None]
            step = local_motion[:, None] if local_motion is not None else local[None, None]
            motion = own @ step
        return Group(self.kind, self.payload, self.mats @ local, resets, motion)

    def moving(self):
        """The group's matrices over the shutter where they change, else None."""
        if self.motion is None or np.allclose(self.motion, self.motion[:1], rtol=0, atol=1e-12):
            return None
        return self.motion


def _np(m):
    return np.array(m, dtype=np.float64).reshape(4, 4)


def _polygon_area(mesh, time):
    """Total area of a mesh's polygons in stage units (Newell's formula per face)."""
    points = np.asarray(mesh.GetPointsAttr().Get(time) or [], dtype=float)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(time) or [], dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(time) or [], dtype=np.int64)
    if len(points) == 0 or counts.sum() != len(indices) or (indices >= len(points)).any():
        return 0.0
    area, start = 0.0, 0
    for n in counts:
        p = points[indices[start:start + n]]
        start += n
        if n >= 3:
            area += 0.5 * float(np.linalg.norm(np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)))
    return area


def stage_to_lucerna(stage):
    """Row-vector matrix from stage space to lucerna's world (Y up, metres)."""
    m = np.identity(4)
    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z:
        m[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    m[:3, :3] *= UsdGeom.GetStageMetersPerUnit(stage)
    return m


class Converter:
    """Converts one stage at one time code; `warnings` collects what was repaired,
    approximated or skipped, each naming its prim."""

    def __init__(self, stage, source, time, purposes=("render",), shutter_times=None):
        self.stage = stage
        self.time = time
        # The time codes over the open shutter at which transforms are sampled, or None.
        self.shutter_times = shutter_times
        # Purposes rendered besides "default" (UsdGeom's render, proxy, guide).
        self.purposes = set(purposes)
        self.writer = SceneWriter(source)
        self.to_lucerna = stage_to_lucerna(stage)
        self.meters_per_unit = UsdGeom.GetStageMetersPerUnit(stage)
        self.materials = MaterialConverter(self.writer, time, self.warn, self.meters_per_unit)
        self._flat = {}
        self._warned = set()
        self._skel = None
        # Skinning at the shutter's time codes, for deformation blur.
        self._skel_at = {}

    def _skinning(self):
        if self._skel is None:
            self._skel = Skinning(self.stage, self.time, self.warn)
        return self._skel

    def _skinning_at(self, time):
        """Skinning at shutter time code `time`."""
        key = time.GetValue()
        if key not in self._skel_at:
            self._skel_at[key] = Skinning(self.stage, time, self.warn)
        return self._skel_at[key]

    def _point_keys(self, prim, mesh, skinned, data):
        """The mesh's points at the open shutter's time codes where they move (its
        deformation blur), or None."""
        if not self.shutter_times:
            return None
        skinned_points = None
        if skinned:
            def skinned_points(time, rest):
                return self._skinning_at(time).points(prim, rest)
        keys, reason = motion.point_keys(mesh, self.shutter_times, self.time, skinned_points)
        if keys is not None and len(keys[0]) != len(data.points):
            keys, reason = None, (f"its points over the shutter number {len(keys[0])}, "
                                  f"at the frame {len(data.points)}")
        if reason:
            self.warn(str(prim.GetPath()), f"{reason}: it keeps the frame's shape (no deformation blur)")
        return keys

    def warn(self, element, message):
        text = f"{element}: {message}"
        if text not in self._warned:
            self._warned.add(text)
            self.writer.warnings.append(text)

    # ---- traversal -----------------------------------------------------------------
    def run(self):
        groups = self._children(self.stage.GetPseudoRoot().GetFilteredChildren(Usd.PrimDefaultPredicate), None)
        for g in groups:
            world_usd = g.mats
            world = g.mats @ self.to_lucerna
            moving = g.moving()
            world_motion = None if moving is None else moving @ self.to_lucerna
            if moving is not None and g.kind not in ("mesh", "camera"):
                self.warn(self._group_name(g), "moves while the shutter is open: only meshes and "
                          "cameras are blurred, it stays where it is at the frame")
            if g.kind == "mesh":
                mesh, name = g.payload
                self.writer.add_instances(name, mesh, world, world_motion)
            elif g.kind == "sphere":
                radius, material, name = g.payload
                for k, m in enumerate(world):
                    scale, uniform = mean_scale(m[:3, :3])
                    if not uniform:
                        self.warn(name, "non-uniform scale on a Sphere: the mean scale is used")
                    self.writer.spheres.append({
                        "name": name if len(world) == 1 else f"{name}[{k}]",
                        "centre": [float(x) for x in m[3, :3]],
                        "radius": radius * scale, "material": material})
            elif g.kind == "points":
                positions, radii, material, name = g.payload
                for k, m in enumerate(world):
                    scale, uniform = mean_scale(m[:3, :3])
                    if not uniform:
                        self.warn(name, "non-uniform scale on Points: the mean scale is used")
                    centres = positions @ m[:3, :3] + m[3, :3]
                    for i, (centre, radius) in enumerate(zip(centres, radii)):
                        self.writer.spheres.append({
                            "name": f"{name}[{i}]" if len(world) == 1 else f"{name}[{k}][{i}]",
                            "centre": [float(x) for x in centre],
                            "radius": float(radius * scale), "material": material})
            elif g.kind == "volume":
                file, grid, material, name, fields = g.payload
                for k, m in enumerate(world):
                    self.writer.add_volume(name if len(world) == 1 else f"{name}[{k}]", file, grid,
                                           matrix(m), material, fields)
            elif g.kind == "camera":
                for k, m in enumerate(world):
                    keys = None if world_motion is None else world_motion[:, k]
                    self._isolated(g.payload.GetPath(), self._camera, g.payload, m, keys)
            elif g.kind == "light":
                self._isolated(g.payload.GetPath(), lights.convert, self.writer, g.payload,
                               list(world_usd), self.to_lucerna, self.time, self.warn)
        lights.finish_domes(self.writer, self.warn)
        if not (self.writer.instances or self.writer.spheres or self.writer.disks or self.writer.cylinders
                or self.writer.volumes):
            self.warn("stage", "no renderable geometry")
        return self.writer

    def _children(self, children, inherited):
        groups = []
        for child in children:
            local, resets, local_motion = np.identity(4), False, None
            if child.IsA(UsdGeom.Xformable):
                xformable = UsdGeom.Xformable(child)
                local = _np(xformable.GetLocalTransformation(self.time))
                resets = xformable.GetResetXformStack()
                if self.shutter_times and xformable.TransformMightBeTimeVarying():
                    local_motion = np.stack([_np(xformable.GetLocalTransformation(t))
                                             for t in self.shutter_times])
            groups.extend(g.placed(local, resets, local_motion) for g in self._flatten(child, inherited))
        return groups

    def _flatten(self, prim, inherited):
        key = (str(prim.GetPath()), inherited)
        if key not in self._flat:
            self._flat[key] = self._isolated(prim.GetPath(), self._convert_prim, prim, inherited) or []
        return self._flat[key]

    def _isolated(self, path, convert, *args):
        """`convert(*args)`, or None after a warning naming `path` if its data cannot be
        converted (a malformed attribute, an unexpected type): one bad prim costs that prim,
        not the stage, as in husk and usdview."""
        from pxr import Tf

        from . import heartbeat

        heartbeat()
        try:
            return convert(*args)
        except (ValueError, TypeError, IndexError, KeyError, AttributeError, ZeroDivisionError,
                FloatingPointError, OverflowError, Tf.ErrorException) as e:
            reason = " ".join(str(e).split())[:300]
            self.warn(str(path), f"skipped: its data cannot be converted "
                                 f"({type(e).__name__}: {reason})")
            return None

    def _convert_prim(self, prim, inherited):
        path = str(prim.GetPath())
        if prim.IsA(UsdGeom.Imageable):
            imageable = UsdGeom.Imageable(prim)
            if imageable.GetVisibilityAttr().Get(self.time) == UsdGeom.Tokens.invisible:
                return []
            purpose = imageable.GetPurposeAttr().Get()
            if purpose != UsdGeom.Tokens.default_ and purpose not in self.purposes:
                return []
        groups = []
        if prim.IsA(UsdGeom.Mesh):
            meshes = self._mesh(prim, inherited)
            if prim.HasAPI(UsdLux.MeshLightAPI) or prim.HasAPI(UsdLux.LightAPI):
                self._mesh_light(prim, meshes)
            groups += meshes
        elif prim.IsA(UsdGeom.Sphere) or any(prim.IsA(t) for t in _TESSELLATED):
            groups += self._implicit(prim, inherited)
        elif prim.IsA(UsdGeom.Points):
            groups += self._points(prim, inherited)
        elif prim.IsA(UsdGeom.PointInstancer):
            return self._point_instancer(prim, inherited)
        elif prim.IsA(UsdGeom.Camera):
            groups.append(Group("camera", prim))
        elif prim.HasAPI(UsdLux.LightAPI):
            groups.append(Group("light", prim))
        elif prim.IsA(UsdGeom.BasisCurves):
            groups += self._curves(prim, inherited)
        elif prim.IsA(UsdVol.Volume):
            groups += self._volume(prim, inherited)
        elif any(prim.IsA(t) for t in _SKIPPED_GPRIMS):
            self.warn(path, f"{prim.GetTypeName()} is not supported: skipped")
        if prim.IsInstance():
            proto = prim.GetPrototype()
            bound = self._bound_material(prim) or inherited
            return groups + self._children(proto.GetFilteredChildren(Usd.PrimDefaultPredicate), bound)
        return groups + self._children(prim.GetFilteredChildren(Usd.PrimDefaultPredicate), inherited)

    def _mesh_light(self, prim, groups):
        """MeshLightAPI: the mesh's surfaces emit the light's radiance (intensity, exposure,
        colour, temperature; normalize divides by the mesh's area in stage units), over
        what their material reflects. The material's own emission is replaced, not tinted
        (materialSyncMode is not read)."""
        path = str(prim.GetPath())
        radiance = lights.emission(prim, self.time)
        if lights.value(prim, "normalize", self.time, False):
            area = _polygon_area(UsdGeom.Mesh(prim), self.time)
            if area > 0:
                radiance = radiance / area
        for g in groups:
            mesh = self.writer.meshes[g.payload[0]]
            material = dict(self.writer.materials[mesh["material"]])
            material["name"] = f"{material.get('name', path)} (mesh light)"
            material["emissive"] = [float(c) for c in radiance]
            mesh["material"] = self.writer.add_material(material)
        sync = prim.GetAttribute("light:materialSyncMode")
        if sync and sync.HasAuthoredValue():
            self.warn(path, f"light:materialSyncMode {sync.Get()!r} is not read: the mesh emits "
                      "the light's radiance over its material")

    def _volume(self, prim, inherited):
        """A Volume: its density field and the medium of its material (volumes.py), or a
        warning saying why it is skipped."""
        path = str(prim.GetPath())
        bound = self._bound_material(prim) or inherited
        material = UsdShade.Material(self.stage.GetPrimAtPath(bound)) if bound else None
        shader = volumes.volume_shader(material)
        inputs = volumes.shader_inputs(shader, self.time)
        field, reason = volumes.density_field(prim, str(inputs["density_channel"]), self.time)
        if field is None:
            self.warn(path, f"Volume skipped: {reason} ({_fields(prim)})")
            return []
        name = f"{path} ({bound})" if shader else path
        unread = volumes.unread_inputs(shader, self.time)
        if unread:
            self.warn(path, f"standard_volume inputs not read (lucerna reads no transparency): "
                            f"{', '.join(unread)}")
        fields = {}
        colour_channel = str(inputs["scatter_color_channel"] or "")
        if colour_channel:
            colour_field, missing = volumes.density_field(prim, colour_channel, self.time)
            if colour_field is None:
                self.warn(path, f"scatter_color_channel is not read: {missing}")
            elif float(inputs["scatter"]) > 0.0:
                fields["scatter_color"] = colour_field
        glow = None
        channel = volumes.glow_channel(inputs)
        if channel is not None:
            kind, field_name = channel
            glow_field, missing = volumes.density_field(prim, field_name, self.time)
            if glow_field is not None:
                glow = (kind, glow_field)
            elif kind == "emission" or (shader is not None and _authored(shader, "emission_mode")):
                what = "blackbody emission needs a temperature field" if kind == "temperature" \
                    else "the emission channel needs its field"
                self.warn(path, f"{what}: {missing}")
        material = volumes.medium_material(name, inputs, 1.0 / self.meters_per_unit, self.warn,
                                           glowing=glow is not None)
        if glow is not None and {"blackbody", "emission_field"} & set(material["volume"]):
            fields[glow[0]] = glow[1]
        if fields.get("scatter_color") and not any(material["volume"]["scattering"]):
            del fields["scatter_color"]
        index = self.writer.add_material(material)
        return [Group("volume", (field[0], field[1], index, path, fields))]

    def _bound_material(self, prim):
        material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial(UsdShade.Tokens.full)[0]
        return str(material.GetPath()) if material else None

    def _material(self, prim, inherited, double_sided):
        """(index, st primvar, colour primvar) of the material bound to `prim` (a mesh or
        subset), else of the instance's material, else None for the caller's fallback."""
        path = self._bound_material(prim) or inherited
        if path is None:
            return None
        return self.materials.material(UsdShade.Material(self.stage.GetPrimAtPath(path)), double_sided)

    # ---- point instancers ------------------------------------------------------------
    def _point_instancer(self, prim, inherited):
        path = str(prim.GetPath())
        pi = UsdGeom.PointInstancer(prim)
        prototypes = pi.GetPrototypesRel().GetForwardedTargets()
        indices = np.asarray(pi.GetProtoIndicesAttr().Get(self.time) or [], dtype=np.int64)
        bad = (indices < 0) | (indices >= len(prototypes))
        if bad.any():
            self.warn(path, f"{int(bad.sum())} protoIndices out of range (there are "
                      f"{len(prototypes)} prototypes): the PointInstancer is skipped")
            return []
        # The transforms come without the masked instances (invisibleIds, inactiveIds).
        mask = pi.ComputeMaskAtTime(self.time)
        if mask:
            indices = indices[np.asarray(mask, dtype=bool)]
        xforms = pi.ComputeInstanceTransformsAtTime(self.time, self.time)
        if xforms is None or len(xforms) != len(indices):
            self.warn(path, "instance transforms cannot be computed (positions, orientations "
                      "or scales disagree with protoIndices): the PointInstancer is skipped")
            return []
        mats = np.array(xforms, dtype=np.float64).reshape(-1, 4, 4)
        motion = self._instancer_motion(pi, path, len(mats))
        groups = []
        for p, target in enumerate(prototypes):
            proto = self.stage.GetPrimAtPath(target)
            if not proto:
                self.warn(path, f"prototype {target} does not exist")
                continue
            placements = mats[indices == p]
            if not len(placements):
                continue
            for g in self._flatten(proto, inherited):
                if g.absolute:
                    groups.append(g)
                    continue
                combined = (g.mats[None, :, :, :] @ placements[:, None, :, :]).reshape(-1, 4, 4)
                combined_motion = None
                if motion is not None or g.motion is not None:
                    own = g.motion if g.motion is not None else g.mats[None]
                    at = motion[:, indices == p] if motion is not None else placements[None]
                    combined_motion = (own[:, None] @ at[:, :, None]).reshape(
                        max(len(own), len(at)), -1, 4, 4)
                groups.append(Group(g.kind, g.payload, combined, motion=combined_motion))
        return groups

    def _instancer_motion(self, pi, path, count):
        """The instances' transforms at the shutter's time codes, (S, count, 4, 4), where the
        shutter is open: position and orientation samples interpolated, or velocities and
        angular velocities from the frame's samples (UsdGeom's rules). None if closed, or
        (with a warning) where the instances cannot be followed over the shutter."""
        if not self.shutter_times:
            return None
        at_times = pi.ComputeInstanceTransformsAtTimes(self.shutter_times, self.time)
        if at_times is None or len(at_times) != len(self.shutter_times) or any(
                x is None or len(x) != count for x in at_times):
            self.warn(path, "its instances cannot be followed over the shutter (their number "
                      "changes): they are not blurred")
            return None
        return np.array([np.array(x, dtype=np.float64).reshape(-1, 4, 4) for x in at_times])

    # ---- implicit gprims -------------------------------------------------------------
    def _curves(self, prim, inherited):
        """BasisCurves as round tubes (curves.py), with the prim's material or display colour."""
        path = str(prim.GetPath())
        gprim = UsdGeom.Gprim(prim)
        material = self._material(prim, inherited, True)
        colors = None
        if material is None:
            constant = self._constant_display_color(gprim)
            material = self.materials.display_color(constant, True,
                                                    self._constant_display_opacity(gprim))
            if constant is None:
                colors = self._curve_colors(gprim)
        shape = curves.tessellate(UsdGeom.BasisCurves(prim), self.time, self.warn, colors)
        if isinstance(shape, str):
            self.warn(path, f"BasisCurves: {shape}: skipped")
            return []
        positions, triangles, normals, tube_colors = shape
        mesh = self.writer.add_mesh(path, material[0], positions, triangles, normals,
                                    colors=tube_colors)
        return [Group("mesh", (mesh, path))]

    def _curve_colors(self, gprim):
        """displayColor per control point of a curves prim (vertex or varying values, or
        uniform ones repeated over each curve's points), or None."""
        pv = UsdGeom.PrimvarsAPI(gprim).GetPrimvar("displayColor")
        if not (pv and pv.HasAuthoredValue()):
            return None
        values = np.asarray(pv.ComputeFlattened(self.time) or [], np.float64).reshape(-1, 3)
        counts = np.asarray(UsdGeom.BasisCurves(gprim.GetPrim()).GetCurveVertexCountsAttr().Get(self.time) or [], np.int64)
        n = int(counts.sum())
        if pv.GetInterpolation() == UsdGeom.Tokens.uniform and len(values) == len(counts):
            return np.repeat(values, counts, axis=0)
        if len(values) == n and np.isfinite(values).all():
            return values
        self.warn(str(gprim.GetPath()), f"displayColor has {len(values)} values for {n} curve points: not used")
        return None

    def _implicit(self, prim, inherited):
        path = str(prim.GetPath())
        gprim = UsdGeom.Gprim(prim)
        double_sided = bool(gprim.GetDoubleSidedAttr().Get(self.time))
        material = self._material(prim, inherited, double_sided)
        if material is None:
            material = self.materials.display_color(self._constant_display_color(gprim), double_sided,
                                                    self._constant_display_opacity(gprim))
        if prim.IsA(UsdGeom.Sphere):
            radius = float(UsdGeom.Sphere(prim).GetRadiusAttr().Get(self.time))
            return [Group("sphere", (radius, material[0], path))]
        shape = _tessellate(prim, self.time)
        if isinstance(shape, str):
            self.warn(path, f"{prim.GetTypeName()}: {shape}: skipped")
            return []
        corners, triangles, normals = shape
        mesh = self.writer.add_mesh(path, material[0], corners, triangles, normals)
        return [Group("mesh", (mesh, path))]

    def _points(self, prim, inherited):
        """UsdGeom.Points as analytic spheres of diameter `widths` (per point, or one for
        all; 1 where unauthored), in the gprim's material or constant displayColor."""
        path = str(prim.GetPath())
        points = UsdGeom.Points(prim)
        positions = np.asarray(points.GetPointsAttr().Get(self.time) or [], np.float64).reshape(-1, 3)
        widths = np.asarray(points.GetWidthsAttr().Get(self.time) or [1.0], np.float64).ravel()
        if len(widths) not in (1, len(positions)):
            self.warn(path, f"{len(widths)} widths for {len(positions)} points: the first is used for all")
            widths = widths[:1]
        radii = np.broadcast_to(widths / 2, (len(positions),))
        keep = np.isfinite(positions).all(axis=1) & np.isfinite(radii) & (radii > 0)
        if not keep.all():
            self.warn(path, f"{int((~keep).sum())} points with NaN positions or non-positive widths: skipped")
        if not keep.any():
            return []
        material = self._material(prim, inherited, False)
        if material is None:
            color = self._constant_display_color(points)
            if color is None:
                self.warn(path, "per-point displayColor is not supported on points: white is used")
            material = self.materials.display_color(color, False, self._constant_display_opacity(points))
        return [Group("points", (positions[keep], np.ascontiguousarray(radii[keep]), material[0], path))]

    def _constant_display_opacity(self, gprim):
        pv = gprim.GetDisplayOpacityPrimvar()
        if pv and pv.HasAuthoredValue() and pv.GetInterpolation() == UsdGeom.Tokens.constant:
            values = pv.ComputeFlattened(self.time)
            if values:
                return values[0]
        return None

    def _constant_display_color(self, gprim):
        pv = gprim.GetDisplayColorPrimvar()
        if pv and pv.HasAuthoredValue() and pv.GetInterpolation() == UsdGeom.Tokens.constant:
            values = pv.ComputeFlattened(self.time)
            if values:
                return values[0]
        return None

    # ---- cameras ---------------------------------------------------------------------
    @staticmethod
    def _group_name(g):
        """The prim a group of a sphere, points, volume or light comes from, for a message."""
        payload = g.payload
        if hasattr(payload, "GetPath"):
            return str(payload.GetPath())
        return next((str(x) for x in reversed(payload) if isinstance(x, str)), "stage")

    def _camera(self, prim, world, motion=None):
        path = str(prim.GetPath())
        cam = UsdGeom.Camera(prim).GetCamera(self.time)
        h_ap, v_ap = cam.horizontalAperture, cam.verticalAperture
        if h_ap <= 0 or v_ap <= 0 or cam.focalLength <= 0:
            self.warn(path, "camera with a zero aperture or focal length: skipped")
            return
        if cam.horizontalApertureOffset or cam.verticalApertureOffset:
            self.warn(path, "aperture offsets (lens shift) are not supported and are ignored")
        mpu = self.meters_per_unit
        if cam.projection == cam.Orthographic:
            # Orthographic apertures are in tenths of a scene unit.
            projection = {"orthographic": {"xmag": h_ap * 0.1 * mpu / 2, "ymag": v_ap * 0.1 * mpu / 2}}
        else:
            projection = {"perspective": {"yfov": 2 * math.atan(v_ap / (2 * cam.focalLength)),
                                          "aspect": h_ap / v_ap}}
        def unscaled(m):
            m = np.array(m, dtype=np.float64)
            m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=1, keepdims=True)
            return m

        transform = unscaled(world)
        near, far = cam.clippingRange.min, cam.clippingRange.max
        aperture = cam.focalLength * 0.1 / (2 * cam.fStop) * mpu if cam.fStop > 0 else 0.0
        self.writer.cameras.append({
            "name": path,
            "projection": projection,
            "transform": matrix(transform),
            "aperture_radius": aperture,
            "focus_distance": cam.focusDistance * mpu if cam.focusDistance > 0 else 1.0,
            "clip_near": max(near, 0.0) * mpu,
            "clip_far": far * mpu if math.isfinite(far) and far > near else None,
            # USD's default aspectRatioConformPolicy: the whole aperture stays in view.
            "fit": "expand_aperture",
        })
        if motion is not None:
            self.writer.cameras[-1]["motion"] = [matrix(unscaled(m)) for m in motion]

    # ---- meshes ----------------------------------------------------------------------
    def _mesh(self, prim, inherited):
        path = str(prim.GetPath())
        mesh = UsdGeom.Mesh(prim)
        double_sided = bool(mesh.GetDoubleSidedAttr().Get(self.time))
        skinned = (prim.HasAPI(UsdSkel.BindingAPI) or prim.HasAttribute("primvars:skel:jointIndices")
                   or prim.HasAttribute("skel:blendShapes"))
        deform = self._skinning().points if skinned else None
        data = MeshData.read(mesh, self.time, self.warn, deform)
        if data is None:
            return []
        keys = self._point_keys(prim, mesh, skinned, data)
        subdivided = data.subdivided()
        if (subdivided and not mesh.GetSubdivisionSchemeAttr().HasAuthoredValue()
                and (mesh.GetNormalsAttr().HasAuthoredValue()
                     or UsdGeom.PrimvarsAPI(prim).HasPrimvar("normals"))):
            self.warn(path, "subdivisionScheme is not authored, so USD's default catmullClark "
                      "applies and the authored normals are ignored (as in Karma); author "
                      'subdivisionScheme = "none" if it is a polygonal model')
        # Faces by material: GeomSubsets of the materialBind family, then the rest.
        parts = []
        taken = np.zeros(data.face_count, bool)
        for subset in UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets():
            faces = np.asarray(subset.GetIndicesAttr().Get(self.time) or [], dtype=np.int64)
            faces = faces[(faces >= 0) & (faces < data.face_count)]
            if self._bound_material(subset.GetPrim()) is None:
                continue
            mat = self._material(subset.GetPrim(), None, double_sided)
            select = np.zeros(data.face_count, bool)
            select[faces] = True
            select &= ~taken
            taken |= select
            parts.append((f"{path}:{subset.GetPrim().GetName()}", select, mat))
        rest = ~taken
        if rest.any():
            mat = self._material(prim, inherited, double_sided)
            parts.append((path, rest, mat))
        groups = []
        for name, faces, mat in parts:
            if mat is None:
                color = self._constant_display_color(mesh)
                mat = self.materials.display_color(color, double_sided, self._constant_display_opacity(mesh))
                color_primvar = None if color is not None else "displayColor"
                mat = (mat[0], None, color_primvar)
            index, st_name, color_primvar = mat
            built = data.build(faces, st_name, color_primvar, name, None if subdivided else keys)
            if built is None:
                continue
            positions, triangles, normals, uvs, colors, deformation = built
            mesh_index = self.writer.add_mesh(name, index, positions, triangles, normals, uvs,
                                              colors, deformation)
            if subdivided:
                self.writer.add_subdivision(
                    mesh_index, data.cage(faces, st_name, color_primvar, name, keys))
            groups.append(Group("mesh", (mesh_index, name)))
        return groups



def _axis_frame(axis):
    """Columns mapping a shape's local (x, y, z-along-axis) to USD's axes for `axis`."""
    return {"X": np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], float),
            "Y": np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0]], float),
            "Z": np.eye(3)}.get(str(axis), np.eye(3))


def _revolve(profile, axis):
    """A surface of revolution around `axis`: `profile` is a list of (r, z, nr, nz) from the
    bottom up, outward normals; consecutive points at the same place (a rim where the
    normal turns) start a new band. Returns (positions, triangles, normals)."""
    angles = np.linspace(0.0, 2 * np.pi, SEGMENTS + 1)[:-1]
    c, s = np.cos(angles), np.sin(angles)
    positions, normals, triangles = [], [], []
    for r, z, nr, nz in profile:
        positions.append(np.stack([r * c, r * s, np.full_like(c, z)], 1))
        normals.append(np.stack([nr * c, nr * s, np.full_like(c, nz)], 1))
    j = np.arange(SEGMENTS)
    j1 = (j + 1) % SEGMENTS
    for i in range(len(profile) - 1):
        (r0, z0, *_), (r1, z1, *_) = profile[i], profile[i + 1]
        if r0 == r1 and z0 == z1:
            continue
        a, b = i * SEGMENTS + j, (i + 1) * SEGMENTS + j
        a1, b1 = i * SEGMENTS + j1, (i + 1) * SEGMENTS + j1
        triangles += [np.stack([a, a1, b1], 1), np.stack([a, b1, b], 1)]
    frame = _axis_frame(axis)
    positions = np.concatenate(positions) @ frame.T
    normals = np.concatenate(normals) @ frame.T
    return positions, np.concatenate(triangles), normals


def _tessellate(prim, time):
    """(positions, triangles, normals) of an implicit gprim, or a reason it has none."""
    def get(schema, name):
        return float(getattr(schema, f"Get{name}Attr")().Get(time))

    if prim.IsA(UsdGeom.Cube):
        size = get(UsdGeom.Cube(prim), "Size") / 2
        if not size > 0:
            return "size is not positive"
        corners = np.array([[x, y, z] for x in (-size, size) for y in (-size, size) for z in (-size, size)])
        faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
        triangles = np.array([[f[0], f[1], f[2]] for f in faces] + [[f[0], f[2], f[3]] for f in faces])
        return corners, triangles, None
    if prim.IsA(UsdGeom.Plane):
        plane = UsdGeom.Plane(prim)
        w, length = get(plane, "Width") / 2, get(plane, "Length") / 2
        if not (w > 0 and length > 0):
            return "width or length is not positive"
        # UsdGeomPlane: width along X (Z for axis X), length along Y (Z for axis Y).
        axis = str(plane.GetAxisAttr().Get(time))
        u, v, normal = {"X": (2, 1, 0), "Y": (0, 2, 1)}.get(axis, (0, 1, 2))
        quad = np.zeros((4, 3))
        quad[:, u] = [-w, w, w, -w]
        quad[:, v] = [-length, -length, length, length]
        n = np.zeros(3)
        n[normal] = 1.0
        triangles = np.array([[0, 1, 2], [0, 2, 3]])
        if np.cross(quad[1] - quad[0], quad[2] - quad[0]) @ n < 0:
            triangles = triangles[:, [0, 2, 1]]
        return quad, triangles, np.repeat(n[None], 4, 0)
    if prim.IsA(UsdGeom.Cylinder):
        shape = UsdGeom.Cylinder(prim)
        r, h = get(shape, "Radius"), get(shape, "Height") / 2
        if not (r > 0 and h > 0):
            return "radius or height is not positive"
        profile = [(0, -h, 0, -1), (r, -h, 0, -1), (r, -h, 1, 0), (r, h, 1, 0), (r, h, 0, 1), (0, h, 0, 1)]
        return _revolve(profile, shape.GetAxisAttr().Get(time))
    if prim.IsA(UsdGeom.Cone):
        shape = UsdGeom.Cone(prim)
        r, h = get(shape, "Radius"), get(shape, "Height") / 2
        if not (r > 0 and h > 0):
            return "radius or height is not positive"
        slope = np.hypot(2 * h, r)
        nr, nz = 2 * h / slope, r / slope
        profile = [(0, -h, 0, -1), (r, -h, 0, -1), (r, -h, nr, nz), (0, h, nr, nz)]
        return _revolve(profile, shape.GetAxisAttr().Get(time))
    if prim.IsA(UsdGeom.Capsule):
        shape = UsdGeom.Capsule(prim)
        r, h = get(shape, "Radius"), get(shape, "Height") / 2
        if not (r > 0 and h >= 0):
            return "radius is not positive or height negative"
        rings = SEGMENTS // 4
        profile = []
        for k in range(rings + 1):
            t = -np.pi / 2 + (np.pi / 2) * k / rings
            profile.append((r * np.cos(t), -h + r * np.sin(t), np.cos(t), np.sin(t)))
        for k in range(rings + 1):
            t = (np.pi / 2) * k / rings
            profile.append((r * np.cos(t), h + r * np.sin(t), np.cos(t), np.sin(t)))
        return _revolve(profile, shape.GetAxisAttr().Get(time))
    return "not a shape lucerna tessellates"
