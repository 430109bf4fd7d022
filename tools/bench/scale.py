#!/usr/bin/env python3
"""Large scenes: memory per triangle, BVH build and preparation time, and the memory
estimate against the measured peak, on generated meshes of millions of unique triangles
and on an instanced forest of a billion; Mitsuba 3 (Embree's BVH) loading the same meshes
as the peer.

Scenes (generated, glTF binary): `grid-N` is one height-field grid of N million unique
triangles; `forest` is one grid of 100k triangles placed 10,000 times (10^9 triangles
instanced). lucerna renders each at 64x64, 1 spp, beauty only (so the film is nothing),
and reports from its log and --stats-json: the whole process's seconds, the preparation
(render space, BVHs, lights), the BVH build, the peak resident memory, bytes a triangle,
and `lucerna inspect`'s estimate (without its film) over the peak. Mitsuba loads the mesh
as a PLY (`mi.load_dict`, Embree's BVH built at load) in a process of its own; its peak
memory over that of an empty scene's process is its cost of the mesh.

    .venv/bin/python tools/bench/scale.py [--millions 10,30] [--forest] [--mitsuba]

Prints a Markdown table (the one in tools/bench/results/scale.md).
"""
import argparse
import json
import re
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import lucerna_tools as lt

UNITS = {"B": 1, "KiB": 2**10, "MiB": 2**20, "GiB": 2**30, "TiB": 2**40}


def grid(triangles):
    """Positions (f32) and triangles (u32) of a bumpy square grid of about `triangles`."""
    n = max(1, int(round((triangles / 2) ** 0.5)))
    i = np.arange(n + 1, dtype=np.float32)
    xs, zs = np.meshgrid(i / n * 2 - 1, i / n * 2 - 1)
    ys = 0.02 * np.sin(xs * 37.0) * np.cos(zs * 29.0)
    positions = np.stack([xs, ys, zs], axis=-1).reshape(-1, 3).astype("<f4")
    a = (np.arange(n, dtype=np.uint32)[:, None] * (n + 1) + np.arange(n, dtype=np.uint32)[None, :]).reshape(-1)
    tris = np.empty((2 * a.size, 3), dtype="<u4")
    tris[0::2] = np.stack([a, a + n + 1, a + 1], 1)
    tris[1::2] = np.stack([a + 1, a + n + 1, a + n + 2], 1)
    return positions, tris


def write_glb(path, positions, tris, placements):
    """A glTF binary of one mesh placed at each (x, z, angle, scale) of `placements`."""
    blob = positions.tobytes() + tris.tobytes()
    nodes = [{"mesh": 0, "translation": [float(x), 0.0, float(z)],
              "rotation": [0.0, float(np.sin(a / 2)), 0.0, float(np.cos(a / 2))], "scale": [float(s)] * 3}
             for x, z, a, s in placements]
    span = max(1.0, max(abs(p[0]) + p[3] for p in placements), max(abs(p[1]) + p[3] for p in placements))
    nodes.append({"camera": 0, "translation": [0.0, 1.2 * span, 1.6 * span],
                  "rotation": [float(np.sin(-0.3)), 0.0, 0.0, float(np.cos(-0.3))]})
    doc = {
        "asset": {"version": "2.0", "generator": "tools/bench/scale.py"},
        "scene": 0, "scenes": [{"nodes": list(range(len(nodes)))}], "nodes": nodes,
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": 1.0, "znear": 0.01}}],
        "materials": [{"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.6, 0.6, 1],
                                                                "metallicFactor": 0, "roughnessFactor": 1}}],
        "meshes": [{"name": "grid", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": positions.nbytes},
                        {"buffer": 0, "byteOffset": positions.nbytes, "byteLength": tris.nbytes}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(positions), "type": "VEC3",
                       "min": positions.min(0).tolist(), "max": positions.max(0).tolist()},
                      {"bufferView": 1, "componentType": 5125, "count": tris.size, "type": "SCALAR"}],
    }
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    blob += b"\0" * (-len(blob) % 4)
    with open(path, "wb") as f:
        f.write(b"glTF" + struct.pack("<II", 2, 12 + 8 + len(js) + 8 + len(blob)))
        f.write(struct.pack("<I", len(js)) + b"JSON" + js)
        f.write(struct.pack("<I", len(blob)) + b"BIN\0")
        f.write(blob)


