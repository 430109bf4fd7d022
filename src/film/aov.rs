//! The AOVs (render passes) lucerna can write, their EXR layer names and channels, and the
//! routing of tagged contributions to the light AOVs that want them.

use crate::integrator::path::{Contribution, Source};

/// Deepest per-depth layer (`nee_d16`, `bsdf_d16`).
pub const MAX_DEPTH_AOV: u8 = 16;

/// An AOV. The light AOVs (beauty through the per-depth layers) sum contributions; the
/// others are data.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Aov {
    Beauty,
    Emission,
    Direct,
    Indirect,
    Nee,
    Bsdf,
    DirectNee,
    DirectBsdf,
    IndirectNee,
    IndirectBsdf,
    DirectNeeUnweighted,
    DirectBsdfUnweighted,
    /// Light sampling's contributions after exactly K scattering events (on request).
    NeeDepth(u8),
    /// BSDF sampling's contributions after exactly K scattering events (on request).
    BsdfDepth(u8),
    /// Light after one scattering event / more, by the lobe of the first (on request).
    DiffuseDirect,
    DiffuseIndirect,
    GlossyDirect,
    GlossyIndirect,
    TransmissionDirect,
    TransmissionIndirect,
    Albedo,
    Normal,
    Depth,
    Position,
    Spp,
    Variance,
    /// Directional albedo of each lobe kind at the first surface (on request).
    DiffuseColor,
    GlossyColor,
    TransmissionColor,
}

/// The lobe layers (`--aov lobes`): full contributions by the lobe of the first scattering
/// event, direct and indirect, then the lobe albedos.
pub const LOBES: [Aov; 9] = [
    Aov::DiffuseDirect,
    Aov::DiffuseIndirect,
    Aov::GlossyDirect,
    Aov::GlossyIndirect,
    Aov::TransmissionDirect,
    Aov::TransmissionIndirect,
    Aov::DiffuseColor,
    Aov::GlossyColor,
    Aov::TransmissionColor,
];

/// Every AOV written by default (`all`), in canonical order; per-depth layers come only on
/// request.
pub const ALL: [Aov; 18] = [
    Aov::Beauty,
    Aov::Emission,
    Aov::Direct,
    Aov::Indirect,
    Aov::Nee,
    Aov::Bsdf,
    Aov::DirectNee,
    Aov::DirectBsdf,
    Aov::IndirectNee,
    Aov::IndirectBsdf,
    Aov::DirectNeeUnweighted,
    Aov::DirectBsdfUnweighted,
    Aov::Albedo,
    Aov::Normal,
    Aov::Depth,
    Aov::Position,
    Aov::Spp,
    Aov::Variance,
];

impl Aov {
    /// Layer name in the EXR (the beauty's channels are unprefixed).
    pub fn name(self) -> String {
        match self {
            Self::NeeDepth(k) => return format!("nee_d{k}"),
            Self::BsdfDepth(k) => return format!("bsdf_d{k}"),
            _ => {}
        }
        match self {
            Self::Beauty => "beauty",
            Self::Emission => "emission",
            Self::Direct => "direct",
            Self::Indirect => "indirect",
            Self::Nee => "nee",
            Self::Bsdf => "bsdf",
            Self::DirectNee => "direct_nee",
            Self::DirectBsdf => "direct_bsdf",
            Self::IndirectNee => "indirect_nee",
            Self::IndirectBsdf => "indirect_bsdf",
            Self::DirectNeeUnweighted => "direct_nee_unweighted",
            Self::DirectBsdfUnweighted => "direct_bsdf_unweighted",
            Self::Albedo => "albedo",
            Self::Normal => "normal",
            Self::Depth => "depth",
            Self::Position => "position",
            Self::Spp => "spp",
            Self::Variance => "variance",
            Self::DiffuseDirect => "diffuse_direct",
            Self::DiffuseIndirect => "diffuse_indirect",
            Self::GlossyDirect => "glossy_direct",
            Self::GlossyIndirect => "glossy_indirect",
            Self::TransmissionDirect => "transmission_direct",
            Self::TransmissionIndirect => "transmission_indirect",
            Self::DiffuseColor => "diffuse_color",
            Self::GlossyColor => "glossy_color",
            Self::TransmissionColor => "transmission_color",
            Self::NeeDepth(_) | Self::BsdfDepth(_) => unreachable!("named above"),
        }
        .to_string()
    }

