//! glTF import: containers and buffers, hierarchy, primitives, attributes, cameras,
//! materials, lights and extensions, checked on the scene and, where it matters, on renders.

use crate::common;

use common::scenes::world_positions;

use common::gltf_builder::{Builder, png_rgba};
use common::scenes::render;
use glam::{DMat4, DVec3, Vec2, Vec3, Vec4};
use lucerna::film::aov::Aov;
use lucerna::ingest;
use lucerna::integrator::Settings;
use lucerna::material::{SurfaceAttributes, texture_lookup};
use lucerna::scene::{AlphaMode, BsdfModel, LightKind, Projection, Scene};
use lucerna::world::World;
use serde_json::json;
use std::path::Path;

fn temp() -> tempdir::TempDir {
    tempdir::TempDir::new()
}

/// A minimal temporary directory (removed on drop).
mod tempdir {
    pub struct TempDir(pub std::path::PathBuf);
    impl TempDir {
        pub fn new() -> Self {
            static COUNTER: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
            let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let dir = std::env::temp_dir().join(format!("lucerna-gltf-{}-{n}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            Self(dir)
        }
        pub fn path(&self) -> &std::path::Path {
            &self.0
        }
    }
    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

fn load(path: &Path) -> Scene {
    ingest::load(path, &Default::default()).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn embedded_external_and_binary_containers_give_the_same_scene() {
    let dir = temp();
    let mut b = Builder::new();
    let prim = b.quad_primitive(None);
    let mesh = b.mesh(json!([prim]));
    b.root(json!({"mesh": mesh}));
    let scenes = [
        load(&b.write_embedded(dir.path(), "embedded")),
        load(&b.write_external(dir.path(), "external")),
        load(&b.write_glb(dir.path(), "binary")),
    ];
    for s in &scenes {
        assert_eq!(s.instanced_triangle_count(), 2);
        assert_eq!(world_positions(s), world_positions(&scenes[0]));
        assert_eq!(s.meshes[0].uvs[0], scenes[0].meshes[0].uvs[0]);
    }
    // External files may also be images, in a subdirectory, with percent-encoded names.
    std::fs::create_dir_all(dir.path().join("tex dir")).unwrap();
    std::fs::write(
        dir.path().join("tex dir/white.png"),
        png_rgba(1, 1, &[[255; 4]]),
    )
    .unwrap();
    b.add("images", json!({"uri": "tex%20dir/white.png"}));
    b.add("textures", json!({"source": 0}));
    let m = b.add(
        "materials",
        json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}),
    );
    b.json["meshes"][0]["primitives"][0]["material"] = json!(m);
    let s = load(&b.write_external(dir.path(), "with_image"));
    assert_eq!(s.textures.len(), 1);
}

#[test]
fn node_hierarchy_composes_trs_and_matrices() {
    let dir = temp();
    let mut b = Builder::new();
    let prim = b.quad_primitive(None);
    let mesh = b.mesh(json!([prim]));
    // Child: a matrix translating by (0, 0, 5) (column-major).
    let child = b.node(json!({"mesh": mesh, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,5,1]}));
    // Parent: TRS with scale 2, 90° about Y, translation (10, 0, 0).
    let s = std::f64::consts::FRAC_1_SQRT_2;
    b.root(json!({"children": [child], "translation": [10, 0, 0], "rotation": [0, s, 0, s], "scale": [2, 2, 2]}));
    let scene = load(&b.write_embedded(dir.path(), "h"));
    let expected = DMat4::from_scale_rotation_translation(
        DVec3::splat(2.0),
        glam::DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2),
        DVec3::new(10.0, 0.0, 0.0),
    ) * DMat4::from_translation(DVec3::new(0.0, 0.0, 5.0));
    assert!(scene.instances[0].transform.abs_diff_eq(expected, 1e-6));
    // The quad's corner (-1, -1, 0) → z=5 → scaled (−2, −2, 10) → rotated (10, −2, 2) → + (10,0,0).
    let p = scene.instances[0]
        .transform
        .transform_point3(DVec3::new(-1.0, -1.0, 0.0));
    assert!((p - DVec3::new(20.0, -2.0, 2.0)).length() < 1e-6, "{p}");
}

