//! The volumes a path is inside, for the medium that absorbs and scatters along its rays
//! (`crate::medium`) and for the index of refraction on the far side of an interface.
//!
//! The rule (docs/glass.md, docs/media.md): a path keeps the volumes it has entered, innermost
//! last, up to [`MAX_NESTED`]. Refracting into the front of a volume's boundary enters it,
//! as does crossing the front of an interface (a boundary that does not scatter);
//! refracting or crossing out through the back of a boundary leaves that volume, wherever
//! it is in the list (overlapping volumes need not be properly nested). Along a ray the
//! innermost volume's medium absorbs and scatters (shadow rays too, through interfaces:
//! [`Media::shadow_transmittance`]). At a boundary, the index outside it is the innermost
//! other refracting volume's (1, air, when there is none; an interface has no index), so
//! that water inside a glass refracts by 1.33 / 1.5 where it meets the glass. A path that
//! starts inside a glass volume (a camera in the water) knows nothing of it until it leaves
//! through a back face: it then sees air outside, which is what such scenes usually mean; a
//! camera inside media behind interfaces starts in them ([`Media::around`]). Reflection
//! changes nothing; thin walls bound no volume.

use crate::geometry::ray::Ray;
use crate::medium::{Flight, Medium};
use crate::scene::{BsdfModel, Material};
use crate::world::{Interaction, Surfaces, World};
use glam::Vec3;

/// The most boundaries a shadow ray crosses on its way through media; beyond, it counts as
/// blocked (a ray through this many interfaces carries no measurable light in any scene
/// that is not built to have it).
const MAX_SHADOW_CROSSINGS: u32 = 64;

/// The deepest nesting kept: entering a fifth volume forgets the outermost.
pub const MAX_NESTED: usize = 4;

/// The volumes (their materials) a path is inside, innermost last, and the colour channel
/// its free flights are sampled in, with the densities of the path's flights so far in each
/// channel relative to that one's (see `crate::medium`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Media {
    materials: [u32; MAX_NESTED],
    len: u8,
    /// The channel the path samples distances in ([`UNCHOSEN`] until its first flight).
    channel: u8,
    /// Per channel, the density of the path's flights relative to `channel`'s, scaled to
    /// a mean of 1 (the throughput is scaled alike: see [`Media::fly`]).
    ratios: Vec3,
}

/// No channel chosen yet: the path has not flown through a scattering medium.
const UNCHOSEN: u8 = u8::MAX;

impl Default for Media {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Media {
    /// Outside every volume.
    pub(crate) const EMPTY: Self = Self {
        materials: [0; MAX_NESTED],
        len: 0,
        channel: UNCHOSEN,
        ratios: Vec3::ONE,
    };

    /// The free flight through `medium` along a segment of length `length`, from `u`: the
    /// path's first flight chooses its channel from `u` (and the rest of `u` its distance).
    /// The weight returned is the balance heuristic's over the channels for the path so far:
    /// the throughput times it divided by the mean of the relative densities, with the
    /// densities rescaled to a mean of one, so that the throughput needs no other
    /// correction wherever it is recorded.
    /// The ray starts at `origin` and goes along unit `dir`.
    #[inline]
    pub(crate) fn fly(
        &mut self,
        medium: &Medium,
        origin: Vec3,
        dir: Vec3,
        u: f32,
        length: f32,
    ) -> Flight {
        let u = if self.channel == UNCHOSEN {
            let channel = ((u * 3.0) as u8).min(2);
            self.channel = channel;
            (u * 3.0 - f32::from(channel)).clamp(0.0, 1.0)
        } else {
            u
        };
        let (flight, ratios) = medium.sample_flight(origin, dir, u, length, self.channel as usize);
        let ratios = self.ratios * ratios;
        let scale = 3.0 / ratios.element_sum();
        if !(scale.is_finite() && scale > 0.0) {
            return Flight::Pass { weight: Vec3::ZERO };
        }
        self.ratios = ratios * scale;
        flight.scaled(scale)
    }

    /// True outside every volume.
    #[inline]
    pub(crate) fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The innermost volume.
    #[inline]
    pub(crate) fn innermost(&self) -> Option<u32> {
        (self.len > 0).then(|| self.materials[self.len as usize - 1])
    }

    /// The innermost volume other than `material`'s (the one outside its boundary).
    #[inline]
    fn innermost_besides(&self, material: u32) -> Option<u32> {
        let inside = &self.materials[..self.len as usize];
        match inside.iter().rposition(|&m| m == material) {
            Some(i) if i + 1 == inside.len() => i.checked_sub(1).map(|j| inside[j]),
            _ => self.innermost(),
        }
    }

