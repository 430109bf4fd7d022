#!/usr/bin/env python3
"""Generate the corpus of broken glTF files under tests/bad-gltf/.

Each file breaks one thing; tests/bad-gltf/expected.json maps it to a fragment of the
element and of the reason that lucerna's one-line error must name. tests/it/bad_input.rs
renders every file and checks exit code 2, that single line, no panic and no output file.
Standard library only:

    python3 tools/generate/bad_gltf.py
"""
import base64
import copy
import json
import struct
import zlib
from pathlib import Path

OUT = Path(__file__).resolve().parents[2] / "tests" / "bad-gltf"


def base_document():
    """A valid document: one indexed triangle, positions and u16 indices in one buffer."""
    positions = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    indices = struct.pack("<3H", 0, 1, 2) + b"\0\0"
    blob = positions + indices
    return {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 6},
        ],
        "buffers": [{"byteLength": len(blob), "uri": data_uri(blob)}],
    }, blob


def data_uri(blob):
    return "data:application/octet-stream;base64," + base64.b64encode(blob).decode()


def glb(doc, blob):
    doc = copy.deepcopy(doc)
    del doc["buffers"][0]["uri"]
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    blob = blob + b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(js) + 8 + len(blob)
    return (b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(js)) + b"JSON" + js
            + struct.pack("<I", len(blob)) + b"BIN\0" + blob)


def png_header_only(width, height):
    """A PNG whose header declares width x height RGBA pixels, with one tiny IDAT: a few
    hundred bytes that would decode to gigabytes."""
    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
            + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b""))


