//! glTF as pipelines deliver it: compressed and quantized geometry (Draco, meshopt,
//! KHR_mesh_quantization), WebP and KTX2 (Basis Universal) textures, GPU instancing, material variants, and
//! deformed meshes (skins and morph targets), checked against the plain asset's render or
//! against hand computations.

use crate::common;

use common::scenes::world_positions;

use common::gltf_builder::Builder;
use common::scenes::{rel_mse, render};
use glam::{DMat4, DQuat, DVec3, Vec3};
use lucerna::ingest;
use lucerna::integrator::Settings;
use lucerna::scene::Scene;
use serde_json::json;
use std::path::{Path, PathBuf};

fn asset(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/assets/gltf")
        .join(path)
}

fn load(path: &Path) -> Scene {
    ingest::load(path, &Default::default()).unwrap_or_else(|e| panic!("{e}"))
}

fn bounds(scene: &Scene) -> (DVec3, DVec3) {
    world_positions(scene)
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        })
}

fn render_lit(mut scene: Scene, seed: u32) -> lucerna::film::Film {
    ingest::set_constant_environment(&mut scene, Vec3::ONE);
    let settings = Settings {
        seed,
        ..Default::default()
    };
    render(scene, (64, 64), 16, settings, 2).0
}

/// Every compressed or quantized Avocado (made with gltf-transform and gltfpack from the
/// plain one, and Khronos' own Draco and quantized exports) renders the plain Avocado's
/// image: with the same seed the difference is far below the noise of two independent
/// renders of the plain asset (the quantization moves vertices by about 1e-5 of the size).
#[test]
fn compressed_avocados_render_the_plain_image() {
    let plain = load(&asset("Avocado/Avocado.gltf"));
    let (lo, hi) = bounds(&plain);
    let size = (hi - lo).length();
    let triangles = plain.instanced_triangle_count();
    let reference = render_lit(plain.clone(), 0);
    let noise = rel_mse(&render_lit(plain, 1), &reference);
    assert!(noise > 0.0);
    for variant in [
        "draco",
        "meshopt",
        "quantized",
        "webp",
        "khronos_draco",
        "khronos_quantized",
    ] {
        let scene = load(&asset(&format!("Avocado/Avocado_{variant}.gltf")));
        assert_eq!(scene.instanced_triangle_count(), triangles, "{variant}");
        let (l, h) = bounds(&scene);
        let moved = (l - lo).length().max((h - hi).length());
        assert!(moved < 2e-3 * size, "{variant}: bounds moved by {moved}");
        let rel = rel_mse(&render_lit(scene, 0), &reference);
        eprintln!("{variant}: relMSE {rel:.3e} (two seeds of the plain asset: {noise:.3e})");
        assert!(
            rel < 0.1 * noise,
            "{variant}: relMSE {rel} against the plain render; independent noise {noise}"
        );
    }
}