#[test]
fn strips_and_fans_are_converted_points_and_lines_skipped() {
    let dir = temp();
    let mut b = Builder::new();
    let pos = b.floats(
        "VEC3",
        &[
            0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 2.0, 0.0, 0.0,
        ],
    );
    let prims = json!([
        {"attributes": {"POSITION": pos}, "mode": 5},
        {"attributes": {"POSITION": pos}, "mode": 6},
        {"attributes": {"POSITION": pos}, "mode": 0},
        {"attributes": {"POSITION": pos}, "mode": 1},
    ]);
    let mesh = b.mesh(prims);
    b.root(json!({"mesh": mesh}));
    let scene = load(&b.write_embedded(dir.path(), "modes"));
    assert_eq!(scene.meshes.len(), 2);
    assert_eq!(
        scene.meshes[0].triangles,
        vec![[0, 1, 2], [1, 3, 2], [2, 3, 4]]
    );
    assert_eq!(
        scene.meshes[1].triangles,
        vec![[1, 2, 0], [2, 3, 0], [3, 4, 0]]
    );
    assert_eq!(
        scene
            .warnings
            .iter()
            .filter(|w| w.contains("skipped"))
            .count(),
        2,
        "{:?}",
        scene.warnings
    );
}

#[test]
fn attributes_normals_uvs_colours_and_generated_tangents() {
    let dir = temp();
    let mut b = Builder::new();
    let quad = b.quad_primitive(None);
    let normal = b.floats("VEC3", &[0.0, 0.0, 1.0].repeat(4));
    let color = b.floats("VEC4", &[0.5, 0.25, 1.0, 1.0].repeat(4));
    let tex = b.png_texture(&png_rgba(1, 1, &[[128, 128, 255, 255]]), json!({}));
    let nm = b.add(
        "materials",
        json!({"normalTexture": {"index": tex, "scale": 0.5}}),
    );
    let mut with_all = quad.clone();
    with_all["attributes"]["NORMAL"] = json!(normal);
    with_all["attributes"]["COLOR_0"] = json!(color);
    with_all["material"] = json!(nm);
    let mesh = b.mesh(json!([quad, with_all]));
    b.root(json!({"mesh": mesh}));
    let scene = load(&b.write_embedded(dir.path(), "attrs"));
    let (plain, full) = (&scene.meshes[0], &scene.meshes[1]);
    assert!(
        plain.normals.is_none() && plain.tangents.is_none(),
        "flat shading, no tangents without a normal map"
    );
    assert_eq!(plain.uvs[0].as_ref().unwrap()[2], Vec2::new(1.0, 0.0));
    assert_eq!(
        full.colors.as_ref().unwrap()[0],
        Vec4::new(0.5, 0.25, 1.0, 1.0)
    );
    let tangents = full
        .tangents
        .as_ref()
        .expect("MikkTSpace tangents for the normal map");
    for t in tangents {
        assert!(
            (t.truncate() - Vec3::X).length() < 1e-4,
            "tangent along +u: {t}"
        );
    }
    assert_eq!(scene.materials[full.material as usize].normal_scale, 0.5);
}

#[test]
fn cameras_perspective_orthographic_and_by_name() {
    let dir = temp();
    let mut b = Builder::new();
    let prim = b.quad_primitive(None);
    let mesh = b.mesh(json!([prim]));
    b.root(json!({"mesh": mesh}));
    b.add("cameras", json!({"name": "wide", "type": "perspective", "perspective": {"yfov": 1.2, "aspectRatio": 2.0, "znear": 0.1}}));
    b.add("cameras", json!({"name": "plan", "type": "orthographic", "orthographic": {"xmag": 3, "ymag": 1.5, "znear": 0.1, "zfar": 100}}));
    b.root(json!({"camera": 0, "translation": [0, 0, 5]}));
    b.root(json!({"camera": 1, "translation": [0, 0, 8]}));
    let path = b.write_embedded(dir.path(), "cams");
    let scene = load(&path);
    assert_eq!(scene.cameras.len(), 2);
    assert!(
        matches!(scene.cameras[0].projection, Projection::Perspective { yfov, aspect: Some(a) } if yfov == 1.2 && a == 2.0)
    );
    assert!(
        matches!(scene.cameras[1].projection, Projection::Orthographic { xmag, ymag } if xmag == 3.0 && ymag == 1.5)
    );
    // The first camera decides the default resolution (aspect 2 → 512x256).
    let world = World::build(
        scene.clone(),
        None,
        None,
        lucerna::integrator::LightSelect::Power,
    )
    .unwrap();
    assert_eq!((world.camera.width(), world.camera.height()), (512, 256));
    let world = World::build(
        scene.clone(),
        Some("plan"),
        None,
        lucerna::integrator::LightSelect::Power,
    )
    .unwrap();
    assert_eq!((world.camera.width(), world.camera.height()), (512, 256));
    let err = World::build(
        scene,
        Some("missing"),
        None,
        lucerna::integrator::LightSelect::Power,
    )
    .err()
    .unwrap();
    assert!(err.to_string().contains("wide, plan"), "{err}");
}

