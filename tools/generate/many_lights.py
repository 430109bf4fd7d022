#!/usr/bin/env python3
"""Generate scenes/many-lights/many-lights.glb: a flat of 4 x 2 rooms (4 m square, 3 m
high) behind walls with a doorway each, every room lit by four ceiling panels of its own
(32 lights, 64 emissive triangles, powers differing by room). The camera stands in one
room; most lights are near it but behind a wall, so selection by distance and power (the
light BVH) spends most light samples on lights whose shadow rays are blocked. This is the
case learned, occlusion-aware light selection is for. Materials are plain glTF PBR
(metallic 0, KHR_materials_specular specularFactor 0: exactly Lambert).

    python3 tools/generate/many_lights.py [output.glb]
"""
import sys
from pathlib import Path

from lucerna_tools.gltf_writer import GltfWriter, write_scene

ROOM, HEIGHT, WALL = 4.0, 3.0, 0.1
COLUMNS, ROWS = 4, 2
DOOR = 0.9


def build():
    w = GltfWriter("lucerna tools/generate/many_lights.py")
    lambert = w.lambert_material
    walls = lambert("walls", (0.7, 0.7, 0.68))
    floor = lambert("floor", (0.5, 0.45, 0.4))
    blue = lambert("blue", (0.15, 0.25, 0.6))
    width, depth = COLUMNS * ROOM, ROWS * ROOM

    add_box = w.add_box
    add_box("floor", (-WALL, -WALL, -WALL), (width + WALL, 0.0, depth + WALL), floor)
    add_box("ceiling", (-WALL, HEIGHT, -WALL), (width + WALL, HEIGHT + WALL, depth + WALL), walls)
    add_box("outer_w", (-WALL, 0, -WALL), (0, HEIGHT, depth + WALL), walls)
    add_box("outer_e", (width, 0, -WALL), (width + WALL, HEIGHT, depth + WALL), walls)
    add_box("outer_n", (0, 0, -WALL), (width, HEIGHT, 0), walls)
    add_box("outer_s", (0, 0, depth), (width, HEIGHT, depth + WALL), walls)
    # Walls between columns (along z) with a doorway in each room's span, and between the
    # rows (along x) likewise.
    h = WALL / 2
    for c in range(1, COLUMNS):
        x = c * ROOM
        for r in range(ROWS):
            z0, z1 = r * ROOM, (r + 1) * ROOM
            zc = (z0 + z1) / 2 + (0.8 if (c + r) % 2 else -0.8)
            add_box(f"wall_x{c}_{r}a", (x - h, 0, z0), (x + h, HEIGHT, zc - DOOR / 2), walls)
            add_box(f"wall_x{c}_{r}b", (x - h, 0, zc + DOOR / 2), (x + h, HEIGHT, z1), walls)
            add_box(f"wall_x{c}_{r}c", (x - h, 2.1, zc - DOOR / 2), (x + h, HEIGHT, zc + DOOR / 2), walls)
    for r in range(1, ROWS):
        z = r * ROOM
        for c in range(COLUMNS):
            x0, x1 = c * ROOM, (c + 1) * ROOM
            xc = (x0 + x1) / 2 + 1.0
            add_box(f"wall_z{r}_{c}a", (x0, 0, z - h), (xc - DOOR / 2, HEIGHT, z + h), walls)
            add_box(f"wall_z{r}_{c}b", (xc + DOOR / 2, 0, z - h), (x1, HEIGHT, z + h), walls)
            add_box(f"wall_z{r}_{c}c", (xc - DOOR / 2, 2.1, z - h), (xc + DOOR / 2, HEIGHT, z + h), walls)
    # Four panels under each room's ceiling, facing down; brighter rooms further away.
    y = HEIGHT - 0.01
    for c in range(COLUMNS):
        for r in range(ROWS):
            power = 6.0 + 5.0 * ((c * 3 + r * 5) % 4)
            light = lambert(f"panel_{c}_{r}", (0, 0, 0), emissive=[power, power * 0.95, power * 0.85],
                            double_sided=False)
            for i, (dx, dz) in enumerate([(1, 1), (3, 1), (1, 3), (3, 3)]):
                cx, cz = c * ROOM + dx, r * ROOM + dz
                s = 0.25
                quad = [(cx - s, y, cz - s), (cx + s, y, cz - s), (cx + s, y, cz + s), (cx - s, y, cz + s)]
                w.node(name=f"panel_{c}_{r}_{i}",
                       mesh=w.mesh(f"panel_{c}_{r}_{i}", quad, [(0, 1, 2), (0, 2, 3)], light))
    # Something to look at in the camera's room (column 1, row 0).
    add_box("block", (5.2, 0.0, 1.2), (6.0, 1.0, 2.0), blue)
    w.camera("camera", yfov=1.1, aspect=1.5, translation=[4.4, 1.6, 3.7], target=[7.0, 0.8, 0.6])
    return w


def main():
    write_scene(build, Path(__file__).resolve().parents[2] / "scenes" / "many-lights" / "many-lights.glb",
                sys.argv)


if __name__ == "__main__":
    main()
