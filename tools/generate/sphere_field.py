#!/usr/bin/env python3
"""Generate scenes/sphere-field/sphere-field.glb: a field of 800 smooth icospheres (1280
triangles each) on a ground plane, in three materials (rough white dielectric, glossy
copper, smooth blue plastic), lit by an emissive panel and a sun: about one million
triangles, for throughput figures with incoherent rays. The sphere mesh is stored once and
placed by 800 nodes (lucerna flattens them, so the BVH holds every triangle).

    python3 tools/generate/sphere_field.py [output.glb]
"""
import json
import random
import struct
import sys
from pathlib import Path

from lucerna_tools.gltf_writer import icosphere, rotation_between, unit

SUBDIVISIONS = 3
GRID = (40, 20)


def build():
    rng = random.Random(7)
    verts, faces = icosphere(SUBDIVISIONS)
    blob = bytearray()
    views, accessors = [], []

    def add(data, kind, component, count, extra=None):
        while len(blob) % 4:
            blob.append(0)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
        blob.extend(data)
        acc = {"bufferView": len(views) - 1, "componentType": component, "count": count, "type": kind}
        acc.update(extra or {})
        accessors.append(acc)
        return len(accessors) - 1

    pos = add(b"".join(struct.pack("<3f", *v) for v in verts), "VEC3", 5126, len(verts),
              {"min": [-1, -1, -1], "max": [1, 1, 1]})
    nrm = add(b"".join(struct.pack("<3f", *v) for v in verts), "VEC3", 5126, len(verts))
    idx = add(b"".join(struct.pack("<3H", *f) for f in faces), "SCALAR", 5123, 3 * len(faces))
    ground = [(-30, 0, -30), (30, 0, -30), (30, 0, 30), (-30, 0, 30)]
    gpos = add(b"".join(struct.pack("<3f", *v) for v in ground), "VEC3", 5126, 4,
               {"min": [-30, 0, -30], "max": [30, 0, 30]})
    gidx = add(struct.pack("<6H", 0, 2, 1, 0, 3, 2), "SCALAR", 5123, 6)
    panel = [(-6, 12, -4), (6, 12, -4), (6, 12, 4), (-6, 12, 4)]
    ppos = add(b"".join(struct.pack("<3f", *v) for v in panel), "VEC3", 5126, 4,
               {"min": [-6, 12, -4], "max": [6, 12, 4]})

    materials = [
        {"name": "white", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1], "metallicFactor": 0, "roughnessFactor": 0.9}},
        {"name": "copper", "pbrMetallicRoughness": {"baseColorFactor": [0.95, 0.64, 0.54, 1], "metallicFactor": 1, "roughnessFactor": 0.3}},
        {"name": "blue", "pbrMetallicRoughness": {"baseColorFactor": [0.1, 0.2, 0.7, 1], "metallicFactor": 0, "roughnessFactor": 0.15}},
        {"name": "ground", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.45, 0.4, 1], "metallicFactor": 0, "roughnessFactor": 1}},
        {"name": "panel", "emissiveFactor": [1, 0.9, 0.8], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 8}},
         "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1]}},
    ]
    meshes = [{"name": f"sphere_{m}", "primitives": [{"attributes": {"POSITION": pos, "NORMAL": nrm}, "indices": idx, "material": m}]}
              for m in range(3)]
    meshes.append({"name": "ground", "primitives": [{"attributes": {"POSITION": gpos}, "indices": gidx, "material": 3}]})
    meshes.append({"name": "panel", "primitives": [{"attributes": {"POSITION": ppos}, "indices": gidx, "material": 4}]})
    nodes = []
    for i in range(GRID[0]):
        for j in range(GRID[1]):
            r = rng.uniform(0.25, 0.55)
            x = (i - GRID[0] / 2 + rng.uniform(-0.3, 0.3)) * 1.2
            z = (j - GRID[1] / 2 + rng.uniform(-0.3, 0.3)) * 1.2
            nodes.append({"mesh": rng.randrange(3), "translation": [x, r, z], "scale": [r, r, r]})
    nodes.append({"name": "ground", "mesh": 3})
    nodes.append({"name": "panel", "mesh": 4})
    # Lights and cameras look down their -Z axis.
    nodes.append({"name": "sun", "extensions": {"KHR_lights_punctual": {"light": 0}},
                  "rotation": rotation_between([0, 0, -1], unit([-1, -2, -1]))})
    eye = [0, 6, 20]
    nodes.append({"name": "camera", "camera": 0, "translation": eye,
                  "rotation": rotation_between([0, 0, -1], unit([-e for e in eye]))})
    doc = {
        "asset": {"version": "2.0", "generator": "lucerna tools/generate/sphere_field.py"},
        "extensionsUsed": ["KHR_materials_emissive_strength", "KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [{"type": "directional", "intensity": 2.0, "color": [1, 0.95, 0.85]}]}},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "cameras": [{"name": "camera", "type": "perspective", "perspective": {"yfov": 0.7, "aspectRatio": 1.5, "znear": 0.05}}],
        "meshes": meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(blob)}],
    }
    return doc, bytes(blob)


def glb(doc, blob):
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    blob = blob + b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(js) + 8 + len(blob)
    return (b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(js)) + b"JSON" + js
            + struct.pack("<I", len(blob)) + b"BIN\0" + blob)


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else \
        Path(__file__).resolve().parents[2] / "scenes" / "sphere-field" / "sphere-field.glb"
    out.parent.mkdir(parents=True, exist_ok=True)
    doc, blob = build()
    out.write_bytes(glb(doc, blob))
    triangles = GRID[0] * GRID[1] * 20 * 4 ** SUBDIVISIONS + 4
    print(f"wrote {out} ({triangles} triangles when flattened)")


if __name__ == "__main__":
    main()
