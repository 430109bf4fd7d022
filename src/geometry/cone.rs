//! Ray cones: how wide a ray is where it starts and how fast it widens, carried along a
//! path so that what it meets can be looked up over the area one sample stands for
//! (`world::footprint` says how a cone starts and turns into texture footprints).

/// A ray's cone: its width (diameter, render-space units) where the ray starts and how
/// fast it widens (radians: width gained per unit of distance).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RayCone {
    pub width: f32,
    pub spread: f32,
}

impl RayCone {
    /// A ray of no extent: textures are looked up at points.
    pub const POINT: RayCone = RayCone {
        width: 0.0,
        spread: 0.0,
    };

    /// The cone's width `distance` along the ray.
    #[inline]
    pub fn width_at(&self, distance: f32) -> f32 {
        self.width + self.spread * distance
    }

    /// The cone of a ray leaving a vertex `distance` along this one by a BSDF sample of
    /// solid-angle density `pdf` (`delta` for a specular lobe), with lobe cones scaled by
    /// `lobe_scale` (`world::footprint::Footprints::lobe_scale`). The spread becomes at least
    /// the half-angle of the cone holding one sample's share of the lobe, `sqrt(1 / (π p))`.
    #[inline]
    pub fn scattered(&self, distance: f32, pdf: f32, delta: bool, lobe_scale: f32) -> RayCone {
        let spread = if delta || !(pdf > 0.0) {
            self.spread
        } else {
            self.spread
                .max(lobe_scale * (std::f32::consts::FRAC_1_PI / pdf).sqrt())
        };
        RayCone {
            width: self.width_at(distance),
            spread,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounces_widen_cones_by_their_lobes() {
        let c = RayCone {
            width: 0.0,
            spread: 0.01,
        };
        let mirror = c.scattered(2.0, 1.0, true, 1.0);
        assert_eq!(
            mirror,
            RayCone {
                width: 0.02,
                spread: 0.01
            }
        );
        // A cosine lobe's density at the normal is 1/π: a cone of half-angle 1.
        let diffuse = c.scattered(2.0, std::f32::consts::FRAC_1_PI, false, 0.5);
        assert!((diffuse.spread - 0.5).abs() < 1e-6);
        // A sharp lobe narrower than the cone leaves it.
        assert_eq!(c.scattered(2.0, 1e8, false, 1.0).spread, 0.01);
    }
}
