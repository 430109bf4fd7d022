#!/usr/bin/env python3
"""Generate scenes/glass-box/glass-box.gltf: the Cornell box (walls, light and camera of
tools/generate/cornell_box.py) with its blocks replaced by the three dielectrics lucerna and
Mitsuba 3 model alike (tools/lucerna_tools/mitsuba_export.py maps them to `dielectric`,
`roughdielectric` and `thindielectric`):

- a smooth glass sphere (ior 1.5; an analytic sphere, KHR_materials_volume: it refracts),
- a rough glass slab (GGX alpha 0.15, ior 1.5, faintly blue: its base colour tints what it
  transmits), 5 mm above the floor (a face coplanar with the floor is ambiguous geometry,
  which renderers resolve differently),
- a thin smooth pane (transmission without a volume: no bending) in front of the green wall.

The glass test scene of tests/python/test_mitsuba_agreement.py and of the convergence and
furnace tests.

    python3 tools/generate/glass_box.py [output.gltf]
"""
import sys
from pathlib import Path

import cornell_box as cb
from lucerna_tools.gltf_writer import GltfWriter, box

SPHERE = ((0.185, 0.1, 0.17), 0.1)
SLAB = ((0.31, 0.005, 0.30), (0.47, 0.245, 0.40))
PANE = [(0.02, 0.02, 0.42), (0.22, 0.02, 0.42), (0.22, 0.40, 0.42), (0.02, 0.40, 0.42)]


def glass(w, name, base, roughness, volume):
    m = w.material(name, base=base, roughness=roughness)
    ext = {"KHR_materials_transmission": {"transmissionFactor": 1.0},
           "KHR_materials_ior": {"ior": 1.5}}
    if volume:
        ext["KHR_materials_volume"] = {"thicknessFactor": 0.1}
    w.doc["materials"][m]["extensions"] = ext
    for e in ext:
        w._use(e)
    return m


def cornell(w, skip=("short_block", "tall_block")):
    """The Cornell box's walls and light (metres, Lambertian) in `w`, without the parts named
    in `skip`; its materials by name."""
    lambert = {"lucerna": {"bsdf": "lambert"}}
    colours = {"white": cb.WHITE, "red": cb.RED, "green": cb.GREEN}
    materials = {name: w.material(name, base=c, extras=lambert) for name, c in colours.items()}
    materials["light"] = w.material("light", base=cb.LIGHT_ALBEDO, emissive=cb.LIGHT_RADIANCE,
                                    double_sided=False, extras=lambert)
    for name, (mat, ref, mode, quads) in cb.QUADS.items():
        if name in skip:
            continue
        positions, triangles = [], []
        for quad in quads:
            quad = cb.oriented(quad, ref, mode)
            base = len(positions)
            positions.extend(tuple(c * cb.MM for c in p) for p in quad)
            triangles += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
        w.node(name=name, mesh=w.mesh(name, positions, triangles, materials[mat]))
    return materials


def cornell_camera(w):
    """The Cornell box's camera."""
    cam = w._list("cameras", {"name": "camera", "type": "perspective",
                              "perspective": {"yfov": 0.6860514, "aspectRatio": 1.0, "znear": 0.01}})
    w.node(name="camera", camera=cam, translation=[0.278, 0.273, -0.8], rotation=[0.0, 1.0, 0.0, 0.0])


def build():
    w = GltfWriter("lucerna tools/generate/glass_box.py")
    cornell(w)
    centre, radius = SPHERE
    w.sphere("glass_sphere", centre, radius, glass(w, "smooth_glass", (1.0, 1.0, 1.0), 0.0, True), subdivisions=3)
    positions, triangles = box(*SLAB)
    slab = glass(w, "rough_glass", (0.9, 0.95, 1.0), 0.15 ** 0.5, True)
    w.node(name="glass_slab", mesh=w.mesh("glass_slab", positions, triangles, slab))
    pane = glass(w, "thin_glass", (1.0, 1.0, 1.0), 0.0, False)
    w.node(name="glass_pane", mesh=w.mesh("glass_pane", PANE, [(0, 1, 2), (0, 2, 3)], pane))
    cornell_camera(w)
    return w


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else \
        Path(__file__).resolve().parents[2] / "scenes" / "glass-box" / "glass-box.gltf"
    build().write_gltf(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
