"""UsdSkel: skinned meshes and blend shapes take their pose at the frame rendered."""

import numpy as np
import pytest
from conftest import HEADER

#: A two-joint arm under a SkelRoot moved to x = 5: the elbow (one unit up) turns 90 degrees
#: about z between frames 1 and 10; a strip of three rows of points is bound with weights
#: 1/0 (bottom), 1/2 each (middle), 0/1 (top). The Strip's own transform is ignored by
#: skinning (UsdSkel skins in skeleton space).
ARM = HEADER.replace(")\n", "    startTimeCode = 1\n    endTimeCode = 10\n)\n", 1) + '''
def SkelRoot "World" (prepend apiSchemas = ["SkelBindingAPI"]) {
    double3 xformOp:translate = (5, 0, 0)
    uniform token[] xformOpOrder = ["xformOp:translate"]
    def Skeleton "Skel" (prepend apiSchemas = ["SkelBindingAPI"]) {
        uniform token[] joints = ["root", "root/elbow"]
        uniform matrix4d[] bindTransforms = [((1,0,0,0),(0,1,0,0),(0,0,1,0),(0,0,0,1)), ((1,0,0,0),(0,1,0,0),(0,0,1,0),(0,1,0,1))]
        uniform matrix4d[] restTransforms = [((1,0,0,0),(0,1,0,0),(0,0,1,0),(0,0,0,1)), ((1,0,0,0),(0,1,0,0),(0,0,1,0),(0,1,0,1))]
        rel skel:animationSource = </World/Skel/Anim>
        def SkelAnimation "Anim" {
            uniform token[] joints = ["root", "root/elbow"]
            float3[] translations = [(0, 0, 0), (0, 1, 0)]
            quatf[] rotations.timeSamples = {
                1: [(1, 0, 0, 0), (1, 0, 0, 0)],
                10: [(1, 0, 0, 0), (0.70710678, 0, 0, 0.70710678)],
            }
            half3[] scales = [(1, 1, 1), (1, 1, 1)]
            uniform token[] blendShapes = ["bulge"]
            float[] blendShapeWeights.timeSamples = {1: [0], 10: [0.5]}
        }
    }
    def Mesh "Strip" (prepend apiSchemas = ["SkelBindingAPI"]) {
        int[] faceVertexCounts = [4, 4]
        int[] faceVertexIndices = [0, 1, 3, 2, 2, 3, 5, 4]
        point3f[] points = [(-0.5, 0, 0), (0.5, 0, 0), (-0.5, 1, 0), (0.5, 1, 0), (-0.5, 2, 0), (0.5, 2, 0)]
        uniform token subdivisionScheme = "none"
        double3 xformOp:translate = (0, 0, 3)
        uniform token[] xformOpOrder = ["xformOp:translate"]
        int[] primvars:skel:jointIndices = [0, 0, 0, 0, 0, 1, 0, 1, 1, 1, 1, 1] (
            elementSize = 2
            interpolation = "vertex"
        )
        float[] primvars:skel:jointWeights = [1, 0, 1, 0, 0.5, 0.5, 0.5, 0.5, 0, 1, 0, 1] (
            elementSize = 2
            interpolation = "vertex"
        )
        matrix4d primvars:skel:geomBindTransform = ((1,0,0,0),(0,1,0,0),(0,0,1,0),(0,0,0,1))
        uniform token[] skel:blendShapes = ["bulge"]
        rel skel:blendShapeTargets = </World/Strip/bulge>
        rel skel:skeleton = </World/Skel>
        def BlendShape "bulge" {
            uniform vector3f[] offsets = [(0, 0, 1)]
            uniform int[] pointIndices = [0]
        }
    }
}
'''


def world_points(scene, name):
    mesh = scene.mesh(name)
    p = scene.positions(mesh).astype(np.float64)
    index = scene["meshes"].index(mesh)
    (inst,) = [i for i in scene["instances"] if i["mesh"] == index]
    m = np.array(inst["transform"], dtype=np.float64).reshape(4, 4)  # row-vector
    return p @ m[:3, :3] + m[3, :3]


