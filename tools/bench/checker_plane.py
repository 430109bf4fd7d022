#!/usr/bin/env python3
"""Writes the checkerboard plane to the horizon that texture filtering is measured on.

A 400 x 400 plane whose 64 x 64-texel texture (8 x 8 checks, black and white, sRGB) repeats
200 times each way, seen from 1 unit above it looking 8 degrees down, unlit
(KHR_materials_unlit), so a pixel's value is the texture's mean over the pixel: whatever
noise a render shows is aliasing. Usage: checker_plane.py OUT.gltf
"""
import base64
import json
import struct
import sys
import zlib


def png_rgba(width, height, pixel):
    """A PNG of `pixel(x, y) -> (r, g, b, a)` bytes."""
    raw = b"".join(
        b"\0" + b"".join(bytes(pixel(x, y)) for x in range(width)) for y in range(height)
    )

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    header = struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(raw, 9))
        + chunk(b"IEND", b"")
    )


def scene(size=400.0, repeats=200.0, texels=64, checks=8, pitch_degrees=8.0):
    check = texels // checks
    png = png_rgba(
        texels,
        texels,
        lambda x, y: (255, 255, 255, 255) if (x // check + y // check) % 2 else (0, 0, 0, 255),
    )
    h = size / 2
    positions = struct.pack("<12f", -h, 0, -h, h, 0, -h, h, 0, h, -h, 0, h)
    uvs = struct.pack("<8f", 0, 0, repeats, 0, repeats, repeats, 0, repeats)
    indices = struct.pack("<6I", 0, 2, 1, 0, 3, 2)
    binary = positions + uvs + indices
    image_offset = len(binary)
    binary += png
    import math

    pitch = math.radians(pitch_degrees)
    # Rotation about x by -pitch (looking down), as a quaternion (x, y, z, w).
    rotation = [-math.sin(pitch / 2), 0.0, 0.0, math.cos(pitch / 2)]
    doc = {
        "asset": {"version": "2.0", "generator": "lucerna tools/bench/checker_plane.py"},
        "extensionsUsed": ["KHR_materials_unlit"],
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [
            {"mesh": 0},
            {"camera": 0, "translation": [0.0, 1.0, 0.0], "rotation": rotation},
        ],
        "cameras": [
            {"type": "perspective", "perspective": {"yfov": 0.6, "znear": 0.01, "aspectRatio": 1.5}}
        ],
        "meshes": [
            {
                "primitives": [
                    {
                        "attributes": {"POSITION": 0, "TEXCOORD_0": 1},
                        "indices": 2,
                        "material": 0,
                    }
                ]
            }
        ],
        "materials": [
            {
                "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0},
                "extensions": {"KHR_materials_unlit": {}},
            }
        ],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"wrapS": 10497, "wrapT": 10497}],
        "images": [{"bufferView": 3, "mimeType": "image/png"}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-h, 0, -h], "max": [h, 0, h]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5125, "count": 6, "type": "SCALAR"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 32},
            {"buffer": 0, "byteOffset": 80, "byteLength": 24},
            {"buffer": 0, "byteOffset": image_offset, "byteLength": len(png)},
        ],
        "buffers": [
            {
                "byteLength": len(binary),
                "uri": "data:application/octet-stream;base64," + base64.b64encode(binary).decode(),
            }
        ],
    }
    return doc


if __name__ == "__main__":
    with open(sys.argv[1], "w") as f:
        json.dump(scene(), f)