/// A one-quad scene with `material` and an orthographic camera looking at it from +Z.
fn quad_scene(
    dir: &Path,
    name: &str,
    material: serde_json::Value,
    textures: &[(&[[u8; 4]], u32, u32)],
) -> Scene {
    let mut b = Builder::new();
    for (pixels, w, h) in textures {
        b.png_texture(
            &png_rgba(*w, *h, pixels),
            json!({"magFilter": 9728, "wrapS": 10497, "wrapT": 10497}),
        );
    }
    let m = b.add("materials", material);
    let prim = b.quad_primitive(Some(m));
    let mesh = b.mesh(json!([prim]));
    b.root(json!({"mesh": mesh}));
    b.add("cameras", json!({"type": "orthographic", "orthographic": {"xmag": 1.0, "ymag": 1.0, "znear": 0.01, "zfar": 100}}));
    b.root(json!({"camera": 0, "translation": [0, 0, 3]}));
    load(&b.write_embedded(dir, name))
}

#[test]
fn materials_factors_textures_and_extensions() {
    let dir = temp();
    let material = json!({
        "pbrMetallicRoughness": {
            "baseColorFactor": [0.5, 1.0, 1.0, 1.0],
            "baseColorTexture": {"index": 0, "extensions": {"KHR_texture_transform": {"offset": [0.5, 0], "rotation": 0.3, "scale": [2, 1], "texCoord": 1}}},
            "metallicFactor": 0.25, "roughnessFactor": 0.75,
            "metallicRoughnessTexture": {"index": 1}
        },
        "emissiveFactor": [1.0, 0.5, 0.25],
        "emissiveTexture": {"index": 0},
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}, "KHR_materials_ior": {"ior": 1.33},
            "KHR_materials_clearcoat": {"clearcoatFactor": 0.6, "clearcoatRoughnessFactor": 0.2,
                "clearcoatTexture": {"index": 0}}},
        "alphaMode": "MASK", "alphaCutoff": 0.3, "doubleSided": true
    });
    let srgb_188: &[[u8; 4]] = &[[188, 188, 188, 255]];
    let mr: &[[u8; 4]] = &[[0, 128, 255, 255]];
    let scene = quad_scene(dir.path(), "mat", material, &[(srgb_188, 1, 1), (mr, 1, 1)]);
    let m = &scene.materials[0];
    assert_eq!(m.model, BsdfModel::GltfPbr);
    assert_eq!((m.metallic, m.roughness, m.ior), (0.25, 0.75, 1.33));
    assert_eq!((m.clearcoat, m.clearcoat_roughness), (0.6, 0.2));
    assert_eq!(m.clearcoat_texture.map(|t| t.texture), Some(0));
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert_eq!(m.emissive, Vec3::new(4.0, 2.0, 1.0));
    assert_eq!(m.alpha_mode, AlphaMode::Mask { cutoff: 0.3 });
    assert!(m.double_sided);
    let t = m.base_color_texture.unwrap();
    assert_eq!(t.tex_coord, 1, "KHR_texture_transform's texCoord overrides");
    let tr = t.transform.unwrap();
    let (s, c) = 0.3f32.sin_cos();
    // u axis → (cos r, -sin r) · scale.x (the image turns clockwise, as
    // TextureTransformTest shows); origin → offset.
    assert!((tr.apply(Vec2::X) - (Vec2::new(c, -s) * 2.0 + Vec2::new(0.5, 0.0))).length() < 1e-6);
    assert!((tr.apply(Vec2::Y) - (Vec2::new(s, c) + Vec2::new(0.5, 0.0))).length() < 1e-6);
    assert!((tr.apply(Vec2::ZERO) - Vec2::new(0.5, 0.0)).length() < 1e-6);
    // sRGB decode of colour textures, none for data textures.
    let attrs = SurfaceAttributes {
        uv: [Vec2::ZERO; 2],
        color: Vec4::ONE,
        footprint: [[Vec2::ZERO; 2]; 2],
    };
    let base = texture_lookup(&scene.textures, &t, &attrs, true);
    assert!(
        (base.x - 0.5029).abs() < 1e-3,
        "sRGB 188 is linear 0.503: {}",
        base.x
    );
    let data = texture_lookup(
        &scene.textures,
        m.metallic_roughness_texture.as_ref().unwrap(),
        &attrs,
        false,
    );
    assert!((data.y - 128.0 / 255.0).abs() < 1e-6 && data.z == 1.0);
}

