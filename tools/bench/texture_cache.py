#!/usr/bin/env python3
"""Textures larger than memory: a texture set of twice --max-memory renders through the tile
cache, says so, stays under the limit and gives the image of the same render with every
texture in memory.

The scene (generated): a wall of N quads, each with a base-colour texture of its own
(SIZE x SIZE 8-bit RGB PNGs of distinct patterns), lit by a constant environment. With
--max-memory LIMIT the textures (N x SIZE^2 x 4 bytes decoded) are twice LIMIT; the texture
memory is LIMIT / 2. For each texture filter, the render through the cache is compared,
pixel for pixel, with the render that keeps the textures in memory (--max-memory off), and
time, tiles read and peak memory (lucerna's --stats-json, and with its children, the USD
plugin, by GNU time: /usr/bin/time) are reported. With --usd the same wall is a USD stage,
so the textures pass through the USD plugin (which gets the same --max-memory).

    .venv/bin/python tools/bench/texture_cache.py [--images 8] [--size 4096] [--limit 256M]
        [--spp 16] [--resolution 960x480] [--usd]

Prints a Markdown table (the one in tools/bench/results/texture-cache.md).
"""
import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

import lucerna_tools as lt
from lucerna_tools.gltf_writer import GltfWriter


def pattern(index, size):
    """A distinct, smooth-and-sharp pattern (checks, rings and a gradient) as 8-bit RGB."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    checks = ((np.floor(x * (8 + index)) + np.floor(y * (8 + index))) % 2).astype(np.float32)
    rings = 0.5 + 0.5 * np.sin(60.0 * np.hypot(x - 0.5, y - 0.5) + index)
    rgb = np.stack([0.2 + 0.6 * checks, rings, 0.3 + 0.5 * x * (index % 3) / 2 + 0.2 * y], axis=-1)
    return (np.clip(rgb, 0, 1) * 255).astype(np.uint8)


def scene(folder, images, size):
    w = GltfWriter("tools/bench/texture_cache.py")
    columns = (images + 1) // 2
    for i in range(images):
        Image.fromarray(pattern(i, size)).save(folder / f"wall{i}.png", compress_level=1)
        material = w.material(f"wall{i}", base=(1, 1, 1), base_texture=w.texture(f"wall{i}.png"))
        x0, y0 = (i % columns) - columns / 2, (i // columns) - 1.0
        positions = [(x0, y0, 0), (x0 + 1, y0, 0), (x0 + 1, y0 + 1, 0), (x0, y0 + 1, 0)]
        uvs = [(0, 1), (1, 1), (1, 0), (0, 0)]
        mesh = w.mesh(f"wall{i}", positions, [(0, 1, 2), (0, 2, 3)], material,
                      normals=[(0, 0, 1)] * 4, uvs=uvs)
        w.node(mesh=mesh, name=f"wall{i}")
    w.camera("camera", yfov=0.9, aspect=2.0, translation=[0, 0, 2.6], target=[0, 0, 0])
    path = folder / "wall.gltf"
    w.write_gltf(path)
    return path


def usd_scene(folder, images):
    """The same wall as a USD stage (UsdPreviewSurface with a UsdUVTexture a quad), reading
    the PNGs `scene` wrote: the textures go through the USD plugin."""
    columns = (images + 1) // 2
    prims = []
    for i in range(images):
        x0, y0 = (i % columns) - columns / 2, (i // columns) - 1.0
        points = [(x0, y0, 0), (x0 + 1, y0, 0), (x0 + 1, y0 + 1, 0), (x0, y0 + 1, 0)]
        prims.append(f"""
    def Mesh "wall{i}" (prepend apiSchemas = ["MaterialBindingAPI"])
    {{
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = {points}
        normal3f[] normals = [(0, 0, 1), (0, 0, 1), (0, 0, 1), (0, 0, 1)] (interpolation = "vertex")
        texCoord2f[] primvars:st = [(0, 0), (1, 0), (1, 1), (0, 1)] (interpolation = "vertex")
        rel material:binding = </World/wall{i}_material>
    }}
    def Material "wall{i}_material"
    {{
        token outputs:surface.connect = </World/wall{i}_material/surface.outputs:surface>
        def Shader "surface"
        {{
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor.connect = </World/wall{i}_material/texture.outputs:rgb>
            float inputs:roughness = 0.5
            token outputs:surface
        }}
        def Shader "texture"
        {{
            uniform token info:id = "UsdUVTexture"
            asset inputs:file = @wall{i}.png@
            float2 inputs:st.connect = </World/wall{i}_material/st.outputs:result>
            float3 outputs:rgb
        }}
        def Shader "st"
        {{
            uniform token info:id = "UsdPrimvarReader_float2"
            string inputs:varname = "st"
            float2 outputs:result
        }}
    }}""")
    path = folder / "wall.usda"
    path.write_text(f"""#usda 1.0
