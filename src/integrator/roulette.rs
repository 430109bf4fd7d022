//! Russian roulette: how paths end beyond the maximum depth, and its textual form.

use super::parameter::name_and_parameter;

/// How paths are terminated beyond the maximum depth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RussianRoulette {
    /// Only the maximum depth ends paths.
    Off,
    /// Continue with a fixed probability p at every bounce.
    Fixed(f32),
    /// Continue with p = min(1, luminance(throughput) / threshold); after
    /// [`ROULETTE_CAP_DEPTH`] bounces p is also capped at [`ROULETTE_CAP`], so that paths in
    /// closed scenes whose albedo is 1 still end (still unbiased).
    Throughput(f32),
    /// Efficiency-aware roulette and splitting (in the spirit of Rath et al. 2022): learned
    /// per-region radiance moments and costs, and per-pixel variances and costs, choose the
    /// survival or splitting factor that maximises efficiency (see `integrator::ears`); the
    /// parameter is the largest splitting factor (default 1: roulette only).
    Efficiency(f32),
}

/// Bounces after which throughput-based roulette caps its survival probability.
pub const ROULETTE_CAP_DEPTH: u32 = 8;
/// The cap on survival probability after [`ROULETTE_CAP_DEPTH`] bounces.
pub const ROULETTE_CAP: f32 = 0.95;

impl RussianRoulette {
    /// Survival probability for a path with throughput luminance `throughput` after
    /// `depth` scattering events (the efficiency mode decides elsewhere; 1 here).
    #[inline]
    pub fn survival(&self, throughput: f32, depth: u32) -> f32 {
        match *self {
            Self::Off | Self::Efficiency(_) => 1.0,
            Self::Fixed(p) => p,
            Self::Throughput(threshold) => {
                let cap = if depth > ROULETTE_CAP_DEPTH {
                    ROULETTE_CAP
                } else {
                    1.0
                };
                (throughput / threshold).min(cap)
            }
        }
    }

    /// Parses `off`, `fixed:P`, `throughput[:THRESHOLD]` or `efficiency[:MAX_SPLIT]`.
    pub fn parse(s: &str) -> Result<Self, String> {
        let (name, param) = name_and_parameter(s)?;
        match (name, param) {
            ("off", None) => Ok(Self::Off),
            ("fixed", Some(p)) if p > 0.0 && p <= 1.0 => Ok(Self::Fixed(p)),
            ("fixed", _) => {
                Err("fixed roulette needs a survival probability in (0, 1], e.g. fixed:0.3".into())
            }
            ("throughput", p) => {
                let t = p.unwrap_or(0.1);
                if t.is_finite() && t > 0.0 {
                    Ok(Self::Throughput(t))
                } else {
                    Err(format!("threshold must be positive, got {t}"))
                }
            }
            ("efficiency", s) => {
                let s = s.unwrap_or(1.0);
                if s.is_finite() && s >= 1.0 {
                    Ok(Self::Efficiency(s))
                } else {
                    Err(format!(
                        "the largest splitting factor must be at least 1, got {s}"
                    ))
                }
            }
            _ => Err(format!(
                "unknown Russian roulette {s:?} (off, fixed:P, throughput[:T], efficiency[:MAX_SPLIT])"
            )),
        }
    }

    /// The textual form [`RussianRoulette::parse`] reads.
    pub fn describe(&self) -> String {
        match self {
            Self::Off => "off".into(),
            Self::Fixed(p) => format!("fixed:{p}"),
            Self::Throughput(t) => format!("throughput:{t}"),
            Self::Efficiency(s) => format!("efficiency:{s}"),
        }
    }
}
