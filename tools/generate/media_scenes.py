#!/usr/bin/env python3
"""Generate scenes/media/: test scenes for participating media, each one that lucerna and
Mitsuba 3's `volpath` model alike (tools/lucerna_tools/mitsuba_export.py exports
interfaces as `null` BSDFs with a `homogeneous` interior medium and an HG phase function):

- fog-spot.gltf: a fog box (an interface, `extras.lucerna.bsdf = "interface"`, around a
  thin, weakly absorbing, forward-scattering medium) on a white floor that it encloses, a
  grey block inside it, lit by a spot light from above: the beam, the block's shadow shaft
  through the fog, light scattered onto the floor. glTF requires a spot's inner cone to be
  narrower than its outer one; Mitsuba's spot falls off linearly in angle, glTF's
  quadratically in cosine, so the comparisons make the cone hard-edged in both
  (mitsuba_compare's `hard_spots`).
- chromatic-cube.gltf: the Cornell box (tools/generate/glass_box.py's walls) with its tall block
  replaced by a dense cube whose extinction differs by channel (8, 3 and 1 per 10 cm in
  red, green, blue), scattering most of it: a chromatic medium, where sampling one channel's
  distances would leave colour noise.
- scattering-glass.gltf: the Cornell box with a smooth glass sphere (ior 1.5, an analytic
  sphere) filled with a milky, faintly absorbing, forward-scattering medium: media behind a
  refracting boundary.

    python3 tools/generate/media_scenes.py [DIR]   (default scenes/media)
"""
import sys
from pathlib import Path

from glass_box import cornell, cornell_camera
from lucerna_tools.gltf_writer import GltfWriter, box, look_rotation, unit

LAMBERT = {"lucerna": {"bsdf": "lambert"}}


def interface(w, name, medium):
    return w.material(name, extras={"lucerna": {"bsdf": "interface", "medium": medium}})


def fog_spot():
    w = GltfWriter("lucerna tools/generate/media_scenes.py")
    white = w.material("floor", base=(0.8, 0.8, 0.8), extras=LAMBERT)
    grey = w.material("block", base=(0.5, 0.5, 0.5), extras=LAMBERT)
    floor = [(-2.0, 0.0, -2.0), (-2.0, 0.0, 2.0), (2.0, 0.0, 2.0), (2.0, 0.0, -2.0)]
    w.node(name="floor", mesh=w.mesh("floor", floor, [(0, 1, 2), (0, 2, 3)], white))
    positions, triangles = box((-0.25, 0.0, -0.15), (0.05, 0.5, 0.15))
    w.node(name="block", mesh=w.mesh("block", positions, triangles, grey))
    fog = interface(w, "fog", {"absorption": 0.05, "scattering": 0.6, "anisotropy": 0.4})
    # The box reaches below the floor, which lies inside the fog.
    positions, triangles = box((-1.2, -0.1, -1.0), (1.2, 1.6, 1.0))
    w.node(name="fog", mesh=w.mesh("fog", positions, triangles, fog))
    w._use("KHR_lights_punctual")
    w.doc["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"name": "spot", "type": "spot", "color": [1.0, 0.95, 0.85], "intensity": 30.0,
         "spot": {"innerConeAngle": 0.34, "outerConeAngle": 0.35}}]}}
    # Above the box, pointing down at the floor beside the block (-Z of the node).
    spot, target = (0.3, 2.2, -0.2), (0.0, 0.0, 0.1)
    w.node(name="spot", translation=list(spot), rotation=look_rotation(unit([t - s for t, s in zip(target, spot)])),
           extensions={"KHR_lights_punctual": {"light": 0}})
    w.camera("camera", yfov=0.75, aspect=1.0, translation=(0.0, 1.0, 3.6), target=(0.0, 0.6, 0.0))
    return w


def chromatic_cube():
    w = GltfWriter("lucerna tools/generate/media_scenes.py")
    cornell(w, skip=("tall_block",))
    cornell_camera(w)
    extinction = [80.0, 30.0, 10.0]
    albedo = [0.95, 0.8, 0.6]
    medium = {"scattering": [e * a for e, a in zip(extinction, albedo)],
              "absorption": [e * (1 - a) for e, a in zip(extinction, albedo)], "anisotropy": 0.0}
    positions, triangles = box((0.30, 0.005, 0.28), (0.46, 0.245, 0.44))
    w.node(name="cube", mesh=w.mesh("cube", positions, triangles, interface(w, "chromatic", medium)))
    return w


def scattering_glass():
    w = GltfWriter("lucerna tools/generate/media_scenes.py")
    cornell(w, skip=("tall_block",))
    cornell_camera(w)
    m = w.material("milky_glass", base=(1.0, 1.0, 1.0), roughness=0.0,
                   extras={"lucerna": {"medium": {"absorption": [1.0, 2.0, 4.0], "scattering": 25.0,
                                                  "anisotropy": 0.5}}})
    ext = {"KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_ior": {"ior": 1.5},
           "KHR_materials_volume": {"thicknessFactor": 0.2}}
    w.doc["materials"][m]["extensions"] = ext
    for e in ext:
        w._use(e)
    w.sphere("milky_sphere", (0.37, 0.125, 0.36), 0.12, m, subdivisions=3)
    return w


SCENES = {"fog-spot": fog_spot, "chromatic-cube": chromatic_cube, "scattering-glass": scattering_glass}


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[2] / "scenes" / "media"
    for name, build in SCENES.items():
        path = out / f"{name}.gltf"
        build().write_gltf(path)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
