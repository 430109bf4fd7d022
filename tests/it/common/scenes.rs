//! Scenes built in code for tests, and a render helper.

use glam::{DMat4, DVec3, Vec3};
use lucerna::film::Film;
use lucerna::film::aov::{Aov, AovSet};
use lucerna::film::filter::PixelFilter;
use lucerna::integrator::Settings;
use lucerna::integrator::settings::TextureFilter;
use lucerna::render::{self, RenderOptions, RenderStats};
use lucerna::scene::{Camera, Environment, Instance, Material, Mesh, Projection, Scene};
use lucerna::world::World;
use std::collections::HashMap;

/// An icosphere of radius 1 with `subdivisions` levels, flat-shaded (no normals).
pub fn icosphere(subdivisions: u32) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut triangles: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut mid = |a: u32, b: u32, positions: &mut Vec<Vec3>| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                positions.push(((positions[a as usize] + positions[b as usize]) * 0.5).normalize());
                (positions.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(triangles.len() * 4);
        for [a, b, c] in triangles {
            let (ab, bc, ca) = (
                mid(a, b, &mut positions),
                mid(b, c, &mut positions),
                mid(c, a, &mut positions),
            );
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        triangles = next;
    }
    Mesh {
        name: "icosphere".into(),
        positions,
        triangles,
        ..Default::default()
    }
}

/// A unit square in the XY plane facing +Z, centred at the origin.
pub fn quad() -> Mesh {
    Mesh {
        name: "quad".into(),
        positions: vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        ..Default::default()
    }
}

/// A material of the given model with base colour `base`, double-sided.
pub fn material(
    model: lucerna::scene::BsdfModel,
    base: Vec3,
    metallic: f32,
    roughness: f32,
) -> Material {
    Material {
        name: "test".into(),
        model,
        base_color: base.extend(1.0),
        metallic,
        roughness,
        double_sided: true,
        ..Default::default()
    }
}

/// An orthographic camera at `eye` looking at the origin, showing a view `half` units high.
pub fn ortho_camera(eye: DVec3, half: f32) -> Camera {
    Camera {
        name: "test".into(),
        projection: Projection::Orthographic {
            xmag: half,
            ymag: half,
        },
        transform: look_at(eye, DVec3::ZERO),
        aperture_radius: 0.0,
        focus_distance: 1.0,
        clip_near: 0.0,
        clip_far: None,
        fit: Default::default(),
        motion: Vec::new(),
    }
}

/// Camera-to-world transform of a camera at `eye` looking at `target` with +Y up.
pub fn look_at(eye: DVec3, target: DVec3) -> DMat4 {
    let forward = (target - eye).normalize();
    let right = forward.cross(DVec3::Y).normalize();
    let up = right.cross(forward);
    DMat4::from_cols(
        right.extend(0.0),
        up.extend(0.0),
        (-forward).extend(0.0),
        eye.extend(1.0),
    )
}

/// A scene of `meshes` (each with its transform) sharing material `mat`, lit by a constant
/// environment `env`, seen through `camera`.
pub fn scene(meshes: Vec<(Mesh, DMat4)>, mat: Material, env: Vec3, camera: Camera) -> Scene {
    let mut scene = Scene {
        source: "test".into(),
        materials: vec![mat],
        environment: Some(Environment::Constant(env)),
        cameras: vec![camera],
        ..Default::default()
    };
    for (i, (mesh, transform)) in meshes.into_iter().enumerate() {
        scene.meshes.push(mesh);
        scene.instances.push(Instance {
            name: format!("mesh{i}"),
            mesh: i as u32,
            motion: Vec::new(),
            transform,
        });
    }
    scene
}

/// Renders `scene` at `res` with `spp` samples on a pool of `threads`, box filter.
pub fn render(
    scene: Scene,
    res: (u32, u32),
    spp: u32,
    settings: Settings,
    threads: usize,
) -> (Film, RenderStats) {
    render_aovs(scene, res, spp, settings, threads, AovSet::default())
}

/// [`render`] with the AOV set `aovs`.
pub fn render_aovs(
    scene: Scene,
    res: (u32, u32),
    spp: u32,
    settings: Settings,
    threads: usize,
    aovs: AovSet,
) -> (Film, RenderStats) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut world =
            World::build(scene, None, Some(res), settings.light_select).expect("test scene builds");
        world.set_footprints(settings.texture_filter == TextureFilter::Mip, Some(spp));
        let options = RenderOptions {
            spp: Some(spp),
            settings,
            aovs,
            filter: PixelFilter::box_filter(),
            ..Default::default()
        };
        render::render(&world, &options)
    })
}

