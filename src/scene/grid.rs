//! Density grids: a medium's density sampled on a regular lattice (smoke, clouds, a plume of
//! steam), which scales its absorption and scattering point by point (`scene::Volume`).
//!
//! The grid fills the unit cube of its own space, which `to_world` places in the scene:
//! voxel (i, j, k) is the value at ((i + ½) / nx, (j + ½) / ny, (k + ½) / nz), values between
//! voxel centres are interpolated trilinearly, clamped to the edge voxels inside the cube,
//! and the density is zero outside it. That is Mitsuba 3's `gridvolume` convention (with
//! `use_grid_bbox`), so the same file renders the same in both.

use glam::DMat4;
use std::sync::Arc;

/// A density grid in the scene.
#[derive(Clone, Debug, PartialEq)]
pub struct DensityGrid {
    /// Where it came from (a file, for messages).
    pub source: String,
    /// Voxels along x, y and z (each at least 1).
    pub resolution: [u32; 3],
    /// The grid's unit cube to world space.
    pub to_world: DMat4,
    /// The densities, x fastest, then y, then z: finite and non-negative.
    pub values: Arc<[f32]>,
}

impl DensityGrid {
    /// The number of voxels of a grid of `resolution`, `None` where it overflows.
    pub fn voxel_count(resolution: [u32; 3]) -> Option<usize> {
        resolution
            .iter()
            .try_fold(1usize, |n, &r| n.checked_mul(r as usize))
    }

    /// Why the grid cannot be rendered (`None` where it can): a resolution that does not
    /// match its values, a value that is negative or not finite, a transform that is not
    /// finite or flattens the cube.
    pub fn defect(&self) -> Option<String> {
        if self.resolution.contains(&0) {
            return Some(format!("resolution {:?} has no voxels", self.resolution));
        }
        if Self::voxel_count(self.resolution) != Some(self.values.len()) {
            return Some(format!(
                "resolution {:?} does not match its {} values",
                self.resolution,
                self.values.len()
            ));
        }
        if let Some(i) = self
            .values
            .iter()
            .position(|v| !(v.is_finite() && *v >= 0.0))
        {
            let [nx, ny, _] = self.resolution.map(|r| r as usize);
            return Some(format!(
                "voxel ({}, {}, {}) has density {}: densities must be finite and non-negative",
                i % nx,
                i / nx % ny,
                i / (nx * ny),
                self.values[i]
            ));
        }
        let det = self.to_world.determinant();
        if !(self.to_world.is_finite() && det.is_normal()) {
            return Some("its transform is not finite or flattens the grid".into());
        }
        None
    }

    /// The largest density.
    pub fn max_density(&self) -> f32 {
        self.values.iter().copied().fold(0.0, f32::max)
    }
}
