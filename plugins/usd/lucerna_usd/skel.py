"""UsdSkel: the points of a skinned mesh at the render's time, computed by usd-core's own
UsdSkel API exactly as Hydra's UsdSkel imaging does: blend shapes first
(UsdSkelBlendShapeQuery), then linear or dual-quaternion skinning
(UsdSkelSkinningQuery.ComputeSkinnedPoints with the skeleton's skinning transforms at the
time), or the rigid transform of a rigidly deformed prim. Skinned points are in skeleton
space; they are returned in the mesh's own space, so that its usual world transform places
them where the skeleton puts them."""

import numpy as np
from pxr import Usd, UsdGeom, UsdSkel, Vt


def _np(m):
    return np.array(m, dtype=np.float64).reshape(4, 4)


class Skinning:
    """Deforms the meshes of SkelRoots at one time code; `warn(path, message)` reports a
    binding that cannot be evaluated (the mesh then keeps its rest points)."""

    def __init__(self, stage, time, warn):
        self.time = time
        self.warn = warn
        self.cache = UsdSkel.Cache()
        self.xforms = UsdGeom.XformCache(time)
        self._populated = set()

    def points(self, prim, points):
        """`prim`'s points (N, 3) float64 deformed by its skeleton and blend shapes at the
        time, in its own space; `points` unchanged when nothing deforms it."""
        root = UsdSkel.Root.Find(prim)
        if not root:
            return points
        key = str(root.GetPath())
        if key not in self._populated:
            self.cache.Populate(root, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate))
            self._populated.add(key)
        query = self.cache.GetSkinningQuery(prim)
        if not query:
            return points
        binding = UsdSkel.BindingAPI(prim)
        skeleton = binding.GetInheritedSkeleton()
        skel_query = self.cache.GetSkelQuery(skeleton) if skeleton else None
        if not skel_query:
            if query.HasJointInfluences() or query.HasBlendShapes():
                self.warn(str(prim.GetPath()), "skinned, but its skeleton cannot be evaluated: "
                          "rendered in its rest pose")
            return points
        path = str(prim.GetPath())
        deformed = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, dtype=np.float32))
        if query.HasBlendShapes():
            self._blend_shapes(prim, query, skel_query, deformed)
        to_mesh = np.linalg.inv(_np(self.xforms.GetLocalToWorldTransform(prim)))
        skel_to_world = _np(self.xforms.GetLocalToWorldTransform(skeleton.GetPrim()))
        if query.HasJointInfluences():
            xforms = skel_query.ComputeSkinningTransforms(self.time)
            if xforms is None:
                self.warn(path, "its skeleton's skinning transforms cannot be computed: "
                          "rendered in its rest pose")
                return points
            if query.IsRigidlyDeformed():
                rigid = query.ComputeSkinnedTransform(xforms, self.time)
                local = np.asarray(deformed, dtype=np.float64)
                local = local @ _np(rigid)[:3, :3] + _np(rigid)[3, :3]
            else:
                if not query.ComputeSkinnedPoints(xforms, deformed, self.time):
                    self.warn(path, "UsdSkel could not skin its points: rendered in its rest pose")
                    return points
                local = np.asarray(deformed, dtype=np.float64)
            # Skinned points are in skeleton space.
            to_local = skel_to_world @ to_mesh
            return local @ to_local[:3, :3] + to_local[3, :3]
        return np.asarray(deformed, dtype=np.float64)

    def _blend_shapes(self, prim, query, skel_query, points):
        anim = skel_query.GetAnimQuery()
        if not anim:
            return
        weights = anim.ComputeBlendShapeWeights(self.time)
        mapper = query.GetBlendShapeMapper()
        if mapper is not None and not mapper.IsNull():
            weights = mapper.Remap(weights)
        shapes = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(prim))
        sub_weights, shape_indices, sub_indices = shapes.ComputeSubShapeWeights(weights)
        shapes.ComputeDeformedPoints(sub_weights, shape_indices, sub_indices,
                                     shapes.ComputeBlendShapePointIndices(),
                                     shapes.ComputeSubShapePointOffsets(), points)
