//! The scene file (`lucerna convert`): a round trip changes nothing the renderer sees, and a
//! malformed file is a bad-input error naming the element, never a panic.

use crate::common;

use common::cli::temp_dir;
use common::gltf_builder::{Builder, png_rgba};
use common::scenes::render;
use lucerna::error::ErrorKind;
use lucerna::film::aov::ALL;
use lucerna::ingest;
use lucerna::integrator::Settings;
use lucerna::scene::{Scene, file};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};

/// A quad with every vertex attribute, two textures sharing one image (so the texels are
/// written once), alpha masking, a normal map, a point light and a lat-long environment.
fn textured_scene(dir: &Path) -> PathBuf {
    let mut b = Builder::new();
    let png = png_rgba(
        2,
        2,
        &[
            [255, 0, 0, 255],
            [0, 255, 0, 128],
            [0, 0, 255, 255],
            [255, 255, 255, 0],
        ],
    );
    let colour = b.png_texture(
        &png,
        json!({"magFilter": 9728, "minFilter": 9729, "wrapS": 33648}),
    );
    let normal = b.png_texture(&png_rgba(1, 1, &[[128, 128, 255, 255]]), json!({}));
    let m = b.add(
        "materials",
        json!({
            "pbrMetallicRoughness": {"baseColorTexture": {"index": colour, "extensions": {
                "KHR_texture_transform": {"offset": [0.1, 0.2], "rotation": 0.3, "scale": [2, 3]}}},
                "metallicFactor": 0.2, "roughnessFactor": 0.6},
            "normalTexture": {"index": normal, "scale": 0.5},
            "alphaMode": "MASK", "alphaCutoff": 0.4, "doubleSided": true,
            "emissiveFactor": [0.1, 0.0, 0.05]
        }),
    );
    let mut quad = b.quad_primitive(Some(m));
    let normals = b.floats(
        "VEC3",
        &[0.0, 0.0, 1.0, 0.0, 0.1, 1.0, 0.1, 0.0, 1.0, 0.0, 0.0, 1.0],
    );
    let colours = b.floats(
        "VEC4",
        &[
            1.0, 0.5, 0.5, 1.0, 0.5, 1.0, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0, 0.2, 0.2, 0.2, 1.0,
        ],
    );
    quad["attributes"]["NORMAL"] = json!(normals);
    quad["attributes"]["COLOR_0"] = json!(colours);
    let mesh = b.mesh(json!([quad]));
    b.root(json!({"mesh": mesh, "rotation": [0.1, 0.2, 0.0, 0.9747]}));
    b.add("cameras", json!({"type": "perspective", "perspective": {"yfov": 0.9, "aspectRatio": 1.25, "znear": 0.05}}));
    b.root(json!({"camera": 0, "translation": [0.2, 0.1, 3.0]}));
    b.write_glb(dir, "textured")
}

fn shipped(scene: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(scene)
}

/// Renders both scenes with the same seed and asserts identical layers.
fn assert_same_image(a: Scene, b: Scene, what: &str) {
    let settings = Settings {
        seed: 5,
        ..Default::default()
    };
    let (fa, _) = render(a, (24, 18), 4, settings.clone(), 2);
    let (fb, _) = render(b, (24, 18), 4, settings, 2);
    for aov in ALL {
        assert!(
            fa.planes(aov) == fb.planes(aov),
            "{what}: {} differs",
            aov.name()
        );
    }
}

