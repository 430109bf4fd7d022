//! Motion blur: an instance that moves over the shutter, or a mesh that changes shape over
//! it, is where it is at each camera ray's time. A bar sliding under a box shutter gives
//! the analytic smear, moved as a whole or vertex by vertex, and so does a bar that
//! stretches; a blade that turns matches the average of renders at instants spread over
//! the shutter, turned by its transform or by its vertices; the image does not depend on
//! the thread count.

use crate::common;

use common::scenes::{material, ortho_camera, quad, render, render_aovs, scene};
use glam::{DMat4, DQuat, DVec3, Vec3};
use lucerna::film::Film;
use lucerna::film::aov::{Aov, AovSet};
use lucerna::geometry::deformation::Deformation;
use lucerna::integrator::Settings;
use lucerna::scene::{BsdfModel, Instance, Mesh, Scene, Shutter};

/// Keys of a motion: `at(t)` at `n` evenly spaced times of the shutter.
fn keys(n: usize, at: impl Fn(f64) -> DMat4) -> Vec<DMat4> {
    (0..n).map(|k| at(k as f64 / (n - 1) as f64)).collect()
}

/// A black bar 0.2 wide and taller than the view, its centre sliding from x = −0.5 to
/// x = 0.5 over the shutter, in front of a white sky, seen from +z by an orthographic
/// camera whose view spans x and y in [−1, 1] (on a square image).
fn sliding_bar(moving: bool) -> Scene {
    let bar = |t: f64| {
        DMat4::from_translation(DVec3::new(-0.5 + t, 0.0, 0.0))
            * DMat4::from_scale(DVec3::new(0.1, 2.0, 1.0))
    };
    let mut s = scene(
        vec![(quad(), bar(0.5))],
        material(BsdfModel::Lambert, Vec3::ZERO, 0.0, 1.0),
        Vec3::ONE,
        ortho_camera(DVec3::new(0.0, 0.0, 10.0), 1.0),
    );
    if moving {
        s.instances[0].motion = keys(2, bar);
    }
    s
}

/// The fraction of the shutter during which the bar leaves the sky at x visible: the bar
/// covers x while its centre −0.5 + t lies within 0.1 of x.
fn sky_seen(x: f64) -> f64 {
    let (from, to) = ((x + 0.4).clamp(0.0, 1.0), (x + 0.6).clamp(0.0, 1.0));
    1.0 - (to - from)
}

/// `mesh` deforming over the shutter: its vertices at `keys` evenly spaced times where
/// `at(t)` puts them (normals none), and at the frame's (mid-shutter) where it puts them
/// then.
fn deforming(mesh: Mesh, keys: usize, at: impl Fn(f64) -> DMat4) -> Mesh {
    let place = |t: f64| -> Vec<Vec3> {
        let m = at(t);
        (mesh.positions.iter())
            .map(|p| m.transform_point3(p.as_dvec3()).as_vec3())
            .collect()
    };
    Mesh {
        positions: place(0.5),
        deformation: Some(Deformation {
            positions: (0..keys)
                .map(|k| place(k as f64 / (keys - 1) as f64))
                .collect(),
            normals: None,
        }),
        ..mesh
    }
}

/// [`sliding_bar`] with the bar's vertices moving instead of its instance.
fn deforming_bar() -> Scene {
    let mut s = sliding_bar(false);
    let bar = |t: f64| {
        DMat4::from_translation(DVec3::new(-0.5 + t, 0.0, 0.0))
            * DMat4::from_scale(DVec3::new(0.1, 2.0, 1.0))
    };
    s.meshes[0] = deforming(quad(), 2, bar);
    s.instances[0].transform = DMat4::IDENTITY;
    s
}

/// Each column's mean of the red channel.
fn column_means(film: &Film, width: usize, height: usize) -> Vec<f64> {
    let plane = &film.planes(Aov::Beauty)[0];
    (0..width)
        .map(|x| {
            (0..height)
                .map(|y| plane[y * width + x] as f64)
                .sum::<f64>()
                / height as f64
        })
        .collect()
}

