#!/usr/bin/env python3
"""lucerna's OpenVDB media against Cycles' (Blender 5.0, pip `bpy`): the same OpenVDB file
rendered by both, each reading it itself (lucerna: `ingest::vdb`; Blender: OpenVDB and
NanoVDB), so that the grid's placement (index space, voxel centres, transform), its
interpolation and the medium's coefficients are compared end to end:

    BLENDER=/path/to/bpy-venv/bin/python .venv/bin/python tools/compare/cycles/vdb_volume.py \\
        [--case plume|cloud|fire|glow|colour] [--spp 256] [--resolution 160x160] [--out tools/compare/cycles/results/vdb-volume]

The smoke plume of tests/assets/vdb/plume.vdb (36 x 36 x 31 active voxels of 9 mm, Blosc)
with extinction 90 per metre at density 1, albedo (0.9, 0.8, 0.65) and Henyey-Greenstein
g = 0.3, over a grey Lambertian floor under a uniform sky, seen from 1.2 m (`--case plume`);
or Walt Disney Animation Studios' cloud (scenes/media/wdas-cloud-sixteenth.vdb, an older,
uncompressed file) with extinction 0.1 per metre, albedo 0.99 and g = 0.8 under a sky of
0.5 (`--case cloud`); or a small fire (tests/assets/vdb/fire.vdb: smoke of extinction 20 per
metre at density 1 and albedo 0.3 over a flame whose `temperature` grid, read as 3000 K per
unit, glows by Cycles' blackbody with intensity 1, under a dim sky: `--case fire`, lucerna's
`medium.blackbody` against the Principled Volume's Temperature and Blackbody Intensity); or
the same fire's `temperature` grid read as an emission grid (`--case glow`: radiance per
metre = value x (2, 1, 0.4), lucerna's `medium.emission_field`, USD standard_volume's
emission channel, against the Principled Volume's Emission Strength driven by the grid's
attribute, Emission Color the tint); or a smoke whose albedo a colour grid tints
(tests/assets/vdb/colour.vdb: the fire's smoke, extinction 40 per metre at density 1, albedo
white times the `Cd` vector grid, saved as halves: `--case colour`, lucerna's
`medium.scatter_color`, USD standard_volume's scatter_color_channel, against the Principled
Volume's Color Attribute).
lucerna: a glTF
interface box around the grid with `extras.lucerna.medium.density` naming the file. Cycles:
a Volume object of the same file (turned from glTF's Y up to Blender's Z up) with a
Principled Volume of Density the extinction (times the grid's `density`), Color the albedo (Cycles
scatters Color x Density and absorbs (1 - Color) x Density: the same coefficients) and
Anisotropy the case's g. Cycles: bounce limits 1024, no clamping, no denoiser, a 1-pixel box
filter, linear EXR. Writes a contact sheet (lucerna | Cycles | |difference| x 4) and
CASE.json: relMSE and luminance ratio over the image and over the volume's pixels (those
the volume darkens or lights by more than 1 % in lucerna's render), and the noise floor
(two seeds of each renderer).
"""
import argparse
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np

import lucerna_tools as lt
from lucerna_tools import cycles
from lucerna_tools.gltf_writer import GltfWriter, box

