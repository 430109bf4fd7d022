//! The dielectric volumes a path is inside, for absorption and for the index of refraction
//! on the far side of an interface.
//!
//! The rule (documented in the README): a path keeps the volumes it has entered, innermost
//! last, up to [`MAX_NESTED`]. Refracting into the front of a volume's boundary enters it;
//! refracting out through the back of a boundary leaves that volume, wherever it is in the
//! list (overlapping volumes need not be properly nested). Along a ray the innermost
//! volume absorbs. At a boundary, the index outside it is the innermost other volume's (1,
//! air, when there is none), so that water inside a glass refracts by 1.33 / 1.5 where it
//! meets the glass. A path that starts inside a volume (a camera in the water) knows
//! nothing of it until it leaves through a back face: it then sees air outside, which is
//! what such scenes usually mean. Reflection changes nothing; thin walls bound no volume.

use crate::scene::Material;
use crate::world::{Interaction, Surfaces};
use glam::Vec3;

/// The deepest nesting kept: entering a fifth volume forgets the outermost.
pub const MAX_NESTED: usize = 4;

/// The volumes (their materials) a path is inside, innermost last.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Media {
    materials: [u32; MAX_NESTED],
    len: u8,
}

impl Media {
    /// Outside every volume.
    pub(crate) const EMPTY: Self = Self {
        materials: [0; MAX_NESTED],
        len: 0,
    };

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
            .filter(|m| m.volume.is_some() && m.ior > 0.0)
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
            .filter(|m| m.volume.is_some() && m.ior > 0.0)
            .map_or(1.0, |m| m.ior * m.ior)
    }

    /// The fraction of light that crosses `length` render-space units of the innermost
    /// volume (one outside every volume and in clear ones).
    #[inline]
    pub(crate) fn transmittance(&self, surfaces: &Surfaces, length: f32) -> Vec3 {
        match self.innermost().and_then(|m| surfaces.absorption(m)) {
            // Channels that do not absorb stay 1 even along an infinite ray.
            Some(sigma) => {
                Vec3::select(sigma.cmpgt(Vec3::ZERO), (-sigma * length).exp(), Vec3::ONE)
            }
            None => Vec3::ONE,
        }
    }
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
}