/// Checks that `film` shows the bar's analytic smear: in each column, the sky shows for the
/// fraction of the shutter (averaged over the column's width) that the bar leaves it. Each
/// camera sample sees the sky or the bar, so a column's mean of N samples has a standard
/// deviation of at most sqrt(p (1 − p) / N); every column lies within 5 of them (plus the
/// float rounding).
fn assert_smear(film: &Film, size: (usize, usize), spp: u32) {
    assert_profile(film, size, spp, sky_seen, 36..=40);
}

/// Checks that each column of `film` shows the sky for the fraction `sky_seen(x)` of the
/// shutter (averaged over the column's width), within 5 standard deviations of a mean of
/// as many samples as the column has (each sees the sky or the black bar), and that
/// `smeared` columns are darkened.
fn assert_profile(
    film: &Film,
    (width, height): (usize, usize),
    spp: u32,
    sky_seen: impl Fn(f64) -> f64,
    smeared: std::ops::RangeInclusive<usize>,
) {
    let measured = column_means(film, width, height);
    let samples = (height as u32 * spp) as f64;
    let mut worst: f64 = 0.0;
    for (x, &m) in measured.iter().enumerate() {
        // The column spans x in [−1 + 2x/W, −1 + 2(x+1)/W].
        let expected = (0..1000)
            .map(|i| sky_seen(-1.0 + 2.0 * (x as f64 + (i as f64 + 0.5) / 1000.0) / width as f64))
            .sum::<f64>()
            / 1000.0;
        let sd = (expected * (1.0 - expected) / samples).sqrt();
        let z = (m - expected).abs() / (sd + 1e-4);
        worst = worst.max(z);
        assert!(
            z < 5.0,
            "column {x}: {m:.4} where the shutter gives {expected:.4} (sd {sd:.4})"
        );
    }
    let darkened = measured.iter().filter(|&&m| m < 0.99).count();
    assert!(smeared.contains(&darkened), "{darkened} columns darkened");
    println!("worst column |z| {worst:.2}");
}

const BAR_IMAGE: (usize, usize) = (64, 64);

/// The sliding bar's smear is the analytic one; frozen, it darkens a few columns only.
#[test]
fn a_sliding_bar_smears_as_the_shutter_integrates() {
    let spp = 16;
    let res = (BAR_IMAGE.0 as u32, BAR_IMAGE.1 as u32);
    let (film, _) = render(sliding_bar(true), res, spp, Settings::default(), 2);
    assert_smear(&film, BAR_IMAGE, spp);
    let (still, _) = render(sliding_bar(false), res, spp, Settings::default(), 2);
    let frozen = column_means(&still, BAR_IMAGE.0, BAR_IMAGE.1)
        .iter()
        .filter(|&&m| m < 0.99)
        .count();
    assert!(frozen <= 8, "{frozen} columns darkened without motion");
}

/// The bar moved vertex by vertex (a deformation of two keys) smears as the moved instance
/// does; a bar whose right edge sweeps from x = 0 to x = 1 while its left edge stays at
/// x = −0.5 leaves the sky at x in [0, 1] visible for the fraction x of the shutter.
#[test]
fn a_deforming_bar_smears_as_the_shutter_integrates() {
    let spp = 16;
    let res = (BAR_IMAGE.0 as u32, BAR_IMAGE.1 as u32);
    let (film, _) = render(deforming_bar(), res, spp, Settings::default(), 2);
    assert_smear(&film, BAR_IMAGE, spp);
    let mut stretching = sliding_bar(false);
    // The quad's right edge (vertices 1 and 2) at x = t, its left edge at x = −0.5; three
    // keys, so the middle one splits the motion into two intervals.
    let mut bar = quad();
    let rest = bar.positions.clone();
    let edges = |t: f64| -> Vec<Vec3> {
        let x = [-0.5, t, t, -0.5];
        (rest.iter().zip(x))
            .map(|(p, x)| Vec3::new(x as f32, 2.0 * p.y, 0.0))
            .collect()
    };
    bar.positions = edges(0.5);
    bar.deformation = Some(Deformation {
        positions: vec![edges(0.0), edges(0.5), edges(1.0)],
        normals: None,
    });
    stretching.meshes[0] = bar;
    stretching.instances[0].transform = DMat4::IDENTITY;
    let (film, _) = render(stretching, res, spp, Settings::default(), 2);
    let sky = |x: f64| {
        if x < -0.5 { 1.0 } else { x.clamp(0.0, 1.0) }
    };
    // Dark from x = −0.5 to 1: 48 columns.
    assert_profile(&film, BAR_IMAGE, spp, sky, 47..=49);
}