#[test]
fn round_trip_renders_identically() {
    let dir = temp_dir("round-trip");
    let sources = [
        shipped("cornell-box/cornell-box.gltf"),
        shipped("mis-plates/mis-plates.glb"),
        shipped("indirect-room/indirect-room.glb"),
        // A density grid travels in the buffer; a medium's emission in the manifest.
        shipped("media/chromatic-smoke.gltf"),
        shipped("media/glowing-smoke.gltf"),
        textured_scene(&dir),
    ];
    for source in &sources {
        let mut original = ingest::load(source, &Default::default()).unwrap();
        ingest::set_constant_environment(&mut original, glam::Vec3::new(0.1, 0.2, 0.3));
        let path = dir.join(format!(
            "{}.lucerna",
            source.file_stem().unwrap().to_string_lossy()
        ));
        file::write(&original, &path).unwrap();
        let read = ingest::load(&path, &Default::default()).unwrap();
        let samplers = |s: &Scene| {
            s.textures
                .iter()
                .map(|t| (t.nearest, t.mipmaps, t.wrap_u, t.wrap_v))
                .collect::<Vec<_>>()
        };
        assert_eq!(samplers(&read), samplers(&original));
        // Writing what was read gives the same files: nothing is lost or reinterpreted.
        let again = dir.join("again").join(path.file_name().unwrap());
        std::fs::create_dir_all(again.parent().unwrap()).unwrap();
        file::write(&read, &again).unwrap();
        for name in [path.clone(), path.with_extension("lucerna.bin")] {
            let copy = again.with_file_name(name.file_name().unwrap());
            assert!(
                std::fs::read(&name).unwrap() == std::fs::read(&copy).unwrap(),
                "{}",
                name.display()
            );
        }
        assert_same_image(original, read, &source.display().to_string());
    }
    // A third texture sharing the first one's image with another sampler (as two glTF
    // textures of one image do) is written once and shared again when read.
    let mut textured = ingest::load(&dir.join("textured.lucerna"), &Default::default()).unwrap();
    let mut variant = textured.textures[0].clone();
    variant.nearest = !variant.nearest;
    textured.textures.push(variant);
    textured.materials[0].emissive_texture = Some(lucerna::scene::TextureRef {
        texture: 2,
        tex_coord: 0,
        transform: None,
    });
    let shared = dir.join("shared.lucerna");
    file::write(&textured, &shared).unwrap();
    let buffer_bytes = std::fs::metadata(dir.join("shared.lucerna.bin"))
        .unwrap()
        .len();
    // 4 vertices × (position 3 + normal 3 + tangent 4 + uv 2 + colour 4 floats), 2 triangles,
    // and 2×2 + 1×1 texels of 4 bytes.
    assert_eq!(buffer_bytes, 4 * 16 * 4 + 2 * 12 + 5 * 4);
    let read = ingest::load(&shared, &Default::default()).unwrap();
    assert!(std::sync::Arc::ptr_eq(
        &read.textures[0].texels,
        &read.textures[2].texels
    ));
    assert_ne!(read.textures[0].nearest, read.textures[2].nearest);
}

/// A UDIM set (the base colour split into tiles 1001 and 1002 along u, the quad's u spread
/// over both) survives the round trip: its tiles, their images and what renders.
#[test]
fn udim_sets_round_trip() {
    let dir = temp_dir("udim-round-trip");
    let mut scene = ingest::load(&textured_scene(&dir), &Default::default()).unwrap();
    let base = scene.materials[0].base_color_texture.unwrap().texture as usize;
    let tile = |value: f32| lucerna::scene::Texture {
        name: format!("tile {value}"),
        width: 1,
        height: 1,
        texels: std::sync::Arc::new(lucerna::scene::Texels::RgbaF32(vec![[
            value, 0.5, 0.25, 1.0,
        ]])),
        ..scene.textures[base].clone()
    };
    let first = scene.textures.len() as u32;
    scene.textures.extend([tile(0.9), tile(0.1)]);
    let udim =
        lucerna::scene::udim_set(vec![(1001, first), (1002, first + 1)], &scene.textures).unwrap();
    scene.textures[base].udim = Some(std::sync::Arc::new(udim));
    for mesh in &mut scene.meshes {
        for uv in mesh.uvs[0].iter_mut().flatten() {
            uv.x *= 2.0;
        }
    }
    let path = dir.join("udim.lucerna");
    file::write(&scene, &path).unwrap();
    let read = ingest::load(&path, &Default::default()).unwrap();
    let tiles = &read.textures[base]
        .udim
        .as_ref()
        .expect("still a UDIM set")
        .tiles;
    assert_eq!(tiles, &[(1001, first), (1002, first + 1)]);
    let at = |s: &Scene, u: f32| s.textures[base].sample(glam::Vec2::new(u, 0.5), false);
    assert_eq!(at(&read, 0.5).x, 0.9);
    assert_eq!(at(&read, 1.5).x, 0.1);
    assert!(
        read.warnings.iter().all(|w| !w.contains("UDIM")),
        "{:?}",
        read.warnings
    );
    assert_same_image(scene, read, "UDIM set");
}

