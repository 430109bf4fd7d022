//! The AOVs (render passes) lucerna can write, their EXR layer names and channels, and
//! which tagged contributions each light AOV takes (`router` turns that into a table).

use super::crypto;
use super::record::{Contribution, FirstHit, Source};
use glam::Vec3;

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
    /// Light whose first scattering event was in a participating medium, direct and
    /// indirect (Cycles' volume passes); the lobe layers above take the rest.
    VolumeDirect,
    VolumeIndirect,
    /// Light of light group K (`lg_<name>`, named by the [`AovSet`]) after one or more
    /// scattering events (on request, with `lightgroups`).
    LightGroup(u16),
    Albedo,
    Normal,
    Depth,
    Position,
    /// Screen-space motion at the first hit: pixels a frame, forward in time (on request).
    Motion,
    /// World-space velocity at the first hit: world units a frame (on request).
    Velocity,
    Spp,
    Variance,
    /// Directional albedo of each lobe kind at the first surface (on request).
    DiffuseColor,
    GlossyColor,
    TransmissionColor,
    /// Cryptomatte layer K (ranks 2K and 2K + 1) of objects or materials (on request).
    Crypto(crypto::Kind, u8),
}

/// The lobe layers (`--aov lobes`): full contributions by the lobe of the first scattering
/// event (or the medium it was in), direct and indirect, then the lobe albedos.
pub const LOBES: [Aov; 11] = [
    Aov::DiffuseDirect,
    Aov::DiffuseIndirect,
    Aov::GlossyDirect,
    Aov::GlossyIndirect,
    Aov::TransmissionDirect,
    Aov::TransmissionIndirect,
    Aov::VolumeDirect,
    Aov::VolumeIndirect,
    Aov::DiffuseColor,
    Aov::GlossyColor,
    Aov::TransmissionColor,
];

/// The motion layers (on request): where the first hit moves on screen and in the world.
pub const MOTION: [Aov; 2] = [Aov::Motion, Aov::Velocity];

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
            // The set knows the group's name: `AovSet::layer_name`.
            Self::LightGroup(k) => return format!("lg_{k}"),
            Self::Crypto(kind, layer) => return format!("{}{layer:02}", kind.type_name()),
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
            Self::Motion => "motion",
            Self::Velocity => "velocity",
            Self::Spp => "spp",
            Self::Variance => "variance",
            Self::DiffuseDirect => "diffuse_direct",
            Self::DiffuseIndirect => "diffuse_indirect",
            Self::GlossyDirect => "glossy_direct",
            Self::GlossyIndirect => "glossy_indirect",
            Self::TransmissionDirect => "transmission_direct",
            Self::TransmissionIndirect => "transmission_indirect",
            Self::VolumeDirect => "volume_direct",
            Self::VolumeIndirect => "volume_indirect",
            Self::DiffuseColor => "diffuse_color",
            Self::GlossyColor => "glossy_color",
            Self::TransmissionColor => "transmission_color",
            Self::NeeDepth(_) | Self::BsdfDepth(_) | Self::LightGroup(_) | Self::Crypto(..) => {
                unreachable!("named above")
            }
        }
        .to_string()
    }

    /// Channel names within the layer.
    pub fn channels(self) -> &'static [&'static str] {
        match self {
            Self::Beauty | Self::Crypto(..) => &["R", "G", "B", "A"],
            Self::Normal | Self::Position | Self::Velocity => &["X", "Y", "Z"],
            // Nuke's motion layer: u right, v up.
            Self::Motion => &["u", "v"],
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
                | Self::Motion
                | Self::Velocity
                | Self::Spp
                | Self::Variance
                | Self::DiffuseColor
                | Self::GlossyColor
                | Self::TransmissionColor
                | Self::Crypto(..)
        )
    }

    /// Whether this light AOV takes the (MIS-weighted) contribution `c`.
    pub(super) fn takes(self, c: &Contribution) -> bool {
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
        ALL.iter()
            .chain(&LOBES)
            .chain(&MOTION)
            .copied()
            .find(|a| a.name() == name)
    }

    /// The lobe (0 diffuse, 1 glossy, 2 transmission, 3 a medium) and whether indirect, of
    /// a lobe light layer.
    pub(super) fn lobe_split(self) -> Option<(usize, usize)> {
        Some(match self {
            Self::DiffuseDirect => (0, 0),
            Self::DiffuseIndirect => (0, 1),
            Self::GlossyDirect => (1, 0),
            Self::GlossyIndirect => (1, 1),
            Self::TransmissionDirect => (2, 0),
            Self::TransmissionIndirect => (2, 1),
            Self::VolumeDirect => (3, 0),
            Self::VolumeIndirect => (3, 1),
            _ => return None,
        })
    }
}

/// The set of AOVs a render writes; the beauty is always in it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AovSet {
    aovs: Vec<Aov>,
    /// Whether the light-group layers are requested (`lightgroups`).
    light_groups: bool,
    /// Names of the light groups, once the scene is known ([`AovSet::with_light_groups`]).
    group_names: Vec<String>,
}

impl Default for AovSet {
    /// Every AOV.
    fn default() -> Self {
        Self {
            aovs: ALL.to_vec(),
            light_groups: false,
            group_names: Vec::new(),
        }
    }
}

