//! OpenVDB files read as density grids: against what OpenVDB itself reads from the same
//! files (tests/assets/vdb/expected.json, written by tools/generate/vdb_assets.py with
//! OpenVDB 10), against the `.vol` file of the same plume, and against damaged files.

use glam::{DVec3, Vec4Swizzles};
use lucerna::ingest::{vdb, vol};
use lucerna::scene::DensityGrid;
use serde_json::Value;
use std::path::{Path, PathBuf};

fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/assets/vdb")
}

fn read(file: &str, grid: Option<&str>) -> Result<vdb::VdbGrid, String> {
    let bytes = std::fs::read(assets().join(file)).unwrap();
    vdb::parse(&bytes, file, grid)
}

/// The voxel of `grid` whose centre is at `world` (which must be one), and its value.
fn voxel_at(grid: &DensityGrid, world: DVec3) -> ([i64; 3], f32) {
    let unit = grid.to_world.inverse() * world.extend(1.0);
    let n = DVec3::from_array(grid.resolution.map(f64::from));
    let v = unit.xyz() * n - 0.5;
    assert!(
        (v - v.round()).abs().max_element() < 1e-4,
        "{world} is not a voxel centre of {} ({v})",
        grid.source
    );
    let [x, y, z] = v.round().to_array().map(|c| c as i64);
    let [nx, ny, nz] = grid.resolution.map(i64::from);
    assert!((0..nx).contains(&x) && (0..ny).contains(&y) && (0..nz).contains(&z));
    ([x, y, z], grid.values[(x + nx * (y + ny * z)) as usize])
}

#[test]
fn grids_read_as_openvdb_reads_them() {
    let expected: Value =
        serde_json::from_str(&std::fs::read_to_string(assets().join("expected.json")).unwrap())
            .unwrap();
    let mut checked = 0;
    for (file, grids) in expected.as_object().unwrap() {
        for (name, e) in grids.as_object().unwrap() {
            if e.get("active_sum").is_none() {
                continue; // a vector grid: vector_grids_read_as_colours
            }
            let read = read(file, Some(name)).unwrap_or_else(|r| panic!("{file}[{name}]: {r}"));
            let grid = &read.grid;
            assert_eq!(grid.source, format!("{file}[{name}]"));
            // The dense grid spans the active voxels' box and a voxel of background around it.
            let [lo, hi]: [Vec<i64>; 2] = serde_json::from_value(e["active_box"].clone()).unwrap();
            let dims: Vec<u32> = (0..3).map(|a| (hi[a] - lo[a] + 3) as u32).collect();
            assert_eq!(grid.resolution.to_vec(), dims, "{file}[{name}]");
            for probe in e["probes"].as_array().unwrap() {
                let world: [f64; 3] = serde_json::from_value(probe["world"].clone()).unwrap();
                let index: [i64; 3] = serde_json::from_value(probe["index"].clone()).unwrap();
                let want = probe["value"].as_f64().unwrap() as f32;
                let inside = (0..3).all(|a| index[a] >= lo[a] - 1 && index[a] <= hi[a] + 1);
                if inside {
                    let (voxel, value) = voxel_at(grid, DVec3::from_array(world));
                    assert_eq!(voxel.map(|v| v - 1), [0, 1, 2].map(|a| index[a] - lo[a]));
                    assert_eq!(value, want.max(0.0), "{file}[{name}] at {index:?}");
                } else {
                    assert_eq!(want, 0.0, "{file}[{name}]: a probe outside holds a value");
                }
            }
            // Negative densities read as zero, so the sum differs by what was clamped.
            let clamped: f64 = if file == "tiles.vdb" { 0.5 } else { 0.0 };
            let sum: f64 = grid.values.iter().map(|&v| v as f64).sum();
            let want = e["active_sum"].as_f64().unwrap() + clamped;
            assert!(
                (sum - want).abs() <= 1e-6 * want,
                "{file}[{name}]: sum {sum} against {want}"
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 7);
}

#[test]
fn negative_densities_are_zero_and_counted() {
    let tiles = read("tiles.vdb", None).unwrap();
    assert_eq!(tiles.warnings.len(), 1, "{:?}", tiles.warnings);
    assert!(tiles.warnings[0].contains("4 voxel(s) with a negative value read as 0"));
    assert!(tiles.grid.values.iter().all(|&v| v >= 0.0));
    assert!(read("plume.vdb", None).unwrap().warnings.is_empty());
}

/// The plume as a VDB file holds the densities of `smoke-plume.vol` at the same places, as
/// 32-bit floats and as halves.
#[test]
fn the_plume_is_the_same_field_as_its_vol_file() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let bytes = std::fs::read(root.join("scenes/media/smoke-plume.vol")).unwrap();
    let reference = vol::parse(&bytes, "smoke-plume.vol").unwrap();
    for (file, round) in [("plume.vdb", false), ("plume-half.vdb", true)] {
        let grid = read(file, None).unwrap().grid;
        let [nx, ny, nz] = reference.resolution.map(|n| n as usize);
        let (mut inside, mut outside) = (0, 0);
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let unit = (DVec3::new(x as f64, y as f64, z as f64) + 0.5)
                        / DVec3::new(nx as f64, ny as f64, nz as f64);
                    let world = (reference.to_world * unit.extend(1.0)).xyz();
                    let want = reference.values[x + nx * (y + ny * z)];
                    let want = match round {
                        true => half::f16::from_f32(want).to_f32(),
                        false => want,
                    };
                    let unit = (grid.to_world.inverse() * world.extend(1.0)).xyz();
                    if unit.cmpge(DVec3::ZERO).all() && unit.cmple(DVec3::ONE).all() {
                        assert_eq!(voxel_at(&grid, world).1, want, "{file} at {x} {y} {z}");
                        inside += 1;
                    } else {
                        assert_eq!(want, 0.0, "{file}: the VDB box leaves out {x} {y} {z}");
                        outside += 1;
                    }
                }
            }
        }
        assert!(inside > 30_000 && outside > 0, "{inside} {outside}");
    }
}