/// Writes the Cornell box, lets `corrupt` change the manifest (and the buffer), and returns
/// the error of reading it.
fn error_after(name: &str, corrupt: impl FnOnce(&mut Value, &mut Vec<u8>)) -> lucerna::Error {
    let dir = temp_dir(name);
    let path = dir.join("box.lucerna");
    file::write(&ingest::default_scene().unwrap(), &path).unwrap();
    let mut manifest: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let bin = dir.join("box.lucerna.bin");
    let mut buffer = std::fs::read(&bin).unwrap();
    corrupt(&mut manifest, &mut buffer);
    if manifest.is_object() {
        manifest["buffer_bytes"] = json!(buffer.len());
    }
    std::fs::write(&path, serde_json::to_vec(&manifest).unwrap()).unwrap();
    std::fs::write(&bin, &buffer).unwrap();
    let error = ingest::load(&path, &Default::default()).expect_err(name);
    assert_eq!(error.kind, ErrorKind::BadInput, "{error}");
    error
}

#[test]
fn malformed_scene_files_are_rejected_with_the_element() {
    let offset =
        |m: &Value, field: &str| m["meshes"][0][field]["offset"].as_u64().unwrap() as usize;
    type Corruption = Box<dyn FnOnce(&mut Value, &mut Vec<u8>)>;
    let cases: Vec<(&str, Corruption, &str)> = vec![
        (
            "version",
            Box::new(|m, _| m["version"] = json!(99)),
            "version",
        ),
        (
            "format",
            Box::new(|m, _| m["format"] = json!("gltf")),
            "format",
        ),
        (
            "unknown-field",
            Box::new(|m, _| m["meshes"][0]["colour"] = json!(1)),
            "manifest",
        ),
        ("not-json", Box::new(|m, _| *m = json!("{")), "manifest"),
        (
            "view-past-end",
            Box::new(|m, _| m["meshes"][0]["triangles"]["count"] = json!(u64::MAX / 4)),
            "meshes[0].triangles",
        ),
        (
            "vertex-index",
            Box::new(move |m, b| {
                let at = offset(m, "triangles");
                b[at..at + 4].copy_from_slice(&1000u32.to_le_bytes());
            }),
            "meshes[0].triangles[0]",
        ),
        (
            "nan-position",
            Box::new(move |m, b| {
                let at = offset(m, "positions") + 12;
                b[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
            }),
            "meshes[0].positions[1]",
        ),
        (
            "material-index",
            Box::new(|m, _| m["meshes"][2]["material"] = json!(40)),
            "meshes[2].material",
        ),
        (
            "instance-mesh",
            Box::new(|m, _| m["instances"][1]["mesh"] = json!(8)),
            "instances[1].mesh",
        ),
        (
            "camera-fov",
            Box::new(|m, _| m["cameras"][0]["projection"]["perspective"]["yfov"] = json!(4.0)),
            "cameras[0]",
        ),
        (
            "disk-normal",
            Box::new(|m, _| {
                m["disks"] = json!([{"name": "d", "centre": [0, 1, 0], "normal": [0, 2, 0],
                    "radius": 0.5, "material": 0}])
            }),
            "disks[0]",
        ),
        (
            "cylinder-length",
            Box::new(|m, _| {
                m["cylinders"] = json!([{"name": "c", "centre": [0, 1, 0], "axis": [1, 0, 0],
                    "radius": 0.5, "length": -1.0, "material": 0}])
            }),
            "cylinders[0]",
        ),
        (
            "cylinder-material",
            Box::new(|m, _| {
                m["cylinders"] = json!([{"name": "c", "centre": [0, 1, 0], "axis": [1, 0, 0],
                    "radius": 0.5, "length": 1.0, "material": 99}])
            }),
            "cylinders[0].material",
        ),
        (
            "sun-angle",
            Box::new(|m, _| {
                m["lights"] = json!([{"name": "sun", "kind": {"directional": {
                    "direction": [0, -1, 0], "irradiance": [1, 1, 1], "angle": 4.0}}}])
            }),
            "lights[0]",
        ),
        (
            "buffer-outside",
            Box::new(|m, _| m["buffer"] = json!("../box.lucerna.bin")),
            "buffer",
        ),
        (
            "buffer-parent",
            Box::new(|m, _| m["buffer"] = json!("..")),
            "buffer",
        ),
        (
            "buffer-missing",
            Box::new(|m, _| m["buffer"] = json!("gone.bin")),
            "buffer",
        ),
        (
            "normals-count",
            Box::new(|m, _| m["meshes"][0]["normals"] = json!({"offset": 0, "count": 1})),
            "meshes[0].normals",
        ),
        (
            "camera-far",
            Box::new(|m, _| m["cameras"][0]["clip_far"] = json!(0.0)),
            "cameras[0]",
        ),
        (
            "texel-count",
            Box::new(|m, _| {
                m["textures"] = json!([{"name": "t", "width": 3, "height": 3, "encoding": "rgba8",
                    "texels": {"offset": 0, "count": 4}, "wrap_u": "repeat", "wrap_v": "repeat",
                    "nearest": false}])
            }),
            "textures[0].texels",
        ),
        (
            "emission",
            Box::new(|m, _| m["materials"][0]["emissive"] = json!([-1.0, 0, 0])),
            "materials[0]",
        ),
        (
            "transmission",
            Box::new(|m, _| m["materials"][0]["transmission"] = json!(1.5)),
            "materials[0]",
        ),
        (
            "absorption",
            Box::new(|m, _| m["materials"][0]["volume"] = json!({"absorption": [0.1, -2.0, 0.0]})),
            "materials[0]",
        ),
        (
            "sheen-roughness",
            Box::new(|m, _| {
                m["materials"][0]["sheen"] = json!({"color": [1, 1, 1], "color_texture": null,
                    "roughness": 2.0, "roughness_texture": null})
            }),
            "materials[0]",
        ),
        (
            "transmission-texture",
            Box::new(|m, _| {
                m["materials"][0]["transmission_texture"] =
                    json!({"texture": 7, "tex_coord": 0, "transform": null})
            }),
            "materials[0].transmission_texture",
        ),
        // Motion keys (the time samples of moving things): 2 to 64 keys that decompose,
        // and a shutter that opens before it closes.
        (
            "motion-one-key",
            Box::new(|m, _| {
                m["instances"][0]["motion"] = json!([m["instances"][0]["transform"].clone()])
            }),
            "instances[0].motion",
        ),
        (
            "motion-too-many-keys",
            Box::new(|m, _| {
                m["instances"][0]["motion"] =
                    json!(vec![m["instances"][0]["transform"].clone(); 65])
            }),
            "instances[0].motion",
        ),
        (
            "motion-singular-key",
            Box::new(|m, _| {
                let key = m["instances"][0]["transform"].clone();
                m["instances"][0]["motion"] = json!([key, vec![0.0; 16]])
            }),
            "instances[0].motion",
        ),
        (
            "camera-motion-singular",
            Box::new(|m, _| m["cameras"][0]["motion"] = json!([vec![0.0; 16], vec![0.0; 16]])),
            "cameras[0].motion",
        ),
        (
            "deformation-one-key",
            Box::new(|m, _| {
                let positions = m["meshes"][0]["positions"].clone();
                m["meshes"][0]["deformation"] = json!({"positions": [positions]})
            }),
            "meshes[0].deformation",
        ),
        (
            "deformation-key-count",
            Box::new(|m, _| {
                let positions = m["meshes"][0]["positions"].clone();
                m["meshes"][0]["deformation"] =
                    json!({"positions": [positions, {"offset": 0, "count": 1}]})
            }),
            "meshes[0].deformation.positions[1]",
        ),
        (
            "shutter-backwards",
            Box::new(|m, _| m["shutter"] = json!({"open": 0.5, "close": -0.5})),
            "shutter",
        ),
        (
            "shutter-huge",
            Box::new(|m, _| m["shutter"] = json!({"open": -1e30, "close": 1e30})),
            "shutter",
        ),
    ];
    for (name, corrupt, element) in cases {
        let error = error_after(name, corrupt);
        assert!(error.element.starts_with(element), "{name}: {error}");
        assert!(error.file.ends_with("box.lucerna"), "{name}: {error}");
    }
    // A buffer shorter than the manifest says (a truncated copy).
    let dir = temp_dir("truncated");
    let path = dir.join("box.lucerna");
    file::write(&ingest::default_scene().unwrap(), &path).unwrap();
    let bin = dir.join("box.lucerna.bin");
    let len = std::fs::metadata(&bin).unwrap().len();
    std::fs::write(&bin, &std::fs::read(&bin).unwrap()[..len as usize - 4]).unwrap();
    let error = ingest::load(&path, &Default::default()).unwrap_err();
    assert_eq!(
        (error.kind, error.element.as_str()),
        (ErrorKind::BadInput, "buffer"),
        "{error}"
    );
}

/// A mesh's deformation keys (positions and normals) survive a round trip.
#[test]
fn deformation_keys_round_trip() {
    use glam::Vec3;
    use lucerna::geometry::deformation::Deformation;
    let mut scene = ingest::default_scene().unwrap();
    let mesh = &mut scene.meshes[0];
    let shifted = |d: f32| {
        mesh.positions
            .iter()
            .map(|p| *p + Vec3::new(d, 0.0, 0.0))
            .collect()
    };
    let normals = mesh.normals.clone();
    let deformation = Deformation {
        positions: vec![shifted(-1.0), shifted(0.0), shifted(2.0)],
        normals: normals.map(|n| vec![n.clone(), n.clone(), n]),
    };
    mesh.deformation = Some(deformation.clone());
    let dir = temp_dir("deformation");
    let path = dir.join("moving.lucerna");
    file::write(&scene, &path).unwrap();
    let read = ingest::load(&path, &Default::default()).unwrap();
    assert_eq!(read.meshes[0].deformation.as_ref(), Some(&deformation));
    assert!(read.meshes[1..].iter().all(|m| m.deformation.is_none()));
}

/// A subdivision surface (cage, creases, corners, per-corner uvs and colours, kept faces)
/// survives a round trip, and its refinement renders the same image; a cage index out of
/// range is refused naming the surface.
#[test]
fn subdivision_surfaces_round_trip() {
    use glam::{Vec2, Vec3, Vec4};
    use lucerna::scene::{BoundaryInterpolation, SubdivisionScheme, SubdivisionSurface};
    let mut scene = ingest::default_scene().unwrap();
    let points: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new((i & 1) as f32, (i >> 1 & 1) as f32, (i >> 2 & 1) as f32) * 100.0 + 200.0
        })
        .collect();
    #[rustfmt::skip]
    let face_indices = vec![0, 2, 3, 1, 4, 5, 7, 6, 0, 1, 5, 4, 2, 6, 7, 3, 0, 4, 6, 2, 1, 3, 7, 5];
    let corners = face_indices.len();
    scene.subdivision_surfaces.push(SubdivisionSurface {
        point_keys: Vec::new(),
        mesh: 0,
        scheme: SubdivisionScheme::CatmullClark,
        boundary: BoundaryInterpolation::EdgeOnly,
        points,
        face_counts: vec![4; 6],
        face_indices,
        creases: vec![([0, 1], 2.5), ([1, 3], 10.0)],
        corners: vec![(7, 3.0)],
        uvs: Some(
            (0..corners)
                .map(|c| Vec2::new(c as f32 / 24.0, 0.5))
                .collect(),
        ),
        colors: Some(vec![Vec4::new(0.5, 0.25, 1.0, 1.0); corners]),
        keep: Some(vec![true, false, true, true, true, true]),
    });
    let dir = temp_dir("subdivision-round-trip");
    let path = dir.join("sub.lucerna");
    file::write(&scene, &path).unwrap();
    let read = ingest::load(&path, &Default::default()).unwrap();
    let (a, b) = (
        &scene.subdivision_surfaces[0],
        &read.subdivision_surfaces[0],
    );
    assert_eq!(
        (
            a.mesh,
            a.scheme,
            a.boundary,
            &a.points,
            &a.face_counts,
            &a.face_indices
        ),
        (
            b.mesh,
            b.scheme,
            b.boundary,
            &b.points,
            &b.face_counts,
            &b.face_indices
        )
    );
    assert_eq!(
        (&a.creases, &a.corners, &a.uvs, &a.colors, &a.keep),
        (&b.creases, &b.corners, &b.uvs, &b.colors, &b.keep)
    );
    assert_same_image(scene, read, "subdivision surface");

    let error = error_after("subdivision-bad-index", |m, buffer| {
        let view = |buffer: &Vec<u8>, count: u64| json!({"offset": buffer.len(), "count": count});
        let points = view(buffer, 4);
        buffer.extend(std::iter::repeat_n(0u8, 48));
        let counts = view(buffer, 1);
        buffer.extend(4u32.to_le_bytes());
        let indices = view(buffer, 4);
        for i in [0u32, 1, 2, 9] {
            buffer.extend(i.to_le_bytes());
        }
        m["subdivision_surfaces"] = json!([{"mesh": 0, "scheme": "catmull_clark",
            "boundary": "edge_and_corner", "points": points, "face_counts": counts,
            "face_indices": indices}]);
    });
    let text = error.to_string();
    assert!(
        text.contains("subdivision_surfaces[0].face_indices"),
        "{text}"
    );
}