    /// After crossing the boundary of `material`'s volume at a point of side `front`.
    #[inline]
    pub(crate) fn crossed(mut self, material: u32, front: bool) -> Self {
        let len = self.len as usize;
        if front {
            if len == MAX_NESTED {
                self.materials.copy_within(1.., 0);
                self.materials[MAX_NESTED - 1] = material;
            } else {
                self.materials[len] = material;
                self.len += 1;
            }
        } else if let Some(i) = self.materials[..len].iter().rposition(|&m| m == material) {
            self.materials.copy_within(i + 1..len, i);
            self.materials[len - 1] = 0;
            self.len -= 1;
        }
        self
    }

    /// The media on the side a direction leaving `it` goes to: across the surface for
    /// `transmitted` directions through a volume's boundary, these otherwise.
    #[inline]
    pub(crate) fn beyond(self, it: &Interaction, material: &Material, transmitted: bool) -> Self {
        if transmitted && material.volume.is_some() {
            self.crossed(it.material, it.front)
        } else {
            self
        }
    }

    /// The medium of the innermost volume, where it absorbs or scatters.
    #[inline]
    pub(crate) fn medium<'s>(&self, surfaces: &'s Surfaces) -> Option<&'s Medium> {
        self.innermost().and_then(|m| surfaces.medium(m))
    }

    /// The media of interfaces that contain point `p`, innermost last: a ray from `p` to
    /// infinity crosses each of their boundaries from the inside first (a back face met
    /// before the front face it pairs with). Where a path starts, a camera inside fog.
    /// Glass volumes keep their rule (a camera in water starts outside it).
    pub(crate) fn around(world: &World, p: Vec3) -> Self {
        // A direction unlikely to graze edges of axis-aligned boxes.
        let dir = Vec3::new(0.5377, 0.6829, 0.4943).normalize();
        let mut entered: Vec<u32> = Vec::new();
        let mut inside: Vec<u32> = Vec::new();
        let mut ray = Ray::new(p, dir);
        for _ in 0..MAX_SHADOW_CROSSINGS {
            let Some(hit) = world.intersect(&ray) else {
                break;
            };
            let it = world.interaction(&ray, &hit);
            let m = &world.surfaces.materials[it.material as usize];
            if m.model == BsdfModel::Interface && m.volume.is_some() {
                if it.front {
                    entered.push(it.material);
                } else if let Some(i) = entered.iter().rposition(|&e| e == it.material) {
                    entered.remove(i);
                } else {
                    inside.push(it.material);
                }
            }
            ray = ray.continued_past(it.p, it.ng, it.magnitude);
        }
        // The first boundary left is the innermost volume.
        inside
            .iter()
            .rev()
            .fold(Self::EMPTY, |media, &m| media.crossed(m, true))
    }

    /// The index of refraction outside the boundary of `it`'s volume (1 where it bounds
    /// none, or where air lies outside).
    #[inline]
    pub(crate) fn outside_ior(&self, surfaces: &Surfaces, it: &Interaction) -> f32 {
        if self.is_empty() {
            return 1.0;
        }
        let outside = if it.front {
            self.innermost()
        } else {
            self.innermost_besides(it.material)
        };
        outside
            .map(|m| &surfaces.materials[m as usize])
            .filter(|m| refracts(m))
            .map_or(1.0, |m| m.ior)
    }

    /// The square of the innermost volume's index of refraction (1 outside every volume):
    /// the factor by which refraction into it scaled a path's throughput down (radiance
    /// grows by η² in a denser medium), which Russian roulette undoes so that it does not
    /// end paths for being in glass (pbrt-v4's `etaScale`).
    #[inline]
    pub(crate) fn radiance_scale(&self, surfaces: &Surfaces) -> f32 {
        self.innermost()
            .map(|m| &surfaces.materials[m as usize])
            .filter(|m| refracts(m))
            .map_or(1.0, |m| m.ior * m.ior)
    }

    /// The fraction of light that crosses `length` render-space units of the innermost
    /// volume along `ray` (one outside every volume and in clear ones).
    #[inline]
    pub(crate) fn transmittance(&self, surfaces: &Surfaces, ray: &Ray, length: f32) -> Vec3 {
        self.medium(surfaces).map_or(Vec3::ONE, |m| {
            m.transmittance(ray.origin, ray.dir.normalize(), length)
        })
    }

    /// What arrives at `shadow`'s origin, inside these media, of light leaving its end: the
    /// transmittance of the media along it, times the straight transmission of the filters
    /// it crosses, zero where something opaque (or a refracting boundary) blocks it. It
    /// walks the ray from surface to surface (closest hits, in order, as pbrt-v4's
    /// transmittance does), entering and leaving the media of the interfaces it crosses.
    /// Adds the rays it traced to `traced`.
    pub(crate) fn shadow_transmittance(
        self,
        world: &World,
        shadow: &Ray,
        traced: &mut u64,
    ) -> Vec3 {
        let surfaces = &world.surfaces;
        let mut media = self;
        let mut ray = *shadow;
        let mut through = Vec3::ONE;
        for _ in 0..MAX_SHADOW_CROSSINGS {
            *traced += 1;
            let hit = world.intersect(&ray);
            let t = hit.map_or(ray.tmax, |h| h.t);
            through *= media.transmittance(surfaces, &ray, t * ray.dir.length());
            let Some(hit) = hit else {
                return through;
            };
            let it = world.interaction(&ray, &hit);
            if surfaces.materials[it.material as usize].model == BsdfModel::Interface {
                // Clear: into or out of its medium.
                media = media.crossed(it.material, it.front);
            } else {
                let Some(straight) = surfaces.straight_transmission(&it, &ray) else {
                    return Vec3::ZERO;
                };
                through *= straight;
                if !(through.max_element() > 0.0) {
                    return Vec3::ZERO;
                }
            }
            // On from the far side, towards the same end (a target point or infinity).
            ray = ray.continued_past(it.p, it.ng, it.magnitude);
        }
        Vec3::ZERO
    }
}