# Each case: the file, the medium (extinction per metre at density 1, albedo, g), the sky,
# the camera (glTF, Y up, looking down -Z; vertical field of view), the interface box around
# the grid in lucerna's scene and the floor's height.
CASES = {
    "plume": {"vdb": lt.ROOT / "tests" / "assets" / "vdb" / "plume.vdb", "extinction": 90.0,
              "albedo": (0.9, 0.8, 0.65), "anisotropy": 0.3, "sky": 1.0, "camera": (0.28, 0.2, 1.2),
              "vfov": 0.55, "box": ((0.09, -0.005, 0.11), (0.47, 0.37, 0.49)), "floor_y": -0.01,
              "floor_half": 20.0, "near": 0.01},
    "cloud": {"vdb": lt.ROOT / "scenes" / "media" / "wdas-cloud-sixteenth.vdb", "extinction": 0.1,
              "albedo": (0.99, 0.99, 0.99), "anisotropy": 0.8, "sky": 0.5, "camera": (-8.0, 70.0, 900.0),
              "vfov": 0.6, "box": ((-230.0, -80.0, -310.0), (205.0, 222.0, 220.0)), "floor_y": -300.0,
              "floor_half": 2e4, "near": 1.0},
    "fire": {"vdb": lt.ROOT / "tests" / "assets" / "vdb" / "fire.vdb", "extinction": 20.0,
             "albedo": (0.3, 0.3, 0.3), "anisotropy": 0.0, "sky": 0.05, "camera": (0.0, 0.28, 1.2),
             "vfov": 0.55, "box": ((-0.18, -0.015, -0.18), (0.17, 0.57, 0.17)), "floor_y": -0.02,
             "floor_half": 20.0, "near": 0.01, "kelvin": 3000.0, "blackbody_intensity": 1.0},
    "glow": {"vdb": lt.ROOT / "tests" / "assets" / "vdb" / "fire.vdb", "extinction": 20.0,
             "albedo": (0.3, 0.3, 0.3), "anisotropy": 0.0, "sky": 0.05, "camera": (0.0, 0.28, 1.2),
             "vfov": 0.55, "box": ((-0.18, -0.015, -0.18), (0.17, 0.57, 0.17)), "floor_y": -0.02,
             "floor_half": 20.0, "near": 0.01, "emission_tint": (2.0, 1.0, 0.4)},
    "colour": {"vdb": lt.ROOT / "tests" / "assets" / "vdb" / "colour.vdb", "extinction": 40.0,
               "albedo": (1.0, 1.0, 1.0), "anisotropy": 0.2, "sky": 1.0, "camera": (0.0, 0.28, 1.2),
               "vfov": 0.55, "box": ((-0.18, -0.015, -0.18), (0.17, 0.57, 0.17)), "floor_y": -0.02,
               "floor_half": 20.0, "near": 0.01, "colour_grid": "Cd"},
}
FLOOR = 0.5

SCENE_SCRIPT = r'''
volume = bpy.data.volumes.new("volume")
volume.filepath = job["vdb"]
grid = bpy.data.objects.new("volume", volume)
# glTF's Y up to Blender's Z up: (x, y, z) -> (x, -z, y).
grid.rotation_euler = (math.pi / 2, 0, 0)
scene.collection.objects.link(grid)
smoke, out = material("smoke")
pv = smoke.node_tree.nodes.new("ShaderNodeVolumePrincipled")
pv.inputs["Color"].default_value = tuple(job["albedo"]) + (1,)
pv.inputs["Density"].default_value = job["extinction"]
pv.inputs["Anisotropy"].default_value = job["anisotropy"]
if job["kelvin"]:
    pv.inputs["Temperature"].default_value = job["kelvin"]
    pv.inputs["Blackbody Intensity"].default_value = job["blackbody_intensity"]
if job["emission_tint"]:
    # Emission per metre: the grid's value x the tint (strength x colour, the colour's
    # largest channel 1).
    tint = job["emission_tint"]
    field = smoke.node_tree.nodes.new("ShaderNodeAttribute")
    field.attribute_name = "temperature"
    scale = smoke.node_tree.nodes.new("ShaderNodeMath")
    scale.operation = "MULTIPLY"
    scale.inputs[1].default_value = max(tint)
    smoke.node_tree.links.new(field.outputs["Fac"], scale.inputs[0])
    smoke.node_tree.links.new(scale.outputs[0], pv.inputs["Emission Strength"])
    pv.inputs["Emission Color"].default_value = tuple(c / max(tint) for c in tint) + (1,)
if job["colour_grid"]:
    # The albedo is Color x the grid's colour; the extinction stays Density (Absorption
    # Color black).
    pv.inputs["Color Attribute"].default_value = job["colour_grid"]
smoke.node_tree.links.new(pv.outputs[0], out.inputs["Volume"])
volume.materials.append(smoke)
grey_floor(job["floor_half"], job["floor_y"], job["floor"])
camera(job["camera"], job["vfov"], job["near"])
'''