def write_ply(path, positions, tris):
    with open(path, "wb") as f:
        f.write(f"ply\nformat binary_little_endian 1.0\nelement vertex {len(positions)}\n"
                f"property float x\nproperty float y\nproperty float z\nelement face {len(tris)}\n"
                "property list uchar int vertex_indices\nend_header\n".encode())
        f.write(positions.tobytes())
        faces = np.empty(len(tris), dtype=[("n", "u1"), ("i", "<i4", 3)])
        faces["n"] = 3
        faces["i"] = tris
        f.write(faces.tobytes())


def parse_bytes(text):
    number, unit = text.strip().split()
    return float(number) * UNITS[unit]


def lucerna(path, folder):
    inspect = subprocess.run([lt.BINARY, "inspect", str(path), "--no-validate"], capture_output=True, text=True)
    line = next(x for x in inspect.stdout.splitlines() if "memory" in x)
    film = parse_bytes(line.rsplit("(", 1)[1].split("film ")[1].rstrip(")"))
    estimate = parse_bytes(line.split("about ")[1].split(" (")[0]) - film
    stats = folder / "stats.json"
    cmd = [lt.BINARY, "render", str(path), "-o", str(folder / "out.exr"), "--spp", "1", "--resolution", "64x64",
           "--aov", "beauty", "--env", "1,1,1", "--max-memory", "off", "--stats-json", str(stats)]
    start = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(done.stderr)
    bvh = float(re.search(r"BVH built in ([0-9.]+) s", done.stderr).group(1))
    figures = json.loads(stats.read_text())
    return {"seconds": seconds, "prepare": figures["prepare_seconds"], "bvh": bvh,
            "peak": figures["peak_memory_bytes"], "estimate": estimate}


MITSUBA = """
import resource, sys, time
import mitsuba as mi
mi.set_variant("llvm_ad_rgb")
start = time.perf_counter()
shapes = {"mesh": {"type": "ply", "filename": sys.argv[1]}} if len(sys.argv) > 1 else {}
scene = mi.load_dict({"type": "scene", **shapes})
print(time.perf_counter() - start, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
"""


def mitsuba(ply=None):
    done = subprocess.run([sys.executable, "-c", MITSUBA] + ([str(ply)] if ply else []),
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(done.stderr)
    seconds, peak = done.stdout.split()
    return float(seconds), int(peak)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--millions", default="10,30")
    parser.add_argument("--forest", action="store_true")
    parser.add_argument("--mitsuba", action="store_true")
    args = parser.parse_args()
    print("| scene | triangles | instanced | whole s | prepare s | BVH s | BVH s / M triangles | peak MiB | "
          "bytes / triangle | estimate / peak | Mitsuba load s | Mitsuba MiB over empty | Mitsuba bytes / triangle |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    empty = mitsuba()[1] if args.mitsuba else 0
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        cases = [(f"grid-{m}M", int(float(m) * 1e6), [(0, 0, 0, 1)]) for m in args.millions.split(",") if m]
        if args.forest:
            side = 100
            rng = np.random.default_rng(1)
            placements = [(2.2 * (i % side - side / 2), 2.2 * (i // side - side / 2), rng.uniform(0, 6.28),
                           rng.uniform(0.8, 1.1)) for i in range(side * side)]
            cases.append(("forest", 100_000, placements))
        for name, triangles, placements in cases:
            positions, tris = grid(triangles)
            path = folder / f"{name}.glb"
            write_glb(path, positions, tris, placements)
            unique = len(tris)
            total = unique * len(placements)
            row = lucerna(path, folder)
            path.unlink()
            cells = [name, f"{unique:,}", f"{total:,}", f"{row['seconds']:.1f}", f"{row['prepare']:.1f}",
                     f"{row['bvh']:.2f}", f"{row['bvh'] / unique * 1e6:.2f}", f"{row['peak'] / 2**20:.0f}",
                     f"{row['peak'] / unique:.0f}", f"{row['estimate'] / row['peak']:.2f}"]
            if args.mitsuba and len(placements) == 1:
                ply = folder / f"{name}.ply"
                write_ply(ply, positions, tris)
                seconds, peak = mitsuba(ply)
                ply.unlink()
                cells += [f"{seconds:.1f}", f"{(peak - empty) / 2**20:.0f}", f"{(peak - empty) / unique:.0f}"]
            else:
                cells += ["-", "-", "-"]
            print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
