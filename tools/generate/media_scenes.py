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
- smoke-plume.gltf: the empty Cornell box with a plume of smoke rising from its floor, a
  heterogeneous medium: a density grid (smoke-plume.vol, 40 x 40 x 40 voxels, Mitsuba's
  volume format) of a turbulent column widening upwards, with empty space around it, scaling
  a grey extinction (peak 90 per metre) of warm albedo inside an interface box.
- chromatic-smoke.gltf: the same plume (the same grid file) with an extinction that differs
  by channel (50, 100 and 180 per metre at density 1): delta tracking with spectral MIS.
- glowing-smoke.gltf: the same plume glowing orange (emitting 60, 22 and 6 per metre at
  density 1, absorbing and scattering), the only light in the dark Cornell box: emission
  gathered along segments through a grid. Mitsuba 3's media do not emit, so this one has
  no Mitsuba counterpart.
- cloud.gltf: Walt Disney Animation Studios' cumulus cloud at a sixteenth of its resolution
  (wdas-cloud-sixteenth.vdb, an OpenVDB file: 415 642 active voxels of 3.3 m; CC BY-SA 3.0,
  LICENSE-wdas-cloud.txt) lit by a low sun: an OpenVDB grid read as it is, in its own
  placement (the interface box around it comes from its active voxels' box), extinction
  0.1 per metre at density 1 and albedo 0.99, strongly forward scattering (g = 0.8).
  Render it with a sky: `--env 0.25,0.35,0.6`.

    .venv/bin/python tools/generate/media_scenes.py [DIR]   (default scenes/media)
"""
import sys
from pathlib import Path

import numpy as np

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


# The box stays well below the light: Mitsuba 3.9.1's volpath loses light where a null
# interface lies between lit surfaces and a nearby area light (a clear box whose top is 7 cm
# below the Cornell light renders 5.6 % darker in volpath than in path; docs/media.md).
PLUME_BOX = ((0.10, 0.0, 0.12), (0.46, 0.36, 0.48))
PLUME_RESOLUTION = (40, 40, 40)


def plume_density():
    """The plume's densities, shape (z, y, x), peak 1: a column that sways and widens as it
    rises, broken up by turbulence (random sinusoids, fixed seed), fading out at the top."""
    nx, ny, nz = PLUME_RESOLUTION
    z, y, x = np.meshgrid(*[(np.arange(n) + 0.5) / n for n in (nz, ny, nx)], indexing="ij")
    cx = 0.5 + 0.10 * np.sin(5.0 * y)
    cz = 0.5 + 0.07 * np.cos(4.0 * y + 1.0)
    radius = 0.10 + 0.28 * y
    profile = np.exp(-2.0 * ((x - cx) ** 2 + (z - cz) ** 2) / radius ** 2)
    rng = np.random.default_rng(7)
    noise = np.zeros_like(x)
    for octave in range(4):
        for _ in range(6):
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            frequency = 6.0 * 2.0 ** octave
            phase = rng.uniform(0.0, 2.0 * np.pi)
            noise += np.sin(frequency * (direction[0] * x + direction[1] * y + direction[2] * z) + phase) \
                / 2.0 ** octave / 6.0
    turbulence = np.clip(0.55 + 0.9 * noise, 0.0, None)
    fade = np.clip(y / 0.06, 0.0, 1.0) * np.clip((0.92 - y) / 0.25, 0.0, 1.0)
    density = profile * turbulence * fade
    density[density < 0.02] = 0.0
    return density / density.max()


def write_vol(path, density, lo, hi):
    nz, ny, nx = density.shape
    header = b"VOL" + bytes([3]) + np.array([1, nx, ny, nz, 1], dtype="<i4").tobytes()
    box = np.array([*lo, *hi], dtype="<f4").tobytes()
    path.write_bytes(header + box + np.ascontiguousarray(density, dtype="<f4").tobytes())


def smoke(out, extinction, albedo, emission=None, light=True):
    """The Cornell box with the plume of `extinction` (RGB, per metre at density 1),
    `albedo` and `emission` (radiance per metre at density 1); writes the grid file into
    `out`. Without `light` the box's ceiling light is left out."""
    w = GltfWriter("lucerna tools/generate/media_scenes.py")
    cornell(w, skip=("short_block", "tall_block") + (() if light else ("light",)))
    cornell_camera(w)
    lo, hi = PLUME_BOX
    write_vol(out / "smoke-plume.vol", plume_density(), lo, hi)
    medium = {"scattering": [e * a for e, a in zip(extinction, albedo)],
              "absorption": [e * (1 - a) for e, a in zip(extinction, albedo)], "anisotropy": 0.3,
              "density": "smoke-plume.vol"}
    if emission:
        medium["emission"] = emission
    # The interface box around the grid's box, above the floor.
    positions, triangles = box((lo[0] - 0.005, 0.001, lo[2] - 0.005), (hi[0] + 0.005, hi[1] + 0.005, hi[2] + 0.005))
    w.node(name="smoke", mesh=w.mesh("smoke", positions, triangles, interface(w, "smoke", medium)))
    return w


def smoke_plume(out):
    return smoke(out, [90.0] * 3, [0.9, 0.8, 0.65])


def chromatic_smoke(out):
    return smoke(out, [50.0, 100.0, 180.0], [0.95, 0.85, 0.7])


def glowing_smoke(out):
    return smoke(out, [30.0, 40.0, 60.0], [0.6, 0.5, 0.4], emission=[60.0, 22.0, 6.0], light=False)


# The cloud's active voxels in index space and its voxel size (OpenVDB's own reading).
CLOUD_INDEX_BOX = ((-66, -21, -90), (59, 64, 63))
CLOUD_VOXEL = 10.0 / 3.0


def cloud(out):
    w = GltfWriter("lucerna tools/generate/media_scenes.py")
    lo = [(c - 1.0) * CLOUD_VOXEL for c in CLOUD_INDEX_BOX[0]]
    hi = [(c + 1.0) * CLOUD_VOXEL for c in CLOUD_INDEX_BOX[1]]
    positions, triangles = box(lo, hi)
    medium = {"scattering": 0.1 * 0.99, "absorption": 0.1 * 0.01, "anisotropy": 0.8,
              "density": "wdas-cloud-sixteenth.vdb", "density_grid": "density"}
    w.node(name="cloud", mesh=w.mesh("cloud", positions, triangles, interface(w, "cloud", medium)))
    w._use("KHR_lights_punctual")
    w.doc["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"name": "sun", "type": "directional", "color": [1.0, 0.93, 0.82], "intensity": 4.0}]}}
    w.node(name="sun", rotation=look_rotation(unit((-0.6, -0.35, -0.5))),
           extensions={"KHR_lights_punctual": {"light": 0}})
    w.camera("camera", yfov=0.7, aspect=1.5, translation=(-60.0, 40.0, 900.0), target=(-8.0, 70.0, -40.0), znear=1.0)
    return w


SCENES = {"fog-spot": fog_spot, "chromatic-cube": chromatic_cube, "scattering-glass": scattering_glass,
          "smoke-plume": smoke_plume, "chromatic-smoke": chromatic_smoke, "glowing-smoke": glowing_smoke,
          "cloud": cloud}


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[2] / "scenes" / "media"
    for name, build in SCENES.items():
        path = out / f"{name}.gltf"
        (build(out) if "smoke" in name or name == "cloud" else build()).write_gltf(path)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
