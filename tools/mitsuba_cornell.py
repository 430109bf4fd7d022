#!/usr/bin/env python3
"""Render scenes/cornell-box with lucerna and with Mitsuba 3 (scalar_rgb) from the same
geometry, and compare them.

The glTF is read here (positions, indices, materials, camera), each mesh is written as a PLY
for Mitsuba with the same Lambertian reflectances, the same one-sided area light and the same
camera; both renderers use a box pixel filter and unlimited path depth. The comparison:

    relMSE(lucerna, Mitsuba)   against   relMSE(Mitsuba seed A, Mitsuba seed B)

relMSE(x, ref) = mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01). Both are
dominated by noise when the renderers agree; a bias in lucerna adds to the first only. The
check passes when the first is within 2x the second.

    .venv/bin/python tools/mitsuba_cornell.py [--spp 1024] [--resolution 256] [--json out.json]

Needs numpy, mitsuba and OpenImageIO (tests/requirements.txt) and a release build of lucerna.
"""
import argparse
import base64
import json
import math
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SCENE = ROOT / "scenes" / "cornell-box" / "cornell-box.gltf"


def quaternion_matrix(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def node_matrix(node):
    if "matrix" in node:
        return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
    m = np.eye(4)
    m[:3, :3] = quaternion_matrix(node.get("rotation", [0, 0, 0, 1])) @ np.diag(node.get("scale", [1, 1, 1]))
    m[:3, 3] = node.get("translation", [0, 0, 0])
    return m


def read_gltf(path):
    """Meshes (world positions, triangles, material) and the first camera of a glTF whose
    buffers are data URIs."""
    doc = json.loads(Path(path).read_text())
    buffers = [base64.b64decode(b["uri"].split(",", 1)[1]) for b in doc["buffers"]]

    def accessor(i):
        a = doc["accessors"][i]
        view = doc["bufferViews"][a["bufferView"]]
        data = buffers[view["buffer"]]
        offset = view.get("byteOffset", 0) + a.get("byteOffset", 0)
        fmt = {5126: "f", 5123: "H", 5125: "I"}[a["componentType"]]
        width = {"SCALAR": 1, "VEC3": 3}[a["type"]]
        values = struct.unpack_from(f"<{a['count'] * width}{fmt}", data, offset)
        return np.array(values).reshape(a["count"], width)

    meshes, camera = [], None
    scene = doc["scenes"][doc.get("scene", 0)]

    def visit(index, parent):
        nonlocal camera
        node = doc["nodes"][index]
        world = parent @ node_matrix(node)
        if "mesh" in node:
            for prim in doc["meshes"][node["mesh"]]["primitives"]:
                p = accessor(prim["attributes"]["POSITION"])
                p = (world @ np.c_[p, np.ones(len(p))].T).T[:, :3]
                tris = accessor(prim["indices"]).reshape(-1, 3)
                meshes.append((node.get("name", f"mesh{len(meshes)}"), p, tris, doc["materials"][prim["material"]]))
        if "camera" in node and camera is None:
            cam = doc["cameras"][node["camera"]]["perspective"]
            camera = {
                "origin": world[:3, 3],
                "forward": world[:3, :3] @ np.array([0, 0, -1.0]),
                "up": world[:3, :3] @ np.array([0, 1.0, 0]),
                "yfov": cam["yfov"],
                "znear": cam.get("znear", 0.01),
            }
        for child in node.get("children", []):
            visit(child, world)

    for root in scene["nodes"]:
        visit(root, np.eye(4))
    return meshes, camera


def write_ply(path, positions, triangles):
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(positions)}\n"
              "property float x\nproperty float y\nproperty float z\n"
              f"element face {len(triangles)}\nproperty list uchar int vertex_indices\nend_header\n")
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(np.asarray(positions, dtype="<f4").tobytes())
        for t in triangles:
            f.write(struct.pack("<B3i", 3, *map(int, t)))