/// A camera that pans from x = 0.5 to x = −0.5 over the shutter sees the bar, still at x = 0,
/// slide as the moving bar does before a still camera: the same smear.
#[test]
fn a_panning_camera_smears_a_still_bar_alike() {
    let mut scene = sliding_bar(false);
    scene.instances[0].transform = DMat4::from_scale(DVec3::new(0.1, 2.0, 1.0));
    let at = scene.cameras[0].transform;
    scene.cameras[0].motion = keys(3, |t| {
        DMat4::from_translation(DVec3::new(0.5 - t, 0.0, 0.0)) * at
    });
    let spp = 16;
    let (film, _) = render(
        scene,
        (BAR_IMAGE.0 as u32, BAR_IMAGE.1 as u32),
        spp,
        Settings::default(),
        2,
    );
    assert_smear(&film, BAR_IMAGE, spp);
}

/// A red blade that turns by 120 degrees about a tilted axis while the shutter is open,
/// above a white floor that it shadows from a white sky, seen from above at an angle.
fn turning_blade(motion: Option<usize>, time: f64) -> Scene {
    let axis = DVec3::new(0.3, 1.0, 0.2).normalize();
    let blade = move |t: f64| {
        DMat4::from_translation(DVec3::new(0.0, 0.6, 0.0))
            * DMat4::from_quat(DQuat::from_axis_angle(axis, t * 120f64.to_radians()))
            * DMat4::from_scale(DVec3::new(1.2, 0.4, 1.0))
    };
    let floor =
        DMat4::from_rotation_x(-std::f64::consts::FRAC_PI_2) * DMat4::from_scale(DVec3::splat(3.0));
    let mut s = scene(
        vec![(quad(), floor)],
        material(BsdfModel::Lambert, Vec3::splat(0.8), 0.0, 1.0),
        Vec3::ONE,
        ortho_camera(DVec3::new(1.0, 6.0, 2.0), 1.4),
    );
    s.materials.push(material(
        BsdfModel::Lambert,
        Vec3::new(0.8, 0.05, 0.05),
        0.0,
        1.0,
    ));
    s.meshes.push(lucerna::scene::Mesh {
        material: 1,
        ..quad()
    });
    s.instances.push(Instance {
        name: "blade".into(),
        mesh: 1,
        transform: blade(time),
        motion: motion.map_or_else(Vec::new, |n| keys(n, blade)),
    });
    s
}

/// [`turning_blade`] with the blade's vertices carried by the turn at `keys` times of the
/// shutter and interpolated linearly between them (a deformation), rather than its
/// transform: with `time`, the still blade where the interpolated vertices are then.
fn deforming_blade(keys: usize, time: Option<f64>) -> Scene {
    let mut s = turning_blade(None, 0.5);
    let axis = DVec3::new(0.3, 1.0, 0.2).normalize();
    let blade = move |t: f64| {
        DMat4::from_translation(DVec3::new(0.0, 0.6, 0.0))
            * DMat4::from_quat(DQuat::from_axis_angle(axis, t * 120f64.to_radians()))
            * DMat4::from_scale(DVec3::new(1.2, 0.4, 1.0))
    };
    let mut mesh = deforming(s.meshes[1].clone(), keys, blade);
    if let Some(t) = time {
        let d = mesh.deformation.take().unwrap();
        mesh.positions = (0..mesh.positions.len())
            .map(|v| d.position(v, t as f32))
            .collect();
    }
    s.meshes[1] = mesh;
    s.instances[1].transform = DMat4::IDENTITY;
    s
}

