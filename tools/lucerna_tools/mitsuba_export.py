"""Export a lucerna scene file (`lucerna convert SCENE -o x.lucerna`) to a Mitsuba 3 scene,
so that Mitsuba renders exactly the geometry, materials, lights and camera lucerna sees.

Only models on which the two renderers agree are exported; anything else is an error that
names the element (never a silent approximation):

- `lambert` materials -> `diffuse`; glTF PBR with metallic 0 and a specular weight of 0
  (KHR_materials_specular specularFactor 0, no texture) is exactly Lambert -> `diffuse`;
  glTF PBR with metallic 1, base colour 1, no textures ->
  `roughconductor` (GGX, alpha = roughness^2, Fresnel 1: `material = "none"`, visible-normal
  sampling); `double_sided` -> `twosided`.
- glass (glTF transmission 1, metallic 0, no other layer, no texture): with a clear volume
  -> `dielectric` (smooth) or `roughdielectric` (GGX, alpha = roughness^2, visible-normal
  sampling), a thin wall -> `thindielectric` (smooth only); int_ior = ior, ext_ior = 1, the
  base colour as `specular_transmittance` (both tint each crossing).
- media: the homogeneous medium inside a material's volume -> a `homogeneous` interior
  medium (sigma_t = absorption + scattering, albedo = scattering / sigma_t, `hg` phase);
  a medium with a density grid -> `heterogeneous` with `sigma_t` a `gridvolume` of the
  density times the extinction (one channel, or three where it differs by channel, `raw`),
  placed by the grid's own transform of the unit cube, as lucerna places it;
  an interface (`model` interface) -> `null`; any medium makes the integrator `volpath`
  (`volpathmis` where a medium's extinction differs by channel);
- emission -> an `area` emitter (one-sided, on the front face, like lucerna);
- meshes (with their shading normals if any) per instance, analytic spheres;
- point and directional lights, hard-edged spot lights (inner cone = outer cone: Mitsuba's
  spot falls off linearly in angle, lucerna's glTF ramp quadratically in cosine), a
  constant environment;
- a pinhole perspective camera, box pixel filter.

One difference remains by construction: lucerna makes the back of a one-sided surface
invisible, Mitsuba makes it a black occluder. Scenes for comparisons show no back faces.
"""
import json
import math
from pathlib import Path

import numpy as np


class Unsupported(ValueError):
    """The scene uses something the two renderers do not model alike."""


def read_scene_file(path):
    """(manifest dict, buffer bytes) of a lucerna scene file."""
    path = Path(path)
    manifest = json.loads(path.read_text())
    if manifest.get("format") != "lucerna-scene" or manifest.get("version") != 1:
        raise ValueError(f"{path}: not a version 1 lucerna scene file")
    return manifest, (path.parent / manifest["buffer"]).read_bytes()


def view(buffer, v, dtype, width):
    """The `count` elements of a buffer view as an array of shape (count, width)."""
    return np.frombuffer(buffer, dtype=dtype, count=v["count"] * width, offset=v["offset"]).reshape(-1, width)


def write_ply(path, positions, triangles, normals=None):
    props = "property float x\nproperty float y\nproperty float z\n"
    if normals is not None:
        props += "property float nx\nproperty float ny\nproperty float nz\n"
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(positions)}\n{props}"
              f"element face {len(triangles)}\nproperty list uchar int vertex_indices\nend_header\n")
    vertices = positions if normals is None else np.hstack([positions, normals])
    faces = np.zeros(len(triangles), dtype=[("n", "u1"), ("v", "<i4", 3)])
    faces["n"] = 3
    faces["v"] = triangles
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(np.ascontiguousarray(vertices, dtype="<f4").tobytes())
        f.write(faces.tobytes())


def matrix(values):
    """A column-major list of 16 numbers as a 4x4 row-major numpy matrix."""
    return np.array(values, dtype=np.float64).reshape(4, 4).T


SMOOTH_ALPHA = 1e-3  # as src/material/microfacet.rs: below it, a delta lobe


