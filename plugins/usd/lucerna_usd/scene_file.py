"""Writer of lucerna's scene file (format "lucerna-scene", version 1; `src/scene/file.rs`
documents it): a JSON manifest and one little-endian binary buffer beside it. Bulk arrays
go to the buffer as views {offset in bytes, count in elements}; everything else is JSON
with the renderer's field names. Both files are written through a temporary file and a
rename, the buffer first, so a reader never sees a manifest without its buffer."""

import io
import json
import math
import os
import shutil
import tempfile

import numpy as np

FORMAT = "lucerna-scene"
VERSION = 1

IDENTITY = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]


def matrix(m):
    """A 4x4 row-vector matrix (Gf.Matrix4d or an array, translation in the last row) as the
    scene file's 16 column-major numbers of the column-vector matrix: the same 16 numbers
    read row by row."""
    return [float(x) for x in np.asarray(m, dtype=np.float64).reshape(16)]


def mean_scale(linear):
    """(mean scale, whether the scale is uniform) of a row-vector 3x3 linear part."""
    scales = np.linalg.norm(np.asarray(linear, dtype=np.float64), axis=1)
    return float(scales.mean()), bool(scales.max() <= scales.min() * (1 + 1e-4))


def default_material(name, **fields):
    """A material with the renderer's defaults (glTF metallic-roughness, opaque, one-sided)
    and `fields` overriding them."""
    material = {
        "name": name,
        "model": "gltf_pbr",
        "base_color": [1.0, 1.0, 1.0, 1.0],
        "base_color_texture": None,
        "metallic": 1.0,
        "roughness": 1.0,
        "metallic_roughness_texture": None,
        "normal_texture": None,
        "normal_scale": 1.0,
        "emissive": [0.0, 0.0, 0.0],
        "emissive_texture": None,
        "ior": 1.5,
        "clearcoat": 0.0,
        "clearcoat_roughness": 0.0,
        "alpha_mode": "opaque",
        "double_sided": False,
    }
    material.update(fields)
    return material


