"""A small glTF 2.0 writer for lucerna's scene generators (standard library only).

    w = GltfWriter()
    m = w.material("white", base=[0.8, 0.8, 0.8], extras={"lucerna": {"bsdf": "lambert"}})
    w.node(mesh=w.mesh("box", positions, triangles, material=m), name="box")
    w.camera("camera", yfov=0.7, aspect=1.5, translation=[0, 1, 5])
    w.write_glb(path)
"""
import base64
import json
import math
import struct
from pathlib import Path


class GltfWriter:
    def __init__(self, generator):
        self.doc = {
            "asset": {"version": "2.0", "generator": generator},
            "scene": 0,
            "scenes": [{"nodes": []}],
        }
        self.blob = bytearray()

    def _list(self, key, item):
        self.doc.setdefault(key, []).append(item)
        return len(self.doc[key]) - 1

    def _use(self, extension):
        used = self.doc.setdefault("extensionsUsed", [])
        if extension not in used:
            used.append(extension)

    def lambert_material(self, name, base, **kw):
        """A plain glTF PBR material that every renderer reads as Lambert: metallic 0,
        KHR_materials_specular specularFactor 0."""
        self._use("KHR_materials_specular")
        index = self.material(name, base=base, **kw)
        self.doc["materials"][index].setdefault("extensions", {}).update(
            {"KHR_materials_specular": {"specularFactor": 0.0}})
        return index

    def add_box(self, name, lo, hi, material, outward=True):
        """A node holding an axis-aligned box mesh (see `box`)."""
        v, t = box(lo, hi, outward)
        self.node(name=name, mesh=self.mesh(name, v, t, material))

    def accessor(self, values, kind, component=5126):
        """A tightly packed accessor; `values` is a list of tuples (or of ints for SCALAR)."""
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[kind]
        fmt = {5126: "f", 5123: "H", 5125: "I"}[component]
        flat = [x for v in values for x in (v if width > 1 else (v,))]
        while len(self.blob) % 4:
            self.blob.append(0)
        data = struct.pack(f"<{len(flat)}{fmt}", *flat)
        view = self._list("bufferViews", {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)})
        self.blob += data
        acc = {"bufferView": view, "componentType": component, "count": len(values), "type": kind}
        if kind == "VEC3" and component == 5126:
            acc["min"] = [min(v[k] for v in values) for k in range(3)]
            acc["max"] = [max(v[k] for v in values) for k in range(3)]
        return self._list("accessors", acc)

    def mesh(self, name, positions, triangles, material, normals=None, extras=None, uvs=None,
             targets=None):
        """A mesh of one primitive; `targets`: morph targets, each a list of position
        displacements."""
        attributes = {"POSITION": self.accessor(positions, "VEC3")}
        if normals is not None:
            attributes["NORMAL"] = self.accessor(normals, "VEC3")
        if uvs is not None:
            attributes["TEXCOORD_0"] = self.accessor(uvs, "VEC2")
        component = 5123 if len(positions) < 65536 else 5125
        indices = self.accessor([i for t in triangles for i in t], "SCALAR", component)
        mesh = {"name": name, "primitives": [{"attributes": attributes, "indices": indices, "material": material}]}
        if targets:
            mesh["primitives"][0]["targets"] = [{"POSITION": self.accessor(t, "VEC3")} for t in targets]
            mesh["weights"] = [0.0] * len(targets)
        if extras is not None:
            mesh["extras"] = extras
        return self._list("meshes", mesh)

    def material(self, name, base=(0.8, 0.8, 0.8), metallic=0.0, roughness=1.0, emissive=None,
                 double_sided=True, extras=None, base_texture=None):
        m = {
            "name": name,
            "pbrMetallicRoughness": {"baseColorFactor": list(base) + [1.0], "metallicFactor": metallic,
                                     "roughnessFactor": roughness},
            "doubleSided": double_sided,
        }
        if base_texture is not None:
            m["pbrMetallicRoughness"]["baseColorTexture"] = {"index": base_texture}
        if emissive is not None:
            peak = max(emissive)
            m["emissiveFactor"] = [c / peak for c in emissive]
            if peak > 1.0:
                self._use("KHR_materials_emissive_strength")
                m["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": peak}}
            else:
                m["emissiveFactor"] = list(emissive)
        if extras is not None:
            m["extras"] = extras
        return self._list("materials", m)

    def texture(self, uri):
        """A texture of the image file `uri` (relative to the glTF) with a repeating sampler."""
        image = self._list("images", {"uri": uri})
        sampler = self._list("samplers", {"wrapS": 10497, "wrapT": 10497})
        return self._list("textures", {"source": image, "sampler": sampler})

    def node(self, root=True, **fields):
        index = self._list("nodes", {k: v for k, v in fields.items() if v is not None})
        if root:
            self.doc["scenes"][0]["nodes"].append(index)
        return index

    def camera(self, name, yfov, aspect, translation, target, znear=0.01):
        cam = self._list("cameras", {"name": name, "type": "perspective",
                                     "perspective": {"yfov": yfov, "aspectRatio": aspect, "znear": znear}})
        forward = unit([t - e for t, e in zip(target, translation)])
        return self.node(name=name, camera=cam, translation=list(translation), rotation=look_rotation(forward))

    def sun(self, direction, intensity):
        """A KHR_lights_punctual directional light of `intensity` lux shining along unit
        `direction` (the file's only punctual light)."""
        self.doc["extensions"] = {"KHR_lights_punctual": {"lights": [{"type": "directional",
                                                                      "intensity": intensity}]}}
        self._use("KHR_lights_punctual")
        return self.node(name="sun", extensions={"KHR_lights_punctual": {"light": 0}},
                         rotation=rotation_between([0, 0, -1], direction))

    def sphere(self, name, centre, radius, material, subdivisions=2):
        """An analytic sphere for lucerna; other viewers see the icosphere fallback."""
        verts, faces = icosphere(subdivisions)
        mesh = self.mesh(name, verts, faces, material, normals=verts, extras={"lucerna": {"shape": "sphere"}})
        return self.node(name=name, mesh=mesh, translation=list(centre), scale=[radius] * 3)

    def write_glb(self, path):
        doc = dict(self.doc)
        doc["buffers"] = [{"byteLength": len(self.blob)}]
        js = json.dumps(doc, separators=(",", ":")).encode()
        js += b" " * (-len(js) % 4)
        blob = bytes(self.blob) + b"\0" * (-len(self.blob) % 4)
        total = 12 + 8 + len(js) + 8 + len(blob)
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_bytes(b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(js)) + b"JSON"
                               + js + struct.pack("<I", len(blob)) + b"BIN\0" + blob)

    def write_gltf(self, path):
        """A .gltf with the buffer as a data URI."""
        doc = dict(self.doc)
        uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.blob)).decode()
        doc["buffers"] = [{"byteLength": len(self.blob), "uri": uri}]
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(doc, indent=1) + "\n")