/// Mean of the beauty's channel `c` over the pixels where `keep(pixel)` holds, and the
/// standard error of that mean from the variance layer.
pub fn mean_and_error(film: &Film, c: usize, keep: impl Fn(usize) -> bool + Copy) -> (f64, f64) {
    let m = mean(film, Aov::Beauty, c, keep);
    let var = &film.planes(Aov::Variance)[c];
    let kept: Vec<usize> = (0..var.len()).filter(|&i| keep(i)).collect();
    let se = kept.iter().map(|&i| var[i] as f64).sum::<f64>().sqrt() / kept.len() as f64;
    (m, se)
}

/// Relative MSE of the beauty of `a` against `b`: mean over pixels and channels of
/// (a - b)² / (b² + 0.01), the design's metric.
pub fn rel_mse(a: &Film, b: &Film) -> f64 {
    let (pa, pb) = (a.planes(Aov::Beauty), b.planes(Aov::Beauty));
    let mut sum = 0.0;
    for c in 0..3 {
        for (x, r) in pa[c].iter().zip(&pb[c]) {
            let (x, r) = (*x as f64, *r as f64);
            sum += (x - r).powi(2) / (r * r + 0.01);
        }
    }
    sum / (3 * pa[0].len()) as f64
}

/// Mean of channel `c` of `aov` over the pixels where `keep(pixel)` holds.
pub fn mean(film: &Film, aov: Aov, c: usize, keep: impl Fn(usize) -> bool) -> f64 {
    let plane = &film.planes(aov)[c];
    let values: Vec<f64> = (0..plane.len())
        .filter(|&i| keep(i))
        .map(|i| plane[i] as f64)
        .collect();
    values.iter().sum::<f64>() / values.len() as f64
}

/// Gives the Cornell box's tall block a material of its own: a smooth white metal (a
/// mirror, a delta lobe).
pub fn make_tall_block_a_mirror(scene: &mut Scene) {
    let tall = scene
        .instances
        .iter()
        .find(|i| i.name == "tall_block")
        .expect("the Cornell box has a tall block")
        .mesh as usize;
    let mut mirror = scene.materials[0].clone();
    mirror.model = lucerna::scene::BsdfModel::GltfPbr;
    mirror.base_color = glam::Vec4::ONE;
    mirror.metallic = 1.0;
    mirror.roughness = 0.0;
    scene.materials.push(mirror);
    scene.meshes[tall].material = (scene.materials.len() - 1) as u32;
}

/// Makes the Cornell box's light a screen: an emissive texture of 128² texels, black but
/// for a bright 56 × 40 patch and a dim 8 × 8 one, mapped once over the light's quad, with
/// the emission scaled so that the light gives off what it did. Light samples that follow
/// the texture (`light::emission_texture`) then differ from uniform ones.
#[allow(dead_code)]
pub fn make_the_light_a_screen(scene: &mut Scene) {
    use lucerna::scene::{Texels, Texture, TextureRef, Wrap};
    let light = scene
        .instances
        .iter()
        .find(|i| i.name == "light")
        .expect("the Cornell box has a light")
        .mesh as usize;
    let (w, h) = (128u32, 128u32);
    let mut texels = vec![[0.0f32, 0.0, 0.0, 1.0]; (w * h) as usize];
    let mut lit = 0.0f32;
    for (x0, y0, sx, sy, value) in [(60, 20, 56, 40, 1.0f32), (20, 90, 8, 8, 0.3)] {
        for y in y0..y0 + sy {
            for x in x0..x0 + sx {
                texels[(y * w + x) as usize] = [value, value, value, 1.0];
                lit += value;
            }
        }
    }
    scene.textures.push(Texture {
        name: "screen".into(),
        width: w,
        height: h,
        texels: std::sync::Arc::new(Texels::RgbaF32(texels)),
        mips: Default::default(),
        wrap_u: Wrap::ClampToEdge,
        wrap_v: Wrap::ClampToEdge,
        nearest: false,
        mipmaps: true,
        udim: None,
    });
    let mesh = &mut scene.meshes[light];
    let (lo, hi) = mesh.positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    mesh.uvs[0] = Some(
        mesh.positions
            .iter()
            .map(|p| glam::Vec2::new((p.x - lo.x) / (hi.x - lo.x), (p.z - lo.z) / (hi.z - lo.z)))
            .collect(),
    );
    let m = &mut scene.materials[mesh.material as usize];
    m.emissive *= (w * h) as f32 / lit;
    m.emissive_texture = Some(TextureRef {
        texture: (scene.textures.len() - 1) as u32,
        tex_coord: 0,
        transform: None,
    });
}

/// Every instanced vertex in world space.
pub fn world_positions(scene: &Scene) -> Vec<glam::DVec3> {
    scene
        .instances
        .iter()
        .flat_map(|i| {
            scene.meshes[i.mesh as usize]
                .positions
                .iter()
                .map(|p| i.transform.transform_point3(p.as_dvec3()))
        })
        .collect()
}