def glass(material, element):
    """Mitsuba's dielectric of a lucerna glass material."""
    layered = [k for k in ("sheen", "iridescence", "anisotropy") if material.get(k)]
    specular = material.get("specular") or {}
    if (material["transmission"] != 1.0 or material["metallic"] != 0.0 or material.get("clearcoat", 0.0) > 0
            or layered or material.get("specular_color") or specular.get("weight", 1.0) != 1.0
            or specular.get("color", [1, 1, 1]) != [1, 1, 1] or material.get("transmission_texture")):
        raise Unsupported(f"{element}: only pure glass (transmission 1, metallic 0, no other layer) is exported")
    volume = material.get("volume")
    alpha = material["roughness"] ** 2
    tint = material.get("transmission_color") or material["base_color"][:3]
    common = {"int_ior": material["ior"], "ext_ior": 1.0,
              "specular_transmittance": {"type": "rgb", "value": tint}}
    if volume is None:
        if alpha >= SMOOTH_ALPHA:
            raise Unsupported(f"{element}: Mitsuba's thindielectric is smooth only")
        return {"type": "thindielectric", **common}
    if alpha < SMOOTH_ALPHA:
        return {"type": "dielectric", **common}
    return {"type": "roughdielectric", "distribution": "ggx", "alpha": alpha, "sample_visible": True, **common}


def extinction(material):
    """The extinction (absorption + scattering, at density 1 for a grid) of a lucerna
    material's volume, None without one."""
    volume = material.get("volume")
    if not volume:
        return None
    return (np.array(volume["absorption"], dtype=np.float64)
            + np.array(volume.get("scattering", [0.0, 0.0, 0.0]), dtype=np.float64))


def medium(material, grid_volume=None):
    """Mitsuba's interior medium of a lucerna material's volume (None: no volume, or clear).
    `grid_volume(index, sigma_t)` gives the `gridvolume` of the scene's density grid `index`
    times the RGB extinction `sigma_t` (scaled to a peak of 1)."""
    volume = material.get("volume")
    if volume and any(volume.get("emission", [0.0, 0.0, 0.0])):
        raise Unsupported(f"material {material.get('name')!r}: Mitsuba 3's media do not emit")
    sigma_t = extinction(material)
    if sigma_t is None or not sigma_t.any():
        return None
    scattering = np.array(volume.get("scattering", [0.0, 0.0, 0.0]), dtype=np.float64)
    albedo = np.divide(scattering, sigma_t, out=np.zeros(3), where=sigma_t > 0)
    # Mitsuba reads an RGB sigma_t as a reflectance (at most 1): the peak goes to `scale`.
    peak = float(sigma_t.max())
    common = {"scale": peak, "albedo": {"type": "rgb", "value": albedo.tolist()},
              "phase": {"type": "hg", "g": float(volume.get("anisotropy", 0.0))}}
    if volume.get("density") is not None:
        if grid_volume is None:
            raise Unsupported("a density grid needs the scene's grids")
        return {"type": "heterogeneous", "sigma_t": grid_volume(volume["density"], sigma_t / peak), **common}
    return {"type": "homogeneous", "sigma_t": {"type": "rgb", "value": (sigma_t / peak).tolist()}, **common}


def write_vol(path, values, channels):
    """A Mitsuba `.vol` file (version 3, float32) of `values` shaped (z, y, x, channels),
    in the unit box."""
    nz, ny, nx = values.shape[:3]
    header = b"VOL" + bytes([3]) + np.array([1, nx, ny, nz, channels], dtype="<i4").tobytes()
    box = np.array([0, 0, 0, 1, 1, 1], dtype="<f4").tobytes()
    Path(path).write_bytes(header + box + np.ascontiguousarray(values, dtype="<f4").tobytes())