    /// Channel names within the layer.
    pub fn channels(self) -> &'static [&'static str] {
        match self {
            Self::Beauty => &["R", "G", "B", "A"],
            Self::Normal | Self::Position => &["X", "Y", "Z"],
            Self::Depth => &["Z"],
            Self::Spp => &["Y"],
            _ => &["R", "G", "B"],
        }
    }

    /// Full EXR channel names (`layer.C`, or `C` for the beauty).
    pub fn channel_names(self) -> Vec<String> {
        self.channels()
            .iter()
            .map(|c| {
                if self == Self::Beauty {
                    c.to_string()
                } else {
                    format!("{}.{c}", self.name())
                }
            })
            .collect()
    }

    /// True for AOVs that sum light contributions.
    pub fn is_light(self) -> bool {
        !matches!(
            self,
            Self::Albedo
                | Self::Normal
                | Self::Depth
                | Self::Position
                | Self::Spp
                | Self::Variance
                | Self::DiffuseColor
                | Self::GlossyColor
                | Self::TransmissionColor
        )
    }

    /// Whether this light AOV takes the (MIS-weighted) contribution `c`.
    fn takes(self, c: &Contribution) -> bool {
        let direct = c.depth == 1;
        let indirect = c.depth >= 2;
        match self {
            Self::Beauty => true,
            Self::Emission => c.source == Source::Emission,
            Self::Direct => direct,
            Self::Indirect => indirect,
            Self::Nee => c.source == Source::Nee,
            Self::Bsdf => c.source == Source::Bsdf,
            Self::DirectNee => direct && c.source == Source::Nee,
            Self::DirectBsdf => direct && c.source == Source::Bsdf,
            Self::IndirectNee => indirect && c.source == Source::Nee,
            Self::IndirectBsdf => indirect && c.source == Source::Bsdf,
            Self::NeeDepth(k) => c.depth == k as u32 && c.source == Source::Nee,
            Self::BsdfDepth(k) => c.depth == k as u32 && c.source == Source::Bsdf,
            _ => false,
        }
    }

    /// Parses a layer name (including `nee_dK` and `bsdf_dK` for K in 1..=16).
    pub fn parse(name: &str) -> Option<Self> {
        let depth = |prefix: &str| {
            name.strip_prefix(prefix)
                .and_then(|k| k.parse::<u8>().ok())
                .filter(|k| (1..=MAX_DEPTH_AOV).contains(k))
        };
        if let Some(k) = depth("nee_d") {
            return Some(Self::NeeDepth(k));
        }
        if let Some(k) = depth("bsdf_d") {
            return Some(Self::BsdfDepth(k));
        }
        ALL.iter().chain(&LOBES).copied().find(|a| a.name() == name)
    }

    /// The lobe (0 diffuse, 1 glossy, 2 transmission) and whether indirect, of a lobe
    /// light layer.
    fn lobe_split(self) -> Option<(usize, usize)> {
        Some(match self {
            Self::DiffuseDirect => (0, 0),
            Self::DiffuseIndirect => (0, 1),
            Self::GlossyDirect => (1, 0),
            Self::GlossyIndirect => (1, 1),
            Self::TransmissionDirect => (2, 0),
            Self::TransmissionIndirect => (2, 1),
            _ => return None,
        })
    }
}

/// The set of AOVs a render writes; the beauty is always in it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AovSet {
    aovs: Vec<Aov>,
}

impl Default for AovSet {
    /// Every AOV.
    fn default() -> Self {
        Self { aovs: ALL.to_vec() }
    }
}

