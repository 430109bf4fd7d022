//! The integrator's settings: every sampling technique of the path tracer as data (MIS
//! heuristic, Russian roulette, depth, light selection and sampling, splitting, sampler,
//! seed).
//!
//! Each setting has one textual form (`name[:parameter]`), used on the command line, in
//! TOML settings files and in the EXR header, so a render can be reproduced from its file.

use super::guiding::GuidingMode;
use super::mis::Mis;
use super::roulette::RussianRoulette;
use crate::light::sample::LightSampling;
use crate::light::selection::LightSelect;
use crate::sampling::sampler::SamplerKind;

/// Shadow rays and BSDF samples at the first vertex seen from the camera.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Split {
    pub nee: u32,
    pub bsdf: u32,
}

/// How the first vertex splits: counts given, or learned from the first samples of every
/// pixel (see `integrator::split`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SplitChoice {
    Fixed(Split),
    Auto,
}

impl SplitChoice {
    /// Parses `auto` or `nee=N,bsdf=M`.
    pub fn parse(s: &str) -> Result<Self, String> {
        if s.trim() == "auto" {
            Ok(Self::Auto)
        } else {
            Split::parse(s).map(Self::Fixed)
        }
    }

    /// The textual form [`SplitChoice::parse`] reads.
    pub fn describe(&self) -> String {
        match self {
            Self::Fixed(split) => split.describe(),
            Self::Auto => "auto".into(),
        }
    }
}

/// How textures are looked up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TextureFilter {
    /// Filtered over the footprint of the path's ray cone through MIP pyramids.
    Mip,
    /// Bilinearly at the point, at full resolution.
    Bilinear,
}

impl TextureFilter {
    /// Parses `mip` or `bilinear`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s.trim() {
            "mip" => Ok(Self::Mip),
            "bilinear" => Ok(Self::Bilinear),
            other => Err(format!("unknown texture filter {other:?} (mip, bilinear)")),
        }
    }

    /// The textual form [`TextureFilter::parse`] reads.
    pub fn describe(&self) -> &'static str {
        match self {
            Self::Mip => "mip",
            Self::Bilinear => "bilinear",
        }
    }
}

/// Which microfacet model rough lobes follow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MicrofacetModel {
    /// Single-scattering GGX with the energy it loses between facets given back
    /// (`material::energy`; Cycles' "Multiscatter GGX").
    Multiscatter,
    /// Single-scattering GGX alone: glTF's appendix B and Mitsuba's rough models exactly.
    Single,
}

impl MicrofacetModel {
    /// Parses `multiscatter` or `single`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s.trim() {
            "multiscatter" => Ok(Self::Multiscatter),
            "single" => Ok(Self::Single),
            other => Err(format!(
                "unknown microfacet model {other:?} (multiscatter, single)"
            )),
        }
    }

    /// The textual form [`MicrofacetModel::parse`] reads.
    pub fn describe(&self) -> &'static str {
        match self {
            Self::Multiscatter => "multiscatter",
            Self::Single => "single",
        }
    }
}

/// Largest split count accepted.
pub const MAX_SPLIT: u32 = 4096;

/// The integrator's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub mis: Mis,
    pub rr: RussianRoulette,
    /// Maximum number of scattering events (1 = direct illumination only); `None` for no
    /// limit.
    pub max_depth: Option<u32>,
    pub light_select: LightSelect,
    pub light_sampling: LightSampling,
    /// Path guiding (`integrator::guiding`).
    pub guiding: GuidingMode,
    /// How textures are looked up (`world::footprint`, `scene::texture`).
    pub texture_filter: TextureFilter,
    /// The microfacet model of every material's rough lobes.
    pub microfacet: MicrofacetModel,
    pub split: SplitChoice,
    pub sampler: SamplerKind,
    pub seed: u32,
}

