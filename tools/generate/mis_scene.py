#!/usr/bin/env python3
"""Generate scenes/mis-plates/mis-plates.glb: the classic multiple importance sampling scene
(Veach & Guibas 1995): four metal plates (reflectance 1) from rough to near-specular (GGX alpha 0.1, 0.05,
0.02, 0.005), each tilted to reflect the row of lights towards the camera, and four
spherical lights of equal power and radii 0.9, 0.3, 0.1 and 0.03 (radiance inversely
proportional to the area). Light sampling wins on rough plates with small lights, BSDF
sampling on smooth plates with large lights, MIS on all.

    python3 tools/generate/mis_scene.py [output.glb]
"""
import sys
from pathlib import Path

from lucerna_tools.gltf_writer import GltfWriter, cross, unit

CAMERA = [0.0, 3.0, 12.0]
LIGHT_ROW = [0.0, 3.0, -2.0]
RADII = [0.9, 0.3, 0.1, 0.03]
COLOURS = [(1.0, 0.6, 0.4), (0.6, 1.0, 0.6), (0.5, 0.7, 1.0), (1.0, 1.0, 1.0)]
RADIANCE_OF_LARGEST = 4.0
# Far (top of the image) to near: rough to near-specular. glTF roughness = sqrt(alpha).
PLATES = [((0.0, -0.8, -0.5), 0.1), ((0.0, -1.3, 0.7), 0.05), ((0.0, -1.8, 1.9), 0.02), ((0.0, -2.3, 3.1), 0.005)]


def luminance(c):
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


def build():
    w = GltfWriter("lucerna tools/generate/mis_scene.py")
    for i, (centre, alpha) in enumerate(PLATES):
        to_camera = unit([a - b for a, b in zip(CAMERA, centre)])
        to_lights = unit([a - b for a, b in zip(LIGHT_ROW, centre)])
        n = unit([a + b for a, b in zip(to_camera, to_lights)])
        x = [1.0, 0.0, 0.0]
        t = unit(cross(n, x))
        half_width, half_depth = 3.75, 0.5
        corners = [[c + sx * half_width * xa + st * half_depth * ta for c, xa, ta in zip(centre, x, t)]
                   for sx, st in [(-1, -1), (1, -1), (1, 1), (-1, 1)]]
        # Reflectance 1 (F0 = 1: Schlick Fresnel is then exactly 1), so that a perfect GGX
        # conductor in another renderer (Mitsuba's roughconductor, material "none") is the same BRDF.
        m = w.material(f"plate_{i}", base=(1.0, 1.0, 1.0), metallic=1.0, roughness=alpha ** 0.5)
        w.node(name=f"plate_{i}", mesh=w.mesh(f"plate_{i}", corners, [(0, 1, 2), (0, 2, 3)], m))
    for i, (radius, colour) in enumerate(zip(RADII, COLOURS)):
        # Equal power: radiance times area is the same for every light.
        radiance = RADIANCE_OF_LARGEST * (RADII[0] / radius) ** 2 / luminance(colour)
        # Pure emitters: a black Lambertian surface reflects nothing (a black glTF dielectric
        # would still reflect 4 %), so every renderer sees the same lights.
        m = w.material(f"light_{i}", base=(0, 0, 0), emissive=[c * radiance for c in colour], double_sided=False,
                       extras={"lucerna": {"bsdf": "lambert"}})
        centre = [LIGHT_ROW[0] + (i - 1.5) * 2.5, LIGHT_ROW[1], LIGHT_ROW[2]]
        w.sphere(f"light_{i}", centre, radius, m)
    w.camera("camera", yfov=0.6, aspect=1.5, translation=CAMERA, target=[0.0, -0.5, 0.0])
    return w


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else \
        Path(__file__).resolve().parents[2] / "scenes" / "mis-plates" / "mis-plates.glb"
    build().write_glb(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
