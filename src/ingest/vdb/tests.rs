//! The reader against files written here (every storage of value arrays) and damaged ones.

use super::*;
use glam::{DVec3, Vec4Swizzles};

/// A VDB file of one grid (0.1 world units a voxel) whose leaves sit in the first 16³
/// node at `leaves` (entry, values, active mask), stored as `compression` says with
/// values of `size` bytes; `raw_in_zip` stores zip-flagged arrays uncompressed (a
/// negative size), as OpenVDB does where zlib does not shrink them.
fn write(
    leaves: &[(usize, Vec<f32>, [u64; 8])],
    compression: u32,
    size: usize,
    raw_in_zip: bool,
) -> Vec<u8> {
    write_with(leaves, compression, size, raw_in_zip, &[])
}

/// [`write`] with active root tiles (origin, value) of 4096³ voxels beside the child.
fn write_with(
    leaves: &[(usize, Vec<f32>, [u64; 8])],
    compression: u32,
    size: usize,
    raw_in_zip: bool,
    tiles: &[([i32; 3], f32)],
) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    let u32s = |out: &mut Vec<u8>, v: &[u32]| v.iter().for_each(|v| out.extend(v.to_le_bytes()));
    let string = |out: &mut Vec<u8>, s: &str| {
        out.extend((s.len() as u32).to_le_bytes());
        out.extend(s.as_bytes());
    };
    u32s(&mut out, &[224, 10, 0]);
    out.push(1);
    out.extend([b'0'; 36]);
    u32s(&mut out, &[0, 1]);
    string(&mut out, "density");
    string(
        &mut out,
        if size == 8 {
            "Tree_double_5_4_3"
        } else {
            "Tree_float_5_4_3"
        },
    );
    string(&mut out, "");
    let offsets = out.len();
    out.extend([0u8; 24]);
    let start = out.len();
    u32s(&mut out, &[compression, 1]);
    string(&mut out, "class");
    string(&mut out, "string");
    string(&mut out, "fog volume");
    string(&mut out, "UniformScaleMap");
    for v in [0.1, 0.1, 0.1].into_iter().chain([0.0; 12]) {
        out.extend(f64::to_le_bytes(v));
    }
    let value = |out: &mut Vec<u8>, v: f32| match size {
        8 => out.extend((v as f64).to_le_bytes()),
        _ => out.extend(v.to_le_bytes()),
    };
    let array = |out: &mut Vec<u8>, values: &[f32], mask: &[u64]| {
        let masked = compression & ACTIVE_MASK != 0;
        out.push(if masked { 0 } else { 6 });
        let mut raw = Vec::new();
        for (i, &v) in values.iter().enumerate() {
            if !masked || bit(mask, i) {
                value(&mut raw, v);
            }
        }
        if compression & ZIP == 0 {
            out.extend(raw);
        } else if raw_in_zip {
            out.extend((-(raw.len() as i64)).to_le_bytes());
            out.extend(raw);
        } else {
            let packed = miniz_oxide::deflate::compress_to_vec_zlib(&raw, 6);
            out.extend((packed.len() as i64).to_le_bytes());
            out.extend(packed);
        }
    };
    let masks =
        |out: &mut Vec<u8>, words: &[u64]| words.iter().for_each(|w| out.extend(w.to_le_bytes()));
    u32s(&mut out, &[1]);
    value(&mut out, 0.0);
    u32s(&mut out, &[tiles.len() as u32, 1]);
    for (origin, v) in tiles {
        origin.iter().for_each(|c| out.extend(c.to_le_bytes()));
        value(&mut out, *v);
        out.push(1);
    }
    u32s(&mut out, &[0, 0, 0]); // one child at the origin
    let mut upper = vec![0u64; 512];
    upper[0] = 1;
    masks(&mut out, &upper);
    masks(&mut out, &[0; 512]);
    array(&mut out, &[0.0; 32768], &[0; 512]);
    let mut lower = vec![0u64; 64];
    for (i, _, _) in leaves {
        lower[i / 64] |= 1 << (i % 64);
    }
    masks(&mut out, &lower);
    masks(&mut out, &[0; 64]);
    array(&mut out, &[0.0; 4096], &[0; 64]);
    let mut sorted: Vec<_> = leaves.iter().collect();
    sorted.sort_by_key(|(i, _, _)| *i);
    for (_, _, mask) in &sorted {
        masks(&mut out, mask);
    }
    for (_, values, mask) in &sorted {
        masks(&mut out, mask);
        array(&mut out, values, mask);
    }
    let end = out.len() as i64;
    for (k, v) in [start as i64, 0, end].into_iter().enumerate() {
        out[offsets + 8 * k..offsets + 8 * k + 8].copy_from_slice(&v.to_le_bytes());
    }
    out
}

fn leaves() -> Vec<(usize, Vec<f32>, [u64; 8])> {
    let mut state = 17u32;
    let mut next = move || {
        state = state.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
        state >> 8
    };
    [3usize, 70, 1000]
        .iter()
        .map(|&entry| {
            let mut mask = [0u64; 8];
            let mut values = vec![0.0; 512];
            for (i, v) in values.iter_mut().enumerate() {
                if next() % 3 != 0 {
                    mask[i / 64] |= 1 << (i % 64);
                    *v = (next() % 1000) as f32 / 250.0;
                }
            }
            (entry, values, mask)
        })
        .collect()
}

