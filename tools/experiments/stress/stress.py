#!/usr/bin/env python3
"""The stress suite (issue 6): hard scenes and broken input, rendered by the lucerna binary
as a user runs it, each checked for what it must give.

Every render is checked for: exit code 0 and no panic; every channel of every AOV finite
(`--aov all`); the discarded-sample count in the EXR header (`lucerna/nan_inf_discarded`)
zero (no case expects any); a bounded time (a timeout). Then each case compares
its image with its reference or its well-conditioned twin:

- relMSE between the case and its twin, rendered with different seeds, must stay within
  the noise: the mean of the case's and the twin's seed-to-seed relMSEs (x 1.35: the ratio
  of two relMSEs over 64x64x3 pixel values varies by a few percent);
- and the image means must agree: |z| < 4.5 with the standard error from the variance AOVs.

Cases are generated as lucerna scene files (f64 transforms, exact light units), starting
from the Cornell box that `lucerna convert` writes, or as glTF for the input-value cases.

    tools/experiments/stress/run [--quick] [--case NAME ...] [--out tools/experiments/stress/results]

--quick runs the subset the test suite runs (tests/python/test_stress.py).
"""
import argparse
import math
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import lucerna_tools as lt
from lucerna_tools.gltf_writer import GltfWriter

ROOT = lt.ROOT
RESOLUTION = (64, 64)
SPP = 64
TIMEOUT = 120
# Allowed ratio of a case's relMSE against its twin to the twin's seed-to-seed relMSE, and
# the largest |z| of the difference of image means.
NOISE_RATIO = 1.35
Z_MAX = 4.5

def affine(m, scale, offset):
    """Column-major 4x4 `m` after scaling by `scale` and moving by `offset` (f64)."""
    m = np.array(m, dtype=np.float64).reshape(4, 4).T
    s = np.diag([scale, scale, scale, 1.0])
    s[:3, 3] = offset
    return list((s @ m).T.reshape(-1))


class Stress:
    def __init__(self, work):
        self.work = Path(work)
        self.cornell_path = self.work / "cornell.lucerna"
        run([lt.BINARY, "convert", str(ROOT / "scenes/cornell-box/cornell-box.gltf"),
             "-o", str(self.cornell_path)])
        self.glass_path = self.work / "glass-box.lucerna"
        run([lt.BINARY, "convert", str(ROOT / "scenes/glass-box/glass-box.gltf"), "-o", str(self.glass_path)])
        self.rendered = {}

    def cornell(self):
        return lt.SceneFile(self.cornell_path)

    def render(self, scene, seed=1, spp=SPP, args=(), resolution=RESOLUTION):
        """Renders `scene` (a path) with all AOVs; returns (channels, header, figures) after
        the checks every render must pass (raised as failures)."""
        key = (str(scene), seed, spp, tuple(args), resolution)
        if key in self.rendered:
            return self.rendered[key]
        out = self.work / f"{Path(scene).stem}-{seed}-{len(self.rendered)}.exr"
        cmd = [lt.BINARY, "render", str(scene), "-o", str(out), "-q", "--aov", "all", "--seed", str(seed),
               "--spp", str(spp), "--resolution", f"{resolution[0]}x{resolution[1]}", "--filter", "box",
               *args]
        start = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT)
        seconds = time.perf_counter() - start
        if proc.returncode != 0 or "panicked" in proc.stderr:
            raise Failure(f"{' '.join(cmd[2:4])}: exit {proc.returncode}: {proc.stderr.strip()[-400:]}")
        channels, header = lt.read_exr(out)
        bad = [n for n, c in channels.items() if not np.all(np.isfinite(c))]
        if bad:
            raise Failure(f"non-finite channels {bad[:5]}")
        discarded = int(header["lucerna/nan_inf_discarded"])
        if discarded != 0:
            raise Failure(f"{discarded} NaN/Inf contributions discarded")
        result = (channels, header, {"seconds": seconds})
        self.rendered[key] = result
        return result

    def against_twin(self, case, twin, args=(), twin_args=(), rows=slice(None)):
        """Renders `case` and `twin` with seeds 1 and 2; returns the figures and fails if the
        case differs from the twin beyond the noise. relMSE(case 2, twin 1) is expected to
        be var(case) + var(twin), the mean of the two seed-to-seed relMSEs."""
        c, _, cf = self.render(case, seed=2, args=args)
        c1, _, _ = self.render(case, seed=1, args=args)
        t1, _, _ = self.render(twin, seed=1, args=twin_args)
        t2, _, _ = self.render(twin, seed=2, args=twin_args)
        image = lambda ch: lt.rgb(ch)[rows]  # noqa: E731
        variance = lambda ch: lt.rgb(ch, "variance")[rows]  # noqa: E731
        error = lt.relmse(image(c), image(t1))
        noise = 0.5 * (lt.relmse(image(t2), image(t1)) + lt.relmse(image(c), image(c1)))
        same_seed = lt.relmse(image(c), image(t2))
        n = image(c).size
        z = (image(c).mean() - image(t1).mean()) / math.sqrt((variance(c).sum() + variance(t1).sum()) / n ** 2)
        figures = {"relMSE": error, "seed-to-seed": noise, "same seed": same_seed, "z": z,
                   "seconds": cf["seconds"]}
        if not (error < NOISE_RATIO * noise and abs(z) < Z_MAX):
            raise Failure(f"differs from its twin beyond the noise: {fmt(figures)}")
        return figures