#[test]
fn grids_are_chosen_by_name() {
    assert_eq!(
        read("plume.vdb", None).unwrap().grid.source,
        "plume.vdb[density]"
    );
    let temperature = read("plume.vdb", Some("temperature")).unwrap().grid;
    assert_eq!(temperature.source, "plume.vdb[temperature]");
    assert!(temperature.max_density() > 1000.0);
    let missing = read("plume.vdb", Some("heat")).unwrap_err();
    assert!(
        missing.contains("no grid \"heat\"")
            && missing.contains("density (Tree_float_5_4_3), temperature (Tree_float_5_4_3), velocity (Tree_vec3s_5_4_3)"),
        "{missing}"
    );
    let vector = read("plume.vdb", Some("velocity")).unwrap_err();
    assert!(
        vector.contains("Tree_vec3s_5_4_3: lucerna reads scalar float and double grids"),
        "{vector}"
    );
    let level_set = read("sphere-level-set.vdb", None).unwrap_err();
    assert!(level_set.contains("level set"), "{level_set}");
}

fn read_color(file: &str, grid: Option<&str>) -> Result<vdb::VdbColor, String> {
    let bytes = std::fs::read(assets().join(file)).unwrap();
    vdb::parse_color(&bytes, file, grid)
}

/// A vector grid read as a colour: each channel holds its component where OpenVDB reads
/// it (halves, as Houdini saves `Cd`), on the lattice of its own active box; a scalar grid
/// read as a colour is grey; the default names are `Cd` and `color`.
#[test]
fn vector_grids_read_as_colours() {
    let expected: Value =
        serde_json::from_str(&std::fs::read_to_string(assets().join("expected.json")).unwrap())
            .unwrap();
    let e = &expected["colour.vdb"]["Cd"];
    let colour = read_color("colour.vdb", None).unwrap();
    assert!(colour.warnings.is_empty(), "{:?}", colour.warnings);
    let [lo, hi]: [Vec<i64>; 2] = serde_json::from_value(e["active_box"].clone()).unwrap();
    let dims: Vec<u32> = (0..3).map(|a| (hi[a] - lo[a] + 3) as u32).collect();
    for (c, grid) in colour.channels.iter().enumerate() {
        assert_eq!(
            grid.source,
            format!("colour.vdb[Cd].{}", ["r", "g", "b"][c])
        );
        assert_eq!(grid.resolution.to_vec(), dims);
        assert!(grid.defect().is_none());
        for probe in e["probes"].as_array().unwrap() {
            let world: [f64; 3] = serde_json::from_value(probe["world"].clone()).unwrap();
            let want = probe["value"][c].as_f64().unwrap() as f32;
            let (_, value) = voxel_at(grid, DVec3::from_array(world));
            assert_eq!(value, want, "{} at {world:?}", grid.source);
        }
    }
    // The colour varies by channel, so no component was read in another's place.
    let mean = |g: &DensityGrid| g.values.iter().sum::<f32>() / g.values.len() as f32;
    let [r, g, b] = colour.channels.each_ref().map(mean);
    assert!(r != g && g != b && r != b, "{r} {g} {b}");
    // A scalar grid is grey: its value in every channel.
    let grey = read_color("colour.vdb", Some("density")).unwrap();
    let density = read("colour.vdb", Some("density")).unwrap().grid;
    for channel in &grey.channels {
        assert_eq!(channel.values, density.values);
        assert_eq!(channel.to_world, density.to_world);
    }
    // A colour is not a density.
    let vector = read("colour.vdb", Some("Cd")).unwrap_err();
    assert!(
        vector.contains("Tree_vec3s_5_4_3: lucerna reads scalar float and double grids")
            && vector.contains("only as colours"),
        "{vector}"
    );
    let none = read_color("fire.vdb", None).unwrap_err();
    assert!(
        none.contains("no grid \"Cd\" or \"color\" and more than one grid"),
        "{none}"
    );
}

#[test]
fn damaged_colour_files_are_errors() {
    let bytes = std::fs::read(assets().join("colour.vdb")).unwrap();
    for n in (0..bytes.len()).step_by(211) {
        assert!(
            vdb::parse_color(&bytes[..n], "colour.vdb", None).is_err(),
            "cut at {n}"
        );
    }
    let mut state = 7u64;
    for _ in 0..300 {
        let mut damaged = bytes.clone();
        for _ in 0..4 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            let at = (state >> 33) as usize % damaged.len();
            damaged[at] ^= (state >> 20) as u8 | 1;
        }
        if let Ok(colour) = vdb::parse_color(&damaged, "colour.vdb", None) {
            for grid in &colour.channels {
                assert!(grid.defect().is_none(), "{}", grid.source);
            }
        }
    }
}

/// Every prefix of a file (sampled), and bytes overwritten at fixed random places, give an
/// error or a valid grid: never a panic, a huge allocation or a non-finite density.
#[test]
fn damaged_files_are_errors() {
    for file in ["plume.vdb", "tiles.vdb"] {
        let bytes = std::fs::read(assets().join(file)).unwrap();
        let lengths = (0..600).chain((600..bytes.len()).step_by(97));
        for n in lengths {
            assert!(
                vdb::parse(&bytes[..n], file, None).is_err(),
                "{file} cut at {n}"
            );
        }
        for damaged in crate::common::damaged_copies(&bytes, 400) {
            if let Ok(read) = vdb::parse(&damaged, file, None) {
                assert!(read.grid.defect().is_none());
            }
        }
    }
}