def bsdf(material, element):
    if material["model"] == "interface":
        return {"type": "null"}
    if any(material.get(k) for k in ("base_color_texture", "metallic_roughness_texture", "normal_texture",
                                     "emissive_texture", "transmission_texture", "clearcoat_texture")):
        raise Unsupported(f"{element}: textures are not exported")
    if material["alpha_mode"] != "opaque":
        raise Unsupported(f"{element}: alpha modes other than opaque are not exported")
    if material.get("transmission", 0.0) > 0.0 and material["model"] == "gltf_pbr":
        return glass(material, element)
    if material.get("clearcoat", 0.0) > 0.0:
        raise Unsupported(f"{element}: clear coats are not exported")
    if material.get("unlit") or material.get("sheen") or material.get("iridescence") or material.get("anisotropy"):
        raise Unsupported(f"{element}: unlit, sheen, iridescence and anisotropy are not exported")
    base = material["base_color"][:3]
    specular = material.get("specular") or {}
    no_specular = (material["model"] == "gltf_pbr" and material["metallic"] == 0.0
                   and specular.get("weight") == 0.0 and not specular.get("weight_texture"))
    if material["model"] == "lambert" or no_specular:
        b = {"type": "diffuse", "reflectance": {"type": "rgb", "value": base}}
    elif material["model"] == "gltf_pbr" and material["metallic"] == 1.0 and base == [1.0, 1.0, 1.0]:
        alpha = max(material["roughness"] ** 2, 1e-4)
        b = {"type": "roughconductor", "distribution": "ggx", "alpha": alpha, "material": "none",
             "sample_visible": True}
    else:
        raise Unsupported(f"{element}: only lambert and glTF metals of base colour 1 are exported "
                          f"({material['model']}, metallic {material['metallic']}, base {base})")
    return {"type": "twosided", "bsdf": b} if material["double_sided"] else b


def emitter(material):
    if material["emissive_texture"]:
        raise Unsupported("emissive textures are not exported")
    radiance = material["emissive"]
    return {"type": "area", "radiance": {"type": "rgb", "value": radiance}} if max(radiance) > 0 else None


def camera(manifest, width, height, name=None, sampler="independent"):
    cameras = manifest["cameras"]
    if not cameras:
        raise Unsupported("the scene has no camera")
    cam = next((c for c in cameras if c["name"] == name), None) if name else cameras[0]
    if cam is None:
        raise Unsupported(f"no camera named {name!r}")
    projection = cam["projection"]
    if "perspective" not in projection or cam["aperture_radius"] > 0:
        raise Unsupported("only pinhole perspective cameras are exported")
    m = matrix(cam["transform"])
    origin = m[:3, 3]
    forward = m[:3, :3] @ np.array([0.0, 0.0, -1.0])
    up = m[:3, :3] @ np.array([0.0, 1.0, 0.0])
    import mitsuba as mi
    return {
        "type": "perspective",
        "fov": math.degrees(projection["perspective"]["yfov"]),
        "fov_axis": "y",
        "near_clip": cam["clip_near"],
        "far_clip": cam["clip_far"] or 1e7,
        "to_world": mi.ScalarTransform4f().look_at(origin=origin.tolist(), target=(origin + forward).tolist(),
                                                   up=up.tolist()),
        "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"},
                 "pixel_format": "rgb"},
        "sampler": {"type": sampler},
    }


