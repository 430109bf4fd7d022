//! Mitsuba's binary volume format (`.vol`, version 3, dense float32), for density grids.
//!
//! The layout (Mitsuba 3's `gridvolume` documentation): the bytes `VOL` and the version 3;
//! then little-endian: the encoding (1: dense float32), the resolution in x, y and z and the
//! number of channels (32-bit integers), the bounding box (minimum x, y, z, maximum x, y, z
//! as 32-bit floats) and the values, x fastest, then y, then z, channels interleaved. The
//! bounding box places the grid in the scene ([`crate::scene::grid`] gives the convention).
//! A density grid has one channel. The header is checked against the file's length before
//! anything is allocated, so a corrupt header cannot ask for gigabytes.

use crate::scene::DensityGrid;
use glam::{DMat4, DVec3};

const HEADER: usize = 48;

/// Reads the density grid of a `.vol` file's `bytes` (`source` names it in the grid);
/// errors are reasons for the user.
pub fn parse(bytes: &[u8], source: &str) -> Result<DensityGrid, String> {
    if bytes.len() < HEADER {
        return Err(format!(
            "{} bytes are too short for a volume file's 48-byte header",
            bytes.len()
        ));
    }
    if &bytes[..3] != b"VOL" {
        return Err("not a Mitsuba volume file (it does not start with VOL)".into());
    }
    if bytes[3] != 3 {
        return Err(format!(
            "volume file version {} (lucerna reads version 3)",
            bytes[3]
        ));
    }
    let int = |at: usize| i32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    let float = |at: usize| f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    let encoding = int(4);
    if encoding != 1 {
        return Err(format!(
            "encoding {encoding} (lucerna reads 1, dense 32-bit floats)"
        ));
    }
    let dims = [int(8), int(12), int(16)];
    if dims.iter().any(|&d| d <= 0) {
        return Err(format!("resolution {dims:?} must be positive"));
    }
    let channels = int(20);
    if channels != 1 {
        return Err(format!("{channels} channels (a density grid has one)"));
    }
    let resolution = dims.map(|d| d as u32);
    let expected = DensityGrid::voxel_count(resolution)
        .and_then(|n| n.checked_mul(4))
        .and_then(|n| n.checked_add(HEADER));
    if expected != Some(bytes.len()) {
        return Err(format!(
            "a grid of {}x{}x{} needs {} bytes, the file has {}",
            dims[0],
            dims[1],
            dims[2],
            expected.map_or("more than addressable".into(), |n| n.to_string()),
            bytes.len()
        ));
    }
    let lo = DVec3::new(float(24) as f64, float(28) as f64, float(32) as f64);
    let hi = DVec3::new(float(36) as f64, float(40) as f64, float(44) as f64);
    if !(lo.is_finite() && hi.is_finite() && hi.cmpgt(lo).all()) {
        return Err(format!("bounding box {lo} to {hi} is empty or not finite"));
    }
    let values: Vec<f32> = bytes[HEADER..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let grid = DensityGrid {
        source: source.into(),
        resolution,
        to_world: DMat4::from_translation(lo) * DMat4::from_scale(hi - lo),
        values: values.into(),
    };
    match grid.defect() {
        Some(reason) => Err(reason),
        None => Ok(grid),
    }
}

/// The bytes of a `.vol` file holding `values` (x fastest) of `resolution` in the box from
/// `lo` to `hi`: what tests and tools write.
pub fn encode(resolution: [u32; 3], lo: [f32; 3], hi: [f32; 3], values: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER + values.len() * 4);
    out.extend_from_slice(b"VOL\x03");
    out.extend_from_slice(&1i32.to_le_bytes());
    for r in resolution {
        out.extend_from_slice(&(r as i32).to_le_bytes());
    }
    out.extend_from_slice(&1i32.to_le_bytes());
    for v in lo.iter().chain(&hi).chain(values) {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp() -> Vec<u8> {
        let values: Vec<f32> = (0..24).map(|i| i as f32).collect();
        encode([2, 3, 4], [-1.0, 0.0, 0.0], [1.0, 3.0, 8.0], &values)
    }

    #[test]
    fn reads_the_values_and_places_the_box() {
        let grid = parse(&ramp(), "ramp.vol").unwrap();
        assert_eq!(grid.resolution, [2, 3, 4]);
        assert_eq!(grid.values[23], 23.0);
        let corner = grid.to_world.transform_point3(DVec3::ONE);
        assert_eq!(corner, DVec3::new(1.0, 3.0, 8.0));
        assert_eq!(
            grid.to_world.transform_point3(DVec3::ZERO),
            DVec3::new(-1.0, 0.0, 0.0)
        );
    }

    #[test]
    fn refuses_bad_files_with_a_reason() {
        let good = ramp();
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (good[..40].to_vec(), "too short"),
            (
                good[..good.len() - 4].to_vec(),
                "needs 144 bytes, the file has 140",
            ),
            (
                [b"VOX".as_slice(), &good[3..]].concat(),
                "does not start with VOL",
            ),
            (
                {
                    let mut b = good.clone();
                    b[3] = 2;
                    b
                },
                "version 2",
            ),
            (
                {
                    let mut b = good.clone();
                    b[4] = 2;
                    b
                },
                "encoding 2",
            ),
            (
                {
                    let mut b = good.clone();
                    b[20] = 3;
                    b
                },
                "3 channels",
            ),
            (
                {
                    let mut b = good.clone();
                    b[8..12].copy_from_slice(&(-2i32).to_le_bytes());
                    b
                },
                "must be positive",
            ),
            (
                {
                    // A header asking for 2^31 cubed voxels allocates nothing.
                    let mut b = good.clone();
                    for at in [8, 12, 16] {
                        b[at..at + 4].copy_from_slice(&i32::MAX.to_le_bytes());
                    }
                    b
                },
                "the file has 144",
            ),
            (
                {
                    let mut b = good.clone();
                    b[36..40].copy_from_slice(&(-5.0f32).to_le_bytes());
                    b
                },
                "is empty or not finite",
            ),
            (
                {
                    let mut b = good.clone();
                    b[48 + 4 * 7..48 + 4 * 8].copy_from_slice(&f32::NAN.to_le_bytes());
                    b
                },
                "voxel (1, 0, 1) has density NaN",
            ),
            (
                {
                    let mut b = good.clone();
                    b[48..52].copy_from_slice(&(-1.0f32).to_le_bytes());
                    b
                },
                "voxel (0, 0, 0) has density -1",
            ),
        ];
        for (bytes, reason) in cases {
            let err = parse(&bytes, "x.vol").unwrap_err();
            assert!(err.contains(reason), "{err:?} should say {reason:?}");
        }
    }
}
