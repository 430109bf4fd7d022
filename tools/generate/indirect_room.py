#!/usr/bin/env python3
"""Generate scenes/indirect-room/indirect-room.glb: two rooms joined by a doorway. The only
light is a panel in the back room facing away from the door, so everything the camera sees
in the front room is lit indirectly, through several bounces off walls of albedo 0.8: paths
are long, which is what Russian roulette and splitting are judged on.

    python3 tools/generate/indirect_room.py [output.glb]
"""
import sys
from pathlib import Path

from lucerna_tools.gltf_writer import GltfWriter, box

LAMBERT = {"lucerna": {"bsdf": "lambert"}}


def build():
    w = GltfWriter("lucerna tools/generate/indirect_room.py")
    walls = w.material("walls", base=(0.8, 0.78, 0.74), extras=LAMBERT)
    blue = w.material("blue", base=(0.25, 0.35, 0.7), extras=LAMBERT)
    metal = w.material("metal", base=(0.9, 0.85, 0.75), metallic=1.0, roughness=0.3)
    light = w.material("panel", base=(0, 0, 0), emissive=[40.0, 36.0, 30.0], double_sided=False)

    def add_box(name, lo, hi, material, outward=True):
        v, t = box(lo, hi, outward)
        w.node(name=name, mesh=w.mesh(name, v, t, material))

    add_box("room", (-4.0, 0.0, -7.0), (4.0, 3.0, 2.5), walls, outward=False)
    # The dividing wall at z = -2, 0.2 thick, with a doorway 1.2 wide and 2.2 high.
    add_box("wall_left", (-4.0, 0.0, -2.1), (-0.6, 3.0, -1.9), walls)
    add_box("wall_right", (0.6, 0.0, -2.1), (4.0, 3.0, -1.9), walls)
    add_box("lintel", (-0.6, 2.2, -2.1), (0.6, 3.0, -1.9), walls)
    # Furniture in the front room.
    add_box("cabinet", (-3.2, 0.0, -1.0), (-2.0, 1.1, 0.2), blue)
    add_box("table", (1.0, 0.0, -0.8), (2.4, 0.75, 0.2), walls)
    w.sphere("ball", (1.7, 1.1, -0.3), 0.35, metal)
    # The light: a panel high in the back room, facing the back wall (-Z).
    panel = [(-0.9, 1.9, -5.0), (0.9, 1.9, -5.0), (0.9, 2.7, -5.0), (-0.9, 2.7, -5.0)]
    w.node(name="panel", mesh=w.mesh("panel", panel, [(0, 2, 1), (0, 3, 2)], light))
    w.camera("camera", yfov=0.9, aspect=1.5, translation=[2.9, 1.6, 2.1], target=[0.0, 1.0, -2.0])
    return w


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else \
        Path(__file__).resolve().parents[2] / "scenes" / "indirect-room" / "indirect-room.glb"
    build().write_glb(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