def unit(v):
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def rotation_between(a, b):
    """Unit quaternion (x, y, z, w) turning unit vector a into unit vector b."""
    c = cross(a, b)
    w = 1 + sum(x * y for x, y in zip(a, b))
    if w < 1e-9:  # opposite vectors: half a turn about any perpendicular axis
        axis = unit(cross(a, [1, 0, 0] if abs(a[0]) < 0.9 else [0, 1, 0]))
        return axis + [0.0]
    n = math.sqrt(sum(x * x for x in c) + w * w)
    return [c[0] / n, c[1] / n, c[2] / n, w / n]


def look_rotation(forward):
    """Quaternion turning a camera's -Z to `forward` with +Y staying up (no roll)."""
    f = unit(forward)
    right = unit(cross(f, [0, 1, 0]))
    up = cross(right, f)
    # Rotation matrix columns: right, up, -forward.
    m = [[right[0], up[0], -f[0]], [right[1], up[1], -f[1]], [right[2], up[2], -f[2]]]
    trace = m[0][0] + m[1][1] + m[2][2]
    if trace > 0:
        s = 0.5 / math.sqrt(trace + 1)
        return [(m[2][1] - m[1][2]) * s, (m[0][2] - m[2][0]) * s, (m[1][0] - m[0][1]) * s, 0.25 / s]
    i = max(range(3), key=lambda k: m[k][k])
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2 * math.sqrt(1 + m[i][i] - m[j][j] - m[k][k])
    q = [0.0, 0.0, 0.0, (m[k][j] - m[j][k]) / s]
    q[i] = 0.25 * s
    q[j] = (m[j][i] + m[i][j]) / s
    q[k] = (m[k][i] + m[i][k]) / s
    return q


def icosphere(subdivisions):
    t = (1 + math.sqrt(5)) / 2
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
             (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    verts = [tuple(unit(v)) for v in verts]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        cache = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                verts.append(tuple(unit([(verts[a][k] + verts[b][k]) / 2 for k in range(3)])))
                cache[key] = len(verts) - 1
            return cache[key]

        next_faces = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            next_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = next_faces
    return verts, faces


def box(lo, hi, outward=True):
    """An axis-aligned box as 8 corners and 12 triangles, wound to face out (or in)."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (3, 7, 6, 2), (0, 4, 7, 3), (1, 2, 6, 5)]
    tris = []
    for a, b, c, d in quads:
        if not outward:
            a, b, c, d = d, c, b, a
        tris += [(a, b, c), (a, c, d)]
    return v, tris


def write_scene(build, default, argv):
    """The generators' command line: writes `build()`'s scene to argv[1] or `default`."""
    out = Path(argv[1]) if len(argv) > 1 else default
    out.parent.mkdir(parents=True, exist_ok=True)
    build().write_glb(out)
    print(f"wrote {out}")