impl Default for Settings {
    /// Power heuristic (β = 2), throughput roulette (threshold 0.1: the most efficient of
    /// 0.01, 0.05, 0.1 and 0.2 at equal time on the Cornell box and the indirect room), no
    /// depth limit, light selection by power, area sampling, no guiding, bilinear texture
    /// lookups (as Mitsuba 3, Cycles and pbrt-v4 by default: MIP filtering costs 10-20 % a
    /// sample on textured assets and pays only at few samples), multiple-scattering
    /// microfacets (as Cycles, Arnold and Karma by default), no splitting, Owen-scrambled
    /// Sobol, seed 0.
    fn default() -> Self {
        Self {
            mis: Mis::Power(2.0),
            rr: RussianRoulette::Throughput(0.1),
            max_depth: None,
            light_select: LightSelect::Power,
            light_sampling: LightSampling::Auto,
            guiding: GuidingMode::Off,
            texture_filter: TextureFilter::Bilinear,
            microfacet: MicrofacetModel::Multiscatter,
            split: SplitChoice::Fixed(Split { nee: 1, bsdf: 1 }),
            sampler: SamplerKind::Sobol,
            seed: 0,
        }
    }
}

impl Split {
    /// Parses `nee=N,bsdf=M` (either part may be left out: 1).
    pub fn parse(s: &str) -> Result<Self, String> {
        let mut split = Split { nee: 1, bsdf: 1 };
        for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (key, value) = part
                .split_once('=')
                .ok_or_else(|| format!("expected nee=N,bsdf=M, got {s:?}"))?;
            let n: u32 = value
                .trim()
                .parse()
                .ok()
                .filter(|n| (1..=MAX_SPLIT).contains(n))
                .ok_or_else(|| {
                    format!("split counts must be integers in 1..={MAX_SPLIT}, got {value:?}")
                })?;
            match key.trim() {
                "nee" => split.nee = n,
                "bsdf" => split.bsdf = n,
                other => return Err(format!("unknown split {other:?} (nee, bsdf)")),
            }
        }
        Ok(split)
    }

    /// The textual form [`Split::parse`] reads.
    pub fn describe(&self) -> String {
        format!("nee={},bsdf={}", self.nee, self.bsdf)
    }
}

/// Names of the integrator's settings, in the order they are written.
pub const SETTING_NAMES: [&str; 11] = [
    "mis",
    "rr",
    "max-depth",
    "light-select",
    "light-sampling",
    "guiding",
    "texture-filter",
    "microfacet",
    "split",
    "sampler",
    "seed",
];

impl Settings {
    /// Sets the setting `name` from its textual value.
    pub fn set(&mut self, name: &str, value: &str) -> Result<(), String> {
        match name {
            "mis" => self.mis = Mis::parse(value)?,
            "rr" => self.rr = RussianRoulette::parse(value)?,
            "max-depth" => {
                self.max_depth = match value {
                    "unlimited" => None,
                    v => Some(v.parse().map_err(|_| {
                        format!("max-depth: a number of bounces or `unlimited`, got {v:?}")
                    })?),
                }
            }
            "light-select" => self.light_select = LightSelect::parse(value)?,
            "light-sampling" => self.light_sampling = LightSampling::parse(value)?,
            "guiding" => self.guiding = GuidingMode::parse(value)?,
            "texture-filter" => self.texture_filter = TextureFilter::parse(value)?,
            "microfacet" => self.microfacet = MicrofacetModel::parse(value)?,
            "split" => self.split = SplitChoice::parse(value)?,
            "sampler" => {
                self.sampler = SamplerKind::parse(value)
                    .ok_or_else(|| format!("unknown sampler {value:?} (sobol, independent)"))?
            }
            "seed" => {
                self.seed = value
                    .parse()
                    .map_err(|_| format!("seed: an integer, got {value:?}"))?
            }
            _ => return Err(format!("unknown setting {name:?}")),
        }
        Ok(())
    }

    /// The textual value of setting `name`.
    pub fn get(&self, name: &str) -> Option<String> {
        Some(match name {
            "mis" => self.mis.describe(),
            "rr" => self.rr.describe(),
            "max-depth" => self.max_depth.map_or("unlimited".into(), |d| d.to_string()),
            "light-select" => self.light_select.describe().into(),
            "light-sampling" => self.light_sampling.describe().into(),
            "guiding" => self.guiding.describe().into(),
            "texture-filter" => self.texture_filter.describe().into(),
            "microfacet" => self.microfacet.describe().into(),
            "split" => self.split.describe(),
            "sampler" => self.sampler.name().into(),
            "seed" => self.seed.to_string(),
            _ => return None,
        })
    }