/// KHR_texture_basisu: a texture's KTX2 image is transcoded, whether or not a PNG fallback
/// is beside it (the fallback is for clients without the extension); a KTX2 image that
/// cannot be decoded is an error naming the image.
#[test]
fn ktx2_textures_are_transcoded() {
    let ktx2 = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/assets/ktx2/etc1s_basecolor.ktx2"),
    )
    .unwrap();
    let build = |fallback: bool, ktx2: &[u8]| {
        let mut b = Builder::new();
        let png = common::gltf_builder::png_rgba(1, 1, &[[255, 0, 0, 255]]);
        let view = b.view(&png);
        b.add(
            "images",
            json!({"bufferView": view, "mimeType": "image/png"}),
        );
        let ktx = b.view(ktx2);
        b.add(
            "images",
            json!({"bufferView": ktx, "mimeType": "image/ktx2"}),
        );
        let mut texture = json!({"extensions": {"KHR_texture_basisu": {"source": 1}}});
        if fallback {
            texture["source"] = json!(0);
        }
        b.add("textures", texture);
        let material = b.add(
            "materials",
            json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}),
        );
        let prim = b.quad_primitive(Some(material));
        let mesh = b.mesh(json!([prim]));
        b.root(json!({"mesh": mesh}));
        b.json["extensionsUsed"] = json!(["KHR_texture_basisu"]);
        if !fallback {
            b.json["extensionsRequired"] = json!(["KHR_texture_basisu"]);
        }
        b.glb()
    };
    for fallback in [false, true] {
        let scene = ingest::gltf::import(&build(fallback, &ktx2), "ktx2.glb", None)
            .unwrap_or_else(|e| panic!("fallback {fallback}: {e}"));
        assert_eq!(scene.textures.len(), 1);
        let t = &scene.textures[0];
        assert_eq!((t.width, t.height), (512, 512), "fallback {fallback}");
        assert!(
            !scene
                .warnings
                .iter()
                .any(|w| w.contains("KHR_texture_basisu")),
            "{:?}",
            scene.warnings
        );
    }
    let err = ingest::gltf::import(&build(true, &ktx2[..ktx2.len() / 2]), "ktx2.glb", None)
        .unwrap_err()
        .to_string();
    assert!(err.contains("images[1]") && err.contains("KTX2"), "{err}");
}

/// EXT_mesh_gpu_instancing: one instance per TRANSLATION/ROTATION/SCALE element, each
/// applied before the node's transform; Khronos' SimpleInstancing gives its 125 cubes.
#[test]
fn gpu_instancing_places_every_instance() {
    let mut b = Builder::new();
    let prim = b.quad_primitive(None);
    let mesh = b.mesh(json!([prim]));
    let translation = b.floats("VEC3", &[0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0, 0.0]);
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let rotation = b.floats(
        "VEC4",
        &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, s, s, 0.0, 0.0, 0.0, 1.0],
    );
    b.root(json!({
        "mesh": mesh,
        "translation": [0, 0, -5],
        "extensions": {"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": translation, "ROTATION": rotation}}}
    }));
    b.json["extensionsUsed"] = json!(["EXT_mesh_gpu_instancing"]);
    let scene = ingest::gltf::import(&b.glb(), "instanced.glb", None).unwrap();
    assert_eq!(scene.instances.len(), 3);
    let expected = [
        DMat4::from_translation(DVec3::new(0.0, 0.0, -5.0)),
        DMat4::from_translation(DVec3::new(2.0, 0.0, -5.0))
            * DMat4::from_quat(DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2)),
        DMat4::from_translation(DVec3::new(0.0, 3.0, -5.0)),
    ];
    for (instance, expected) in scene.instances.iter().zip(expected) {
        assert!(
            instance.transform.abs_diff_eq(expected, 1e-6),
            "{:?}",
            instance.transform
        );
    }
    let simple = load(&asset("SimpleInstancing/SimpleInstancing.gltf"));
    assert_eq!(simple.instances.len(), 125);
}

