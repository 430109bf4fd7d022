//! Choosing which light to sample: uniformly, by power, or by estimated contribution at
//! the shading point (bounded lights through a light BVH; infinite lights, which no bound
//! contains, are chosen as a group alongside the tree, as in pbrt-v4).

use super::Light;
use super::environment::Environment;
use super::tree::{LightBounds, LightTree};
use crate::sampling::distribution::AliasTable;
use glam::Vec3;

/// How a light is chosen for next-event estimation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightSelect {
    /// Every light that emits equally likely.
    Uniform,
    /// In proportion to emitted power.
    Power,
    /// In proportion to an estimate of the unoccluded contribution at the shading point,
    /// through a light BVH (see `light::tree`).
    Contribution,
    /// The light BVH's selection mixed with what light samples found each group of
    /// lights to bring to each region of the scene, shadow rays included (see
    /// `light::learned`).
    Learned,
}

impl LightSelect {
    /// Parses `uniform`, `power` or `contribution`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "uniform" => Ok(Self::Uniform),
            "power" => Ok(Self::Power),
            "contribution" => Ok(Self::Contribution),
            "learned" => Ok(Self::Learned),
            _ => Err(format!(
                "unknown light selection {s:?} (uniform, power, contribution, learned)"
            )),
        }
    }

    /// The textual form [`LightSelect::parse`] reads.
    pub fn describe(&self) -> &'static str {
        match self {
            Self::Uniform => "uniform",
            Self::Power => "power",
            Self::Contribution => "contribution",
            Self::Learned => "learned",
        }
    }
}

/// How lights are chosen.
#[derive(Clone, Debug)]
enum Selector {
    /// Every light of positive power equally likely (`selectable[i]`: light i is one).
    Uniform {
        lights: Vec<u32>,
        selectable: Vec<bool>,
    },
    Power(AliasTable),
    Contribution {
        tree: LightTree,
        /// Lights without bounds (environment, directional), chosen uniformly.
        infinite: Vec<u32>,
    },
}

/// All lights with their selection strategy.
#[derive(Clone, Debug)]
pub struct LightSet {
    pub lights: Vec<Light>,
    pub environment: Option<Environment>,
    /// Index of the environment in `lights`, if any.
    pub environment_index: Option<u32>,
    /// Indices of the distant lights with an angular size, which escaping rays can reach.
    pub distant_cones: Vec<u32>,
    /// Lights that emit nothing (no selection strategy ever picks them).
    pub zero_power: usize,
    selector: Option<Selector>,
}

/// What the light tree knows of light `l`; `None` for lights at infinity.
fn bounds(l: &Light, environment: Option<&Environment>, radius: f32) -> Option<LightBounds> {
    l.bounds(l.power(environment, radius))
}

impl LightSet {
    /// Builds the set with its selection strategy. `radius` is the scene's bounding radius.
    pub fn new(
        mut lights: Vec<Light>,
        environment: Option<Environment>,
        radius: f32,
        strategy: LightSelect,
    ) -> Self {
        let environment_index = environment.as_ref().map(|_| {
            lights.push(Light::Environment);
            (lights.len() - 1) as u32
        });
        let powers: Vec<f32> = lights
            .iter()
            .map(|l| l.power(environment.as_ref(), radius))
            .collect();
        let selector = match strategy {
            _ if !powers.iter().any(|&p| p > 0.0) => None,
            LightSelect::Uniform => Some(Selector::Uniform {
                lights: (0..lights.len() as u32)
                    .filter(|&i| powers[i as usize] > 0.0)
                    .collect(),
                selectable: powers.iter().map(|&p| p > 0.0).collect(),
            }),
            LightSelect::Power => AliasTable::new(&powers).map(Selector::Power),
            LightSelect::Contribution | LightSelect::Learned => {
                let mut bounded = Vec::new();
                let mut infinite = Vec::new();
                for (i, l) in lights.iter().enumerate() {
                    match bounds(l, environment.as_ref(), radius) {
                        Some(b) => bounded.push((i as u32, b)),
                        None if powers[i] > 0.0 => infinite.push(i as u32),
                        None => {}
                    }
                }
                Some(Selector::Contribution {
                    tree: LightTree::build(&bounded, lights.len()),
                    infinite,
                })
            }
        };
        let distant_cones = (0..lights.len() as u32)
            .filter(|&i| matches!(lights[i as usize], Light::DistantCone(_)))
            .collect();
        Self {
            lights,
            environment,
            environment_index,
            distant_cones,
            zero_power: powers.iter().filter(|&&p| !(p > 0.0)).count(),
            selector,
        }
    }