def scene_dict(scene_file, width, height, workdir, max_depth=-1, camera_name=None, sampler="independent"):
    """A Mitsuba scene dictionary (for `mi.load_dict`) of the lucerna scene file, sampled by
    Mitsuba's `sampler` plugin (its sample count is the one `mi.render` is given). Meshes are
    written as PLY files into `workdir`, which must outlive the loaded scene's creation."""
    import mitsuba as mi
    manifest, buffer = read_scene_file(scene_file)
    materials = manifest["materials"]
    grids = manifest.get("grids", [])
    written = {}

    def grid_volume(index, sigma_t):
        """The gridvolume of density grid `index` times `sigma_t` (written once per pair)."""
        key = (index, tuple(sigma_t))
        if key not in written:
            g = grids[index]
            nx, ny, nz = g["resolution"]
            density = view(buffer, g["values"], "<f4", 1).reshape(nz, ny, nx, 1).astype(np.float64)
            channels = 1 if len(set(sigma_t)) == 1 else 3
            path = Path(workdir) / f"grid{index}_{len(written)}.vol"
            write_vol(path, density * sigma_t[:channels], channels)
            written[key] = {"type": "gridvolume", "filename": str(path), "raw": True,
                            "to_world": mi.ScalarTransform4f(matrix(g["to_world"]).tolist())}
        return dict(written[key])

    def medium_of(material):
        return medium(material, grid_volume)
    media = [m for m in map(medium_of, materials) if m]
    # Mitsuba's volpath samples distances in one channel without MIS over the channels: in
    # a medium whose extinction differs by channel its estimate is unbiased but so
    # heavy-tailed that it reads several per cent dark at thousands of samples; volpathmis
    # (spectral MIS, Miller et al. 2019) is the exact peer there, as lucerna's channel MIS.
    chromatic = any(len(set(e)) > 1 for e in map(extinction, materials) if e is not None and e.any())
    integrator = ("volpathmis" if chromatic else "volpath") if media else "path"
    scene = {"type": "scene", "integrator": {"type": integrator, "max_depth": max_depth},
             "sensor": camera(manifest, width, height, camera_name, sampler)}

    def bounded(shape, material):
        """The shape with the medium its material's volume holds, if any."""
        if m := medium_of(material):
            shape["interior"] = m
        return shape
    plys = {}
    for i, inst in enumerate(manifest["instances"]):
        mesh = manifest["meshes"][inst["mesh"]]
        if inst["mesh"] not in plys:
            ply = Path(workdir) / f"mesh{inst['mesh']}.ply"
            normals = view(buffer, mesh["normals"], "<f4", 3) if mesh["normals"] else None
            write_ply(ply, view(buffer, mesh["positions"], "<f4", 3), view(buffer, mesh["triangles"], "<u4", 3),
                      normals)
            plys[inst["mesh"]] = (ply, normals is not None)
        ply, has_normals = plys[inst["mesh"]]
        material = materials[mesh["material"]]
        shape = {"type": "ply", "filename": str(ply), "face_normals": not has_normals,
                 "to_world": mi.ScalarTransform4f(matrix(inst["transform"]).tolist()),
                 "bsdf": bsdf(material, f"materials[{mesh['material']}] ({material['name']})")}
        if e := emitter(material):
            shape["emitter"] = e
        scene[f"instance_{i}"] = bounded(shape, material)
    for i, sphere in enumerate(manifest["spheres"]):
        material = materials[sphere["material"]]
        shape = {"type": "sphere", "center": sphere["centre"], "radius": sphere["radius"],
                 "bsdf": bsdf(material, f"materials[{sphere['material']}] ({material['name']})")}
        if e := emitter(material):
            shape["emitter"] = e
        scene[f"sphere_{i}"] = bounded(shape, material)
    for key in ("disks", "cylinders"):
        if manifest.get(key):
            raise Unsupported(f"{key}: analytic disks and cylinders are not exported to Mitsuba")
    for i, light in enumerate(manifest["lights"]):
        (kind, values), = light["kind"].items()
        if kind == "point":
            scene[f"light_{i}"] = {"type": "point", "position": values["position"],
                                   "intensity": {"type": "rgb", "value": values["intensity"]}}
        elif kind == "spot":
            if values["inner_cone"] != values["outer_cone"]:
                raise Unsupported(f"lights[{i}]: only hard-edged spots (inner = outer cone) fall off alike")
            position = np.array(values["position"], dtype=np.float64)
            direction = np.array(values["direction"], dtype=np.float64)
            up = [0.0, 1.0, 0.0] if abs(direction[1]) < 0.9 * np.linalg.norm(direction) else [1.0, 0.0, 0.0]
            angle = math.degrees(values["outer_cone"])
            scene[f"light_{i}"] = {"type": "spot", "cutoff_angle": angle, "beam_width": angle,
                                   "intensity": {"type": "rgb", "value": values["intensity"]},
                                   "to_world": mi.ScalarTransform4f().look_at(
                                       origin=position.tolist(), target=(position + direction).tolist(), up=up)}
        elif kind == "directional" and values.get("angle", 0.0) > 0.0:
            raise Unsupported(f"lights[{i}]: Mitsuba's directional light has no angular size")
        elif kind == "directional":
            scene[f"light_{i}"] = {"type": "directional", "direction": values["direction"],
                                   "irradiance": {"type": "rgb", "value": values["irradiance"]}}
        else:
            raise Unsupported(f"lights[{i}]: {kind} lights fall off differently in Mitsuba")
    env = manifest["environment"]
    if env is not None:
        if "constant" not in env:
            raise Unsupported("environment: only a constant environment is exported")
        scene["environment"] = {"type": "constant", "radiance": {"type": "rgb", "value": env["constant"]}}
    return scene
