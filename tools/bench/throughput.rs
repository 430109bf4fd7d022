//! Ray throughput benchmark: BVH build time, closest-hit and shadow rays per second with 1
//! and 2 threads for coherent and incoherent rays, and memory per triangle, on the Cornell
//! box and the ~1M-triangle sphere field, flattened (every triangle in one BVH) and as the
//! renderer builds it (800 placements of three shared sphere meshes, a two-level BVH).
//!
//!     cargo bench --bench throughput [-- --out FILE.md] [--scene NAME]...
//!
//! `--scene` (repeatable) measures only the named scenes: `cornell-box`, `sphere-field
//! placed`, `sphere-field flattened` (the Cornell box alone takes seconds, the sphere field
//! minutes).
//!
//! Rays are generated up front and traced in chunks on a rayon pool, so the figures are the
//! traversal and intersection cost alone (no shading, no sampling):
//! - coherent closest-hit: one camera ray through each pixel centre of a 1024×1024 image;
//! - incoherent closest-hit: from each camera hit, a cosine-distributed direction around the
//!   geometric normal (a diffuse bounce);
//! - coherent shadow: segments from the camera hits to one point (the centre of the first
//!   light, or above the scene), like shadow rays towards a small light;
//! - incoherent shadow: segments between two random camera hits.
//!
//! Where the CPU has AVX2 and FMA, each set is traced twice more as the packet kernel
//! traces it: eight consecutive rays of the set at a time, as one packet.
//!
//! Each figure is the best of three runs (the machine is shared; the best run is the least
//! disturbed one).

use glam::{Vec2, Vec3};
use lucerna::geometry::ray::{Ray, offset_ray_origin};
use lucerna::ingest;
use lucerna::integrator::LightSelect;
use lucerna::light::Light;
use lucerna::render::peak_memory_bytes;
use lucerna::sampling::pcg::Pcg32;
use lucerna::sampling::warp::square_to_cosine_hemisphere;
use lucerna::world::World;
use rayon::prelude::*;
use std::path::Path;
use std::time::Instant;

const SIDE: u32 = 1024;
const RUNS: usize = 3;
const CHUNK: usize = 4096;

/// The four ray sets of one scene.
struct RaySets {
    coherent: Vec<Ray>,
    incoherent: Vec<Ray>,
    shadow_coherent: Vec<Ray>,
    shadow_incoherent: Vec<Ray>,
}

fn ray_sets(world: &World) -> RaySets {
    let camera = &world.camera;
    let (w, h) = (camera.width(), camera.height());
    let coherent: Vec<Ray> = (0..w * h)
        .map(|i| {
            camera.generate_ray(
                Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5),
                Vec2::splat(0.5),
            )
        })
        .collect();
    let hits: Vec<(Vec3, Vec3)> = coherent
        .iter()
        .filter_map(|ray| {
            let hit = world.intersect(ray)?;
            let it = world.interaction(ray, &hit);
            Some((offset_ray_origin(it.p, it.ng), it.ng))
        })
        .collect();
    let mut rng = Pcg32::new(7, 1);
    let mut u2 = || Vec2::new(rng.next_f32(), rng.next_f32());
    let incoherent = hits
        .iter()
        .map(|&(p, n)| {
            let local = square_to_cosine_hemisphere(u2());
            let frame = lucerna::geometry::frame::Frame::from_normal(n);
            Ray::new(p, frame.to_world(local))
        })
        .collect();
    let target = match world.lights.lights.first() {
        Some(Light::Triangle(t)) => (t.p[0] + t.p[1] + t.p[2]) / 3.0,
        Some(Light::Sphere(s)) => s.centre,
        Some(Light::Point(l)) => l.position,
        Some(Light::Spot(l)) => l.position,
        _ => Vec3::new(0.0, world.radius, 0.0),
    };
    let segment = |from: Vec3, to: Vec3| Ray {
        origin: from,
        dir: to - from,
        tmax: 1.0,
        time: 0.0,
    };
    let shadow_coherent = hits.iter().map(|&(p, _)| segment(p, target)).collect();
    let mut rng = Pcg32::new(11, 3);
    let shadow_incoherent = hits
        .iter()
        .map(|&(p, _)| segment(p, hits[rng.next_u32() as usize % hits.len()].0))
        .collect();
    RaySets {
        coherent,
        incoherent,
        shadow_coherent,
        shadow_incoherent,
    }
}

/// Best rays per second of `RUNS` runs of tracing `rays` with `trace` on `threads` threads;
/// `trace` takes a chunk of rays and returns how many hit.
fn rays_per_second(rays: &[Ray], threads: usize, trace: &(dyn Fn(&[Ray]) -> usize + Sync)) -> f64 {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let mut best = f64::INFINITY;
    let mut hits = 0;
    for _ in 0..RUNS {
        let start = Instant::now();
        hits = pool.install(|| rays.par_chunks(CHUNK).map(trace).sum::<usize>());
        best = best.min(start.elapsed().as_secs_f64());
    }
    std::hint::black_box(hits);
    rays.len() as f64 / best
}

