//! Density grids (Mitsuba `.vol` files, `ingest::vol`) and the heterogeneous medium built
//! over them: any bytes must parse or give an error, never panic, hang or exhaust memory;
//! what parses must give a medium whose walks (delta-tracked flights, ratio-tracked
//! transmittance, gathered emission) end and return finite, non-negative values along any
//! ray, whatever the densities (zero everywhere, one voxel near f32::MAX among thin ones).
#![no_main]

mod grid_walks;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = grid_walks::walk_the_grid(data);
});
