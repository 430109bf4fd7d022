"""Writes the OpenVDB test files of tests/assets/vdb with OpenVDB's own library, and what
OpenVDB reads back from them (expected.json), for the reader's tests.

Run with a Python that has `pyopenvdb` (Debian/Ubuntu: `apt-get install python3-openvdb`,
then `/usr/bin/python3 tools/generate/vdb_assets.py`). The files:

- plume.vdb: the smoke plume of scenes/media/smoke-plume.vol as a float grid placed where
  the .vol file's box is (so both read as the same density field), with a second grid
  (`temperature`) and a vector grid (`velocity`) beside it; Blosc-compressed (OpenVDB's
  default when it has Blosc).
- plume-half.vdb: the same plume saved as halves.
- tiles.vdb: active tiles beside leaves, negative coordinates and a rotated, scaled
  transform (an affine map), values that include negative ones.
- sphere-level-set.vdb: a level set, which the reader refuses.
- fire.vdb: a small fire: `temperature` (a flame, values 0 to about 1.2, to be read as
  3000 K per unit) over voxels that reach below the smoke's, and `density` (smoke
  rising above it), on one transform of 1 cm voxels.
- colour.vdb: the fire's smoke (`density`) and a colour (`Cd`, a vector grid saved as
  halves, as Houdini writes it) from orange where the smoke is low to blue where it is
  high, over voxels that reach beyond the smoke's.

wdas-cloud-sixteenth.vdb (vendored: Walt Disney Animation Studios' cloud at a sixteenth of
its resolution, CC BY-SA 3.0, LICENSE-wdas-cloud.txt) is described too when it is there.
"""

import json
import math
import sys
from pathlib import Path

import numpy as np
import pyopenvdb as vdb

sys.path[:0] = [str(Path(__file__).resolve().parent), str(Path(__file__).resolve().parents[1])]
from media_scenes import PLUME_BOX, PLUME_RESOLUTION, plume_density  # noqa: E402


def describe(grid, probes):
    """What OpenVDB reads back: counts, sums, bounds and values at `probes` (index points)."""
    active = 0
    total = 0.0
    for item in grid.citerOnValues():  # a tile counts for all its voxels
        active += item.count
        total += item.value * item.count
    accessor = grid.getConstAccessor()
    lo, hi = grid.evalActiveVoxelBoundingBox()
    return {
        "name": grid.name,
        "active_voxels": active,
        "active_sum": total,
        "active_box": [list(lo), list(hi)],
        "background": grid.background,
        "probes": [{"index": list(p), "value": accessor.getValue(tuple(p)),
                    "world": list(grid.transform.indexToWorld(tuple(float(c) for c in p)))}
                   for p in probes],
    }


def plume_grid(half):
    lo, hi = PLUME_BOX
    nx, ny, nz = PLUME_RESOLUTION
    voxel = [(h - l) / n for l, h, n in zip(lo, hi, (nx, ny, nz))]
    density = np.ascontiguousarray(plume_density().astype(np.float32).transpose(2, 1, 0))
    grid = vdb.FloatGrid()
    grid.copyFromArray(density, ijk=(0, 0, 0), tolerance=0)
    grid.name = "density"
    grid.gridClass = vdb.GridClass.FOG_VOLUME
    # Voxel (i, j, k) at the centre of the .vol file's voxel (i, j, k).
    grid.transform = vdb.createLinearTransform(
        [[voxel[0], 0, 0, 0], [0, voxel[1], 0, 0], [0, 0, voxel[2], 0],
         [lo[0] + voxel[0] / 2, lo[1] + voxel[1] / 2, lo[2] + voxel[2] / 2, 1]])
    grid.saveFloatAsHalf = half
    return grid


def fire_grids():
    """(density, temperature) of a small fire: a flame whose core is hot where the smoke
    is thin, smoke that thickens above it; each grid active only where it is not small,
    so their active boxes differ."""
    n = (32, 56, 32)
    x, y, z = np.meshgrid(*(np.arange(k) + 0.5 for k in n), indexing="ij")
    r2 = ((x - 16) ** 2 + (z - 16) ** 2) / 16.0 ** 2
    flame = 1.2 * np.exp(-r2 / (2 * 0.18 ** 2) - ((y - 14) / 9.0) ** 2 / 2) * (1 + 0.15 * np.sin(0.7 * y + 0.4 * x))
    smoke = 1.5 * np.exp(-r2 / (2 * (0.12 + 0.006 * y) ** 2)) / (1 + np.exp(-(y - 26) / 3.0))
    smoke *= 1 + 0.3 * np.sin(0.5 * x) * np.sin(0.45 * y + 0.3 * z)
    transform = vdb.createLinearTransform(
        [[0.01, 0, 0, 0], [0, 0.01, 0, 0], [0, 0, 0.01, 0], [-0.16, 0.0, -0.16, 1]])
    grids = []
    for name, values in (("density", smoke), ("temperature", flame)):
        values = np.where(values > 0.02, values, 0.0).astype(np.float32)
        grid = vdb.FloatGrid()
        grid.copyFromArray(np.ascontiguousarray(values), ijk=(0, 0, 0), tolerance=0)
        grid.prune()
        grid.name = name
        grid.gridClass = vdb.GridClass.FOG_VOLUME
        grid.transform = transform
        grids.append(grid)
    return grids