    /// Chooses a light for shading point `p` with shading normal `n`: (index, probability).
    #[inline(always)]
    pub fn select(&self, u: f32, p: Vec3, n: Vec3) -> Option<(usize, f32)> {
        match self.selector.as_ref()? {
            Selector::Uniform { lights, .. } => {
                let count = lights.len();
                Some((
                    lights[((u * count as f32) as usize).min(count - 1)] as usize,
                    1.0 / count as f32,
                ))
            }
            Selector::Power(table) => Some(table.sample(u)),
            Selector::Contribution { tree, infinite } => {
                let groups = infinite.len() + usize::from(!tree.is_empty());
                let p_infinite = infinite.len() as f32 / groups as f32;
                if u < p_infinite {
                    let i =
                        ((u / p_infinite * infinite.len() as f32) as usize).min(infinite.len() - 1);
                    Some((infinite[i] as usize, 1.0 / groups as f32))
                } else {
                    let u = ((u - p_infinite) / (1.0 - p_infinite)).min(1.0 - f32::EPSILON);
                    tree.sample(p, n, u)
                        .map(|(i, pmf)| (i, pmf * (1.0 - p_infinite)))
                }
            }
        }
    }

    /// Probability that [`LightSet::select`] picks light `i` at `p` with normal `n`.
    #[inline]
    pub fn selection_probability(&self, i: usize, p: Vec3, n: Vec3) -> f32 {
        match self.selector.as_ref() {
            None => 0.0,
            Some(Selector::Uniform { lights, selectable }) if selectable[i] => {
                1.0 / lights.len() as f32
            }
            Some(Selector::Uniform { .. }) => 0.0,
            Some(Selector::Power(table)) => table.pmf(i),
            Some(Selector::Contribution { tree, infinite }) => {
                if infinite.contains(&(i as u32)) {
                    1.0 / (infinite.len() + usize::from(!tree.is_empty())) as f32
                } else {
                    tree.pmf(p, n, i) * self.tree_share()
                }
            }
        }
    }

    /// The light tree and the lights at infinity beside it, under selection by
    /// contribution (`None` under other strategies).
    pub fn tree(&self) -> Option<(&LightTree, &[u32])> {
        match self.selector.as_ref()? {
            Selector::Contribution { tree, infinite } => Some((tree, infinite)),
            _ => None,
        }
    }

    /// Under selection by contribution, the share of selections that go to the light tree
    /// (the rest go to the lights at infinity, each a group of its own).
    pub fn tree_share(&self) -> f32 {
        match self.selector.as_ref() {
            Some(Selector::Contribution { tree, infinite }) => {
                let groups = (infinite.len() + usize::from(!tree.is_empty())) as f32;
                1.0 - infinite.len() as f32 / groups
            }
            _ => 0.0,
        }
    }

    /// The alias table of selection by power (`None` under other strategies).
    pub fn power_table(&self) -> Option<&AliasTable> {
        match self.selector.as_ref()? {
            Selector::Power(table) => Some(table),
            _ => None,
        }
    }

    /// True if there is nothing to sample.
    pub fn is_empty(&self) -> bool {
        self.selector.is_none()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(intensity: f32) -> Light {
        Light::Point(crate::light::PointLight {
            position: Vec3::ZERO,
            intensity: Vec3::splat(intensity),
        })
    }

    /// Uniform selection never picks a light that emits nothing, and its probabilities
    /// still sum to 1 over the lights it picks.
    #[test]
    fn uniform_selection_skips_lights_of_zero_power() {
        let set = LightSet::new(
            vec![point(0.0), point(1.0), point(0.0), point(2.0)],
            None,
            1.0,
            LightSelect::Uniform,
        );
        assert_eq!(set.zero_power, 2);
        let p = Vec3::ONE;
        for k in 0..100 {
            let (i, pmf) = set.select((k as f32 + 0.5) / 100.0, p, Vec3::Y).unwrap();
            assert!(i == 1 || i == 3, "picked light {i}");
            assert_eq!(pmf, 0.5);
        }
        let total: f32 = (0..4)
            .map(|i| set.selection_probability(i, p, Vec3::Y))
            .sum();
        assert_eq!(total, 1.0);
        assert_eq!(set.selection_probability(0, p, Vec3::Y), 0.0);
    }
}