class Failure(Exception):
    pass


def run(cmd):
    proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=TIMEOUT)
    if proc.returncode != 0:
        raise Failure(f"{cmd[1]}: {proc.stderr.strip()}")
    return proc


def fmt(figures):
    return ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in figures.items())


# --- The cases. Each takes the Stress runner and returns its figures (or raises Failure).

def transformed(s, scale, offset):
    scene = s.cornell()
    m = scene.manifest
    for inst in m["instances"]:
        inst["transform"] = affine(inst["transform"], scale, offset)
    for cam in m["cameras"]:
        cam["transform"] = affine(cam["transform"], scale, offset)
        cam["clip_near"] *= scale
        cam["focus_distance"] *= scale
    return scene.write(s.work / f"cornell-{scale:g}-{offset:g}.lucerna")


def moved_cornell(scale, offset):
    def case(s):
        figures = s.against_twin(transformed(s, scale, offset), s.cornell_path)
        if not figures["same seed"] < 0.01 * figures["seed-to-seed"]:
            raise Failure(f"the same samples give another image: {fmt(figures)}")
        return figures
    where = f"{offset:g} units from the origin" if offset else f"scaled by {scale:g}"
    case.__doc__ = (f"Cornell box {where} (f64 transforms) renders like the original, and from the "
                    "same samples almost exactly so")
    return case


def duplicate_triangles(s):
    """Every non-emitting triangle duplicated (coplanar, half of the copies wound the other
    way) plus a zero-area triangle at each: no leak through double walls, no acne, the same
    image (a doubled emitter would rightly emit twice)"""
    scene = s.cornell()
    m = scene.manifest
    for mesh, arrays in zip(m["meshes"], scene.arrays):
        if max(m["materials"][mesh["material"]]["emissive"]) > 0:
            continue
        t = arrays["triangles"]
        flipped = t[:, [0, 2, 1]]
        copies = np.where((np.arange(len(t)) % 2 == 0)[:, None], t, flipped)
        degenerate = np.stack([t[:, 0], t[:, 0], t[:, 1]], axis=1)
        arrays["triangles"] = np.concatenate([t, copies, degenerate])
    return s.against_twin(scene.write(s.work / "duplicates.lucerna"), s.cornell_path)


def normals(kind):
    def case(s):
        scene = s.cornell()
        for arrays in scene.arrays:
            p, t = arrays["positions"], arrays["triangles"]
            n = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
            n /= np.linalg.norm(n, axis=1, keepdims=True)
            if not np.allclose(n, n[0], atol=1e-6):
                continue  # the blocks: their corners have no one exact normal
            exact = np.tile(n[0], (len(p), 1))
            arrays["normals"] = {"flipped": -exact, "unnormalised": 7.0 * exact,
                                 "zero-length": 0.0 * exact}[kind]
        return s.against_twin(scene.write(s.work / f"normals-{kind}.lucerna"), s.cornell_path)
    case.__doc__ = f"vertex normals {kind} on the flat walls render like flat shading"
    return case