impl AovSet {
    /// Parses a comma-separated list of layer names, or `all`; the beauty is added.
    pub fn parse(list: &str) -> Result<Self, String> {
        let mut aovs = vec![Aov::Beauty];
        for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            if name == "all" {
                aovs.extend(ALL);
                continue;
            }
            if name == "lobes" {
                aovs.extend(LOBES);
                continue;
            }
            let aov = Aov::parse(name).ok_or_else(|| {
                let known: Vec<String> = ALL.iter().map(|a| a.name()).collect();
                format!("unknown AOV {name:?} (known: all, lobes, {}, nee_dK, bsdf_dK for K up to {MAX_DEPTH_AOV})", known.join(", "))
            })?;
            aovs.push(aov);
        }
        aovs.sort();
        aovs.dedup();
        Ok(Self { aovs })
    }

    /// The AOVs in canonical order.
    pub fn iter(&self) -> impl Iterator<Item = Aov> + '_ {
        self.aovs.iter().copied()
    }

    /// True if `aov` is requested.
    pub fn contains(&self, aov: Aov) -> bool {
        self.aovs.contains(&aov)
    }

    /// Comma-separated names (`all` for the default set).
    pub fn describe(&self) -> String {
        if self.aovs == ALL {
            return "all".into();
        }
        let mut all = ALL.to_vec();
        all.extend(LOBES);
        all.sort();
        if self.aovs == all {
            return "all,lobes".into();
        }
        self.aovs
            .iter()
            .map(|a| a.name())
            .collect::<Vec<_>>()
            .join(",")
    }
}

/// Rows of the routing table: depths 0 to [`MAX_DEPTH_AOV`], then one for every deeper one.
const ROUTED_DEPTHS: usize = MAX_DEPTH_AOV as usize + 2;

/// Precomputed routing: for each (source, depth) the light-AOV slots a contribution goes
/// to, and the slots of the two single-technique AOVs.
#[derive(Clone, Debug)]
pub struct Router {
    /// Light AOVs in slot order (slot 0 is the beauty).
    pub slots: Vec<Aov>,
    /// [source][depth] → slots.
    table: [[Vec<u8>; ROUTED_DEPTHS]; 3],
    /// Slots of `direct_nee_unweighted` and `direct_bsdf_unweighted`.
    pub single_technique: [Option<u8>; 2],
    /// [lobe][direct, indirect] → slot of the lobe layers, which take each contribution
    /// times its lobe share.
    pub lobes: [[Option<u8>; 2]; 3],
}

impl Router {
    /// Routing for the light AOVs of `set`.
    pub fn new(set: &AovSet) -> Self {
        let slots: Vec<Aov> = set.iter().filter(|a| a.is_light()).collect();
        let slot_of = |aov: Aov| slots.iter().position(|&a| a == aov).map(|i| i as u8);
        let sources = [Source::Emission, Source::Nee, Source::Bsdf];
        let table = std::array::from_fn(|s| {
            std::array::from_fn(|d| {
                let probe = Contribution {
                    value: glam::Vec3::ZERO,
                    depth: d as u32,
                    source: sources[s],
                    single_technique: None,
                    lobes: None,
                };
                slots
                    .iter()
                    .enumerate()
                    .filter(|(_, a)| a.takes(&probe))
                    .map(|(i, _)| i as u8)
                    .collect()
            })
        });
        let mut lobes = [[None; 2]; 3];
        for (i, aov) in slots.iter().enumerate() {
            if let Some((lobe, indirect)) = aov.lobe_split() {
                lobes[lobe][indirect] = Some(i as u8);
            }
        }
        Self {
            single_technique: [
                slot_of(Aov::DirectNeeUnweighted),
                slot_of(Aov::DirectBsdfUnweighted),
            ],
            lobes,
            table,
            slots,
        }
    }

    /// True if some layer takes lobe shares.
    pub fn wants_lobes(&self) -> bool {
        self.lobes.iter().flatten().any(Option::is_some)
    }

    /// The slots taking contribution `c`'s weighted value.
    #[inline]
    pub fn route(&self, c: &Contribution) -> &[u8] {
        let s = match c.source {
            Source::Emission => 0,
            Source::Nee => 1,
            Source::Bsdf => 2,
        };
        &self.table[s][(c.depth as usize).min(ROUTED_DEPTHS - 1)]
    }
}