/// The Cornell box's scene file with an interface material of a medium and `volumes`
/// entries (as the USD plugin writes for `Volume` prims) added by `volumes`.
fn with_volumes(name: &str, volumes: impl FnOnce(&mut Value)) -> lucerna::Result<Scene> {
    let dir = temp_dir(name);
    let path = dir.join("box.lucerna");
    file::write(&ingest::default_scene().unwrap(), &path).unwrap();
    let mut manifest: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let mut smoke = manifest["materials"][0].clone();
    smoke["name"] = json!("smoke");
    smoke["model"] = json!("interface");
    smoke["volume"] = json!({"absorption": [1.0, 1.0, 1.0], "scattering": [9.0, 9.0, 9.0]});
    manifest["materials"].as_array_mut().unwrap().push(smoke);
    volumes(&mut manifest);
    std::fs::write(&path, serde_json::to_vec(&manifest).unwrap()).unwrap();
    ingest::load(&path, &Default::default())
}

fn plume_vdb() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/assets/vdb/plume.vdb")
        .to_string_lossy()
        .into_owned()
}

#[test]
fn volumes_read_their_grids_and_get_a_box() {
    let base = ingest::default_scene().unwrap();
    let scene = with_volumes("volumes-read", |m| {
        let smoke = m["materials"].as_array().unwrap().len() - 1;
        let placed = |x: f64| {
            json!({"name": format!("/Smoke{x}"), "file": plume_vdb(), "grid": "density",
                   "to_world": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, x, 0, 0, 1], "material": smoke})
        };
        m["volumes"] = json!([placed(0.0), placed(0.5)]);
    })
    .unwrap();
    // Two instances of one grid: its densities are read once and shared.
    assert_eq!(scene.grids.len(), 2);
    assert!(std::sync::Arc::ptr_eq(
        &scene.grids[0].values,
        &scene.grids[1].values
    ));
    assert_eq!(
        scene.grids[1].to_world.w_axis.x - scene.grids[0].to_world.w_axis.x,
        0.5
    );
    // Each box has its own material (the second a copy), scaled by its own grid.
    assert_eq!(scene.materials.len(), base.materials.len() + 2);
    assert_eq!(scene.meshes.len(), base.meshes.len() + 2);
    for (k, instance) in scene.instances[base.instances.len()..].iter().enumerate() {
        assert_eq!(instance.name, format!("/Smoke{}", [0.0, 0.5][k]));
        assert_eq!(instance.transform, scene.grids[k].to_world);
        let mesh = &scene.meshes[instance.mesh as usize];
        let volume = scene.materials[mesh.material as usize].volume.unwrap();
        assert_eq!(volume.density, Some(k as u32));
        assert_eq!(mesh.triangles.len(), 12);
    }
}