def cases():
    """(file name, contents, element fragment, reason fragment)"""
    doc, blob = base_document()

    def variant(edit):
        d = copy.deepcopy(doc)
        edit(d)
        return json.dumps(d, indent=1).encode()

    def with_blob(new_blob, edit=lambda d: None):
        def apply(d):
            d["buffers"][0]["uri"] = data_uri(new_blob)
            d["buffers"][0]["byteLength"] = len(new_blob)
            edit(d)
        return variant(apply)

    full = glb(doc, blob)
    yield "truncated.glb", full[: len(full) // 2], "GLB container", "file is truncated"
    yield ("glb-chunk-too-long.glb", full[:12] + struct.pack("<I", 10**6) + full[16:],
           "GLB container", "")
    yield "empty.glb", b"", "JSON", "EOF"
    yield "not-json.gltf", b"this is not a glTF file\n", "JSON", "expected"
    yield ("missing-buffer-file.gltf",
           variant(lambda d: d["buffers"][0].update(uri="missing.bin")),
           "buffers[0].uri", "cannot read")
    yield ("buffer-shorter-than-byte-length.gltf",
           variant(lambda d: d["buffers"][0].update(uri=data_uri(blob[:20]))),
           "buffers[0]", "truncated")
    yield ("accessor-past-buffer-view.gltf",
           variant(lambda d: d["accessors"][0].update(count=300)),
           "accessors[0]", "past the end of bufferViews[0]")
    yield ("buffer-view-past-buffer.gltf",
           variant(lambda d: d["bufferViews"][1].update(byteLength=4000)),
           "accessors[1]", "past the end of its buffer")
    yield ("accessor-index-out-of-range.gltf",
           variant(lambda d: d["meshes"][0]["primitives"][0]["attributes"].update(POSITION=7)),
           "attributes.POSITION", "accessor 7 does not exist")
    yield ("vertex-index-out-of-range.gltf",
           with_blob(blob[:36] + struct.pack("<3H", 0, 1, 99) + b"\0\0"),
           "indices", "index 99 at position 2 is out of range")
    yield ("nan-positions.gltf",
           with_blob(struct.pack("<9f", 0, 0, 0, float("nan"), 0, 0, 0, 1, 0) + blob[36:]),
           "attributes.POSITION", "NaN or infinite")
    yield ("zero-triangles.gltf",
           variant(lambda d: d["meshes"][0]["primitives"][0].update(mode=0)),
           "scenes[0]", "contains no triangles")
    yield ("degenerate-triangles-only.gltf",
           with_blob(blob[:36] + struct.pack("<3H", 0, 1, 1) + b"\0\0"),
           "scenes[0]", "contains no triangles")
    yield ("dotdot-uri.gltf",
           variant(lambda d: d["buffers"][0].update(uri="../outside.bin")),
           "buffers[0].uri", "leaves the scene's directory")
    yield ("absolute-uri.gltf",
           variant(lambda d: d["buffers"][0].update(uri="/etc/passwd")),
           "buffers[0].uri", "absolute path")
    yield ("http-uri.gltf",
           variant(lambda d: d["buffers"][0].update(uri="http://example.com/scene.bin")),
           "buffers[0].uri", "scheme \"http\" is not allowed")
    yield ("unsupported-required-extension.gltf",
           variant(lambda d: d.update(extensionsUsed=["ADOBE_materials_thin_transparency"],
                                      extensionsRequired=["ADOBE_materials_thin_transparency"])),
           "extensionsRequired[0]", "required extension is not supported")
    yield ("position-unsigned-int.gltf",
           variant(lambda d: d["accessors"][0].update(componentType=5125)),
           "attributes.POSITION", "UNSIGNED_INT components is not allowed")
    yield ("wrong-accessor-type.gltf",
           variant(lambda d: d["accessors"][0].update(type="VEC2", count=3, min=[0, 0], max=[1, 1])),
           "attributes.POSITION", "expected [Vec3]")
    yield ("stride-smaller-than-element.gltf",
           variant(lambda d: d["bufferViews"][0].update(byteStride=4)),
           "attributes.POSITION", "byteStride 4 is smaller than the element size 12")
    yield ("huge-count.gltf",
           variant(lambda d: d["accessors"][0].update(count=4000000000)),
           "accessors[0]", "past the end")
    yield ("node-cycle.gltf",
           variant(lambda d: d.update(nodes=[{"mesh": 0, "children": [1]}, {"children": [0]}])),
           "nodes[0]", "cycle")
    yield ("bad-image.gltf",
           variant(lambda d: d.update(
               images=[{"uri": data_uri(b"GIF89a not really an image")}],
               textures=[{"source": 0}],
               materials=[{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
               meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
                                        "material": 0}]}])),
           "images[0]", "unsupported image format")
    yield ("unknown-bsdf-in-extras.gltf",
           variant(lambda d: d.update(
               materials=[{"extras": {"lucerna": {"bsdf": "velvet"}}}],
               meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
                                        "material": 0}]}])),
           "materials[0].extras.lucerna", "unknown bsdf \"velvet\"")
    yield ("diffuse-roughness-out-of-range.gltf",
           variant(lambda d: d.update(
               materials=[{"extras": {"lucerna": {"diffuse_roughness": 2.0}}}],
               meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
                                        "material": 0}]}])),
           "materials[0].extras.lucerna", "diffuse_roughness 2 must be in [0, 1]")
    yield ("medium-negative-scattering.gltf",
           variant(lambda d: d.update(
               materials=[{"extras": {"lucerna": {"bsdf": "interface",
                                                  "medium": {"scattering": [1.0, -2.0, 1.0]}}}}],
               meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
                                        "material": 0}]}])),
           "materials[0].extras.lucerna.medium", "absorption, scattering and emission must be in [0, 1e8] per metre")
    yield ("medium-density-1e30.gltf",
           variant(lambda d: d.update(
               materials=[{"extras": {"lucerna": {"bsdf": "interface", "medium": {"absorption": 1e30}}}}],
               meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
                                        "material": 0}]}])),
           "materials[0].extras.lucerna.medium", "absorption, scattering and emission must be in [0, 1e8] per metre")
    yield ("medium-negative-emission.gltf",
           variant(lambda d: d.update(
               materials=[{"extras": {"lucerna": {"bsdf": "interface",
                                                  "medium": {"absorption": 1.0, "emission": [2.0, -1.0, 0.0]}}}}],
               meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
                                        "material": 0}]}])),
           "materials[0].extras.lucerna.medium", "absorption, scattering and emission must be in [0, 1e8] per metre")
    yield ("medium-anisotropy-one.gltf",
           variant(lambda d: d.update(
               materials=[{"extras": {"lucerna": {"bsdf": "interface",
                                                  "medium": {"scattering": 1.0, "anisotropy": 1.0}}}}],
               meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
                                        "material": 0}]}])),
           "materials[0].extras.lucerna.medium.anisotropy", "1 must be in (-1, 1)")
    yield ("medium-grid-missing.gltf",
           variant(lambda d: d.update(
               materials=[{"extras": {"lucerna": {"bsdf": "interface",
                                                  "medium": {"scattering": 1.0, "density": "missing.vol"}}}}],
               meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
                                        "material": 0}]}])),
           "materials[0].extras.lucerna.medium.density", "missing.vol: cannot read")
    # A grid header that asks for 2^31 voxels a side, in a file of 48 bytes.
    huge = b"VOL\x03" + struct.pack("<5i", 1, 2**31 - 1, 2**31 - 1, 2**31 - 1, 1) + struct.pack("<6f", 0, 0, 0, 1, 1, 1)
    yield ("medium-grid-truncated.gltf",
           variant(lambda d: d.update(
               materials=[{"extras": {"lucerna": {"bsdf": "interface", "medium": {
                   "scattering": 1.0,
                   "density": "data:application/octet-stream;base64," + base64.b64encode(huge).decode()}}}}],
               meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
                                        "material": 0}]}])),
           "materials[0].extras.lucerna.medium.density", "bytes, the file has 48")
    def vdb(kind="Tree_float_5_4_3", grid_class="fog volume", cut=None):
        """An OpenVDB file of one grid up to its metadata (enough for the errors wanted)."""
        def string(text):
            return struct.pack("<I", len(text)) + text.encode()
        grid = struct.pack("<I", 0x6) + struct.pack("<I", 1) + string("class") + string("string") + string(grid_class)
        head = b" BDV\0\0\0\0" + struct.pack("<3I", 224, 10, 0) + b"\1" + b"0" * 36 + struct.pack("<2I", 0, 1)
        head += string("density") + string(kind) + string("")
        start = len(head) + 24
        data = head + struct.pack("<3q", start, start + len(grid), start + len(grid)) + grid
        return data[:cut] if cut else data

    def with_vdb(data, **medium):
        uri = "data:application/octet-stream;base64," + base64.b64encode(data).decode()
        fields = {"scattering": 1.0, "density": uri, **medium}
        return variant(lambda d: d.update(
            materials=[{"extras": {"lucerna": {"bsdf": "interface", "medium": {
                k: v for k, v in fields.items() if v is not None}}}}],
            meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}]))
    yield ("medium-vdb-level-set.gltf", with_vdb(vdb(grid_class="level set")),
           "materials[0].extras.lucerna.medium.density", "is a level set (signed distances), not a density")
    yield ("medium-vdb-vector-grid.gltf", with_vdb(vdb(kind="Tree_vec3s_5_4_3")),
           "materials[0].extras.lucerna.medium.density", "lucerna reads scalar float and double grids")
    yield ("medium-vdb-truncated.gltf", with_vdb(vdb(cut=30)),
           "materials[0].extras.lucerna.medium.density", "the file ends early")
    yield ("medium-vdb-missing-grid.gltf", with_vdb(vdb(), density_grid="smoke"),
           "materials[0].extras.lucerna.medium.density", "it has no grid \"smoke\" (grids: density (Tree_float_5_4_3))")
    one_voxel = (b"VOL\x03" + struct.pack("<5i", 1, 1, 1, 1, 1) + struct.pack("<6f", 0, 0, 0, 1, 1, 1)
                 + struct.pack("<f", 2.0))
    one_voxel_uri = "data:application/octet-stream;base64," + base64.b64encode(one_voxel).decode()
    yield ("medium-blackbody-without-density.gltf", with_vdb(vdb(), density=None,
                                                             blackbody={"temperature": one_voxel_uri}),
           "materials[0].extras.lucerna.medium.blackbody", "a blackbody needs the medium's density grid")
    yield ("medium-blackbody-zero-kelvin.gltf", with_vdb(vdb(), blackbody={"temperature": one_voxel_uri, "kelvin": 0}),
           "materials[0].extras.lucerna.medium.blackbody.kelvin", "0 must be positive and finite")
    yield ("medium-blackbody-too-hot.gltf",
           with_vdb(one_voxel, blackbody={"temperature": one_voxel_uri, "kelvin": 1e6}),
           "materials[0].extras.lucerna.medium.blackbody", "the temperature grid reaches 2e6 K")
    yield ("medium-blackbody-missing-grid.gltf",
           with_vdb(one_voxel, blackbody={"temperature": "data:application/octet-stream;base64,"
                                      + base64.b64encode(vdb()).decode()}),
           "materials[0].extras.lucerna.medium.blackbody.temperature",
           "it has no grid \"temperature\" (grids: density (Tree_float_5_4_3))")
    yield ("medium-emission-field-without-density.gltf",
           with_vdb(vdb(), density=None, emission_field={"file": one_voxel_uri}),
           "materials[0].extras.lucerna.medium.emission_field",
           "an emission field needs the medium's density grid")
    yield ("medium-emission-field-and-blackbody.gltf",
           with_vdb(vdb(), blackbody={"temperature": one_voxel_uri}, emission_field={"file": one_voxel_uri}),
           "materials[0].extras.lucerna.medium.emission_field", "a medium glows by one field")
    yield ("medium-emission-field-negative-tint.gltf",
           with_vdb(vdb(), emission_field={"file": one_voxel_uri, "tint": [1, -1, 1]}),
           "materials[0].extras.lucerna.medium.emission_field.tint", "must be in [0, 1e8]")
    yield ("medium-emission-field-missing-grid.gltf",
           with_vdb(one_voxel, emission_field={"file": "data:application/octet-stream;base64,"
                                               + base64.b64encode(vdb()).decode(), "grid": "heat"}),
           "materials[0].extras.lucerna.medium.emission_field.file",
           "it has no grid \"heat\" (grids: density (Tree_float_5_4_3))")
    yield ("medium-scatter-color-without-density.gltf",
           with_vdb(vdb(), density=None, scatter_color={"file": one_voxel_uri}),
           "materials[0].extras.lucerna.medium.scatter_color",
           "a scatter colour grid needs the medium's density grid")
    yield ("medium-scatter-color-not-vdb.gltf",
           with_vdb(one_voxel, scatter_color={"file": one_voxel_uri}),
           "materials[0].extras.lucerna.medium.scatter_color.file", "is not an OpenVDB file")
    yield ("medium-scatter-color-missing-grid.gltf",
           with_vdb(one_voxel, scatter_color={"file": "data:application/octet-stream;base64,"
                                              + base64.b64encode(vdb(kind="Tree_vec3s_5_4_3")).decode(),
                                              "grid": "Cd"}),
           "materials[0].extras.lucerna.medium.scatter_color.file",
           "it has no grid \"Cd\" (grids: density (Tree_vec3s_5_4_3))")
    yield ("medium-scatter-color-truncated.gltf",
           with_vdb(one_voxel, scatter_color={"file": "data:application/octet-stream;base64,"
                                              + base64.b64encode(vdb(kind="Tree_vec3s_5_4_3", cut=30)).decode()}),
           "materials[0].extras.lucerna.medium.scatter_color.file", "the file ends early")
    # What glTF-Validator calls errors and lucerna accepted quietly before.
    yield ("version-3.gltf", variant(lambda d: d["asset"].update(version="3.0")),
           "asset.version", "lucerna reads glTF 2.x")
    yield ("min-version-2.1.gltf", variant(lambda d: d["asset"].update(minVersion="2.1")),
           "asset.minVersion", "a later glTF than 2.0")
    yield "glb-trailing-bytes.glb", full + b"\0" * 8, "GLB container", "the header declares"
    yield ("animation-missing-node.gltf",
           variant(lambda d: d.update(animations=[{
               "samplers": [{"input": 1, "output": 0}],
               "channels": [{"sampler": 0, "target": {"node": 5, "path": "translation"}}]}])),
           "animations[0].channels[0].target.node", "node 5 does not exist")
    sparse_blob = blob[:44] + struct.pack("<H", 99) + b"\0\0"

    def sparse(d):
        d["bufferViews"].append({"buffer": 0, "byteOffset": 44, "byteLength": 2})
        d["accessors"][0]["sparse"] = {
            "count": 1, "indices": {"bufferView": 2, "componentType": 5123},
            "values": {"bufferView": 0}}
    yield ("sparse-index-out-of-range.gltf", with_blob(sparse_blob, sparse),
           "attributes.POSITION", "sparse.indices[0] = 99 is past the accessor's 3 elements")

    def with_material(material):
        def apply(d):
            d["materials"] = [material]
            d["meshes"][0]["primitives"][0]["material"] = 0
        return variant(apply)
    yield ("negative-roughness.gltf",
           with_material({"pbrMetallicRoughness": {"roughnessFactor": -0.5}}),
           "materials[0]", "roughnessFactor is outside its range")
    yield ("base-color-above-one.gltf",
           with_material({"pbrMetallicRoughness": {"baseColorFactor": [2, 0.5, 0.5, 1]}}),
           "materials[0]", "baseColorFactor is outside its range")
    def translucent(extension):
        return {"extensions": {"KHR_materials_diffuse_transmission": extension}}
    yield ("diffuse-transmission-above-one.gltf",
           with_material(translucent({"diffuseTransmissionFactor": 1.5})),
           "materials[0]", "diffuseTransmissionFactor = 1.5 is outside [0, 1]")
    yield ("diffuse-transmission-negative-color.gltf",
           with_material(translucent({"diffuseTransmissionFactor": 0.5,
                                      "diffuseTransmissionColorFactor": [1, -0.2, 0.5]})),
           "materials[0]", "diffuseTransmissionColorFactor")

    def with_camera(perspective):
        def apply(d):
            d["cameras"] = [{"type": "perspective", "perspective": perspective}]
            d["nodes"].append({"camera": 0, "translation": [0, 0, 3]})
            d["scenes"][0]["nodes"].append(1)
        return variant(apply)
    yield ("znear-beyond-zfar.gltf", with_camera({"yfov": 0.8, "znear": 10, "zfar": 1}),
           "cameras[0]", "zfar 1 must be greater than znear 10")
    yield ("aspect-ratio-zero.gltf",
           with_camera({"yfov": 0.8, "znear": 0.1, "aspectRatio": 0}),
           "cameras[0]", "aspectRatio 0 must be positive")

    def spot(d):
        d["extensionsUsed"] = ["KHR_lights_punctual"]
        d["extensions"] = {"KHR_lights_punctual": {"lights": [
            {"type": "spot", "intensity": 10,
             "spot": {"innerConeAngle": 1.0, "outerConeAngle": 0.5}}]}}
        d["nodes"].append({"extensions": {"KHR_lights_punctual": {"light": 0}}})
        d["scenes"][0]["nodes"].append(1)
    yield ("spot-inner-beyond-outer.gltf", variant(spot),
           "KHR_lights_punctual.lights[0]", "must satisfy 0 <= inner < outer")
    yield ("png-header-65535-square.gltf",
           variant(lambda d: d.update(
               images=[{"uri": "data:image/png;base64,"
                        + base64.b64encode(png_header_only(65535, 65535)).decode()}],
               textures=[{"source": 0}],
               materials=[{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
               meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
                                        "material": 0}]}])),
           "images[0]", "larger than the limit")
    # 1e39 overflows f32: the JSON reader (exact float parsing) rejects it with its position.
    yield ("infinite-transform.gltf",
           variant(lambda d: d["nodes"][0].update(translation=[1e39, 0, 0])),
           "JSON", "number out of range at line")


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    expected = {}
    for name, contents, element, reason in cases():
        (OUT / name).write_bytes(contents)
        expected[name] = {"element": element, "reason": reason}
    (OUT / "expected.json").write_text(json.dumps(expected, indent=1, sort_keys=True) + "\n")
    print(f"wrote {len(expected)} files to {OUT}")


if __name__ == "__main__":
    main()