def sealed_thin_box(s):
    """A point light and an emitter sealed in a box whose walls are 1e-5 thick: no light
    may leak out (the whole image is exactly black), though the box is in view"""
    scene = s.cornell()
    m = scene.manifest
    m["meshes"], m["instances"], scene.arrays = [], [], []
    white = 0
    emitter = scene.add_material("emitter", emissive=[5.0, 5.0, 5.0], base_color=[0, 0, 0, 1])
    for name, half in [("outer", 0.2 + 1e-5), ("inner", 0.2)]:
        pos, tri = cube(np.array([0.278, 0.25, 0.28]), half)
        scene.add_mesh(name, pos, tri, white)
    floor = np.array([[-1, 0.0, -1], [2, 0, -1], [2, 0, 2], [-1, 0, 2]]) + [0, 0.05 - 1e-5, 0]
    scene.add_mesh("floor", floor, [[0, 2, 1], [0, 3, 2]], white)
    pos, tri = cube(np.array([0.278, 0.25, 0.28]), 0.05)
    scene.add_mesh("glow", pos, tri, emitter)
    m["lights"] = [{"name": "bulb", "kind": {"point": {"position": [0.278, 0.35, 0.28], "intensity": [10, 10, 10]}}}]
    path = scene.write(s.work / "sealed.lucerna")
    channels, _, figures = s.render(path, args=["--env", "0,0,0"])
    beauty = lt.rgb(channels)
    seen = float(np.mean(np.isfinite(channels["depth.Z"]) & (channels["depth.Z"] < 1e30)))
    figures.update({"max pixel": float(beauty.max()), "covered share": seen})
    if beauty.max() != 0.0 or seen < 0.1:
        raise Failure(f"light leaks out of the sealed box (or it is not in view): {fmt(figures)}")
    return figures


def cube(centre, half):
    """A cube's 8 corners and 12 outward triangles."""
    corners = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float) * half + centre
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    tris = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return corners, tris


def grazing_camera(s):
    """A Lambert floor 1e4 wide under a sun, seen from 1e-2 above at angles down to 0.3
    degrees: every floor pixel has the analytic radiance rho E cos(theta) / pi (no acne, no
    shadow leaks), the sky none"""
    scene = s.cornell()
    m = scene.manifest
    m["meshes"], m["instances"], scene.arrays = [], [], []
    rho, irradiance, theta = 0.5, 2.0, math.radians(60)
    grey = scene.add_material("grey", base_color=[rho, rho, rho, 1.0])
    w = 5e3
    scene.add_mesh("floor", [[-w, 0, -w], [w, 0, -w], [w, 0, w], [-w, 0, w]], [[0, 2, 1], [0, 3, 2]], grey)
    m["lights"] = [{"name": "sun", "kind": {"directional": {
        "direction": [math.sin(theta), -math.cos(theta), 0.0], "irradiance": [irradiance] * 3, "angle": 0.0}}}]
    # Looking along -z, pitched down 2 degrees, vertical field of view 4 degrees: the top
    # rows see the horizon at grazing angles.
    pitch = math.radians(2.0)
    cam = m["cameras"][0]
    forward = np.array([0.0, -math.sin(pitch), -math.cos(pitch)])
    right = np.array([1.0, 0.0, 0.0])
    up = np.cross(right, forward)
    cam["transform"] = [*right, 0, *up, 0, *(-forward), 0, 0.0, 1e-2, 0.0, 1.0]
    cam["projection"] = {"perspective": {"yfov": math.radians(4.0), "aspect": 1.0}}
    cam["clip_near"] = 1e-4
    path = scene.write(s.work / "grazing.lucerna")
    channels, _, figures = s.render(path, args=["--env", "0,0,0"])
    beauty = lt.rgb(channels)
    floor = channels["A"] >= 1.0
    expected = rho * irradiance * math.cos(theta) / math.pi
    worst = float(np.max(np.abs(beauty[floor] - expected)) / expected)
    figures.update({"floor share": float(floor.mean()), "expected": expected, "worst relative error": worst,
                    "sky max": float(beauty[channels["A"] == 0].max(initial=0.0))})
    if floor.mean() < 0.5 or worst > 1e-3 or figures["sky max"] != 0.0:
        raise Failure(f"grazing floor wrong: {fmt(figures)}")
    return figures


def shading_normals_far(s):
    """A sphere whose shading normals lean 80 degrees from the geometric ones, albedo 0.8
    in a uniform environment of radiance 1 (a furnace): finite, and no pixel brighter than
    the environment beyond noise (shading normals must not create energy)"""
    scene = s.cornell()
    m = scene.manifest
    m["meshes"], m["instances"], scene.arrays = [], [], []
    grey = scene.add_material("grey", base_color=[0.8, 0.8, 0.8, 1.0])
    pos, tri = icosphere(3)
    tilt = math.radians(80)
    axis = np.cross(pos, [0.3, 1.0, 0.2])
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    # Rodrigues' rotation of each normal (the position) by `tilt` about its own tangent axis.
    normals = pos * math.cos(tilt) + np.cross(axis, pos) * math.sin(tilt)
    scene.add_mesh("ball", pos * 0.2 + [0.278, 0.273, 0.3], tri, grey, normals=normals)
    path = scene.write(s.work / "shading-normals.lucerna")
    channels, _, figures = s.render(path, args=["--env", "1,1,1"])
    beauty, sigma = lt.rgb(channels), np.sqrt(lt.rgb(channels, "variance"))
    excess = float(np.max((beauty - 1.0) / np.maximum(sigma, 1e-6)))
    figures.update({"mean": float(beauty.mean()), "max": float(beauty.max()), "max excess / sigma": excess})
    if excess > 5.0:
        raise Failure(f"pixels brighter than the furnace: {fmt(figures)}")
    return figures


