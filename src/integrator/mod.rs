//! The integrator: one path tracer whose techniques are settings (see `../shared/design.md`,
//! "Render settings"), and the records it produces.

pub mod mis;
pub mod path;

use crate::sampling::sampler::SamplerKind;
pub use mis::{Mis, Technique};

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
}

/// Splits a setting value `name[:number]` into its name and optional parameter.
pub(crate) fn name_and_parameter(s: &str) -> Result<(&str, Option<f32>), String> {
    match s.split_once(':') {
        Some((name, p)) => {
            let value = p
                .parse::<f32>()
                .map_err(|_| format!("invalid number in {s:?}"))?;
            Ok((name, Some(value)))
        }
        None => Ok((s, None)),
    }
}

/// Bounces after which throughput-based roulette caps its survival probability.
pub const ROULETTE_CAP_DEPTH: u32 = 8;
/// The cap on survival probability after [`ROULETTE_CAP_DEPTH`] bounces.
pub const ROULETTE_CAP: f32 = 0.95;

impl RussianRoulette {
    /// Survival probability for a path with throughput luminance `throughput` after
    /// `depth` scattering events.
    #[inline]
    pub fn survival(&self, throughput: f32, depth: u32) -> f32 {
        match *self {
            Self::Off => 1.0,
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

    /// Parses `off`, `fixed:P` or `throughput[:THRESHOLD]`.
    pub fn parse(s: &str) -> Result<Self, String> {
        let (name, param) = name_and_parameter(s)?;
        match (name, param) {
            ("off", None) => Ok(Self::Off),
            ("fixed", Some(p)) if p > 0.0 && p <= 1.0 => Ok(Self::Fixed(p)),
            ("fixed", _) => {
                Err("fixed roulette needs a survival probability in (0, 1], e.g. fixed:0.3".into())
            }
            ("throughput", p) => {
                let t = p.unwrap_or(0.01);
                if t.is_finite() && t > 0.0 {
                    Ok(Self::Throughput(t))
                } else {
                    Err(format!("threshold must be positive, got {t}"))
                }
            }
            _ => Err(format!(
                "unknown Russian roulette {s:?} (off, fixed:P, throughput[:T])"
            )),
        }
    }

    /// Name and parameter as written in settings and EXR metadata.
    pub fn describe(&self) -> String {
        match self {
            Self::Off => "off".into(),
            Self::Fixed(p) => format!("fixed({p})"),
            Self::Throughput(t) => format!("throughput({t})"),
        }
    }
}

/// The integrator's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub mis: Mis,
    pub rr: RussianRoulette,
    /// Maximum number of scattering events (1 = direct illumination only); `None` for no
    /// limit.
    pub max_depth: Option<u32>,
    pub sampler: SamplerKind,
    pub seed: u32,
}

impl Default for Settings {
    /// Power heuristic (β = 2), throughput roulette (threshold 0.01), no depth limit,
    /// Owen-scrambled Sobol, seed 0.
    fn default() -> Self {
        Self {
            mis: Mis::Power(2.0),
            rr: RussianRoulette::Throughput(0.01),
            max_depth: None,
            sampler: SamplerKind::Sobol,
            seed: 0,
        }
    }
}

impl Settings {
    /// One line naming every setting, for logs and EXR metadata.
    pub fn describe(&self) -> String {
        format!(
            "mis={} rr={} max-depth={} light-select=power sampler={} seed={}",
            self.mis.describe(),
            self.rr.describe(),
            self.max_depth
                .map_or("unlimited".to_string(), |d| d.to_string()),
            self.sampler.name(),
            self.seed
        )
    }
}