def usd_skinned_world_points(path, frame):
    """usd-core's own answer: blend shapes, then UsdSkelSkinningQuery's skinning, in
    skeleton space, then the skeleton's local-to-world."""
    from pxr import Usd, UsdGeom, UsdSkel

    stage = Usd.Stage.Open(str(path))
    time = Usd.TimeCode(frame)
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(stage.GetPrimAtPath("/World"))
    cache.Populate(root, Usd.PrimDefaultPredicate)
    prim = stage.GetPrimAtPath("/World/Strip")
    query = cache.GetSkinningQuery(prim)
    skel_query = cache.GetSkelQuery(UsdSkel.Skeleton(stage.GetPrimAtPath("/World/Skel")))
    points = UsdGeom.Mesh(prim).GetPointsAttr().Get(time)
    shapes = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(prim))
    weights = query.GetBlendShapeMapper().Remap(skel_query.GetAnimQuery().ComputeBlendShapeWeights(time)) \
        if query.GetBlendShapeMapper() else skel_query.GetAnimQuery().ComputeBlendShapeWeights(time)
    sub = shapes.ComputeSubShapeWeights(weights)
    shapes.ComputeDeformedPoints(*sub, shapes.ComputeBlendShapePointIndices(),
                                 shapes.ComputeSubShapePointOffsets(), points)
    xforms = skel_query.ComputeSkinningTransforms(time)
    assert query.ComputeSkinnedPoints(xforms, points, time)
    l2w = np.array(UsdGeom.XformCache(time).GetLocalToWorldTransform(stage.GetPrimAtPath("/World/Skel")))
    p = np.asarray(points, dtype=np.float64)
    return p @ l2w[:3, :3] + l2w[3, :3]


@pytest.mark.parametrize("frame", [1, 10])
def test_skinned_points_match_usd_skel(stage_file, converted, frame):
    path = stage_file(ARM)
    s = converted(path, frame=frame)
    got = world_points(s, "/World/Strip")
    expected = usd_skinned_world_points(path, frame)
    # The scene's vertices are the welded corners: compare as sets of points.
    for p in expected:
        assert np.min(np.linalg.norm(got - p, axis=1)) < 1e-4, (p, got)
    assert len(got) == len(expected)


def test_the_arm_bends_between_frames_as_computed_by_hand(stage_file, converted):
    path = stage_file(ARM)
    rest = world_points(converted(path, frame=1), "/World/Strip")
    bent = world_points(converted(path, frame=10), "/World/Strip")

    def has(points, p):
        return np.min(np.linalg.norm(points - np.array(p), axis=1)) < 1e-4

    # Frame 1: the rest pose, moved by the SkelRoot (the Strip's own z = 3 is ignored).
    assert has(rest, (4.5, 2, 0)) and has(rest, (4.5, 0, 0))
    # Frame 10: the top row turns 90 degrees about the elbow at (5, 1, 0): (-0.5, 1) from
    # it goes to (-1, -0.5); the middle row is the mean of unbent and bent: (-0.25, 0.75)
    # from the root; the bulge moves point 0 by half its offset (weight 0.5) in z.
    assert has(bent, (4.0, 0.5, 0)) and has(bent, (4.0, 1.5, 0))
    assert has(bent, (4.75, 0.75, 0))
    assert has(bent, (4.5, 0, 0.5))
    assert not has(bent, (4.5, 2, 0))


def test_an_open_shutter_gives_the_skinned_points_at_its_keys(stage_file, converted):
    """Deformation blur: with the shutter open, the strip's points at each key are the
    points a conversion at that key's time gives (same vertices, same order), and the
    frame's own points are the middle key."""
    from lucerna_usd.motion import KEYS

    path = stage_file(ARM)
    blurred = converted(path, frame=5, shutter=(-0.5, 0.5))
    mesh = blurred.mesh("/World/Strip")
    keys = [blurred.array(v, "<f4", 3) for v in mesh["deformation"]["positions"]]
    assert len(keys) == KEYS
    assert np.array_equal(keys[KEYS // 2], blurred.positions(mesh))
    for k, key in enumerate(keys):
        at = converted(path, frame=4.5 + k / (KEYS - 1))
        expected = at.positions(at.mesh("/World/Strip"))
        assert np.allclose(key, expected, atol=1e-5), (k, key, expected)
    # The strip's normals are recomputed from each key's points (it is skinned).
    assert len(mesh["deformation"]["normals"]) == KEYS