    /// Checks combinations that cannot work.
    pub fn validate(&self) -> Result<(), String> {
        if self.rr == RussianRoulette::Off && self.max_depth.is_none() {
            return Err("rr=off needs a finite max-depth (paths would never end)".into());
        }
        if self.split == SplitChoice::Auto && matches!(self.rr, RussianRoulette::Efficiency(_)) {
            return Err(
                "split=auto and rr=efficiency both learn how paths split at first; choose one"
                    .into(),
            );
        }
        Ok(())
    }

    /// One line naming every setting, for logs.
    pub fn describe(&self) -> String {
        SETTING_NAMES
            .iter()
            .map(|n| {
                format!(
                    "{n}={}",
                    self.get(n).expect("every listed name is a setting")
                )
            })
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// Reads a TOML settings file into `(name, textual value)` pairs. Values may be strings or
/// numbers; tables and arrays are refused.
pub fn read_settings_toml(text: &str) -> Result<Vec<(String, String)>, String> {
    let table: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| e.message().to_string())?;
    let scalar = |key: &str, value: toml::Value| match value {
        toml::Value::String(s) => Ok(s),
        toml::Value::Integer(i) => Ok(i.to_string()),
        toml::Value::Float(f) => Ok(f.to_string()),
        toml::Value::Boolean(b) => Ok(b.to_string()),
        other => Err(format!(
            "{key}: expected a string, a number or a boolean, got {}",
            other.type_str()
        )),
    };
    let mut pairs = Vec::new();
    for (key, value) in table {
        match value {
            // A repeatable setting (variant, light-group): one pair per element.
            toml::Value::Array(items) => {
                for item in items {
                    pairs.push((key.clone(), scalar(&key, item)?));
                }
            }
            value => pairs.push((key.clone(), scalar(&key, value)?)),
        }
    }
    Ok(pairs)
}

/// Writes `(name, textual value)` pairs as TOML.
pub fn write_settings_toml(pairs: &[(String, String)]) -> String {
    let mut table = toml::Table::new();
    for (key, value) in pairs {
        let v = match value.parse::<i64>() {
            Ok(i) if ["seed", "spp", "min-spp", "max-depth"].contains(&key.as_str()) => {
                toml::Value::Integer(i)
            }
            _ => toml::Value::String(value.clone()),
        };
        table.insert(key.clone(), v);
    }
    toml::to_string(&table).expect("a flat table of strings and integers serialises")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_setting_round_trips_through_its_text() {
        let mut s = Settings::default();
        for (name, value) in [
            ("mis", "cutoff:0.2"),
            ("rr", "fixed:0.3"),
            ("max-depth", "10"),
            ("light-select", "contribution"),
            ("light-sampling", "solid-angle"),
            ("texture-filter", "mip"),
            ("microfacet", "single"),
            ("split", "nee=4,bsdf=2"),
            ("split", "auto"),
            ("sampler", "independent"),
            ("seed", "7"),
        ] {
            s.set(name, value).unwrap();
            assert_eq!(s.get(name).unwrap(), value);
        }
        let pairs: Vec<(String, String)> = SETTING_NAMES
            .iter()
            .map(|n| (n.to_string(), s.get(n).unwrap()))
            .collect();
        let mut back = Settings::default();
        for (k, v) in read_settings_toml(&write_settings_toml(&pairs)).unwrap() {
            back.set(&k, &v).unwrap();
        }
        assert_eq!(back, s);
        assert!(s.set("split", "nee=0").is_err() && s.set("colour", "red").is_err());
        s.set("rr", "efficiency").unwrap();
        assert_eq!(s.get("rr").unwrap(), "efficiency:1");
        assert!(s.validate().is_err(), "split=auto with rr=efficiency");
        assert!(s.set("rr", "efficiency:0.5").is_err());
        s.set("rr", "off").unwrap();
        s.set("max-depth", "unlimited").unwrap();
        assert!(s.validate().is_err());
    }
}