#[test]
fn texture_transform_moves_the_texture() {
    // A 2x1 texture, red left and green right; offset 0.5 with REPEAT swaps them.
    let dir = temp();
    let texture: &[[u8; 4]] = &[[255, 0, 0, 255], [0, 255, 0, 255]];
    let plain = quad_scene(
        dir.path(),
        "plain",
        json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}),
        &[(texture, 2, 1)],
    );
    let moved = quad_scene(
        dir.path(),
        "moved",
        json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": 0, "extensions": {"KHR_texture_transform": {"offset": [0.5, 0]}}}}}),
        &[(texture, 2, 1)],
    );
    let attrs = SurfaceAttributes {
        uv: [Vec2::new(0.25, 0.5); 2],
        color: Vec4::ONE,
        footprint: [[Vec2::ZERO; 2]; 2],
    };
    let lookup = |s: &Scene| {
        texture_lookup(
            &s.textures,
            s.materials[0].base_color_texture.as_ref().unwrap(),
            &attrs,
            true,
        )
    };
    assert_eq!(lookup(&plain).truncate(), Vec3::X);
    assert_eq!(lookup(&moved).truncate(), Vec3::Y);
}

#[test]
fn renders_honour_base_colour_textures_alpha_cutouts_and_sidedness() {
    let dir = temp();
    let env = Vec3::splat(1.0);
    let settings = Settings::default();
    // Lambert quad, texture sRGB 188 = linear 0.503, under a white environment: radiance =
    // albedo (one bounce, the quad is flat).
    let texture: &[[u8; 4]] = &[[188, 188, 188, 255]];
    let mut lambert = quad_scene(
        dir.path(),
        "lambert",
        json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}, "extras": {"lucerna": {"bsdf": "lambert"}}}),
        &[(texture, 1, 1)],
    );
    ingest::set_constant_environment(&mut lambert, env);
    let (film, _) = render(lambert, (16, 16), 64, settings.clone(), 2);
    let beauty = &film.planes(Aov::Beauty)[0];
    let mean = beauty.iter().map(|&v| v as f64).sum::<f64>() / beauty.len() as f64;
    assert!(
        (mean - 0.5029).abs() < 0.01,
        "textured Lambert in a furnace: {mean}"
    );

    // Cut-out: alpha 0 on the left half (below the 0.5 cutoff) shows the environment.
    let texture: &[[u8; 4]] = &[[0, 0, 0, 0], [0, 0, 0, 255]];
    let mut cutout = quad_scene(
        dir.path(),
        "cutout",
        json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}, "alphaMode": "MASK", "extras": {"lucerna": {"bsdf": "lambert"}}}),
        &[(texture, 2, 1)],
    );
    ingest::set_constant_environment(&mut cutout, env);
    let (film, _) = render(cutout, (16, 16), 16, settings.clone(), 2);
    let beauty = &film.planes(Aov::Beauty)[0];
    let alpha = &film.planes(Aov::Beauty)[3];
    assert!(
        beauty[8 * 16 + 2] > 0.99 && alpha[8 * 16 + 2] == 0.0,
        "left: the environment through the hole"
    );
    assert!(
        beauty[8 * 16 + 13] < 0.01 && alpha[8 * 16 + 13] == 1.0,
        "right: the black quad"
    );

    // One-sided: seen from behind, the quad is not there.
    let mut back = quad_scene(dir.path(), "back", json!({"doubleSided": false}), &[]);
    back.cameras[0].transform = DMat4::from_translation(DVec3::new(0.0, 0.0, -3.0))
        * DMat4::from_rotation_y(std::f64::consts::PI);
    ingest::set_constant_environment(&mut back, env);
    let (film, _) = render(back, (8, 8), 4, settings, 1);
    assert!(
        film.planes(Aov::Beauty)[3].iter().all(|&a| a == 0.0),
        "back faces of one-sided quads are invisible"
    );
}