def integrating_sphere(s):
    """A closed box of albedo exactly 1 around a one-sided emitter of radiance 1 (1/24 of
    its area): every pixel sees radiance 1 (an integrating sphere); long paths, ended only
    by roulette, give it within the noise"""
    scene = s.cornell()
    m = scene.manifest
    m["meshes"], m["instances"], scene.arrays = [], [], []
    white = scene.add_material("white", base_color=[1.0, 1.0, 1.0, 1.0])
    emitter = scene.add_material("emitter", emissive=[1.0, 1.0, 1.0], base_color=[0, 0, 0, 1], double_sided=False)
    pos, tri = cube(np.zeros(3), 1.0)
    scene.add_mesh("walls", pos, [t[::-1] for t in tri], white)
    h = 0.5
    scene.add_mesh("emitter", [[-h, -0.5, -h], [-h, -0.5, h], [h, -0.5, h], [h, -0.5, -h]],
                   [[0, 1, 2], [0, 2, 3]], emitter)
    eye, target = np.array([0.3, 0.5, 0.2]), np.array([0.0, -1.0, 0.0])
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    m["cameras"][0].update(transform=[*right, 0, *up, 0, *(-forward), 0, *eye, 1.0], clip_near=0.0,
                           projection={"perspective": {"yfov": 1.5, "aspect": 1.0}})
    path = scene.write(s.work / "integrating-sphere.lucerna")
    channels, _, figures = s.render(path, spp=256, resolution=(16, 16), args=["--env", "0,0,0"])
    # The box is white: the three channels are one estimate, so the red one alone.
    red = channels["R"]
    se = math.sqrt(channels["variance.R"].sum()) / red.size
    figures.update({"mean": float(red.mean()), "standard error": se})
    if abs(red.mean() - 1.0) > Z_MAX * se:
        raise Failure(f"not radiance 1: {fmt(figures)}")
    return figures


def icosphere(subdivisions):
    from gltf_writer import icosphere as ico
    verts, faces = ico(subdivisions)
    return np.array(verts, float), faces


def spheres_scene(s, name, materials):
    """The Cornell box with a row of spheres of the given materials (name, fields)."""
    scene = s.cornell()
    m = scene.manifest
    m["instances"] = [i for i in m["instances"] if "block" not in i["name"]]
    m["spheres"] = []
    for k, (mname, fields) in enumerate(materials):
        mat = scene.add_material(mname, **fields)
        m["spheres"].append({"name": mname, "centre": [0.1 + 0.12 * k, 0.1, 0.3], "radius": 0.05, "material": mat})
    return scene.write(s.work / f"{name}.lucerna")


def phong(exponent):
    return {"model": {"phong": {"exponent": exponent, "specular": [1.0, 1.0, 1.0]}}, "base_color": [0, 0, 0, 1]}


def mirror():
    return {"model": "gltf_pbr", "base_color": [1, 1, 1, 1], "metallic": 1.0, "roughness": 0.0}


def phong_exponents(s):
    """Phong exponents 1, 100, 1e4 and 1e6 render finite; the 1e6 lobe (a thousandth of a
    radian) renders like a perfect mirror"""
    figures = {}
    for e in [1, 1e2, 1e4]:
        s.render(spheres_scene(s, f"phong-{e:g}", [("phong", phong(e))]))
    figures.update(s.against_twin(spheres_scene(s, "phong-1e6", [("phong", phong(1e6))]),
                                  spheres_scene(s, "mirror", [("mirror", mirror())])))
    return figures


def ggx_roughness(s):
    """GGX roughness 1 and 1e-4 render finite; 1e-4 renders like roughness 0"""
    rough = lambda r: {**mirror(), "roughness": r}  # noqa: E731
    s.render(spheres_scene(s, "ggx-1", [("rough", rough(1.0))]))
    return s.against_twin(spheres_scene(s, "ggx-1e-4", [("rough", rough(1e-4))]),
                          spheres_scene(s, "ggx-0", [("rough", rough(0.0))]))


def without_ceiling_light(s):
    scene = s.cornell()
    m = scene.manifest
    for mat in m["materials"]:
        if max(mat["emissive"]) > 0:
            mat["emissive"] = [0.0, 0.0, 0.0]
    return scene


