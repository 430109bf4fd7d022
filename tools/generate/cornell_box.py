#!/usr/bin/env python3
"""Generate scenes/cornell-box/cornell-box.gltf from the Cornell box measurements.

Geometry: the measured Cornell box (https://www.graphics.cornell.edu/online/box/data.html),
converted from millimetres to metres. Reflectances and the light's radiance are the RGB
values of Mitsuba 3's `cbox` scene, so that tools/lucerna_tools/mitsuba_compare.py can render the same
scene with Mitsuba 3. Every material is a Lambertian (lucerna's `extras` selector), the walls
are double-sided and the light emits downwards only.

The output is a single .gltf with its buffer embedded as a data URI, so the renderer can
embed it as the default scene. Only the Python standard library is used.

    python3 tools/generate/cornell_box.py [output.gltf]
"""
import base64
import json
import struct
import sys
from pathlib import Path

MM = 0.001

WHITE = [0.885809, 0.698859, 0.666422]
RED = [0.570068, 0.0430135, 0.0443706]
GREEN = [0.105421, 0.37798, 0.076425]
LIGHT_RADIANCE = [18.387, 13.9873, 6.75357]
LIGHT_ALBEDO = [0.78, 0.78, 0.78]

# Quads in millimetres, each with the point its front side must face ("in": the box
# interior, "out": away from the block's centre).
BOX_CENTRE = (278.0, 274.4, 279.6)
SHORT_CENTRE = (185.0, 82.5, 169.0)
TALL_CENTRE = (368.5, 165.0, 351.5)

QUADS = {
    "floor": ("white", BOX_CENTRE, "towards", [
        [(552.8, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 559.2), (549.6, 0.0, 559.2)]]),
    "ceiling": ("white", BOX_CENTRE, "towards", [
        [(556.0, 548.8, 0.0), (556.0, 548.8, 559.2), (0.0, 548.8, 559.2), (0.0, 548.8, 0.0)]]),
    "back_wall": ("white", BOX_CENTRE, "towards", [
        [(549.6, 0.0, 559.2), (0.0, 0.0, 559.2), (0.0, 548.8, 559.2), (556.0, 548.8, 559.2)]]),
    "green_wall": ("green", BOX_CENTRE, "towards", [
        [(0.0, 0.0, 559.2), (0.0, 0.0, 0.0), (0.0, 548.8, 0.0), (0.0, 548.8, 559.2)]]),
    "red_wall": ("red", BOX_CENTRE, "towards", [
        [(552.8, 0.0, 0.0), (549.6, 0.0, 559.2), (556.0, 548.8, 559.2), (556.0, 548.8, 0.0)]]),
    "short_block": ("white", SHORT_CENTRE, "away", [
        [(130.0, 165.0, 65.0), (82.0, 165.0, 225.0), (240.0, 165.0, 272.0), (290.0, 165.0, 114.0)],
        [(290.0, 0.0, 114.0), (290.0, 165.0, 114.0), (240.0, 165.0, 272.0), (240.0, 0.0, 272.0)],
        [(130.0, 0.0, 65.0), (130.0, 165.0, 65.0), (290.0, 165.0, 114.0), (290.0, 0.0, 114.0)],
        [(82.0, 0.0, 225.0), (82.0, 165.0, 225.0), (130.0, 165.0, 65.0), (130.0, 0.0, 65.0)],
        [(240.0, 0.0, 272.0), (240.0, 165.0, 272.0), (82.0, 165.0, 225.0), (82.0, 0.0, 225.0)]]),
    "tall_block": ("white", TALL_CENTRE, "away", [
        [(423.0, 330.0, 247.0), (265.0, 330.0, 296.0), (314.0, 330.0, 456.0), (472.0, 330.0, 406.0)],
        [(423.0, 0.0, 247.0), (423.0, 330.0, 247.0), (472.0, 330.0, 406.0), (472.0, 0.0, 406.0)],
        [(472.0, 0.0, 406.0), (472.0, 330.0, 406.0), (314.0, 330.0, 456.0), (314.0, 0.0, 456.0)],
        [(314.0, 0.0, 456.0), (314.0, 330.0, 456.0), (265.0, 330.0, 296.0), (265.0, 0.0, 296.0)],
        [(265.0, 0.0, 296.0), (265.0, 330.0, 296.0), (423.0, 330.0, 247.0), (423.0, 0.0, 247.0)]]),
    # 0.1 mm below the ceiling, facing down.
    "light": ("light", (278.0, 0.0, 279.5), "towards", [
        [(343.0, 548.7, 227.0), (343.0, 548.7, 332.0), (213.0, 548.7, 332.0), (213.0, 548.7, 227.0)]]),
}


def sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def oriented(quad, reference, mode):
    """Return the quad wound counter-clockwise as seen from the side it must face."""
    normal = cross(sub(quad[1], quad[0]), sub(quad[2], quad[0]))
    centre = tuple(sum(c) / 4.0 for c in zip(*quad))
    to_ref = sub(reference, centre)
    faces_ref = dot(normal, to_ref) > 0.0
    if faces_ref != (mode == "towards"):
        quad = list(reversed(quad))
    return quad