def write_gltf(path, width, height, case):
    w = GltfWriter("lucerna tools/compare/cycles/vdb_volume.py")
    floor = w.material("floor", base=(FLOOR,) * 3, extras={"lucerna": {"bsdf": "lambert"}})
    y, h = case["floor_y"], case["floor_half"]
    w.node(name="floor", mesh=w.mesh("floor", [(-h, y, -h), (-h, y, h), (h, y, h), (h, y, -h)],
                                     [(0, 1, 2), (0, 2, 3)], floor))
    e, albedo = case["extinction"], case["albedo"]
    medium = {"scattering": [e * a for a in albedo], "absorption": [e * (1 - a) for a in albedo],
              "anisotropy": case["anisotropy"], "density": case["vdb"].name}
    if case.get("kelvin"):
        medium["density_grid"] = "density"
        medium["blackbody"] = {"temperature": case["vdb"].name, "temperature_grid": "temperature",
                               "kelvin": case["kelvin"], "intensity": case["blackbody_intensity"]}
    if case.get("emission_tint"):
        medium["density_grid"] = "density"
        medium["emission_field"] = {"file": case["vdb"].name, "grid": "temperature",
                                    "tint": list(case["emission_tint"])}
    if case.get("colour_grid"):
        medium["density_grid"] = "density"
        medium["scatter_color"] = {"file": case["vdb"].name, "grid": case["colour_grid"]}
    smoke = w.material("smoke", extras={"lucerna": {"bsdf": "interface", "medium": medium}})
    positions, triangles = box(*case["box"])
    w.node(name="smoke", mesh=w.mesh("smoke", positions, triangles, smoke))
    cam = w._list("cameras", {"name": "camera", "type": "perspective",
                              "perspective": {"yfov": case["vfov"], "aspectRatio": width / height,
                                              "znear": case["near"]}})
    w.node(name="camera", camera=cam, translation=list(case["camera"]))
    w.write_gltf(path)


def cycles_job(work, width, height, spp, case):
    """The values SCENE_SCRIPT reads."""
    return {"width": width, "height": height, "spp": spp, "sky": case["sky"], "vdb": str(work / case["vdb"].name),
            "extinction": case["extinction"], "albedo": case["albedo"], "anisotropy": case["anisotropy"],
            "floor": FLOOR, "floor_y": case["floor_y"], "floor_half": case["floor_half"], "vfov": case["vfov"],
            "camera": case["camera"], "near": case["near"], "kelvin": case.get("kelvin", 0.0),
            "blackbody_intensity": case.get("blackbody_intensity", 0.0),
            "emission_tint": case.get("emission_tint"), "colour_grid": case.get("colour_grid")}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--resolution", default="160x160")
    parser.add_argument("--case", choices=sorted(CASES), default="plume")
    parser.add_argument("--out", default=str(lt.ROOT / "tools" / "compare" / "cycles" / "results" / "vdb-volume"))
    args = parser.parse_args()
    case = CASES[args.case]
    width, height = map(int, args.resolution.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        shutil.copy(case["vdb"], work / case["vdb"].name)
        gltf = work / "scene.gltf"
        write_gltf(gltf, width, height, case)
        ours, ours_b, header = cycles.lucerna_seeds(gltf, work, (width, height), args.spp, case["sky"])
        empty = work / "empty.gltf"
        doc = json.loads(gltf.read_text())
        doc["scenes"][0]["nodes"] = [n for n in doc["scenes"][0]["nodes"] if doc["nodes"][n].get("name") != "smoke"]
        empty.write_text(json.dumps(doc))
        env = ",".join([str(case["sky"])] * 3)
        background, _, _ = lt.render(empty, work / "e.exr", (width, height), spp=16, seed=1, filter="box", env=env)
        job = cycles_job(work, width, height, args.spp, case)
        cycles_a, cycles_b = (cycles.render(work, "vdb_volume", SCENE_SCRIPT, job, seed) for seed in (1, 2))
    change = (ours - background) @ cycles.LUMINANCE
    volume = np.abs(change) > 0.01 * np.maximum(background @ cycles.LUMINANCE, 1e-3)
    regions = {"image": np.ones(volume.shape, dtype=bool), "volume": volume}
    if case.get("kelvin") or case.get("emission_tint"):
        # Where the fire's own light outshines what the sky and floor give.
        regions["flame"] = change > background @ cycles.LUMINANCE
    figures = {"case": args.case, "spp": args.spp, "resolution": [width, height],
               "volume_pixels": int(volume.sum())}
    figures.update({f"{name}_pixels": int(mask.sum()) for name, mask in regions.items() if name == "flame"})
    figures.update(cycles.figures(ours, ours_b, cycles_a, cycles_b, regions))
    figures["seconds_lucerna"] = header["lucerna/render_seconds"]
    (out / f"{args.case}.json").write_text(json.dumps(figures, indent=1) + "\n")
    print(json.dumps(figures, indent=1))
    lt.difference_sheet(ours, cycles_a, out / f"{args.case}.png")


if __name__ == "__main__":
    main()
