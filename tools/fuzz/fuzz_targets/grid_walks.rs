//! What the `density_grid` and `vdb_decode` fuzz targets do with their bytes, shared with
//! the regression test (tests/it/fuzz_regressions.rs): parse them as a Mitsuba `.vol`
//! density grid or an OpenVDB file, build the heterogeneous medium over the grid, and walk
//! rays through it (delta-tracked flights, ratio-tracked transmittance, gathered emission),
//! panicking (a finding) where a walk returns a value that is not finite or is negative.

use glam::{DMat4, Vec3};
use lucerna::medium::grid::{FieldRadiance, GlowField};
use lucerna::medium::{Flight, Heterogeneous};

/// The most bytes a fuzzed VDB file's dense grid may take.
const VDB_LIMIT: u64 = 64 << 20;

/// `Err` with the reader's message where the bytes are refused.
pub fn walk_the_grid(data: &[u8]) -> Result<(), String> {
    walk(&lucerna::ingest::vol::parse(data, "fuzz.vol")?)
}

/// The same for an OpenVDB file: its default grid, then its grid `temperature` if it
/// names one (a second grid read from the same bytes), then its default colour grid (a
/// vector grid read component by component) tinting the default grid's scattering.
pub fn walk_the_vdb(data: &[u8]) -> Result<(), String> {
    let read = lucerna::ingest::vdb::parse_within(data, "fuzz.vdb", None, Some(VDB_LIMIT));
    if let Ok(read) = &read {
        walk(&read.grid)?;
    }
    if let Ok(other) =
        lucerna::ingest::vdb::parse_within(data, "fuzz.vdb", Some("temperature"), Some(VDB_LIMIT))
    {
        walk(&other.grid)?;
    }
    let colour = lucerna::ingest::vdb::parse_color_within(data, "fuzz.vdb", None, Some(VDB_LIMIT));
    if let Ok(colour) = &colour {
        let [r, g, b] = &colour.channels;
        let density = read.as_ref().map_or(r, |read| &read.grid);
        let coefficients = [
            Vec3::new(0.5, 1.0, 2.0),
            Vec3::new(3.0, 1.0, 0.2),
            Vec3::ZERO,
        ];
        if let Some(medium) = Heterogeneous::new(
            density,
            coefficients,
            0.3,
            DMat4::IDENTITY,
            None,
            Some([r, g, b]),
        ) {
            walk_the_medium(density, &medium);
        }
    }
    match (read, colour) {
        (Err(reason), Err(_)) => Err(reason),
        _ => Ok(()),
    }
}

fn walk(grid: &lucerna::scene::DensityGrid) -> Result<(), String> {
    // Coefficients as a glTF medium gives them: absorbing, scattering, chromatic, emitting.
    let coefficients = [
        Vec3::new(0.5, 1.0, 2.0),
        Vec3::new(3.0, 1.0, 0.2),
        Vec3::new(1.0, 0.5, 0.1),
    ];
    // The grid glows by its own values too: as a temperature grid as hot as a scene allows,
    // and as an emission grid.
    let blackbody = FieldRadiance::Blackbody {
        kelvin_per_unit: (1e6 / grid.max_density().max(1.0)).min(3000.0),
        scale: Vec3::ONE,
    };
    let linear = FieldRadiance::Linear {
        scale: Vec3::new(2.0, 1.0, 0.5),
    };
    for radiance in [blackbody, linear] {
        let glow = GlowField { grid, radiance };
        if let Some(medium) =
            Heterogeneous::new(grid, coefficients, 0.3, DMat4::IDENTITY, Some(glow), None)
        {
            walk_the_medium(grid, &medium);
        }
    }
    Ok(())
}

/// Rays through `medium` (over `grid`), panicking where a walk's value is not finite or is
/// negative.
fn walk_the_medium(grid: &lucerna::scene::DensityGrid, medium: &Heterogeneous) {
    // Rays from outside the grid's box through its centre, and one starting inside it.
    let (lo, hi) = (
        grid.to_world.transform_point3(glam::DVec3::ZERO).as_vec3(),
        grid.to_world.transform_point3(glam::DVec3::ONE).as_vec3(),
    );
    let centre = lo * 0.5 + hi * 0.5;
    // The box's diagonal in f64 (it may overflow f32), kept finite.
    let reach = ((hi - lo).as_dvec3().length() as f32).clamp(1e-3, 1e30);
    for (k, dir) in [
        Vec3::X,
        Vec3::new(1.0, 0.7, 0.3),
        Vec3::new(-0.2, 1.0, -0.9),
    ]
    .into_iter()
    .enumerate()
    {
        let dir = dir.normalize();
        let origin = if k == 2 { centre } else { centre - dir * reach };
        for length in [f32::INFINITY, reach] {
            let through = medium.transmittance(origin, dir, length);
            assert!(
                through.is_finite() && through.min_element() >= 0.0,
                "{through}"
            );
            let emitted = medium.emitted(origin, dir, length);
            assert!(
                emitted.is_finite() && emitted.min_element() >= 0.0,
                "{emitted}"
            );
            for channel in 0..3 {
                let (flight, ratios) = medium.sample_flight(origin, dir, 0.37, length, channel);
                assert!(
                    ratios.is_finite() && ratios.min_element() >= 0.0,
                    "{ratios}"
                );
                let weight = match flight {
                    Flight::Scatter { t, weight } => {
                        assert!(t >= 0.0 && t <= length, "{t}");
                        weight
                    }
                    Flight::Pass { weight } => weight,
                };
                assert!(
                    weight.is_finite() && weight.min_element() >= 0.0,
                    "{weight}"
                );
            }
        }
    }
}
