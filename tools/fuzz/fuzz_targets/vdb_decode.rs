//! OpenVDB files (`ingest::vdb`): any bytes must parse or give an error, never panic, hang
//! or allocate beyond the dense grid's limit; what parses must give a medium whose walks end
//! and return finite, non-negative values along any ray (`grid_walks`).
#![no_main]

mod grid_walks;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = grid_walks::walk_the_vdb(data);
});