/// True for a volume's boundary that refracts: a material with a volume and an index,
/// not an interface.
#[inline]
fn refracts(m: &Material) -> bool {
    m.volume.is_some() && m.ior > 0.0 && m.model != BsdfModel::Interface
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn volumes_nest_and_are_left_wherever_they_are() {
        let air = Media::default();
        let glass = air.crossed(1, true);
        assert_eq!(glass.innermost(), Some(1));
        let water_in_glass = glass.crossed(2, true);
        assert_eq!(water_in_glass.innermost(), Some(2));
        assert_eq!(water_in_glass.innermost_besides(2), Some(1));
        assert_eq!(water_in_glass.innermost_besides(1), Some(2));
        // Leaving the glass through its inner wall while in the water keeps the water.
        let water = water_in_glass.crossed(1, false);
        assert_eq!(water.innermost(), Some(2));
        assert_eq!(water.crossed(2, false), air);
        // Leaving a volume never entered changes nothing.
        assert_eq!(air.crossed(3, false), air);
        // A fifth volume forgets the outermost.
        let deep = (1..=5).fold(air, |m, v| m.crossed(v, true));
        assert_eq!(deep.materials, [2, 3, 4, 5]);
    }

    /// A path's flights through a chromatic medium, combined over its channel by the
    /// balance heuristic, are unbiased in every channel where the flights of a path
    /// multiply: a rod (light scattering only forwards or backwards, with probability 1/2
    /// each) through a slab of optical depth 12, 4 and 1 by channel reflects
    /// σL/2 / (1 + σL/2) of the light in each. Mixing the channels' densities per flight
    /// reads about 10 % low in the densest channel at this sample count.
    #[test]
    fn flights_through_a_chromatic_slab_converge_in_every_channel() {
        use crate::sampling::pcg::Pcg32;
        let sigma = Vec3::new(12.0, 4.0, 1.0);
        let medium =
            Medium::Homogeneous(crate::medium::Homogeneous::new(Vec3::ZERO, sigma, 0.0).unwrap());
        let mut rng = Pcg32::new(5, 3);
        let n = 100_000;
        let (mut sum, mut squares) = (Vec3::ZERO, Vec3::ZERO);
        for _ in 0..n {
            let (mut x, mut forward, mut beta) = (0.0f32, true, Vec3::ONE);
            let mut media = Media::EMPTY;
            loop {
                let length = if forward { 1.0 - x } else { x };
                match media.fly(&medium, Vec3::ZERO, Vec3::X, rng.next_f32(), length) {
                    Flight::Scatter { t, weight } => {
                        beta *= weight;
                        x += if forward { t } else { -t };
                        forward = rng.next_f32() < 0.5;
                    }
                    Flight::Pass { weight } => {
                        if !forward {
                            beta *= weight;
                            sum += beta;
                            squares += beta * beta;
                        }
                        break;
                    }
                }
            }
        }
        let mean = sum / n as f32;
        let se = ((squares / n as f32 - mean * mean) / n as f32).powf(0.5);
        let exact = sigma / 2.0 / (Vec3::ONE + sigma / 2.0);
        for c in 0..3 {
            assert!(
                (mean[c] - exact[c]).abs() < 4.5 * se[c],
                "reflectance {mean} ± {se}, exact {exact}"
            );
        }
    }
}