class SceneWriter:
    """Collects a scene and writes it as a scene file."""

    def __init__(self, source):
        self.source = source
        # The buffer is spooled to an unnamed temporary file as it grows, so that the
        # conversion does not hold a copy of every mesh and texel in memory besides the
        # arrays it converts; `write` copies it out.
        self._spool = tempfile.TemporaryFile()
        self._size = 0
        self.meshes = []
        self.subdivision_surfaces = []
        self.instances = []
        self.spheres = []
        self.disks = []
        self.cylinders = []
        self.materials = []
        self.textures = []
        self.lights = []
        self.cameras = []
        self.environment = None
        # Dome lights met so far (lights.finish_domes makes the environment of them).
        self.domes = []
        self.light_groups = []
        # Volumes whose OpenVDB grids the renderer reads (add_volume).
        self.volumes = []
        self.warnings = []
        # The stage's UsdRender settings and products (render_settings.convert), or None.
        self.render_settings = None
        # The open shutter the motion keys span: {"open": frames, "close": frames}, or None.
        self.shutter = None
        # Textures added so far under a caller's key (an image several materials pass
        # through unchanged is stored once): {(key, wrap): index}.
        self._texels = {}

    def _view(self, array, dtype, width):
        data = np.ascontiguousarray(np.asarray(array, dtype=dtype).reshape(-1, width))
        view = {"offset": self._size, "count": int(data.shape[0])}
        raw = data.astype(data.dtype.newbyteorder("<"), copy=False)
        self._spool.write(memoryview(raw).cast("B"))
        self._size += raw.nbytes
        return view

    def add_mesh(self, name, material, positions, triangles, normals=None, uvs=None, colors=None,
                 deformation=None):
        """Adds a triangle mesh (object space, counter-clockwise front faces); returns its
        index. `uvs` are glTF-style (v down), `colors` linear RGBA; `deformation` is
        (positions, normals or None) at the shutter's keys for a mesh that deforms."""
        self.meshes.append({
            "name": name,
            "material": int(material),
            "positions": self._view(positions, "<f4", 3),
            "normals": None if normals is None else self._view(normals, "<f4", 3),
            "tangents": None,
            "uvs": [None if uvs is None else self._view(uvs, "<f4", 2), None],
            "colors": None if colors is None else self._view(colors, "<f4", 4),
            "triangles": self._view(triangles, "<u4", 3),
        })
        if deformation is not None:
            key_positions, key_normals = deformation
            entry = {"positions": [self._view(k, "<f4", 3) for k in key_positions]}
            if key_normals is not None and normals is not None:
                entry["normals"] = [self._view(k, "<f4", 3) for k in key_normals]
            self.meshes[-1]["deformation"] = entry
        return len(self.meshes) - 1

    def add_subdivision(self, mesh, cage):
        """Makes mesh `mesh` (its placeholder: the cage triangulated) a subdivision surface
        that lucerna refines when it renders. `cage` (mesh.Cage) holds the scheme, boundary
        rule, points, polygons, creases, corners, per-corner uvs/colours and the faces kept."""
        entry = {
            "mesh": int(mesh),
            "scheme": cage.scheme,
            "boundary": cage.boundary,
            "points": self._view(cage.points, "<f4", 3),
            "face_counts": self._view(cage.counts, "<u4", 1),
            "face_indices": self._view(cage.indices, "<u4", 1),
            "keep": self._view(np.flatnonzero(cage.keep), "<u4", 1),
        }
        if len(cage.creases):
            words = np.empty((len(cage.creases), 3), "<u4")
            words[:, :2] = cage.creases
            words[:, 2] = np.asarray(cage.crease_sharpness, "<f4").view("<u4")
            entry["creases"] = self._view(words, "<u4", 3)
        if len(cage.corners):
            words = np.empty((len(cage.corners), 2), "<u4")
            words[:, 0] = cage.corners
            words[:, 1] = np.asarray(cage.corner_sharpness, "<f4").view("<u4")
            entry["corners"] = self._view(words, "<u4", 2)
        if cage.uvs is not None:
            entry["uvs"] = self._view(cage.uvs, "<f4", 2)
        if cage.colors is not None:
            entry["colors"] = self._view(cage.colors, "<f4", 4)
        if cage.point_keys is not None:
            entry["point_keys"] = [self._view(k, "<f4", 3) for k in cage.point_keys]
        self.subdivision_surfaces.append(entry)

    def add_instances(self, name, mesh, matrices, motion=None):
        """Places `mesh` once per row-vector matrix in `matrices` (shape (K, 4, 4)); `motion`
        (S, K, 4, 4): each placement's matrices over the shutter, kept where they change."""
        for k, m in enumerate(np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)):
            self.instances.append({
                "name": name if len(matrices) == 1 else f"{name}[{k}]",
                "mesh": int(mesh),
                "transform": matrix(m),
            })
            if motion is not None and not np.allclose(motion[:, k], motion[:1, k], rtol=0, atol=1e-12):
                self.instances[-1]["motion"] = [matrix(key) for key in motion[:, k]]

    def add_volume(self, name, file, grid, to_world, material, fields=None):
        """Adds a volume: grid `grid` of the OpenVDB `file` (an absolute path), its index
        space placed by `to_world` (the scene file's 16 numbers) after the grid's own
        transform, filling an interface box of `material` (whose medium the grid's
        densities scale); `fields`: {kind: (file, grid)} of its other fields, under the same
        transform: "temperature" for its material's blackbody, "emission" for its emission
        field, "scatter_color" for the colour that tints its scattering."""
        entry = {"name": name, "file": file, "grid": grid, "to_world": to_world, "material": material}
        for kind, (field_file, field_grid) in (fields or {}).items():
            entry[kind] = {"file": field_file, "grid": field_grid}
        self.volumes.append(entry)

    def add_to_light_group(self, group, member):
        """Puts the emitter named `member` into light group `group` (the lg_<group> AOV)."""
        for g in self.light_groups:
            if g["name"] == group:
                g["members"].append(member)
                return
        self.light_groups.append({"name": group, "members": [member]})

    def add_material(self, material):
        self.materials.append(material)
        return len(self.materials) - 1

    def add_texture(self, name, texels, wrap=("repeat", "repeat"), key=None):
        """Adds an image (H, W, 4): uint8 (sRGB-encoded or data as the material slot
        reads it) or float32 (linear); returns its index. Texels added under a `key` (what
        they are, e.g. an image passed through as stored) with the same wrap are stored
        once. The texels are written out at once: the writer keeps no reference to them."""
        if key is not None and (key, tuple(wrap)) in self._texels:
            return self._texels[key, tuple(wrap)]
        texels = np.asarray(texels)
        height, width = texels.shape[:2]
        if texels.dtype == np.uint8:
            encoding, view = "rgba8", self._view(texels.reshape(-1, 4).view("<u4"), "<u4", 1)
        else:
            encoding, view = "rgba32f", self._view(texels, "<f4", 4)
        self.textures.append({
            "name": name,
            "width": int(width),
            "height": int(height),
            "encoding": encoding,
            "texels": view,
            "wrap_u": wrap[0],
            "wrap_v": wrap[1],
            "nearest": False,
        })
        if key is not None:
            self._texels[key, tuple(wrap)] = len(self.textures) - 1
        return len(self.textures) - 1

    def set_tiles(self, index, tiles, asset):
        """Makes texture `index` a UDIM set of `tiles`, [(tile number, texture index)], read
        from `asset` (the path with its UDIM token, which the set's name then shows): its
        own image is read where the set has no tile. The tiles are named after the set."""
        entry = self.textures[index]
        if "tiles" in entry:
            raise ValueError(f"texture {index} is a UDIM set already")
        entry["tiles"] = [[int(n), int(i)] for n, i in tiles]
        for n, i in tiles:
            self.textures[i]["name"] = f"{entry['name']} tile {n}"
        entry["name"] = f"{entry['name']} ({asset})"

    def write(self, path):
        """Writes the manifest `path` and its buffer `path + '.bin'`."""
        buffer_name = os.path.basename(path) + ".bin"
        manifest = {
            "format": FORMAT,
            "version": VERSION,
            "source": self.source,
            "buffer": buffer_name,
            "buffer_bytes": self._size,
            "meshes": self.meshes,
            "instances": self.instances,
            "spheres": self.spheres,
            "disks": self.disks,
            "cylinders": self.cylinders,
            "materials": self.materials,
            "textures": self.textures,
            "lights": self.lights,
            "cameras": self.cameras,
            "environment": self.environment,
            "light_groups": self.light_groups,
            "warnings": self.warnings,
            "render_settings": self.render_settings,
            "subdivision_surfaces": self.subdivision_surfaces,
        }
        if self.volumes:
            manifest["volumes"] = self.volumes
        if self.shutter is not None:
            manifest["shutter"] = self.shutter
        _check_numbers(manifest)
        text = json.dumps(manifest, indent=1, allow_nan=False)
        self._spool.seek(0)
        _write_atomically(os.path.join(os.path.dirname(path), buffer_name), self._spool)
        _write_atomically(path, io.BytesIO(text.encode()))