/// Every active voxel of `leaves` is where the grid's transform puts its index point,
/// with its value; the rest of the grid is empty.
fn check(grid: &DensityGrid, leaves: &[(usize, Vec<f32>, [u64; 8])], tolerance: f32) {
    let inverse = grid.to_world.inverse();
    let n = DVec3::from_array(grid.resolution.map(f64::from));
    let mut total = 0.0;
    for (entry, values, mask) in leaves {
        let origin = local(*entry, LOG2_LOWER) << LOG2_LEAF;
        for i in (0..512).filter(|&i| bit(mask, i)) {
            let world = (origin + local(i, LOG2_LEAF)).as_dvec3() * 0.1;
            let v = (inverse * world.extend(1.0)).xyz() * n - 0.5;
            assert!((v - v.round()).abs().max_element() < 1e-9);
            let [x, y, z] = v.round().to_array().map(|c| c as usize);
            let [nx, ny, _] = grid.resolution.map(|r| r as usize);
            let got = grid.values[x + nx * (y + ny * z)];
            assert!(
                (got - values[i]).abs() <= tolerance,
                "{got} against {}",
                values[i]
            );
            total += got as f64;
        }
    }
    let sum: f64 = grid.values.iter().map(|&v| v as f64).sum();
    assert!(
        (sum - total).abs() < 1e-6 * total.max(1.0),
        "{sum} against {total}"
    );
}

#[test]
fn every_storage_of_value_arrays_reads_back() {
    let leaves = leaves();
    for compression in [0, ACTIVE_MASK, ZIP, ZIP | ACTIVE_MASK] {
        for size in [4, 8] {
            for raw_in_zip in [false, true] {
                let bytes = write(&leaves, compression, size, raw_in_zip);
                let read = parse(&bytes, "test.vdb", None)
                    .unwrap_or_else(|r| panic!("{compression} {size}: {r}"));
                check(&read.grid, &leaves, 0.0);
                assert!(read.warnings.is_empty());
            }
        }
    }
}

#[test]
fn a_grid_without_active_voxels_is_empty() {
    let empty = vec![(5, vec![0.0; 512], [0u64; 8])];
    let read = parse(
        &write(&empty, ZIP | ACTIVE_MASK, 4, false),
        "empty.vdb",
        None,
    )
    .unwrap();
    assert_eq!(read.grid.max_density(), 0.0);
    assert!(
        read.warnings[0].contains("no active voxels"),
        "{:?}",
        read.warnings
    );
}

#[test]
fn corrupt_arrays_and_headers_are_errors() {
    let leaves = leaves();
    let good = write(&leaves, ZIP | ACTIVE_MASK, 4, false);
    let mut future = good.clone();
    future[8..12].copy_from_slice(&221u32.to_le_bytes());
    assert!(
        parse(&future, "x", None)
            .unwrap_err()
            .contains("version 221")
    );
    assert!(
        parse(b"VOL\x03", "x", None)
            .unwrap_err()
            .contains("not an OpenVDB file")
    );
    // A node's metadata byte out of range, and zlib data that is not zlib.
    let at = good.len() - 1;
    let mut bad = good.clone();
    bad[at] ^= 0xff;
    assert!(parse(&bad, "x", None).is_err());
    let raw = write(&leaves, ZIP | ACTIVE_MASK, 4, true);
    let mut short = raw.clone();
    short.truncate(raw.len() - 1);
    assert!(
        parse(&short, "x", None)
            .unwrap_err()
            .contains("outside the file")
    );
    // A dense box beyond the memory limit is refused before it is allocated.
    let far = vec![
        (0, vec![1.0; 512], [u64::MAX; 8]),
        (4095, vec![1.0; 512], [u64::MAX; 8]),
    ];
    let far = write(&far, ZIP | ACTIVE_MASK, 4, false);
    assert!(parse_within(&far, "x", None, Some(16 << 20)).is_ok());
    let refused = parse_within(&far, "x", None, Some(1 << 20)).unwrap_err();
    assert!(
        refused.contains("130x130x130 voxels would need") && refused.contains("--max-memory"),
        "{refused}"
    );
}

#[test]
fn non_finite_densities_are_errors_naming_the_voxel() {
    let mut values = vec![0.5; 512];
    values[9] = f32::NAN;
    values[10] = f32::INFINITY;
    let leaves = vec![(0, values, [u64::MAX; 8])];
    for compression in [0, ZIP | ACTIVE_MASK] {
        let err = parse(&write(&leaves, compression, 4, false), "x", None).unwrap_err();
        // Entry 9 of the leaf at the origin: x 0, y 1, z 1 (z fastest).
        assert!(
            err.contains("voxel [0, 1, 1] has value NaN: values must be finite"),
            "{err}"
        );
    }
}

#[test]
fn active_tiles_too_wide_for_a_dense_grid_are_refused_before_allocation() {
    // An active root tile of 4096³ voxels beside leaves at the origin: 1.4e11, beyond any
    // dense grid.
    let bytes = write_with(
        &leaves(),
        ZIP | ACTIVE_MASK,
        4,
        false,
        &[([4096, 0, 0], 0.5)],
    );
    let err = parse_within(&bytes, "x", None, None).unwrap_err();
    assert!(
        err.contains("8194x4098x4098 voxels, more than the 2147483648"),
        "{err}"
    );
}