/// Per pixel, the mean and its variance over `films`, each an estimate of the same image.
fn mean_and_variance_of_mean(films: &[Film]) -> (Vec<f64>, Vec<f64>) {
    let n = films.len() as f64;
    let pixels = films[0].planes(Aov::Beauty)[0].len();
    let (mut mean, mut var) = (vec![0.0; 3 * pixels], vec![0.0; 3 * pixels]);
    for c in 0..3 {
        for p in 0..pixels {
            let values: Vec<f64> = films
                .iter()
                .map(|f| f.planes(Aov::Beauty)[c][p] as f64)
                .collect();
            let m = values.iter().sum::<f64>() / n;
            let v = values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0);
            mean[c * pixels + p] = m;
            var[c * pixels + p] = v / n;
        }
    }
    (mean, var)
}

/// The blurred blade is the average of instantaneous renders at 256 times spread over the
/// shutter (one in each 1/256 of it, jittered): both estimate the same image, so the
/// squared differences of the pixels, each over the variance of the difference (measured
/// from independent blurred renders and from the spread of the instants), average to one.
/// Rendering the blade frozen at mid-shutter misses it by far.
#[test]
fn a_turning_blade_is_the_average_of_its_instants() {
    assert_average_of_instants(|t| turning_blade(None, t), || turning_blade(Some(9), 0.5));
}

/// The blade turned by its vertices (nine keys, interpolated linearly) is the average of
/// the instants of the same interpolated vertices, as the transformed blade is of its own.
#[test]
fn a_deforming_blade_is_the_average_of_its_instants() {
    assert_average_of_instants(|t| deforming_blade(9, Some(t)), || deforming_blade(9, None));
}

/// Checks that the blurred renders of `blurred()` estimate the average of renders of
/// `instant(t)` at 256 times spread over the shutter, and that `instant(0.5)` (frozen at
/// mid-shutter) does not.
pub(crate) fn assert_average_of_instants(
    instant: impl Fn(f64) -> Scene,
    blurred: impl Fn() -> Scene,
) {
    let (res, spp) = ((24u32, 24u32), 16u32);
    let settings = |seed: u32| Settings {
        seed,
        ..Settings::default()
    };
    let mut rng = lucerna::sampling::pcg::Pcg32::new(11, 3);
    let instants: Vec<Film> = (0..256)
        .map(|k| {
            let t = (k as f64 + rng.next_f32() as f64) / 256.0;
            render(instant(t), res, 1, settings(1000 + k), 1).0
        })
        .collect();
    let (reference, reference_var) = mean_and_variance_of_mean(&instants);
    let blurred: Vec<Film> = (0..8)
        .map(|seed| render(blurred(), res, spp, settings(seed), 2).0)
        .collect();
    let (blur, blur_var) = mean_and_variance_of_mean(&blurred);
    // Over the pixels where either estimate is noisy (elsewhere both see the same thing at
    // every sample, the sky say, and agree exactly).
    let noisy: Vec<usize> = (0..blur.len())
        .filter(|&i| blur_var[i] + reference_var[i] > 0.0)
        .collect();
    let chi2 = |image: &[f64], var: &[f64]| {
        noisy
            .iter()
            .map(|&i| (image[i] - reference[i]).powi(2) / (var[i] + reference_var[i] + 1e-8))
            .sum::<f64>()
            / noisy.len() as f64
    };
    // Mean of n terms of one degree each; the variances are estimates, so a wider band.
    let band = 8.0 * (2.0 / noisy.len() as f64).sqrt() + 0.15;
    let blurred_chi2 = chi2(&blur, &blur_var);
    let frozen = render(instant(0.5), res, 8 * spp, settings(99), 2).0;
    let planes = frozen.planes(Aov::Beauty);
    let frozen_image: Vec<f64> = (0..3)
        .flat_map(|c| planes[c].iter().map(|&v| v as f64))
        .collect();
    let frozen_chi2 = chi2(&frozen_image, &blur_var);
    println!(
        "mean squared z over {} noisy values: blurred {blurred_chi2:.3}, frozen {frozen_chi2:.3}, band {band:.3}",
        noisy.len()
    );
    assert!(
        (blurred_chi2 - 1.0).abs() < band,
        "blurred against its instants: mean squared z {blurred_chi2:.3}"
    );
    assert!(
        frozen_chi2 - 1.0 > 3.0 * band,
        "frozen at mid-shutter, it should not match: mean squared z {frozen_chi2:.3}"
    );
}