# The largest magnitude a 32-bit float holds: the renderer reads every number as one.
FLOAT32_MAX = 3.4028234663852886e38


def _check_numbers(manifest):
    """Refuses a manifest number that is not finite or does not fit a 32-bit float, naming
    the prim of the element that holds it (elements carry their prim's path as their name)
    and the field, so that no value the renderer would refuse reaches it unnamed."""
    from . import StageError

    def walk(value, where):
        if isinstance(value, float) and not (math.isfinite(value) and abs(value) <= FLOAT32_MAX):
            return where, value
        if isinstance(value, dict):
            for k, v in value.items():
                found = walk(v, where + [str(k)])
                if found:
                    return found
        if isinstance(value, list):
            for i, v in enumerate(value):
                found = walk(v, where + [str(i)])
                if found:
                    return found
        return None

    for key in ("meshes", "instances", "spheres", "disks", "cylinders", "materials", "lights",
                "cameras", "environment", "render_settings", "subdivision_surfaces"):
        items = manifest.get(key)
        if items is None:
            continue
        for i, item in enumerate(items if isinstance(items, list) else [items]):
            found = walk(item, [])
            if found:
                field, v = found
                name = item.get("name") if isinstance(item, dict) else None
                element = name if isinstance(name, str) and name.startswith("/") else f"{key}[{i}]"
                raise StageError(element, f"{'.'.join(field)} is {v}: not a number the renderer "
                                          "holds (finite, within 32-bit float range)")


def _write_atomically(path, source):
    """Copies the file object `source` to `path` through a temporary file and a rename."""
    tmp = path + ".tmp"
    try:
        with open(tmp, "wb") as f:
            shutil.copyfileobj(source, f, 1 << 24)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