def colour_grid(density):
    """`Cd` over the voxels of `density` grown by two: orange low, blue high, with a
    sideways green ripple so that the components differ voxel by voxel."""
    n = (32, 56, 32)
    x, y, z = np.meshgrid(*(np.arange(k) + 0.5 for k in n), indexing="ij")
    h = y / n[1]
    rgb = np.stack([1.0 - 0.8 * h, 0.35 + 0.25 * np.sin(0.4 * x + 0.3 * z), 0.15 + 0.8 * h], axis=-1)
    dense = np.zeros(n, dtype=np.float32)
    density.copyToArray(dense, ijk=(0, 0, 0))
    grown = dense > 0.0
    for axis in range(3):
        for shift in (-2, -1, 1, 2):
            grown |= np.roll(dense > 0.0, shift, axis=axis)
    rgb = np.where(grown[..., None], rgb, 0.0).astype(np.float32)
    grid = vdb.Vec3SGrid()
    grid.copyFromArray(np.ascontiguousarray(rgb), ijk=(0, 0, 0), tolerance=(0, 0, 0))
    grid.prune((0, 0, 0))
    grid.name = "Cd"
    grid.transform = density.transform
    grid.saveFloatAsHalf = True
    return grid


def describe_vector(grid, probes):
    """What OpenVDB reads back from a vector grid: its active box and values at `probes`."""
    accessor = grid.getConstAccessor()
    lo, hi = grid.evalActiveVoxelBoundingBox()
    return {
        "name": grid.name,
        "active_box": [list(lo), list(hi)],
        "probes": [{"index": list(p), "value": list(accessor.getValue(tuple(p))),
                    "world": list(grid.transform.indexToWorld(tuple(float(c) for c in p)))}
                   for p in probes],
    }


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[2] / "tests" / "assets" / "vdb"
    out.mkdir(parents=True, exist_ok=True)
    expected = {}
    probes = [(0, 0, 0), (20, 5, 20), (13, 31, 25), (39, 39, 39), (21, 12, 18)]

    plume = plume_grid(False)
    temperature = plume.deepCopy()
    temperature.name = "temperature"
    temperature.mapOn(lambda v: 300.0 + 900.0 * v)
    velocity = vdb.Vec3SGrid()
    velocity.name = "velocity"
    velocity.fill((0, 0, 0), (7, 7, 7), (0.0, 1.0, 0.0))
    vdb.write(str(out / "plume.vdb"), grids=[plume, temperature, velocity])
    expected["plume.vdb"] = {"density": describe(plume, probes), "temperature": describe(temperature, probes)}

    half = plume_grid(True)
    vdb.write(str(out / "plume-half.vdb"), grids=[half])
    # OpenVDB reads the halves back: describe what it reads.
    expected["plume-half.vdb"] = {"density": describe(vdb.read(str(out / "plume-half.vdb"), "density"), probes)}

    tiles = vdb.FloatGrid()
    tiles.name = "density"
    tiles.gridClass = vdb.GridClass.FOG_VOLUME
    tiles.fill((-16, -8, 0), (15, 15, 31), 0.75)  # whole 8^3 leaves: active tiles
    accessor = tiles.getAccessor()
    for i in range(24):
        accessor.setValueOn((20 + i % 5, -3 + i // 5, 9 + i % 3), 0.05 * i - 0.2)
    c, s = math.cos(0.4), math.sin(0.4)
    tiles.transform = vdb.createLinearTransform(
        [[0.02 * c, 0.02 * s, 0, 0], [-0.03 * s, 0.03 * c, 0, 0], [0, 0, 0.025, 0], [0.5, -0.25, 1.0, 1]])
    tiles.prune()
    vdb.write(str(out / "tiles.vdb"), grids=[tiles])
    expected["tiles.vdb"] = {"density": describe(tiles, [(-16, -8, 0), (0, 0, 0), (15, 15, 31), (22, -1, 10),
                                                         (16, 0, 0), (-17, 0, 0), (43, 1, 11)])}

    sphere = vdb.createLevelSetSphere(radius=1.0, center=(0, 0, 0), voxelSize=0.25, halfWidth=3.0)
    sphere.name = "surface"
    vdb.write(str(out / "sphere-level-set.vdb"), grids=[sphere])

    smoke, flame = fire_grids()
    vdb.write(str(out / "fire.vdb"), grids=[smoke, flame])
    expected["fire.vdb"] = {g.name: describe(g, [(16, 14, 16), (16, 40, 16), (3, 2, 16)]) for g in (smoke, flame)}

    colour = colour_grid(smoke)
    vdb.write(str(out / "colour.vdb"), grids=[smoke, colour])
    read_back = vdb.read(str(out / "colour.vdb"), "Cd")  # the halves as OpenVDB reads them
    colour_probes = [(16, 14, 16), (16, 40, 16), (10, 30, 14), (2, 2, 2)]
    expected["colour.vdb"] = {"Cd": describe_vector(read_back, colour_probes)}

    cloud = out / "wdas-cloud-sixteenth.vdb"
    if cloud.exists():
        grid = vdb.read(str(cloud), "density")
        expected[cloud.name] = {"density": describe(grid, [(0, 0, 0), (-20, 10, 5), (3, 40, -12), (10, -30, 20)])}
    (out / "expected.json").write_text(json.dumps(expected, indent=1) + "\n")
    for f in sorted(out.glob("*.vdb")):
        print(f"wrote {f} ({f.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