/// KHR_materials_variants: `--material-variant` picks a variant's material; a name the file
/// does not have is refused with the names it has; without the option the file's variants
/// are named in a warning.
#[test]
fn material_variants_are_selectable() {
    let mut b = Builder::new();
    let red = b.add(
        "materials",
        json!({"name": "red", "pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 1]}}),
    );
    let blue = b.add(
        "materials",
        json!({"name": "blue", "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 1, 1]}}),
    );
    let mut prim = b.quad_primitive(Some(red));
    prim["extensions"] =
        json!({"KHR_materials_variants": {"mappings": [{"material": blue, "variants": [1]}]}});
    let mesh = b.mesh(json!([prim]));
    b.root(json!({"mesh": mesh}));
    b.json["extensionsUsed"] = json!(["KHR_materials_variants"]);
    b.json["extensions"] =
        json!({"KHR_materials_variants": {"variants": [{"name": "Ripe"}, {"name": "Midnight"}]}});
    let glb = b.glb();
    let import = |variant: Option<&str>| {
        ingest::gltf::import_with(
            &glb,
            "variants.glb",
            None,
            None,
            ingest::gltf::Choices {
                material_variant: variant,
                ..Default::default()
            },
        )
    };
    let base = |variant: Option<&str>| {
        let scene = import(variant).unwrap();
        let material = scene.meshes[scene.instances[0].mesh as usize].material;
        (
            scene.materials[material as usize].base_color,
            scene.warnings,
        )
    };
    let (default, warnings) = base(None);
    assert_eq!(default.truncate(), Vec3::X);
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("Ripe, Midnight") && w.contains("--material-variant")),
        "{warnings:?}"
    );
    assert_eq!(base(Some("Midnight")).0.truncate(), Vec3::Z);
    assert_eq!(base(Some("Ripe")).0.truncate(), Vec3::X); // Not mapped: the default.
    let err = import(Some("Raw")).unwrap_err().to_string();
    assert!(
        err.contains("\"Raw\"") && err.contains("Ripe, Midnight"),
        "{err}"
    );
}

/// A two-joint skin: joint 1 (child of joint 0, one unit up) turns 90° about z over one
/// second. Each vertex's position is checked against the hand-computed blend of
/// `global(joint) × inverseBind` matrices with its weights.
#[test]
fn skinning_matches_a_hand_computation() {
    let mut b = Builder::new();
    // A vertical strip: vertices at y = 0, 1, 2 (x = ±0.5).
    #[rustfmt::skip]
    let positions = [
        -0.5, 0.0, 0.0, 0.5, 0.0, 0.0,
        -0.5, 1.0, 0.0, 0.5, 1.0, 0.0,
        -0.5, 2.0, 0.0, 0.5, 2.0, 0.0,
    ];
    let weights_per_vertex: [[f32; 2]; 6] = [
        [1.0, 0.0],
        [1.0, 0.0],
        [0.5, 0.5],
        [0.5, 0.5],
        [0.0, 1.0],
        [0.0, 1.0],
    ];
    let pos = b.floats("VEC3", &positions);
    let joints_bytes: Vec<u8> = (0..6).flat_map(|_| [0u8, 1, 0, 0]).collect();
    let jv = b.view(&joints_bytes);
    let joints = b.add(
        "accessors",
        json!({"bufferView": jv, "componentType": 5121, "count": 6, "type": "VEC4"}),
    );
    let w: Vec<f32> = weights_per_vertex
        .iter()
        .flat_map(|w| [w[0], w[1], 0.0, 0.0])
        .collect();
    let weights = b.floats("VEC4", &w);
    let indices = b.indices(&[0, 1, 3, 0, 3, 2, 2, 3, 5, 2, 5, 4]);
    let mesh = b.mesh(json!([{
        "attributes": {"POSITION": pos, "JOINTS_0": joints, "WEIGHTS_0": weights},
        "indices": indices
    }]));
    // Inverse bind matrices: joint 0 at the origin, joint 1 at y = 1.
    #[rustfmt::skip]
    let ibm: Vec<f32> = [
        DMat4::IDENTITY,
        DMat4::from_translation(DVec3::new(0.0, -1.0, 0.0)),
    ]
    .iter()
    .flat_map(|m| m.to_cols_array().map(|v| v as f32))
    .collect();
    let ibm_bytes: Vec<u8> = ibm.iter().flat_map(|v| v.to_le_bytes()).collect();
    let ibm_view = b.view(&ibm_bytes);
    let ibm_acc = b.add(
        "accessors",
        json!({"bufferView": ibm_view, "componentType": 5126, "count": 2, "type": "MAT4"}),
    );
    let joint1 = b.node(json!({"name": "elbow", "translation": [0, 1, 0]}));
    let joint0 = b.root(json!({"name": "root", "translation": [3, 0, 0], "children": [joint1]}));
    // The skinned node's own transform is ignored (glTF 2.0 section 3.7.3.3).
    b.root(json!({"mesh": mesh, "skin": 0, "translation": [100, 100, 100]}));
    b.add(
        "skins",
        json!({"joints": [joint0, joint1], "inverseBindMatrices": ibm_acc}),
    );
    let times = b.floats("SCALAR", &[0.0, 1.0]);
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let rotations = b.floats("VEC4", &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, s, s]);
    b.add(
        "animations",
        json!({"samplers": [{"input": times, "output": rotations}],
               "channels": [{"sampler": 0, "target": {"node": joint1, "path": "rotation"}}]}),
    );
    let glb = b.glb();
    for time in [0.0, 0.5, 1.0] {
        let scene = ingest::gltf::import_at(&glb, "skin.glb", None, Some(time)).unwrap();
        assert_eq!(scene.instances.len(), 1);
        assert_eq!(scene.instances[0].transform, DMat4::IDENTITY);
        let got = &scene.meshes[scene.instances[0].mesh as usize].positions;
        // By hand: joint 0's global transform is T(3,0,0); joint 1's is
        // T(3,0,0) T(0,1,0) Rz(angle). Joint matrices are those times the inverse binds.
        let angle = std::f64::consts::FRAC_PI_2 * time; // slerp between 0 and 90° is linear
        let j0 = DMat4::from_translation(DVec3::new(3.0, 0.0, 0.0));
        let j1 = DMat4::from_translation(DVec3::new(3.0, 1.0, 0.0))
            * DMat4::from_rotation_z(angle)
            * DMat4::from_translation(DVec3::new(0.0, -1.0, 0.0));
        for (v, w) in weights_per_vertex.iter().enumerate() {
            let p = DVec3::new(positions[3 * v] as f64, positions[3 * v + 1] as f64, 0.0);
            let expected =
                j0.transform_point3(p) * w[0] as f64 + j1.transform_point3(p) * w[1] as f64;
            assert!(
                got[v].as_dvec3().distance(expected) < 1e-5,
                "t = {time}, vertex {v}: {} vs {expected}",
                got[v]
            );
        }
    }
}

/// Morph target weights, static and animated: a target moving every vertex by +x at weight
/// 1, animated linearly from 0 to 1 over one second, moves them by +0.25 at 0.25 s; the mesh's
/// default weight applies without a frame. Khronos' AnimatedMorphCube changes shape.
#[test]
fn morph_targets_follow_their_weights() {
    let mut b = Builder::new();
    let mut prim = b.quad_primitive(None);
    let count = 4;
    let delta: Vec<f32> = (0..count).flat_map(|_| [1.0, 0.0, 0.0]).collect();
    let target = b.floats("VEC3", &delta);
    prim["targets"] = json!([{"POSITION": target}]);
    let mesh = b.add("meshes", json!({"primitives": [prim], "weights": [0.5]}));
    let node = b.root(json!({"mesh": mesh}));
    let times = b.floats("SCALAR", &[0.0, 1.0]);
    let weights = b.floats("SCALAR", &[0.0, 1.0]);
    b.add(
        "animations",
        json!({"samplers": [{"input": times, "output": weights}],
               "channels": [{"sampler": 0, "target": {"node": node, "path": "weights"}}]}),
    );
    let glb = b.glb();
    let rest = ingest::gltf::import(&b_without_animation(&b), "m.glb", None).unwrap();
    let base = rest_positions(&b);
    let shift = |scene: &Scene| {
        let p = &scene.meshes[scene.instances[0].mesh as usize].positions;
        p.iter()
            .zip(&base)
            .map(|(p, b)| (*p - *b).x)
            .collect::<Vec<f32>>()
    };
    assert!(shift(&rest).iter().all(|d| (d - 0.5).abs() < 1e-6));
    let at = ingest::gltf::import_at(&glb, "m.glb", None, Some(0.25)).unwrap();
    assert!(
        shift(&at).iter().all(|d| (d - 0.25).abs() < 1e-6),
        "{:?}",
        shift(&at)
    );

    let cube = asset("AnimatedMorphCube/AnimatedMorphCube.gltf");
    let bytes = std::fs::read(&cube).unwrap();
    let dir = cube.parent().unwrap();
    let at = |t: f64| {
        let scene = ingest::gltf::import_at(&bytes, "cube", Some(dir), Some(t)).unwrap();
        world_positions(&scene)
    };
    let (a, b) = (at(0.0), at(1.0));
    let moved = a
        .iter()
        .zip(&b)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max);
    assert!(moved > 0.1, "the cube keeps its shape ({moved})");
}

