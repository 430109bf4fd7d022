//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod chi2;
pub mod cli;
pub mod gltf_builder;
pub mod scenes;

/// `copies` copies of `good`, each with 4 bytes changed at places drawn from a fixed
/// xorshift sequence: damaged files for readers that must refuse them cleanly.
pub fn damaged_copies(good: &[u8], copies: usize) -> Vec<Vec<u8>> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    (0..copies)
        .map(|_| {
            let mut bad = good.to_vec();
            for _ in 0..4 {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let at = (state % bad.len() as u64) as usize;
                bad[at] ^= (state >> 32) as u8 | 1;
            }
            bad
        })
        .collect()
}