/// An emission field named by a volume entry is read under the volume's transform and set on
/// its material, and the box around the volume holds it.
#[test]
fn volumes_read_their_emission_field() {
    let scene = with_volumes("volumes-emission", |m| {
        let smoke = m["materials"].as_array().unwrap().len() - 1;
        m["materials"][smoke]["volume"]["emission_field"] = json!({"tint": [2.0, 1.0, 0.5]});
        m["volumes"] = json!([{"name": "/Smoke", "file": plume_vdb(), "grid": "density",
            "emission": {"file": plume_vdb(), "grid": "temperature"},
            "to_world": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], "material": smoke}]);
    })
    .unwrap();
    let instance = scene.instances.last().unwrap();
    let mesh = &scene.meshes[instance.mesh as usize];
    let volume = scene.materials[mesh.material as usize].volume.unwrap();
    let field = volume.emission_field.unwrap();
    assert_eq!(field.tint, glam::Vec3::new(2.0, 1.0, 0.5));
    let grid = &scene.grids[field.grid.unwrap() as usize];
    assert!(grid.source.ends_with("[temperature]"), "{}", grid.source);
    assert!(grid.max_density() > 1000.0);
    assert!(volume.emits());
}

/// A scatter colour named by a volume entry is read (three channels, shared between the
/// instances of one volume) under the volume's transform and set on its material; on a
/// material that does not scatter it is left out with a warning.
#[test]
fn volumes_read_their_scatter_colour() {
    let entry = |smoke: usize, x: f64| {
        json!({"name": format!("/Smoke{x}"), "file": plume_vdb(), "grid": "density",
            "scatter_color": {"file": plume_vdb(), "grid": "velocity"},
            "to_world": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, x, 0, 0, 1], "material": smoke})
    };
    let scene = with_volumes("volumes-colour", |m| {
        let smoke = m["materials"].as_array().unwrap().len() - 1;
        m["volumes"] = json!([entry(smoke, 0.0), entry(smoke, 0.5)]);
    })
    .unwrap();
    let volumes: Vec<_> = scene.instances[scene.instances.len() - 2..]
        .iter()
        .map(|i| {
            scene.materials[scene.meshes[i.mesh as usize].material as usize]
                .volume
                .unwrap()
        })
        .collect();
    let [first, second] = [0, 1].map(|k| volumes[k].scatter_color.unwrap());
    for (k, g) in first.iter().enumerate() {
        let channel = &scene.grids[*g as usize];
        assert!(
            channel
                .source
                .ends_with(&format!("[velocity].{}", ["r", "g", "b"][k]))
        );
        // velocity is (0, 1, 0) over its voxels: green alone.
        assert_eq!(
            channel.max_density(),
            [0.0, 1.0, 0.0][k],
            "{}",
            channel.source
        );
        let other = &scene.grids[second[k] as usize];
        assert!(std::sync::Arc::ptr_eq(&channel.values, &other.values));
        assert_eq!(other.to_world.w_axis.x - channel.to_world.w_axis.x, 0.5);
    }
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    // A medium that only absorbs has nothing to tint.
    let absorbing = with_volumes("volumes-colour-absorbing", |m| {
        let smoke = m["materials"].as_array().unwrap().len() - 1;
        m["materials"][smoke]["volume"]["scattering"] = json!([0.0, 0.0, 0.0]);
        m["volumes"] = json!([entry(smoke, 0.0)]);
    })
    .unwrap();
    let instance = absorbing.instances.last().unwrap();
    let mesh = &absorbing.meshes[instance.mesh as usize];
    assert!(
        absorbing.materials[mesh.material as usize]
            .volume
            .unwrap()
            .scatter_color
            .is_none()
    );
    assert!(
        absorbing
            .warnings
            .iter()
            .any(|w| w.contains("/Smoke0: material") && w.contains("does not scatter")),
        "{:?}",
        absorbing.warnings
    );
}