def mitsuba_scene(meshes, camera, width, height, workdir):
    import mitsuba as mi
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": -1},
        "sensor": {
            "type": "perspective",
            "fov": math.degrees(camera["yfov"]),
            "fov_axis": "y",
            "near_clip": camera["znear"],
            "far_clip": 1000.0,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=camera["origin"].tolist(),
                target=(camera["origin"] + camera["forward"]).tolist(),
                up=camera["up"].tolist()),
            "film": {"type": "hdrfilm", "width": width, "height": height,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent"},
        },
    }
    for i, (name, positions, triangles, material) in enumerate(meshes):
        ply = Path(workdir) / f"{i}_{name}.ply"
        write_ply(ply, positions, triangles)
        base = material["pbrMetallicRoughness"]["baseColorFactor"][:3]
        bsdf = {"type": "diffuse", "reflectance": {"type": "rgb", "value": base}}
        if material.get("doubleSided", False):
            bsdf = {"type": "twosided", "bsdf": bsdf}
        shape = {"type": "ply", "filename": str(ply), "face_normals": True, "bsdf": bsdf}
        emissive = material.get("emissiveFactor")
        if emissive:
            strength = material.get("extensions", {}).get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": [c * strength for c in emissive]}}
        scene[f"shape_{i}"] = shape
    return mi.load_dict(scene)


def render_mitsuba(scene, spp, seed):
    import mitsuba as mi
    start = time.perf_counter()
    image = np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)
    return image[:, :, :3], time.perf_counter() - start


def render_lucerna(binary, spp, seed, width, height, workdir):
    import OpenImageIO as oiio
    out = Path(workdir) / f"lucerna_{seed}.exr"
    start = time.perf_counter()
    subprocess.run([binary, "render", str(SCENE), "--spp", str(spp), "--seed", str(seed),
                    "--resolution", f"{width}x{height}", "--filter", "box", "--aov", "beauty",
                    "-q", "-o", str(out)], check=True)
    seconds = time.perf_counter() - start
    image = oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)
    return np.array(image, dtype=np.float64)[:, :, :3], seconds


def relmse(x, ref):
    return float(np.mean((x - ref) ** 2 / (ref ** 2 + 0.01)))


def compare(spp, width, height, binary):
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    meshes, camera = read_gltf(SCENE)
    with tempfile.TemporaryDirectory() as workdir:
        scene = mitsuba_scene(meshes, camera, width, height, workdir)
        mitsuba_a, seconds_a = render_mitsuba(scene, spp, 1)
        mitsuba_b, seconds_b = render_mitsuba(scene, spp, 2)
        lucerna_a, lucerna_seconds = render_lucerna(binary, spp, 1, width, height, workdir)
    result = {
        "spp": spp,
        "resolution": [width, height],
        "relmse_lucerna_vs_mitsuba": relmse(lucerna_a, mitsuba_a),
        "relmse_mitsuba_a_vs_b": relmse(mitsuba_b, mitsuba_a),
        "mean_lucerna": lucerna_a.mean(axis=(0, 1)).tolist(),
        "mean_mitsuba": mitsuba_a.mean(axis=(0, 1)).tolist(),
        "seconds_lucerna": lucerna_seconds,
        "seconds_mitsuba": (seconds_a + seconds_b) / 2,
    }
    result["ratio"] = result["relmse_lucerna_vs_mitsuba"] / result["relmse_mitsuba_a_vs_b"]
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=1024)
    parser.add_argument("--resolution", type=int, default=256, help="square image side")
    parser.add_argument("--lucerna", default=str(ROOT / "target" / "release" / "lucerna"))
    parser.add_argument("--json", help="also write the figures to this file")
    args = parser.parse_args()
    r = compare(args.spp, args.resolution, args.resolution, args.lucerna)
    print(f"Cornell box {args.resolution}x{args.resolution}, {args.spp} spp, box filter")
    print(f"  mean radiance   lucerna {np.round(r['mean_lucerna'], 5)}   Mitsuba {np.round(r['mean_mitsuba'], 5)}")
    print(f"  relMSE(lucerna, Mitsuba A)   = {r['relmse_lucerna_vs_mitsuba']:.6g}")
    print(f"  relMSE(Mitsuba B, Mitsuba A) = {r['relmse_mitsuba_a_vs_b']:.6g}")
    print(f"  ratio = {r['ratio']:.3f} (must be <= 2)")
    print(f"  seconds per render: lucerna {r['seconds_lucerna']:.1f}, Mitsuba {r['seconds_mitsuba']:.1f}")
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=1) + "\n")
    sys.exit(0 if r["ratio"] <= 2.0 else 1)


if __name__ == "__main__":
    main()