#[test]
fn emission_with_strength_and_texture_is_seen_directly() {
    let dir = temp();
    let texture: &[[u8; 4]] = &[[255, 188, 0, 255]];
    let scene = quad_scene(
        dir.path(),
        "emissive",
        json!({"emissiveFactor": [1, 1, 1], "emissiveTexture": {"index": 0}, "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 3.0}}}),
        &[(texture, 1, 1)],
    );
    let (film, _) = render(scene, (8, 8), 4, Settings::default(), 1);
    let e = film.planes(Aov::Emission);
    assert!(
        (e[0][36] - 3.0).abs() < 1e-4 && (e[1][36] - 3.0 * 0.5029).abs() < 2e-3 && e[2][36] == 0.0
    );
}

#[test]
fn punctual_lights_follow_the_specification() {
    let dir = temp();
    let mut b = Builder::new();
    let m = b.add("materials", json!({"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}, "extras": {"lucerna": {"bsdf": "lambert"}}}));
    let prim = b.quad_primitive(Some(m));
    let mesh = b.mesh(json!([prim]));
    b.root(json!({"mesh": mesh, "scale": [10, 10, 1]}));
    b.add("cameras", json!({"type": "orthographic", "orthographic": {"xmag": 0.05, "ymag": 0.05, "znear": 0.01, "zfar": 100}}));
    b.root(json!({"camera": 0, "translation": [0, 0, 3]}));
    b.json["extensionsUsed"] = json!(["KHR_lights_punctual"]);
    let lights = json!({"lights": [
        {"type": "directional", "intensity": 2.0, "color": [1, 1, 1]},
        {"type": "point", "intensity": 8.0, "color": [1, 0, 0]},
        {"type": "spot", "intensity": 8.0, "color": [0, 0, 1], "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.6}}
    ]});
    b.json["extensions"] = json!({"KHR_lights_punctual": lights});
    // Directional straight down the -Z axis; point 2 units above; spot pointing down from
    // 2 units above and off to the side, so the centre is 0.4 rad off its axis, between
    // the cone angles.
    b.root(json!({"extensions": {"KHR_lights_punctual": {"light": 0}}}));
    b.root(json!({"extensions": {"KHR_lights_punctual": {"light": 1}}, "translation": [0, 0, 2]}));
    let side = 2.0 * 0.4f32.tan();
    b.root(
        json!({"extensions": {"KHR_lights_punctual": {"light": 2}}, "translation": [0, side, 2]}),
    );
    let scene = load(&b.write_embedded(dir.path(), "lights"));
    assert_eq!(scene.lights.len(), 3);
    assert!(
        matches!(scene.lights[0].kind, LightKind::Directional { direction, .. } if (direction + DVec3::Z).length() < 1e-9)
    );
    // One light at a time: delta lights then need no selection and the estimate is exact
    // up to the pixel footprint.
    let albedo_over_pi = 0.5 / std::f64::consts::PI;
    // Directional: E = 2 in every channel. Point (red) 2 units away: E = 8 / 2². Spot
    // (blue): 0.4 rad off its axis, falloff ((cos 0.4 − cos 0.6)/(cos 0.2 − cos 0.6))², at
    // distance 2 / cos 0.4, incidence cos 0.4.
    let falloff = ((0.4f64.cos() - 0.6f64.cos()) / (0.2f64.cos() - 0.6f64.cos())).powi(2);
    let spot = 8.0 * falloff * 0.4f64.cos() / (2.0 / 0.4f64.cos()).powi(2);
    let expected = [[2.0, 2.0, 2.0], [2.0, 0.0, 0.0], [0.0, 0.0, spot]];
    for (i, rgb) in expected.iter().enumerate() {
        let mut one = scene.clone();
        one.lights = vec![scene.lights[i].clone()];
        let (film, _) = render(one, (4, 4), 4, Settings::default(), 1);
        let b = film.planes(Aov::Beauty);
        for c in 0..3 {
            let centre = (b[c][5] + b[c][6] + b[c][9] + b[c][10]) as f64 / 4.0;
            let e = albedo_over_pi * rgb[c];
            assert!(
                (centre - e).abs() <= 2e-3 * e + 1e-7,
                "light {i} channel {c}: {centre} vs {e}"
            );
        }
    }
}

/// KHR_materials_diffuse_transmission: a leaf lit by the sun from behind shows
/// diffuseTransmission × colour / π × E on its front (factor × texture A, colour factor ×
/// sRGB texture), and lit from the front the diffuse reflection it keeps, (1 −
/// diffuseTransmission) × base / π × E (no specular layer: KHR_materials_specular 0).
#[test]
fn diffuse_transmission_lights_a_leaf_from_behind() {
    let dir = temp();
    let mut b = Builder::new();
    let texel: &[[u8; 4]] = &[[188, 188, 188, 128]];
    b.png_texture(&png_rgba(1, 1, texel), json!({"magFilter": 9728}));
    let m = b.add(
        "materials",
        json!({
            "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1], "metallicFactor": 0},
            "extensions": {
                "KHR_materials_specular": {"specularFactor": 0},
                "KHR_materials_diffuse_transmission": {
                    "diffuseTransmissionFactor": 0.6,
                    "diffuseTransmissionTexture": {"index": 0},
                    "diffuseTransmissionColorFactor": [1.0, 0.5, 0.25],
                    "diffuseTransmissionColorTexture": {"index": 0}
                }
            }
        }),
    );
    let prim = b.quad_primitive(Some(m));
    let mesh = b.mesh(json!([prim]));
    b.root(json!({"mesh": mesh, "scale": [10, 10, 1]}));
    b.add("cameras", json!({"type": "orthographic", "orthographic": {"xmag": 0.05, "ymag": 0.05, "znear": 0.01, "zfar": 100}}));
    b.root(json!({"camera": 0, "translation": [0, 0, 3]}));
    b.json["extensionsUsed"] = json!([
        "KHR_lights_punctual",
        "KHR_materials_specular",
        "KHR_materials_diffuse_transmission"
    ]);
    b.json["extensions"] = json!({"KHR_lights_punctual": {"lights": [
        {"type": "directional", "intensity": 2.0}
    ]}});
    // Turned half a turn about y: the light shines along +z, through the quad's back.
    b.root(json!({"extensions": {"KHR_lights_punctual": {"light": 0}}, "rotation": [0, 1, 0, 0]}));
    let scene = load(&b.write_embedded(dir.path(), "leaf"));
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let d = scene.materials[0].diffuse_transmission.unwrap();
    assert_eq!((d.factor, d.color), (0.6, Vec3::new(1.0, 0.5, 0.25)));
    let share = 0.6 * 128.0 / 255.0;
    let colour = [1.0, 0.5, 0.25].map(|c| c * 0.5029 * share);
    let kept = [0.8 * (1.0 - share); 3];
    let mut front = scene.clone();
    if let LightKind::Directional { direction, .. } = &mut front.lights[0].kind {
        *direction = -*direction;
    }
    for (name, scene, expected) in [("behind", scene, colour), ("front", front, kept)] {
        let (film, _) = render(scene, (4, 4), 4, Settings::default(), 1);
        let beauty = film.planes(Aov::Beauty);
        for c in 0..3 {
            let centre = (beauty[c][5] + beauty[c][6] + beauty[c][9] + beauty[c][10]) as f64 / 4.0;
            let e = expected[c] * 2.0 / std::f64::consts::PI;
            assert!(
                (centre - e).abs() <= 2e-3 * e,
                "lit from the {name}, channel {c}: {centre} vs {e}"
            );
        }
    }
}

#[test]
fn extras_select_lambert_phong_and_diffuse_roughness() {
    let dir = temp();
    let phong = quad_scene(
        dir.path(),
        "phong",
        json!({"extras": {"lucerna": {"bsdf": "phong", "exponent": 50, "specular": 0.3}}}),
        &[],
    );
    assert_eq!(
        phong.materials[0].model,
        BsdfModel::Phong {
            exponent: 50.0,
            specular: Vec3::splat(0.3)
        }
    );
    let lambert = quad_scene(
        dir.path(),
        "lambert",
        json!({"extras": {"lucerna": {"bsdf": "lambert"}}}),
        &[],
    );
    assert_eq!(lambert.materials[0].model, BsdfModel::Lambert);
    let other_extras = quad_scene(
        dir.path(),
        "other",
        json!({"extras": {"author": "someone"}}),
        &[],
    );
    assert_eq!(other_extras.materials[0].model, BsdfModel::GltfPbr);
    // A diffuse roughness (OpenPBR's EON), which glTF itself lacks, for the glTF BRDF.
    let rough = quad_scene(
        dir.path(),
        "rough",
        json!({"extras": {"lucerna": {"diffuse_roughness": 0.5}}}),
        &[],
    );
    assert_eq!(rough.materials[0].model, BsdfModel::GltfPbr);
    assert_eq!(rough.materials[0].diffuse_roughness, 0.5);
    assert_eq!(other_extras.materials[0].diffuse_roughness, 0.0);
}

#[test]
fn extensions_required_error_used_warning() {
    let dir = temp();
    let mut b = Builder::new();
    let prim = b.quad_primitive(None);
    let mesh = b.mesh(json!([prim]));
    b.root(json!({"mesh": mesh}));
    b.json["extensionsUsed"] = json!(["KHR_materials_dispersion"]);
    let scene = load(&b.write_embedded(dir.path(), "used"));
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("KHR_materials_dispersion")),
        "{:?}",
        scene.warnings
    );
    b.json["extensionsRequired"] = json!(["KHR_materials_dispersion"]);
    let err = ingest::load(
        &b.write_embedded(dir.path(), "required"),
        &Default::default(),
    )
    .err()
    .unwrap();
    assert_eq!(err.exit_code(), 2);
    assert!(
        err.to_string().contains("KHR_materials_dispersion")
            && err.to_string().contains("not supported"),
        "{err}"
    );
}

#[test]
fn sphere_meshes_in_extras_become_analytic_spheres() {
    let dir = temp();
    let mut b = Builder::new();
    // An octahedron stands in for the tessellated sphere other viewers show.
    let pos = b.floats(
        "VEC3",
        &[
            1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0,
            -1.0,
        ],
    );
    let idx = b.indices(&[
        0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5,
    ]);
    let m = b.add("materials", json!({"emissiveFactor": [1, 1, 1]}));
    b.json["meshes"] = json!([{"primitives": [{"attributes": {"POSITION": pos}, "indices": idx, "material": m}], "extras": {"lucerna": {"shape": "sphere"}}}]);
    b.root(json!({"mesh": 0, "translation": [0.5, 0.0, 0.0], "scale": [0.8, 0.8, 0.8]}));
    b.add("cameras", json!({"type": "orthographic", "orthographic": {"xmag": 1.0, "ymag": 1.0, "znear": 0.01, "zfar": 100}}));
    b.root(json!({"camera": 0, "translation": [0.5, 0, 3]}));
    let scene = load(&b.write_embedded(dir.path(), "sphere"));
    assert_eq!(scene.spheres.len(), 1);
    assert_eq!(scene.instances.len(), 0);
    let s = &scene.spheres[0];
    assert!(
        (s.centre - DVec3::new(0.5, 0.0, 0.0)).length() < 1e-6 && (s.radius - 0.8).abs() < 1e-6
    );
    // The silhouette is exact: coverage is the disk's area, π 0.8² of the 2x2 view.
    let (film, _) = render(scene, (64, 64), 16, Settings::default(), 2);
    let alpha = &film.planes(Aov::Beauty)[3];
    let covered: f64 = alpha.iter().map(|&a| a as f64).sum::<f64>() / alpha.len() as f64 * 4.0;
    assert!(
        (covered - std::f64::consts::PI * 0.64).abs() < 0.01,
        "{covered}"
    );
    assert_eq!(film.planes(Aov::Emission)[0][32 * 64 + 32], 1.0);
}

/// KHR_materials_unlit as Blender reads it: the camera sees the base colour whatever the
/// light, and every other ray passes through the surface (a required extension lucerna
/// implements loads, though the gltf crate has no feature for it).
#[test]
fn unlit_surfaces_show_their_colour_to_the_camera_and_let_other_rays_pass() {
    let dir = temp();
    let material = json!({"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.4, 0.2, 1.0]},
        "doubleSided": true, "extensions": {"KHR_materials_unlit": {}}});
    let mut b = Builder::new();
    b.json["extensionsUsed"] = json!(["KHR_materials_unlit"]);
    b.json["extensionsRequired"] = json!(["KHR_materials_unlit"]);
    let m = b.add("materials", material);
    let prim = b.quad_primitive(Some(m));
    let mesh = b.mesh(json!([prim]));
    b.root(json!({"mesh": mesh}));
    b.add("cameras", json!({"type": "orthographic", "orthographic": {"xmag": 1.0, "ymag": 1.0, "znear": 0.01, "zfar": 100}}));
    b.root(json!({"camera": 0, "translation": [0, 0, 3]}));
    let mut scene = load(&b.write_embedded(dir.path(), "unlit"));
    assert!(scene.materials[0].unlit && !scene.materials[0].is_emissive());
    // Under any environment the camera sees the colour exactly.
    for env in [0.0f32, 3.0] {
        ingest::set_constant_environment(&mut scene, Vec3::splat(env));
        let (film, _) = render(scene.clone(), (8, 8), 4, Settings::default(), 2);
        let beauty = film.planes(Aov::Beauty);
        for c in 0..3 {
            let expected = [0.8, 0.4, 0.2][c];
            assert!(
                beauty[c].iter().all(|&v| (v - expected).abs() < 1e-5),
                "env {env}: channel {c}: {:?}",
                &beauty[c][..4]
            );
        }
    }
    // It neither lights nor shadows: a Lambert floor under an oblique sun, the unlit quad
    // above it, shows the sun's full irradiance everywhere the camera sees it, where the
    // quad's shadow would fall too.
    let mut lit = scene.clone();
    lit.materials.push(lucerna::scene::Material {
        model: BsdfModel::Lambert,
        base_color: Vec4::new(0.5, 0.5, 0.5, 1.0),
        double_sided: true,
        ..Default::default()
    });
    let floor = lit.meshes[0].clone();
    lit.meshes.push(lucerna::scene::Mesh {
        material: 1,
        ..floor
    });
    lit.instances.push(lucerna::scene::Instance {
        name: "floor".into(),
        mesh: 1,
        motion: Vec::new(),
        transform: DMat4::from_translation(DVec3::new(0.0, 0.0, -1.0))
            * DMat4::from_scale(DVec3::splat(8.0)),
    });
    lit.instances[0].transform = DMat4::from_scale(DVec3::splat(0.25));
    let direction = DVec3::new(-1.0, 0.0, -1.0).normalize();
    lit.lights.push(lucerna::scene::Light {
        name: "sun".into(),
        kind: LightKind::Directional {
            direction,
            irradiance: Vec3::ONE,
            angle: 0.0,
        },
    });
    ingest::set_constant_environment(&mut lit, Vec3::ZERO);
    let (film, _) = render(lit, (32, 32), 2, Settings::default(), 2);
    let (r, g) = (&film.planes(Aov::Beauty)[0], &film.planes(Aov::Beauty)[1]);
    let expected = 0.5 * (-direction.z) as f32 / std::f32::consts::PI;
    let mut floor = 0;
    for (&r, &g) in r.iter().zip(g) {
        // The quad's own pixels are its colour (R 0.8, G 0.4); the rest is floor.
        if (r - 0.8).abs() < 1e-4 && (g - 0.4).abs() < 1e-4 {
            continue;
        }
        floor += 1;
        assert!(
            (r - expected).abs() < 1e-4,
            "floor {r}, expected {expected}"
        );
    }
    assert!(floor > 900, "{floor} floor pixels");
}

#[test]
fn samplers_without_mipmaps_keep_full_resolution_lookups() {
    // minFilter NEAREST (9728) or LINEAR (9729) asks for no MIP levels; unset or a
    // *_MIPMAP_* filter allows them.
    let dir = temp();
    let mut b = Builder::new();
    let png = png_rgba(1, 1, &[[200, 100, 50, 255]]);
    let filters = [
        json!({"minFilter": 9729}),
        json!({"minFilter": 9728}),
        json!({}),
        json!({"minFilter": 9987}),
    ];
    let textures: Vec<usize> = filters
        .iter()
        .map(|f| b.png_texture(&png, f.clone()))
        .collect();
    let quad = b.quad_primitive(None);
    let mut primitives = Vec::new();
    for t in &textures {
        let m = b.add(
            "materials",
            json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": t}}}),
        );
        let mut p = quad.clone();
        p["material"] = json!(m);
        primitives.push(p);
    }
    let mesh = b.mesh(json!(primitives));
    b.root(json!({"mesh": mesh}));
    let scene = load(&b.write_embedded(dir.path(), "min_filters"));
    let mipmaps: Vec<bool> = scene.textures.iter().map(|t| t.mipmaps).collect();
    assert_eq!(mipmaps, [false, false, true, true]);
}