(
    defaultPrim = "World"
    upAxis = "Y"
)
def Xform "World"
{{
    def Camera "camera"
    {{
        float focalLength = 50
        float horizontalAperture = 96.63
        float verticalAperture = 48.31
        double3 xformOp:translate = (0, 0, 2.6)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}{"".join(prims)}
}}
""")
    return path


def render(scene_path, out, resolution, spp, limit, texture_filter):
    stats = out.with_suffix(".json")
    cmd = [lt.BINARY, "render", str(scene_path), "-o", str(out), "--spp", str(spp),
           "--resolution", resolution, "--max-memory", limit, "--texture-filter", texture_filter,
           "--env", "1,1,1", "--stats-json", str(stats)]
    start = time.perf_counter()
    # GNU time reports the render's peak resident memory and that of the children it waited
    # for (the USD plugin). Not wait4's figure from here: a child started by this process
    # counts this process's own peak, which holds the images compared.
    peak = out.with_suffix(".peak")
    done = subprocess.run(["/usr/bin/time", "-f", "%M", "-o", str(peak), *cmd],
                          capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: exit {done.returncode}: {done.stderr}")
    said = [line for line in done.stderr.splitlines() if "tiled copies" in line]
    channels, _ = lt.read_exr(out)
    stats = json.loads(stats.read_text())
    stats["peak_with_plugin"] = int(peak.read_text().split()[-1]) * 1024
    return lt.rgb(channels), stats, seconds, said


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=8)
    parser.add_argument("--size", type=int, default=4096)
    parser.add_argument("--limit", default="256M")
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--resolution", default="960x480")
    parser.add_argument("--usd", action="store_true",
                        help="the wall as a USD stage: the textures pass through the plugin")
    args = parser.parse_args()
    decoded = args.images * args.size ** 2 * 4
    print(f"{args.images} textures of {args.size}x{args.size}: {decoded / 2**20:.0f} MiB decoded, "
          f"--max-memory {args.limit}\n")
    print("| filter | textures | seconds (whole process) | tiles read | MiB read | peak memory MiB | "
          "peak with the USD plugin MiB | pixels differing from in memory |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = scene(folder, args.images, args.size)
        if args.usd:
            path = usd_scene(folder, args.images)
        for texture_filter in ("mip", "bilinear"):
            resident, resident_stats, resident_seconds, _ = render(
                path, folder / "memory.exr", args.resolution, args.spp, "off", texture_filter)
            cached, stats, seconds, said = render(
                path, folder / "cache.exr", args.resolution, args.spp, args.limit, texture_filter)
            if not said:
                sys.exit("the render through the cache did not say so")
            cache = stats["texture_cache"]
            differing = int(np.count_nonzero(np.any(cached != resident, axis=-1)))
            print(f"| {texture_filter} | in memory | {resident_seconds:.2f} | - | - | "
                  f"{resident_stats['peak_memory_bytes'] / 2**20:.0f} | "
                  f"{resident_stats['peak_with_plugin'] / 2**20:.0f} | - |")
            print(f"| {texture_filter} | tile cache | {seconds:.2f} | {cache['tiles_read']} | "
                  f"{cache['bytes_read'] / 2**20:.0f} | {stats['peak_memory_bytes'] / 2**20:.0f} | "
                  f"{stats['peak_with_plugin'] / 2**20:.0f} | "
                  f"{differing} |", flush=True)
        print(f"\nsaid: {said[0]}")


if __name__ == "__main__":
    main()