def tiny_bright_light(s):
    """A sphere light of radius 1e-4 and radiance 1e6 renders like the point light of the
    same intensity (I = L pi r^2), without fireflies (rows below the light's image)"""
    radius, radiance = 1e-4, 1e6
    centre = [0.278, 0.45, 0.28]
    scene = without_ceiling_light(s)
    mat = scene.add_material("tiny", emissive=[radiance] * 3, base_color=[0, 0, 0, 1])
    scene.manifest["spheres"] = [{"name": "tiny", "centre": centre, "radius": radius, "material": mat}]
    tiny = scene.write(s.work / "tiny-light.lucerna")
    scene = without_ceiling_light(s)
    intensity = radiance * math.pi * radius ** 2
    scene.manifest["lights"] = [{"name": "point", "kind": {"point": {"position": centre, "intensity": [intensity] * 3}}}]
    point = scene.write(s.work / "point-light.lucerna")
    return s.against_twin(tiny, point, rows=slice(RESOLUTION[1] // 3, None))


def edge_on_light(s):
    """A quad light in the plane of the camera (seen exactly edge-on, and coplanar with the
    shading points of the wall it touches) renders like the same light turned 1e-3 rad"""
    def scene_with(angle):
        scene = without_ceiling_light(s)
        mat = scene.add_material("panel", emissive=[20.0, 20.0, 20.0], base_color=[0, 0, 0, 1])
        c, a = np.array([0.278, 0.3, 0.3]), angle
        d = np.array([math.sin(a), 0.0, math.cos(a)]) * 0.1
        up = np.array([0.0, 0.1, 0.0])
        quad = [c - d - up, c + d - up, c + d + up, c - d + up]
        scene.add_mesh("panel", quad, [[0, 1, 2], [0, 2, 3]], mat)
        return scene.write(s.work / f"edge-on-{angle:g}.lucerna")
    return s.against_twin(scene_with(0.0), scene_with(1e-3))


def many_lights(count):
    def case(s):
        scene = without_ceiling_light(s)
        side = int(math.sqrt(count))
        # A checkerboard of dim and bright bulbs, so that power selection is not uniform.
        size = 0.4 / side
        for parity, radiance in [(0, 10.0), (1, 50.0)]:
            mat = scene.add_material(f"bulbs-{parity}", emissive=[radiance] * 3, base_color=[0, 0, 0, 1])
            positions, triangles = [], []
            for i in range(side):
                for j in range(side):
                    if (i + j) % 2 != parity:
                        continue
                    x0, z0, h = 0.078 + 0.4 * i / side, 0.08 + 0.4 * j / side, 0.548
                    k = len(positions)
                    positions += [[x0, h, z0], [x0 + size * 0.5, h, z0], [x0 + size * 0.5, h, z0 + size * 0.5],
                                  [x0, h, z0 + size * 0.5]]
                    triangles += [[k, k + 2, k + 1], [k, k + 3, k + 2]]
            scene.add_mesh(f"bulbs-{parity}", positions, triangles, mat)
        path = scene.write(s.work / f"lights-{count}.lucerna")
        figures = {}
        for select in ["power", "uniform"]:
            f = s.against_twin(path, path, args=["--light-select", select], twin_args=["--light-select", "contribution"])
            figures.update({f"{select}: {k}": v for k, v in f.items() if k in ("relMSE", "z", "seconds")})
        figures["seed-to-seed"] = f["seed-to-seed"]
        return figures
    case.__doc__ = (f"{count} small quad lights ({2 * count} emitting triangles): power, uniform "
                    "and light-tree selection converge to the same image in bounded time")
    return case


def bad_values(s):
    """NaN and Inf in positions, normals, uvs, colours and material factors: each file is
    rejected (exit 2, one line naming the element) or repaired with a warning that counts
    the values; never a panic, never a non-finite pixel"""
    outcomes = {}
    nan, inf = float("nan"), float("inf")
    for what in ["positions", "normals", "uvs", "colors", "factor"]:
        w = GltfWriter("lucerna tools/experiments/stress")
        pos = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
        bad = {"positions": [(nan, 0, 0)], "normals": [(0, 0, nan)], "uvs": [(inf, 0)], "colors": [(nan, 1, 1, 1)]}
        mat = w.material("m", base=(0.5, 0.5, 0.5))
        if what == "factor":
            w.doc["materials"][mat]["pbrMetallicRoughness"]["baseColorFactor"] = [1e39, 0.5, 0.5, 1.0]
        normals = [(0, 0, 1)] * 3 + (bad["normals"] if what == "normals" else [(0, 0, 1)])
        positions = pos[:3] + (bad["positions"] if what == "positions" else pos[3:])
        uvs = [(0, 0)] * 3 + (bad["uvs"] if what == "uvs" else [(0, 0)])
        mesh = w.mesh("quad", positions, [(0, 1, 2), (0, 2, 3)], mat, normals=normals, uvs=uvs)
        if what == "colors":
            prim = w.doc["meshes"][mesh]["primitives"][0]
            prim["attributes"]["COLOR_0"] = w.accessor([(1, 1, 1, 1)] * 3 + bad["colors"], "VEC4")
        w.node(mesh=mesh, name="quad")
        w.camera("camera", 0.8, 1.0, (0.5, 0.5, 3), (0.5, 0.5, 0))
        path = s.work / f"bad-{what}.gltf"
        w.write_gltf(path)
        out = s.work / f"bad-{what}.exr"
        proc = subprocess.run([lt.BINARY, "render", str(path), "-o", str(out), "-q", "--spp", "4",
                               "--resolution", "32x32", "--env", "1,1,1"],
                              capture_output=True, text=True, timeout=TIMEOUT)
        text = proc.stderr.strip()
        if "panicked" in text or proc.returncode not in (0, 2):
            raise Failure(f"{what}: exit {proc.returncode}: {text[-300:]}")
        if proc.returncode == 2:
            lines = text.splitlines()
            if len(lines) != 1 or "error:" not in lines[0] or out.exists():
                raise Failure(f"{what}: rejection must be one error line and no output: {text}")
            outcomes[what] = "rejected: " + lines[0].split(": ", 2)[-1]
        else:
            warnings = [line.split("warning: ", 1)[1] for line in text.splitlines()
                        if "warning: " in line]
            if not any(ch.isdigit() for line in warnings for ch in line.split(":", 1)[-1]):
                raise Failure(f"{what}: repaired without a counting warning: {text}")
            channels, _ = lt.read_exr(out)
            if not all(np.all(np.isfinite(c)) for c in channels.values()):
                raise Failure(f"{what}: non-finite pixels")
            outcomes[what] = "repaired: " + warnings[0].split(": ", 2)[-1]
    return outcomes


def memory_limit(s):
    """--max-memory: a render estimated to need more fails at once with exit 2 and an
    error that names the parts, and writes nothing"""
    out = s.work / "limited.exr"
    start = time.perf_counter()
    proc = subprocess.run([lt.BINARY, "render", "-o", str(out), "-q", "--max-memory", "16M",
                           "--resolution", "2048x2048"], capture_output=True, text=True, timeout=TIMEOUT)
    seconds = time.perf_counter() - start
    if proc.returncode != 2 or "--max-memory" not in proc.stderr or out.exists() or seconds > 10:
        raise Failure(f"exit {proc.returncode} after {seconds:.1f} s: {proc.stderr.strip()}")
    return {"seconds": seconds, "message": proc.stderr.strip().split(": ", 2)[-1]}


def memory_estimate(s):
    """The memory estimate (lucerna inspect) against the measured peak of rendering a
    single 2-million-triangle mesh at 32x32 with the beauty only"""
    w = GltfWriter("lucerna tools/experiments/stress")
    n = 1000
    ys = 0.05 * ((np.arange(n + 1)[None, :] * 7 + np.arange(n + 1)[:, None] * 13) % 5) / 5
    xs, zs = np.meshgrid(np.linspace(-1, 1, n + 1), np.linspace(-1, 1, n + 1))
    pos = np.stack([xs, ys, zs], axis=-1).reshape(-1, 3).astype("<f4")
    a = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).reshape(-1)
    tris = np.concatenate([np.stack([a, a + n + 1, a + 1], 1), np.stack([a + 1, a + n + 1, a + n + 2], 1)])
    # Buffers written directly: the writer's lists would take minutes at this size.
    w.blob += pos.tobytes()
    w.doc["bufferViews"] = [{"buffer": 0, "byteOffset": 0, "byteLength": pos.nbytes},
                            {"buffer": 0, "byteOffset": pos.nbytes, "byteLength": tris.size * 4}]
    w.blob += tris.astype("<u4").tobytes()
    w.doc["accessors"] = [{"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3",
                           "min": pos.min(0).tolist(), "max": pos.max(0).tolist()},
                          {"bufferView": 1, "componentType": 5125, "count": tris.size, "type": "SCALAR"}]
    mat = w.material("white")
    w.doc["meshes"] = [{"name": "grid", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": mat}]}]
    w.node(mesh=0, name="grid")
    w.camera("camera", 0.8, 1.0, (0, 3, 3), (0, 0, 0))
    path = s.work / "grid.glb"
    w.write_glb(path)
    inspect = run([lt.BINARY, "inspect", str(path)]).stdout
    line = next(x for x in inspect.splitlines() if "memory" in x)
    proc = run([lt.BINARY, "render", str(path), "-o", str(s.work / "grid.exr"), "--spp", "1",
                "--resolution", "32x32", "--aov", "beauty", "-q", "--env", "1,1,1"])
    peak = float(proc.stderr.split("peak memory ")[1].split(" MB")[0]) * 1e6
    # The estimate without the film (inspect's is for the default resolution and AOVs).
    parts = line.rsplit("(", 1)[1]
    film = parse_bytes(parts.split("film ")[1].rstrip(")"))
    estimate = parse_bytes(line.split("about ")[1].split(" (")[0]) - film
    figures = {"triangles": len(tris), "estimate MB": estimate / 1e6, "peak MB": peak / 1e6,
               "estimate / peak": estimate / peak}
    if not 0.8 < estimate / peak < 1.3:
        raise Failure(f"estimate off: {fmt(figures)}")
    return figures


def glass(**fields):
    """A glass material: smooth, ior 1.5, bounding a clear volume (fields override)."""
    return {"model": "gltf_pbr", "base_color": [1, 1, 1, 1], "metallic": 0.0, "roughness": 0.0, "ior": 1.5,
            "transmission": 1.0, "volume": {"absorption": [0.0, 0.0, 0.0]}, **fields}


def glass_index_matched(s):
    """A glass ball of ior 1.0 (nothing reflects or bends; every path enters and leaves a
    volume) is invisible: the box renders as without it"""
    return s.against_twin(spheres_scene(s, "glass-ior-1", [("glass", glass(ior=1.0))]),
                          spheres_scene(s, "no-spheres", []))


def glass_extremes(s):
    """Glass balls of ior 3 (total internal reflection past 19.5 degrees), thin walls of ior 3,
    roughness 1, strong absorption and ior 1.0001 render finite; nearly smooth rough glass
    (GGX alpha 1.2e-3, just above the delta threshold: D peaks near 2e5) renders like smooth
    glass"""
    s.render(spheres_scene(s, "glass-extremes", [
        ("dense", glass(ior=3.0)), ("thin-dense", glass(ior=3.0, volume=None)),
        ("rough", glass(ior=3.0, roughness=1.0)), ("absorbing", glass(volume={"absorption": [5.0, 40.0, 300.0]})),
        ("almost-matched", glass(ior=1.0001))]))
    return s.against_twin(spheres_scene(s, "glass-nearly-smooth", [("g", glass(roughness=0.035))]),
                          spheres_scene(s, "glass-smooth", [("g", glass())]))


def moved_glass(scale, offset):
    def case(s):
        scene = lt.SceneFile(s.glass_path)
        m = scene.manifest
        for inst in m["instances"]:
            inst["transform"] = affine(inst["transform"], scale, offset)
        for sphere in m["spheres"]:
            sphere["centre"] = [scale * c + offset for c in sphere["centre"]]
            sphere["radius"] *= scale
        for cam in m["cameras"]:
            cam["transform"] = affine(cam["transform"], scale, offset)
            cam["clip_near"] *= scale
            cam["focus_distance"] *= scale
        for mat in m["materials"]:
            if mat.get("volume"):
                mat["volume"]["absorption"] = [a / scale for a in mat["volume"]["absorption"]]
        return s.against_twin(scene.write(s.work / f"glass-{scale:g}-{offset:g}.lucerna"), s.glass_path)
    where = f"{offset:g} units from the origin" if offset else f"scaled by {scale:g}"
    case.__doc__ = (f"The glass box (refracting ball, rough slab, thin pane) {where} "
                    "renders like the original (paths through glass diverge with rounding, so only within the "
                    "noise)")
    return case


def glass_grazing(s):
    """A thin glass pane and a 1 cm rough glass slab nearly containing the camera's view
    axis (rays meet them at up to 89.8 degrees: Fresnel near 1, refraction at the critical
    angle, TIR inside the slab) render finite"""
    scene = s.cornell()
    m = scene.manifest
    thin = scene.add_material("thin", **glass(volume=None))
    rough = scene.add_material("rough", **glass(roughness=0.4))
    tilt = math.radians(0.2)
    # Planes through the camera's height, rising 0.2 degrees over the depth of the box.
    y0, z0, z1 = 0.2, -0.5, 0.6
    def quad(y, x0, x1):
        return [[x0, y, z0], [x1, y, z0], [x1, y + (z1 - z0) * math.tan(tilt), z1], [x0, y + (z1 - z0) * math.tan(tilt), z1]]
    pane = quad(y0, 0.0, 0.28)
    scene.add_mesh("pane", pane, [[0, 1, 2], [0, 2, 3]], thin)
    bottom, top = quad(y0 + 0.05, 0.28, 0.56), quad(y0 + 0.06, 0.28, 0.56)
    slab = bottom + top
    faces = [[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
             [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]]
    scene.add_mesh("slab", slab, faces, rough)
    cam = m["cameras"][0]
    t = cam["transform"]
    cam["transform"] = t[:12] + [t[12], y0 + 0.0005, t[14], 1.0]
    path = scene.write(s.work / "glass-grazing.lucerna")
    _, _, figures = s.render(path)
    return figures


def parse_bytes(text):
    number, unit = text.split()
    return float(number) * {"B": 1, "KiB": 2 ** 10, "MiB": 2 ** 20, "GiB": 2 ** 30, "TiB": 2 ** 40}[unit]


# (name, case, in the quick subset)
CASES = [
    ("translated-1e3", moved_cornell(1.0, 1e3), False),
    ("translated-1e5", moved_cornell(1.0, 1e5), False),
    ("translated-1e7", moved_cornell(1.0, 1e7), True),
    ("scaled-1e-4", moved_cornell(1e-4, 0.0), True),
    ("scaled-1e4", moved_cornell(1e4, 0.0), False),
    ("duplicate-and-zero-area-triangles", duplicate_triangles, True),
    ("normals-flipped", normals("flipped"), False),
    ("normals-unnormalised", normals("unnormalised"), False),
    ("normals-zero-length", normals("zero-length"), True),
    ("sealed-thin-box", sealed_thin_box, True),
    ("grazing-camera", grazing_camera, True),
    ("shading-normals-far", shading_normals_far, False),
    ("integrating-sphere", integrating_sphere, False),
    ("phong-exponents", phong_exponents, False),
    ("ggx-roughness", ggx_roughness, True),
    ("tiny-bright-light", tiny_bright_light, True),
    ("edge-on-light", edge_on_light, False),
    ("many-lights-256", many_lights(256), True),
    ("many-lights-4096", many_lights(4096), False),
    ("bad-values", bad_values, True),
    ("memory-limit", memory_limit, True),
    ("memory-estimate", memory_estimate, False),
    ("glass-index-matched", glass_index_matched, True),
    ("glass-extremes", glass_extremes, True),
    ("glass-far-1e5", moved_glass(1.0, 1e5), False),
    ("glass-far-1e7", moved_glass(1.0, 1e7), True),
    ("glass-scaled-1e-3", moved_glass(1e-3, 0.0), False),
    ("glass-grazing", glass_grazing, True),
]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="the subset the test suite runs")
    parser.add_argument("--case", action="append", help="run only these cases (repeatable)")
    parser.add_argument("--out", type=Path, help="write the report (stress.md) here")
    args = parser.parse_args()
    cases = [(n, c) for n, c, quick in CASES if (quick or not args.quick) and (not args.case or n in args.case)]
    if not cases:
        parser.error("no such case")
    rows, failed = [], []
    with tempfile.TemporaryDirectory(prefix="lucerna-stress-") as work:
        s = Stress(work)
        for name, case in cases:
            start = time.perf_counter()
            try:
                figures = case(s)
                status = "pass"
            except (Failure, subprocess.TimeoutExpired) as e:
                figures, status = {"failure": str(e)}, "FAIL"
                failed.append(name)
            seconds = time.perf_counter() - start
            rows.append((name, status, seconds, (case.__doc__ or "").strip(), figures))
            print(f"{status:4}  {name:36} {seconds:6.1f} s  {fmt(figures)}", flush=True)
    report = ["# lucerna stress suite", "",
              f"{'Quick subset' if args.quick else 'Full suite'}, {RESOLUTION[0]}x{RESOLUTION[1]}, {SPP} spp, "
              f"box filter; {platform.node()}, {platform.processor() or platform.machine()}, "
              f"{time.strftime('%Y-%m-%d')}.", "",
              "| case | result | seconds | checks | figures |", "|---|---|---|---|---|"]
    for name, status, seconds, doc, figures in rows:
        report.append(f"| {name} | {status} | {seconds:.1f} | {' '.join(doc.split())} | {fmt(figures)} |")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "stress.md").write_text("\n".join(report) + "\n")
    print(f"\n{len(rows) - len(failed)} of {len(rows)} cases pass" + (f"; failed: {', '.join(failed)}" if failed else ""))
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