def material(name, colour, emissive=None, pbr=False):
    """A Lambertian material: lucerna's `lambert` model named in `extras`, or (`pbr`) as a
    plain glTF file says it, metallic-roughness with KHR_materials_specular's specularFactor
    0, which is exactly Lambert too (every renderer reads it)."""
    m = {
        "name": name,
        "pbrMetallicRoughness": {"baseColorFactor": colour + [1.0], "metallicFactor": 0.0,
                                 "roughnessFactor": 1.0},
        "doubleSided": emissive is None,
    }
    if pbr:
        m["extensions"] = {"KHR_materials_specular": {"specularFactor": 0.0}}
    else:
        m["extras"] = {"lucerna": {"bsdf": "lambert"}}
    if emissive is not None:
        peak = max(emissive)
        m["emissiveFactor"] = [c / peak for c in emissive]
        m.setdefault("extensions", {})["KHR_materials_emissive_strength"] = {"emissiveStrength": peak}
    return m


# The animated variant: over ANIMATION_SECONDS the short block slides 0.1 m towards the red
# wall (LINEAR) and the camera dollies 0.25 m in (CUBICSPLINE, easing in and out).
ANIMATION_SECONDS = 2.0


def animate(nodes, accessors, views, blob):
    def accessor(values, kind):
        data = b"".join(struct.pack(f"<{len(v)}f", *v) for v in values)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
        blob.extend(data)
        accessors.append({"bufferView": len(views) - 1, "componentType": 5126,
                          "count": len(values), "type": kind})
        return len(accessors) - 1

    times = accessor([(0.0,), (ANIMATION_SECONDS,)], "SCALAR")
    slide = accessor([(0.0, 0.0, 0.0), (0.1, 0.0, 0.0)], "VEC3")
    camera = next(i for i, n in enumerate(nodes) if n["name"] == "camera")
    start, end = nodes[camera]["translation"], [0.278, 0.273, -0.55]
    zero = (0.0, 0.0, 0.0)
    dolly = accessor([zero, tuple(start), zero, zero, tuple(end), zero], "VEC3")
    block = next(i for i, n in enumerate(nodes) if n["name"] == "short_block")
    return [{"name": "shot", "samplers": [
        {"input": times, "output": slide, "interpolation": "LINEAR"},
        {"input": times, "output": dolly, "interpolation": "CUBICSPLINE"}],
        "channels": [{"sampler": 0, "target": {"node": block, "path": "translation"}},
                     {"sampler": 1, "target": {"node": camera, "path": "translation"}}]}]


def build(animated=False, pbr=False):
    materials = [material("white", WHITE, pbr=pbr), material("red", RED, pbr=pbr),
                 material("green", GREEN, pbr=pbr),
                 material("light", LIGHT_ALBEDO, LIGHT_RADIANCE, pbr=pbr)]
    material_index = {"white": 0, "red": 1, "green": 2, "light": 3}
    blob = bytearray()
    accessors, views, meshes, nodes = [], [], [], []
    for name, (mat, ref, mode, quads) in QUADS.items():
        positions, indices = [], []
        for quad in quads:
            quad = oriented(quad, ref, mode)
            base = len(positions)
            positions.extend(tuple(c * MM for c in p) for p in quad)
            indices.extend([base, base + 1, base + 2, base, base + 2, base + 3])
        pos_bytes = b"".join(struct.pack("<3f", *p) for p in positions)
        idx_bytes = b"".join(struct.pack("<H", i) for i in indices)
        lo = [min(p[k] for p in positions) for k in range(3)]
        hi = [max(p[k] for p in positions) for k in range(3)]
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(pos_bytes),
                      "target": 34962})
        blob += pos_bytes
        accessors.append({"bufferView": len(views) - 1, "componentType": 5126,
                          "count": len(positions), "type": "VEC3", "min": lo, "max": hi})
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(idx_bytes),
                      "target": 34963})
        blob += idx_bytes
        while len(blob) % 4:
            blob.append(0)
        accessors.append({"bufferView": len(views) - 1, "componentType": 5123,
                          "count": len(indices), "type": "SCALAR"})
        meshes.append({"name": name, "primitives": [{
            "attributes": {"POSITION": len(accessors) - 2}, "indices": len(accessors) - 1,
            "material": material_index[mat]}]})
        nodes.append({"name": name, "mesh": len(meshes) - 1})
    nodes.append({"name": "camera", "camera": 0, "translation": [0.278, 0.273, -0.8],
                  "rotation": [0.0, 1.0, 0.0, 0.0]})
    animations = animate(nodes, accessors, views, blob) if animated else []
    uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()
    doc = {
        "asset": {"version": "2.0", "generator": "lucerna tools/generate/cornell_box.py"},
        "extensionsUsed": ["KHR_materials_emissive_strength"]
        + (["KHR_materials_specular"] if pbr else []),
        "scene": 0,
        "scenes": [{"name": "cornell-box", "nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "cameras": [{"name": "camera", "type": "perspective", "perspective": {
            "yfov": 0.6860514, "aspectRatio": 1.0, "znear": 0.01}}],
        "meshes": meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(blob), "uri": uri}],
    }
    if animations:
        doc["animations"] = animations
    return doc


def main():
    # cornell_box.py [--animated | --pbr] [OUT]
    args = sys.argv[1:]
    animated = "--animated" in args
    pbr = "--pbr" in args
    args = [a for a in args if a not in ("--animated", "--pbr")]
    name = "cornell-box-animated.gltf" if animated else "cornell-box-pbr.gltf" if pbr else "cornell-box.gltf"
    out = Path(args[0]) if args else \
        Path(__file__).resolve().parents[2] / "scenes" / "cornell-box" / name
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(build(animated, pbr), indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