impl AovSet {
    /// Parses a comma-separated list of layer names, or `all`; the beauty is added.
    pub fn parse(list: &str) -> Result<Self, String> {
        let mut aovs = vec![Aov::Beauty];
        let mut light_groups = false;
        for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            if name == "lightgroups" {
                light_groups = true;
                continue;
            }
            if name == "crypto" {
                for kind in [crypto::Kind::Object, crypto::Kind::Material] {
                    aovs.extend((0..crypto::LAYERS).map(|k| Aov::Crypto(kind, k)));
                }
                continue;
            }
            if name == "all" {
                aovs.extend(ALL);
                continue;
            }
            if name == "comp" {
                // A compositor's usual set: light by lobe and by light group, the data
                // layers a comp uses, and Cryptomatte.
                aovs.extend(LOBES);
                aovs.extend([
                    Aov::Emission,
                    Aov::Albedo,
                    Aov::Normal,
                    Aov::Depth,
                    Aov::Position,
                ]);
                for kind in [crypto::Kind::Object, crypto::Kind::Material] {
                    aovs.extend((0..crypto::LAYERS).map(|k| Aov::Crypto(kind, k)));
                }
                light_groups = true;
                continue;
            }
            if name == "lobes" {
                aovs.extend(LOBES);
                continue;
            }
            let aov = Aov::parse(name).ok_or_else(|| {
                let known: Vec<String> = ALL.iter().map(|a| a.name()).collect();
                format!("unknown AOV {name:?} (known: comp, all, lobes, lightgroups, crypto, {}, nee_dK, bsdf_dK for K up to {MAX_DEPTH_AOV})", known.join(", "))
            })?;
            aovs.push(aov);
        }
        aovs.sort();
        aovs.dedup();
        Ok(Self {
            aovs,
            light_groups,
            group_names: Vec::new(),
        })
    }

    /// Whether the Cryptomatte layers are requested.
    pub fn wants_crypto(&self) -> bool {
        self.aovs.iter().any(|a| matches!(a, Aov::Crypto(..)))
    }

    /// Whether the light-group layers are requested.
    pub fn wants_light_groups(&self) -> bool {
        self.light_groups
    }

    /// This set with one `lg_<name>` layer for each of `names` (if light groups are
    /// requested).
    pub fn with_light_groups(&self, names: &[String]) -> Self {
        let mut set = self.clone();
        if set.light_groups {
            set.aovs.retain(|a| !matches!(a, Aov::LightGroup(_)));
            set.aovs
                .extend((0..names.len()).map(|k| Aov::LightGroup(k as u16)));
            set.aovs.sort();
            set.group_names = names.to_vec();
        }
        set
    }

    /// The EXR layer name of `aov` (light groups by their names).
    pub fn layer_name(&self, aov: Aov) -> String {
        match aov {
            Aov::LightGroup(k) => format!("lg_{}", self.group_names[k as usize]),
            _ => aov.name(),
        }
    }

    /// Full EXR channel names of `aov` (`layer.C`, or `C` for the beauty).
    pub fn channel_names(&self, aov: Aov) -> Vec<String> {
        match aov {
            Aov::LightGroup(_) => {
                let layer = self.layer_name(aov);
                aov.channels()
                    .iter()
                    .map(|c| format!("{layer}.{c}"))
                    .collect()
            }
            _ => aov.channel_names(),
        }
    }

    /// The AOVs in canonical order.
    pub fn iter(&self) -> impl Iterator<Item = Aov> + '_ {
        self.aovs.iter().copied()
    }

    /// True if `aov` is requested.
    pub fn contains(&self, aov: Aov) -> bool {
        self.aovs.contains(&aov)
    }

    /// Comma-separated names (`all` for the default set), as [`AovSet::parse`] reads them.
    pub fn describe(&self) -> String {
        let crypto = self.wants_crypto();
        let aovs: Vec<Aov> = self
            .aovs
            .iter()
            .copied()
            .filter(|a| !matches!(a, Aov::LightGroup(_) | Aov::Crypto(..)))
            .collect();
        let mut all_lobes = ALL.to_vec();
        all_lobes.extend(LOBES);
        all_lobes.sort();
        let mut names = if aovs == ALL {
            vec!["all".to_string()]
        } else if aovs == all_lobes {
            vec!["all".to_string(), "lobes".to_string()]
        } else {
            aovs.iter().map(|a| a.name()).collect()
        };
        if self.light_groups {
            names.push("lightgroups".into());
        }
        if crypto {
            names.push("crypto".into());
        }
        names.join(",")
    }
}

/// The data AOVs that are means of a first-hit vector over the pixel's samples, in the
/// order of [`mean_data`].
pub const MEAN_DATA: [Aov; 8] = [
    Aov::Albedo,
    Aov::Normal,
    Aov::Position,
    Aov::DiffuseColor,
    Aov::GlossyColor,
    Aov::TransmissionColor,
    Aov::Motion,
    Aov::Velocity,
];

/// The values of [`MEAN_DATA`] at a first hit.
#[inline]
pub(super) fn mean_data(hit: &FirstHit) -> [Vec3; 8] {
    let [diffuse, glossy, transmission] = hit.lobe_albedo;
    [
        hit.albedo,
        hit.normal,
        hit.position,
        diffuse,
        glossy,
        transmission,
        hit.motion.extend(0.0),
        hit.velocity,
    ]
}
