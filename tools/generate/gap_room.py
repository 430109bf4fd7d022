#!/usr/bin/env python3
"""Generate scenes/gap-room/gap-room.glb: a closed room lit only through a 6 cm slit in one
wall. Outside the slit a bright panel faces the wall; inside, the light that gets through
draws a thin stripe on the floor and the far wall, and everything the camera sees is lit by
light bouncing off that stripe. Unguided paths find the stripe by chance; this is the case
path guiding is for. Materials are plain glTF PBR (metallic 0, KHR_materials_specular
specularFactor 0: exactly Lambert), as other renderers read them.

    python3 tools/generate/gap_room.py [output.glb]
"""
import sys
from pathlib import Path

from lucerna_tools.gltf_writer import GltfWriter, write_scene

GAP = 0.06


def build():
    w = GltfWriter("lucerna tools/generate/gap_room.py")
    lambert = w.lambert_material
    walls = lambert("walls", (0.75, 0.75, 0.72))
    floor = lambert("floor", (0.6, 0.55, 0.5))
    red = lambert("red", (0.7, 0.15, 0.1))
    # A black emitter without a specular layer: it reflects nothing, in any renderer.
    light = lambert("panel", (0, 0, 0), emissive=[400.0, 380.0, 340.0], double_sided=False)

    add_box = w.add_box
    # The room's inside: x in [-3, 2.95], y in [0, 3], z in [-3, 3]; its walls are slabs.
    add_box("floor", (-3.1, -0.1, -3.1), (3.05, 0.0, 3.1), floor)
    add_box("ceiling", (-3.1, 3.0, -3.1), (3.05, 3.1, 3.1), walls)
    add_box("wall_back", (-3.1, 0.0, -3.1), (-3.0, 3.0, 3.1), walls)
    add_box("wall_north", (-3.0, 0.0, -3.1), (2.95, 3.0, -3.0), walls)
    add_box("wall_south", (-3.0, 0.0, 3.0), (2.95, 3.0, 3.1), walls)
    # The wall at x = 3 (0.1 thick), whole but for a slit GAP high at y = 1.6, |z| < 1.5.
    y0, y1 = 1.6 - GAP / 2, 1.6 + GAP / 2
    add_box("wall_low", (2.95, 0.0, -3.0), (3.05, y0, 3.0), walls)
    add_box("wall_high", (2.95, y1, -3.0), (3.05, 3.0, 3.0), walls)
    add_box("wall_left", (2.95, y0, -3.0), (3.05, y1, -1.5), walls)
    add_box("wall_right", (2.95, y0, 1.5), (3.05, y1, 3.0), walls)
    # Something to look at.
    add_box("block", (-1.2, 0.0, -1.6), (-0.2, 1.2, -0.6), red)
    # The light: a panel outside, above the slit, facing the slit (normal from its centre
    # towards (3, 1.6, 0)); its long side along z.
    cx, cy = 5.5, 3.5
    nx, ny = 3.0 - cx, 1.6 - cy
    length = (nx * nx + ny * ny) ** 0.5
    tx, ty = -ny / length, nx / length  # in the panel's plane, across z: t x z = n
    corners = [(-0.6, -1.5), (0.6, -1.5), (0.6, 1.5), (-0.6, 1.5)]
    panel = [(cx + a * tx, cy + a * ty, z) for a, z in corners]
    w.node(name="panel", mesh=w.mesh("panel", panel, [(0, 1, 2), (0, 2, 3)], light))
    w.camera("camera", yfov=1.0, aspect=1.5, translation=[-2.6, 1.7, 2.6], target=[1.0, 0.7, -1.0])
    return w


def main():
    write_scene(build, Path(__file__).resolve().parents[2] / "scenes" / "gap-room" / "gap-room.glb",
                sys.argv)


if __name__ == "__main__":
    main()