fn main() {
    let (mut out, mut only) = (None, Vec::new());
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => out = args.next(),
            "--scene" => only.extend(args.next()),
            // cargo bench passes --bench; nothing else is an option here.
            _ => {}
        }
    }
    const SCENES: [&str; 3] = [
        "cornell-box",
        "sphere-field placed",
        "sphere-field flattened",
    ];
    if let Some(unknown) = only.iter().find(|o| !SCENES.contains(&o.as_str())) {
        eprintln!("throughput: no scene {unknown:?}; the scenes are {SCENES:?}");
        std::process::exit(2);
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut report = String::from(
        "| scene | triangles | BVH build 1 thr (s/Mtri) | BVH build 2 thr (s/Mtri) | rays | closest 1 thr (Mrays/s) | closest 2 thr | shadow 1 thr (Mrays/s) | shadow 2 thr |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut memory = String::new();
    let sphere_field = root.join("scenes/sphere-field/sphere-field.glb");
    for (name, path, flatten) in [
        (SCENES[0], None, false),
        // The smaller one first: the process peak only grows.
        (SCENES[1], Some(&sphere_field), false),
        (SCENES[2], Some(&sphere_field), true),
    ] {
        if !only.is_empty() && !only.iter().any(|o| o == name) {
            continue;
        }
        let load = || {
            let scene = match &path {
                Some(p) => ingest::load(p, &Default::default()).expect("scene loads"),
                None => ingest::default_scene().unwrap(),
            };
            if flatten { scene.unshared() } else { scene }
        };
        let rss_before = peak_memory_bytes().unwrap_or(0);
        let mut build = [0.0; 2];
        let mut world = None;
        for (i, threads) in [1, 2].into_iter().enumerate() {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut best = f64::INFINITY;
            for _ in 0..RUNS {
                drop(world.take()); // one world alive at a time: the peak is one scene's
                let scene = load();
                let w = pool.install(|| {
                    World::build(scene, None, Some((SIDE, SIDE)), LightSelect::Power).unwrap()
                });
                best = best.min(w.bvh_seconds);
                world = Some(w);
            }
            build[i] = best;
        }
        let world = world.unwrap();
        let triangles = world.primitive_count();
        let peak = peak_memory_bytes().unwrap_or(0);
        memory += &format!(
            "- {name}: {triangles} triangles, BVH {} bytes ({:.1} per triangle; nodes and primitives of both levels), process peak {:.0} MB ({} bytes per triangle above the {} MB before loading)\n",
            world.bvh_bytes(),
            world.bvh_bytes() as f64 / triangles.max(1) as f64,
            peak as f64 / 1e6,
            peak.saturating_sub(rss_before) / triangles.max(1) as u64,
            rss_before / 1_000_000
        );
        let m_tri = triangles as f64 / 1e6;
        let sets = ray_sets(&world);
        let closest = |rays: &[Ray]| rays.iter().filter(|r| world.intersect(r).is_some()).count();
        let shadow = |rays: &[Ray]| rays.iter().filter(|r| world.occluded(r)).count();
        // The packet kernel's queries: eight rays at a time, consecutive rays of a set.
        let closest_packets = |rays: &[Ray]| world.count_hits_in_packets(rays, false).unwrap();
        let shadow_packets = |rays: &[Ray]| world.count_hits_in_packets(rays, true).unwrap();
        let packets = world.count_hits_in_packets(&[], false).is_some();
        let mut kinds = vec![
            ("coherent", &sets.coherent, &sets.shadow_coherent, false),
            (
                "incoherent",
                &sets.incoherent,
                &sets.shadow_incoherent,
                false,
            ),
        ];
        if packets {
            kinds.push((
                "coherent, packets of 8",
                &sets.coherent,
                &sets.shadow_coherent,
                true,
            ));
            kinds.push((
                "incoherent, packets of 8",
                &sets.incoherent,
                &sets.shadow_incoherent,
                true,
            ));
        }
        for (kind, primary, secondary, in_packets) in kinds {
            type Trace<'a> = &'a (dyn Fn(&[Ray]) -> usize + Sync);
            let (closest, shadow): (Trace, Trace) = if in_packets {
                (&closest_packets, &shadow_packets)
            } else {
                (&closest, &shadow)
            };
            let c = [1, 2].map(|t| rays_per_second(primary, t, closest) / 1e6);
            let s = [1, 2].map(|t| rays_per_second(secondary, t, shadow) / 1e6);
            let line = format!(
                "| {name} | {triangles} | {:.3} | {:.3} | {kind} | {:.2} | {:.2} | {:.2} | {:.2} |\n",
                build[0] / m_tri,
                build[1] / m_tri,
                c[0],
                c[1],
                s[0],
                s[1]
            );
            eprint!("{line}");
            report += &line;
        }
    }
    let text = format!("{report}\nMemory:\n{memory}");
    println!("{text}");
    if let Some(out) = out {
        std::fs::write(&out, text).expect("report written");
    }
}