/// The builder's document without animations (weights then come from the mesh).
fn b_without_animation(b: &Builder) -> Vec<u8> {
    let mut copy = Builder {
        json: b.json.clone(),
        bin: b.bin.clone(),
    };
    copy.json.as_object_mut().unwrap().remove("animations");
    copy.glb()
}

/// The quad's undeformed positions.
fn rest_positions(b: &Builder) -> Vec<Vec3> {
    let mut copy = Builder {
        json: b.json.clone(),
        bin: b.bin.clone(),
    };
    copy.json.as_object_mut().unwrap().remove("animations");
    copy.json["meshes"][0]["weights"] = json!([0.0]);
    let scene = ingest::gltf::import(&copy.glb(), "rest.glb", None).unwrap();
    scene.meshes[scene.instances[0].mesh as usize]
        .positions
        .clone()
}

/// Khronos' RiggedSimple bends between frames: its skinned vertices move, and the file's
/// default (no frame) keeps the bind pose with a warning that it is animated.
#[test]
fn a_rigged_asset_changes_pose_between_frames() {
    let path = asset("RiggedSimple/RiggedSimple.gltf");
    let bytes = std::fs::read(&path).unwrap();
    let dir = path.parent().unwrap();
    let at = |t: Option<f64>| {
        let scene = ingest::gltf::import_at(&bytes, "rigged", Some(dir), t).unwrap();
        (world_positions(&scene), scene.warnings)
    };
    let (rest, warnings) = at(None);
    assert!(
        warnings.iter().any(|w| w.contains("animated")),
        "{warnings:?}"
    );
    let (a, _) = at(Some(0.5));
    let (b, _) = at(Some(1.5));
    let moved = a
        .iter()
        .zip(&b)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max);
    assert!(moved > 0.1, "the pose does not change ({moved})");
    assert_eq!(rest.len(), a.len());
}

