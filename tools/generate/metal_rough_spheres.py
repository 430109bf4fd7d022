#!/usr/bin/env python3
"""Generate a grid of glTF PBR spheres for comparing rough lobes with other renderers (as
Khronos' MetalRoughSpheresNoTextures, whose sample-assets repository is too large to fetch
here): rows of a white metal (base colour 1, metallic 1: a white furnace for the specular
lobe), a gold metal, a white dielectric (base 0.8, metallic 0) and a clear glass
(KHR_materials_transmission 1 bounding a volume, ior 1.5), columns of perceptual roughness
0, 0.25, 0.5, 0.75 and 1; and a row of rough diffuse spheres (base 0.8, no specular layer:
KHR_materials_specular 0) whose columns are the diffuse roughness (lucerna's
`extras.lucerna.diffuse_roughness`, OpenPBR's EON; compare.py's Blender script sets the
Principled BSDF's Diffuse Roughness from it). The spheres lie in the XY plane, seen by a camera on
+Z that they fill at 3:2; no light: tools/compare/cycles/compare.py lights them.

    python3 tools/generate/metal_rough_spheres.py DIR

writes DIR/MetalRoughGrid/glTF/MetalRoughGrid.gltf (buffer inlined), the layout compare.py's
--models reads.
"""
import sys
from pathlib import Path

from lucerna_tools.gltf_writer import GltfWriter, icosphere

NAME = "MetalRoughGrid"
ROUGHNESS = [0.0, 0.25, 0.5, 0.75, 1.0]
ROWS = [
    ("white metal", (1.0, 1.0, 1.0), 1.0),
    ("gold", (1.0, 0.78, 0.34), 1.0),
    ("white dielectric", (0.8, 0.8, 0.8), 0.0),
    ("glass", (1.0, 1.0, 1.0), 0.0),
    ("rough diffuse", (0.8, 0.8, 0.8), 0.0),
]
GLASS = {"KHR_materials_transmission": {"transmissionFactor": 1.0},
         "KHR_materials_volume": {"thicknessFactor": 2.0}}
DIFFUSE = {"KHR_materials_specular": {"specularFactor": 0.0}}


def build():
    w = GltfWriter("lucerna tools/generate/metal_rough_spheres.py")
    verts, faces = icosphere(4)
    for row, (name, base, metallic) in enumerate(ROWS):
        for column, roughness in enumerate(ROUGHNESS):
            label = f"{name} roughness {roughness}"
            material = w.material(label, base=base, metallic=metallic, roughness=roughness, double_sided=False)
            if name == "glass":
                w.doc["materials"][material]["extensions"] = GLASS
                w.doc.setdefault("extensionsUsed", []).extend(GLASS)
            if name == "rough diffuse":
                w.doc["materials"][material]["extensions"] = DIFFUSE
                w.doc["materials"][material]["extras"] = {"lucerna": {"diffuse_roughness": roughness}}
                w.doc.setdefault("extensionsUsed", []).extend(DIFFUSE)
            mesh = w.mesh(label, verts, faces, material, normals=verts)
            w.node(mesh=mesh, translation=[2.2 * (column - 2), -2.2 * (row - 2), 0.0])
    w.doc["extensionsUsed"] = sorted(set(w.doc["extensionsUsed"]))
    w.camera("camera", yfov=0.9, aspect=1.5, translation=(0.0, 0.0, 13.0), target=(0.0, 0.0, 0.0), znear=0.1)
    return w


def main():
    out = Path(sys.argv[1]) / NAME / "glTF" / f"{NAME}.gltf"
    build().write_gltf(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
