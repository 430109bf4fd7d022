//! Multiple importance sampling heuristics (Veach & Guibas 1995) for two techniques: light
//! sampling (NEE) and BSDF sampling. Densities passed in already include sample counts
//! (n_t · p_t) and are in the same measure (solid angle).

/// How the two techniques' estimates are weighted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mis {
    /// w_t = p_t / Σ p_k.
    Balance,
    /// w_t = p_t^β / Σ p_k^β.
    Power(f32),
    /// w_t = 1 for the technique with the largest density (ties go to light sampling).
    Maximum,
    /// Balance among the techniques with p_k ≥ α · max p, the others 0.
    Cutoff(f32),
    /// Light sampling alone, except where it cannot sample (delta BSDF lobes).
    NeeOnly,
    /// BSDF sampling alone, except where it cannot sample (delta lights).
    BsdfOnly,
}

/// Which technique a weight is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Technique {
    Nee,
    Bsdf,
}

impl Mis {
    /// Weight of a sample of `technique` with density `own`, the other technique having
    /// density `other` for the same direction. The two weights of a direction sum to 1
    /// wherever either density is positive, which keeps the combination unbiased.
    #[inline]
    pub fn weight(&self, technique: Technique, own: f32, other: f32) -> f32 {
        if !(own > 0.0) {
            return 0.0;
        }
        if !(other > 0.0) {
            return 1.0;
        }
        match *self {
            Self::Balance => own / (own + other),
            Self::Power(beta) => {
                let q = other / own;
                // β = 2, the default, without the cost of powf.
                let r = if beta == 2.0 { q * q } else { q.powf(beta) };
                1.0 / (1.0 + r)
            }
            Self::Maximum => {
                let wins = match technique {
                    Technique::Nee => own >= other,
                    Technique::Bsdf => own > other,
                };
                if wins { 1.0 } else { 0.0 }
            }
            Self::Cutoff(alpha) => {
                let max = own.max(other);
                if own < alpha * max {
                    0.0
                } else if other < alpha * max {
                    1.0
                } else {
                    own / (own + other)
                }
            }
            Self::NeeOnly => match technique {
                Technique::Nee => 1.0,
                Technique::Bsdf => 0.0,
            },
            Self::BsdfOnly => match technique {
                Technique::Nee => 0.0,
                Technique::Bsdf => 1.0,
            },
        }
    }

    /// Parses `balance`, `power[:β]`, `maximum`, `cutoff[:α]`, `nee-only` or `bsdf-only`.
    pub fn parse(s: &str) -> Result<Self, String> {
        let (name, param) = super::parameter::name_and_parameter(s)?;
        let positive = |v: f32| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(format!("parameter of {s:?} must be positive"))
            }
        };
        match (name, param) {
            ("balance", None) => Ok(Self::Balance),
            ("power", p) => Ok(Self::Power(positive(p.unwrap_or(2.0))?)),
            ("maximum", None) => Ok(Self::Maximum),
            ("cutoff", p) => {
                let a = p.unwrap_or(0.1);
                if (0.0..=1.0).contains(&a) {
                    Ok(Self::Cutoff(a))
                } else {
                    Err(format!("cutoff α must be in [0, 1], got {a}"))
                }
            }
            ("nee-only", None) => Ok(Self::NeeOnly),
            ("bsdf-only", None) => Ok(Self::BsdfOnly),
            _ => Err(format!(
                "unknown MIS heuristic {s:?} (balance, power[:β], maximum, cutoff[:α], nee-only, bsdf-only)"
            )),
        }
    }

    /// The textual form [`Mis::parse`] reads.
    pub fn describe(&self) -> String {
        match self {
            Self::Balance => "balance".into(),
            Self::Power(b) => format!("power:{b}"),
            Self::Maximum => "maximum".into(),
            Self::Cutoff(a) => format!("cutoff:{a}"),
            Self::NeeOnly => "nee-only".into(),
            Self::BsdfOnly => "bsdf-only".into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::pcg::Pcg32;

    #[test]
    fn weights_of_a_direction_sum_to_one() {
        let all = [
            Mis::Balance,
            Mis::Power(2.0),
            Mis::Power(3.5),
            Mis::Maximum,
            Mis::Cutoff(0.1),
            Mis::NeeOnly,
            Mis::BsdfOnly,
        ];
        let mut rng = Pcg32::new(5, 6);
        for _ in 0..10_000 {
            let mut draw = || {
                let x = rng.next_f32();
                if x < 0.1 {
                    0.0
                } else {
                    (x * 40.0 - 20.0).exp()
                }
            };
            let (p, q) = (draw(), draw());
            if p == 0.0 && q == 0.0 {
                continue;
            }
            for h in all {
                let s = h.weight(Technique::Nee, p, q) + h.weight(Technique::Bsdf, q, p);
                assert!((s - 1.0).abs() < 1e-5, "{h:?} p={p} q={q} sum={s}");
            }
        }
    }
}
