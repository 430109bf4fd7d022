//! Routing: for each tagged contribution, the light-AOV slots that take it, precomputed per
//! (source, depth) from the requested AOVs; and [`SampleRecord`], the film's recorder for
//! one camera sample, which routes contributions into those slots as they arrive.

use super::aov::{Aov, AovSet, MAX_DEPTH_AOV, mean_data};
use super::record::{Contribution, FirstHit, Recorder, Source};
use crate::material::PerLobe;
use glam::Vec3;

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
    /// times its lobe share; lobe 3 is a medium (see [`medium_share`]).
    pub lobes: [[Option<u8>; 2]; 4],
    /// Slot of each light group's layer.
    group_slots: Vec<u8>,
    /// Slot of each light's group (empty without light groups).
    light_slot: Vec<u8>,
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
                    light: None,
                };
                slots
                    .iter()
                    .enumerate()
                    .filter(|(_, a)| a.takes(&probe))
                    .map(|(i, _)| i as u8)
                    .collect()
            })
        });
        let mut lobes = [[None; 2]; 4];
        let mut group_slots = Vec::new();
        for (i, aov) in slots.iter().enumerate() {
            if let Some((lobe, indirect)) = aov.lobe_split() {
                lobes[lobe][indirect] = Some(i as u8);
            }
            if let Aov::LightGroup(k) = aov {
                debug_assert_eq!(*k as usize, group_slots.len());
                group_slots.push(i as u8);
            }
        }
        Self {
            single_technique: [
                slot_of(Aov::DirectNeeUnweighted),
                slot_of(Aov::DirectBsdfUnweighted),
            ],
            lobes,
            group_slots,
            light_slot: Vec::new(),
            table,
            slots,
        }
    }

    /// Routes each light's contributions to its group's layer: `of_light[l]` is the group
    /// of light `l` (see `light::groups`).
    pub fn set_light_groups(&mut self, of_light: &[u32]) {
        if !self.group_slots.is_empty() {
            self.light_slot = of_light
                .iter()
                .map(|&g| self.group_slots[g as usize])
                .collect();
        }
    }

    /// The light-group slot of light `light`, if light groups are routed.
    #[inline]
    pub fn light_group_slot(&self, light: u32) -> Option<u8> {
        self.light_slot.get(light as usize).copied()
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

/// What one camera sample produced, routed into light-AOV slots as it arrives. Without
/// `ROUTED` (the beauty is the only light layer) every contribution goes to slot 0 and the
/// routing table is never read.
pub struct SampleRecord<'r, const ROUTED: bool> {
    router: &'r Router,
    pub(super) values: Vec<Vec3>,
    pub(super) covered: bool,
    pub(super) hit: Option<FirstHit>,
    pub(super) discarded: u64,
}

impl<'r, const ROUTED: bool> SampleRecord<'r, ROUTED> {
    /// An empty record for `router`'s slots.
    pub fn new(router: &'r Router) -> Self {
        Self {
            router,
            values: vec![Vec3::ZERO; router.slots.len()],
            covered: false,
            hit: None,
            discarded: 0,
        }
    }

    /// Empties the record for the next sample.
    #[inline]
    pub fn clear(&mut self) {
        self.values.fill(Vec3::ZERO);
        self.covered = false;
        self.hit = None;
    }

    /// The value of light slot `slot` so far.
    pub fn value(&self, slot: usize) -> Vec3 {
        self.values[slot]
    }
}

impl<const ROUTED: bool> Recorder for SampleRecord<'_, ROUTED> {
    #[inline]
    fn wants_single_technique(&self) -> bool {
        ROUTED && self.router.single_technique.iter().any(Option::is_some)
    }

    #[inline]
    fn wants_lobes(&self) -> bool {
        ROUTED && self.router.wants_lobes()
    }

    #[inline]
    fn contribution(&mut self, c: Contribution) {
        // A non-finite contribution is dropped whole, from every AOV, and counted.
        let finite = c.value.is_finite()
            && c.single_technique
                .is_none_or(|s| s[0].is_finite() && s[1].is_finite());
        if !finite {
            self.discarded += 1;
            return;
        }
        if !ROUTED {
            self.values[0] += c.value;
            return;
        }
        for &slot in self.router.route(&c) {
            self.values[slot as usize] += c.value;
        }
        if let Some(single) = c.single_technique {
            for (value, slot) in single.iter().zip(self.router.single_technique) {
                if let Some(slot) = slot {
                    self.values[slot as usize] += *value;
                }
            }
        }
        if let Some(slot) = c
            .light
            .filter(|_| c.depth >= 1)
            .and_then(|l| self.router.light_group_slot(l))
        {
            self.values[slot as usize] += c.value;
        }
        if let Some(shares) = c.lobes.filter(|_| c.depth >= 1) {
            let indirect = usize::from(c.depth >= 2);
            let all = [shares[0], shares[1], shares[2], medium_share(&shares)];
            for (share, slots) in all.iter().zip(&self.router.lobes) {
                if let Some(slot) = slots[indirect] {
                    self.values[slot as usize] += c.value * *share;
                }
            }
        }
    }

    #[inline]
    fn first_hit(&mut self, hit: Option<FirstHit>) {
        let Some(hit) = hit else {
            self.covered = true;
            return;
        };
        let finite = mean_data(&hit).iter().all(|v| v.is_finite()) && hit.depth.is_finite();
        if finite {
            self.covered = true;
            self.hit = Some(hit);
        } else {
            self.discarded += 1;
        }
    }
}

/// The share of a contribution owed to a medium as its first scattering event: a path that
/// first scattered in a medium carries lobe shares of zero (`integrator::path::medium`),
/// and a surface's shares add up to one in every channel that carries light, so a channel
/// whose shares are all zero is the medium's.
#[inline]
fn medium_share(shares: &PerLobe) -> Vec3 {
    let total = shares[0] + shares[1] + shares[2];
    Vec3::select(total.cmpeq(Vec3::ZERO), Vec3::ONE, Vec3::ZERO)
}
