//! Stress cases of numerical conditioning (issue 6, first part): the Cornell box far from
//! the origin and at extreme scales must render like the well-conditioned original, with no
//! NaN or Inf reaching a pixel.
//!
//! Render space (`world::RenderSpace`) recentres the scene in double precision and scales it
//! by a power of two, so placing the box 1e7 units away or making it 1e4 times larger only
//! changes float rounding: with the same samples the image is almost the same, and against
//! another seed its error is the original's own noise.

mod common;

use common::scenes::{rel_mse, render};
use glam::{DMat4, DVec3};
use lucerna::film::Film;
use lucerna::ingest;
use lucerna::integrator::Settings;
use lucerna::scene::Scene;

const RESOLUTION: (u32, u32) = (48, 48);
const SPP: u32 = 64;

/// The Cornell box moved by `offset` after scaling it by `scale` about the origin, camera
/// and its distances included.
fn cornell(offset: f64, scale: f64) -> Scene {
    let mut scene = ingest::default_scene().unwrap();
    let m = DMat4::from_translation(DVec3::splat(offset)) * DMat4::from_scale(DVec3::splat(scale));
    for inst in &mut scene.instances {
        inst.transform = m * inst.transform;
    }
    for s in &mut scene.spheres {
        s.centre = m.transform_point3(s.centre);
        s.radius *= scale;
    }
    for c in &mut scene.cameras {
        // The camera keeps its orientation (its frame is re-orthonormalised) and moves with
        // the box; its lengths scale.
        c.transform = m * c.transform;
        c.clip_near *= scale;
        c.clip_far = c.clip_far.map(|f| f * scale);
        c.aperture_radius *= scale;
        c.focus_distance *= scale;
    }
    assert!(
        scene.lights.is_empty(),
        "punctual lights would need their units scaled"
    );
    scene
}

fn render_with_seed(scene: Scene, seed: u32) -> Film {
    let settings = Settings {
        seed,
        ..Settings::default()
    };
    let (film, stats) = render(scene, RESOLUTION, SPP, settings, 2);
    assert_eq!(stats.discarded, 0, "NaN or Inf contributions");
    film
}

#[test]
fn cornell_box_far_away_and_at_extreme_scales_renders_like_the_original() {
    let original = render_with_seed(cornell(0.0, 1.0), 1);
    let other_seed = render_with_seed(cornell(0.0, 1.0), 2);
    let noise = rel_mse(&other_seed, &original);
    for (offset, scale) in [(1e3, 1.0), (1e5, 1.0), (1e7, 1.0), (0.0, 1e-4), (0.0, 1e4)] {
        let case = render_with_seed(cornell(offset, scale), 2);
        for plane in case.planes(lucerna::film::aov::Aov::Beauty) {
            assert!(plane.iter().all(|v| v.is_finite()));
        }
        // Against the original with the other seed: only the original's noise.
        let error = rel_mse(&case, &original);
        // Against the original with the same seed: the same paths up to rounding.
        let same_samples = rel_mse(&case, &other_seed);
        eprintln!(
            "offset {offset:e}, scale {scale:e}: relMSE vs original {error:.3e} (seed-to-seed {noise:.3e}), same seed {same_samples:.3e}"
        );
        assert!(
            error < 1.35 * noise && same_samples < 0.01 * noise,
            "offset {offset:e}, scale {scale:e}: relMSE {error:e} (same seed {same_samples:e}), seed-to-seed noise {noise:e}"
        );
    }
}

/// Every non-emitting triangle of the Cornell box duplicated (coplanar, coincident copies,
/// half of them wound the other way) and a zero-area triangle added at each of its vertices:
/// no light leaks through a double wall, no acne, no NaN, the same image.
#[test]
fn duplicate_and_zero_area_triangles_change_nothing() {
    let mut scene = cornell(0.0, 1.0);
    for mesh in &mut scene.meshes {
        if scene.materials[mesh.material as usize].is_emissive() {
            continue;
        }
        let original = mesh.triangles.clone();
        for (i, t) in original.iter().enumerate() {
            mesh.triangles
                .push(if i % 2 == 0 { *t } else { [t[0], t[2], t[1]] });
            mesh.triangles.push([t[0], t[0], t[1]]);
        }
    }
    let original = render_with_seed(cornell(0.0, 1.0), 1);
    let other_seed = render_with_seed(cornell(0.0, 1.0), 2);
    let noise = rel_mse(&other_seed, &original);
    let case = render_with_seed(scene, 2);
    let error = rel_mse(&case, &original);
    let same_samples = rel_mse(&case, &other_seed);
    eprintln!(
        "duplicates and zero-area triangles: relMSE {error:.3e}, seed-to-seed {noise:.3e}, same seed {same_samples:.3e}"
    );
    // The same samples mostly follow the same paths (a coincident copy with its corners in
    // another order rounds t differently, and a few paths part ways).
    assert!(
        error < 1.35 * noise && same_samples < 0.1 * noise,
        "relMSE {error:e} (same seed {same_samples:e}), seed-to-seed {noise:e}"
    );
}