#[test]
fn volumes_that_cannot_be_read_are_errors() {
    type Edit = Box<dyn FnOnce(&mut Value)>;
    // A volume entry for the smoke material (with `glow` set on it) and `fields` added.
    fn glowing(m: &mut Value, glow: Value, fields: Value) {
        let smoke = m["materials"].as_array().unwrap().len() - 1;
        for (k, v) in glow.as_object().unwrap() {
            m["materials"][smoke]["volume"][k] = v.clone();
        }
        let mut entry = json!({"name": "/V", "file": plume_vdb(), "grid": "density",
            "to_world": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], "material": smoke});
        for (k, v) in fields.as_object().unwrap() {
            entry[k] = v.clone();
        }
        m["volumes"] = json!([entry]);
    }
    let cases: [(&str, Edit, &str); 8] = [
        (
            "volume-colour-missing-grid",
            Box::new(|m| {
                let grid = json!({"file": plume_vdb(), "grid": "Cd"});
                glowing(m, json!({}), json!({"scatter_color": grid}));
            }),
            "volumes[0].scatter_color.file: ",
        ),
        (
            "volume-colour-level-set",
            Box::new(|m| {
                let file = plume_vdb().replace("plume.vdb", "sphere-level-set.vdb");
                glowing(
                    m,
                    json!({}),
                    json!({"scatter_color": {"file": file, "grid": null}}),
                );
            }),
            "level set",
        ),
        (
            "volume-no-medium",
            Box::new(|m| {
                m["volumes"] = json!([{"name": "/V", "file": plume_vdb(), "grid": null,
                    "to_world": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], "material": 0}])
            }),
            "volumes[0].material: material 0 has no medium for the grid to scale",
        ),
        (
            "volume-missing-file",
            Box::new(|m| {
                let smoke = m["materials"].as_array().unwrap().len() - 1;
                m["volumes"] = json!([{"name": "/V", "file": "nowhere.vdb", "grid": null,
                    "to_world": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], "material": smoke}])
            }),
            "volumes[0].file",
        ),
        (
            "volume-flat",
            Box::new(|m| {
                let smoke = m["materials"].as_array().unwrap().len() - 1;
                m["volumes"] = json!([{"name": "/V", "file": plume_vdb(), "grid": "density",
                    "to_world": [1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], "material": smoke}])
            }),
            "volumes[0].to_world: its transform is not finite or flattens the grid",
        ),
        (
            "volume-emission-without-field",
            Box::new(|m| {
                let grid = json!({"file": plume_vdb(), "grid": "temperature"});
                glowing(m, json!({}), json!({"emission": grid}));
            }),
            "has no emission_field for it",
        ),
        (
            "volume-two-glowing-fields",
            Box::new(|m| {
                let grid = json!({"file": plume_vdb(), "grid": "temperature"});
                glowing(
                    m,
                    json!({"emission_field": {"tint": [1, 1, 1]}, "blackbody": {}}),
                    json!({"emission": grid.clone(), "temperature": grid}),
                );
            }),
            "volumes[0].emission: a volume glows by one field",
        ),
        (
            "volume-emission-missing-grid",
            Box::new(|m| {
                let grid = json!({"file": plume_vdb(), "grid": "heat"});
                glowing(
                    m,
                    json!({"emission_field": {"tint": [1, 1, 1]}}),
                    json!({"emission": grid}),
                );
            }),
            "volumes[0].emission.file",
        ),
    ];
    for (name, volumes, fragment) in cases {
        let error = with_volumes(name, volumes).err().unwrap();
        assert_eq!(error.kind, ErrorKind::BadInput, "{error}");
        assert!(error.to_string().contains(fragment), "{name}: {error}");
    }
}