/// A morphed primitive whose normal map needs MikkTSpace tangents: the tangents are made
/// after the morph (MikkTSpace splits vertices where UVs mirror, which would misalign the
/// targets' per-vertex displacements).
#[test]
fn morph_targets_apply_before_generated_tangents() {
    let mut b = Builder::new();
    let png = common::gltf_builder::png_rgba(1, 1, &[[128, 128, 255, 255]]);
    let view = b.view(&png);
    b.add(
        "images",
        json!({"bufferView": view, "mimeType": "image/png"}),
    );
    b.add("textures", json!({"source": 0}));
    let material = b.add("materials", json!({"normalTexture": {"index": 0}}));
    let pos = b.floats(
        "VEC3",
        &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0],
    );
    // The second triangle's UVs are mirrored: MikkTSpace splits the shared corners.
    let uv = b.floats("VEC2", &[0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 2.0, 0.0]);
    let target = b.floats(
        "VEC3",
        &[0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0],
    );
    let indices = b.indices(&[0, 1, 2, 0, 2, 3]);
    let mesh = b.add(
        "meshes",
        json!({"primitives": [{"attributes": {"POSITION": pos, "TEXCOORD_0": uv},
                "indices": indices, "material": material, "targets": [{"POSITION": target}]}],
               "weights": [1.0]}),
    );
    b.root(json!({"mesh": mesh}));
    let scene = ingest::gltf::import(&b.glb(), "mirrored.glb", None).unwrap();
    let m = &scene.meshes[scene.instances[0].mesh as usize];
    assert!(m.tangents.is_some());
    assert!(
        m.positions.len() > 4,
        "MikkTSpace did not split the mirrored corners"
    );
    for p in &m.positions {
        assert!(
            (p.z - 1.0).abs() < 1e-6,
            "a vertex missed its displacement: {p}"
        );
    }
}
