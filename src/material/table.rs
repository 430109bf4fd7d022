//! Reading the tabulated albedos (`sheen_albedo`, `microfacet_albedo`): tables of evenly
//! spaced samples over [0, max] on each axis, read with linear interpolation, inputs outside
//! an axis (and NaN) clamped onto it.

/// The cell of an axis of `n` evenly spaced samples over [0, `max`] that `x` falls in, and
/// the position in it.
#[inline]
#[allow(clippy::manual_clamp)] // max then min maps NaN to 0; clamp would keep it.
pub(super) fn cell(x: f32, n: usize, max: f32) -> (usize, f32) {
    let s = (x / max).max(0.0).min(1.0) * (n - 1) as f32;
    let i = (s as usize).min(n - 2);
    (i, s - i as f32)
}

/// A table over [0, 1]² (rows: `row`, columns: `column`) read at (`row`, `column`).
#[inline]
pub(super) fn bilinear<const N: usize>(table: &[[f32; N]; N], row: f32, column: f32) -> f32 {
    let (i, fi) = cell(row, N, 1.0);
    let (j, fj) = cell(column, N, 1.0);
    let at = |k: usize| table[k][j] + (table[k][j + 1] - table[k][j]) * fj;
    at(i) + (at(i + 1) - at(i)) * fi
}

/// A table over [0, 1] read at `x`.
#[inline]
pub(super) fn linear<const N: usize>(table: &[f32; N], x: f32) -> f32 {
    let (i, f) = cell(x, N, 1.0);
    table[i] + (table[i + 1] - table[i]) * f
}