/// A moving scene renders the same with one thread and with two.
#[test]
fn motion_blur_is_identical_with_one_and_two_threads() {
    let one = render(
        turning_blade(Some(9), 0.5),
        (32, 32),
        8,
        Settings::default(),
        1,
    )
    .0;
    let two = render(
        turning_blade(Some(9), 0.5),
        (32, 32),
        8,
        Settings::default(),
        2,
    )
    .0;
    for c in 0..3 {
        assert_eq!(one.planes(Aov::Beauty)[c], two.planes(Aov::Beauty)[c]);
    }
}

/// The motion and velocity layers of the sliding bar rendered at the frame's instant (no
/// blur, a shutter of one frame around it): where the bar covers a pixel throughout, the
/// bar's known motion, 1 unit a frame to the right, which is 32 pixels a frame on the
/// 64-pixel view of 2 units (v 0); the sky has none. A camera panning the other way
/// gives the bar the same motion, and so does moving the bar's vertices; the frame's image
/// is the still bar's.
#[test]
fn motion_vectors_are_the_known_pixel_motion() {
    let aovs = AovSet::parse("motion,velocity").unwrap();
    let res = (BAR_IMAGE.0 as u32, BAR_IMAGE.1 as u32);
    let instant = Shutter {
        open: -0.5,
        close: 0.5,
        blur: false,
    };
    let mut moving_bar = sliding_bar(true);
    moving_bar.shutter = Some(instant);
    let mut panning = sliding_bar(false);
    panning.instances[0].transform = DMat4::from_scale(DVec3::new(0.1, 2.0, 1.0));
    let at = panning.cameras[0].transform;
    panning.cameras[0].motion = keys(2, |t| {
        DMat4::from_translation(DVec3::new(0.5 - t, 0.0, 0.0)) * at
    });
    panning.shutter = Some(instant);
    let mut deformed_bar = deforming_bar();
    deformed_bar.shutter = Some(instant);
    let still = render(sliding_bar(false), res, 4, Settings::default(), 2).0;
    for (name, scene) in [
        ("moving bar", moving_bar),
        ("panning camera", panning),
        ("deforming bar", deformed_bar),
    ] {
        let film = render_aovs(scene, res, 4, Settings::default(), 2, aovs.clone()).0;
        let (motion, velocity) = (film.planes(Aov::Motion), film.planes(Aov::Velocity));
        let width = BAR_IMAGE.0;
        for y in [0, 17, 40, 63] {
            // The bar covers x in [-0.1, 0.1]: columns 29 to 34 whole.
            for x in 29..=34 {
                let i = y * width + x;
                let expected_u = 32.0;
                assert!(
                    (motion[0][i] - expected_u).abs() < 0.01 && motion[1][i].abs() < 0.01,
                    "{name}: pixel ({x}, {y}): motion ({}, {})",
                    motion[0][i],
                    motion[1][i]
                );
                let expected_velocity = if name == "panning camera" { 0.0 } else { 1.0 };
                assert!(
                    (velocity[0][i] - expected_velocity).abs() < 1e-4,
                    "{name}: velocity {}",
                    velocity[0][i]
                );
                assert!(velocity[1][i].abs() < 1e-4 && velocity[2][i].abs() < 1e-4);
            }
            for x in [0, 10, 50, 63] {
                assert_eq!(motion[0][y * width + x], 0.0, "{name}: the sky moved");
            }
        }
        // Without blur the image is the frame's instant: the still bar's.
        let (a, b) = (film.planes(Aov::Beauty), still.planes(Aov::Beauty));
        let differing = a[0]
            .iter()
            .zip(&b[0])
            .filter(|(p, q)| (*p - *q).abs() > 1e-4)
            .count();
        assert_eq!(
            differing, 0,
            "{name}: {differing} pixels differ from the still bar"
        );
    }
}
