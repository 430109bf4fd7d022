//! A path's continuation at a guided vertex: the mixture of the learned distribution and
//! the BSDF's own sampling, one sample of it with its density (one-sample MIS).

use super::{Distribution, GUIDE_PROBABILITY};
use crate::geometry::frame::Frame;
use crate::material::{Bsdf, BsdfSample, Lobe};
use crate::sampling::sampler::VertexSample;
use glam::Vec3;

/// A continuation at a vertex from the mixture of its guide and its BSDF (one-sample
/// MIS): with probability [`GUIDE_PROBABILITY`] a direction from the guide, else the BSDF's
/// sample (the lobe number rescaled to choose its lobe). A non-delta direction's weight is
/// f · cos over the mixture's density; a delta lobe, which only the BSDF samples, keeps its
/// weight divided by the BSDF's share.
#[inline]
pub fn guided_sample(
    bsdf: &Bsdf,
    wo: Vec3,
    frame: &Frame,
    guide: &Distribution,
    vs: &VertexSample,
) -> Option<BsdfSample> {
    let alpha = GUIDE_PROBABILITY;
    if vs.lobe < alpha {
        let (d, p_guide) = guide.sample(vs.bsdf)?;
        let wi = frame.to_local(d);
        let f = bsdf.eval(wo, wi);
        let pdf = alpha * p_guide + (1.0 - alpha) * bsdf.pdf(wo, wi);
        let lobe = if wi.z * wo.z < 0.0 {
            Lobe::GlossyTransmission
        } else {
            Lobe::Diffuse
        };
        return BsdfSample::from_mixture(wi, f, pdf, lobe);
    }
    let u_lobe = ((vs.lobe - alpha) / (1.0 - alpha)).min(0.999_999_94);
    let bs = bsdf.sample(wo, u_lobe, vs.bsdf)?;
    if bs.is_delta() {
        return Some(BsdfSample {
            weight: bs.weight / (1.0 - alpha),
            pdf: bs.pdf * (1.0 - alpha),
            ..bs
        });
    }
    let pdf = alpha * guide.pdf(frame.to_world(bs.wi)) + (1.0 - alpha) * bs.pdf;
    Some(BsdfSample {
        weight: bs.weight * (bs.pdf / pdf),
        pdf,
        ..bs
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrator::guiding::dtree::{DTree, direction_to_square};
    use crate::material::lambert::Lambert;
    use crate::sampling::pcg::Pcg32;
    use glam::Vec2;

    /// Guided continuations are unbiased: over a Lambert BSDF and a learned distribution
    /// peaked away from the normal, the mean weight is the albedo within five standard
    /// errors (the densities themselves: `tests/it/chi2.rs`).
    #[test]
    fn guided_continuations_are_unbiased() {
        let mut tree = DTree::new();
        let mut rng = Pcg32::new(5, 9);
        for _ in 0..3 {
            let mut next = tree.refined();
            for _ in 0..20000 {
                let d =
                    Vec3::new(0.6 + 0.2 * rng.next_f32(), 0.1 * rng.next_f32(), 0.5).normalize();
                let leaf = next.leaf_of(direction_to_square(d));
                next.add_to_leaf(leaf, 1.0);
            }
            next.sum_up();
            tree = next;
        }
        let frozen = tree.frozen();
        let guide = Distribution::new(&frozen);
        let albedo = Vec3::new(0.8, 0.5, 0.2);
        let bsdf = Bsdf::Lambert(Lambert { albedo });
        let frame = Frame::from_normal(Vec3::Z);
        let wo = Vec3::new(0.3, 0.1, 0.9).normalize();
        let n = 400_000;
        let (mut sum, mut squares) = (Vec3::ZERO, Vec3::ZERO);
        for _ in 0..n {
            let vs = VertexSample {
                light: Vec2::ZERO,
                light_select: 0.0,
                rr: 0.0,
                bsdf: Vec2::new(rng.next_f32(), rng.next_f32()),
                lobe: rng.next_f32(),
                medium: 0.0,
            };
            if let Some(s) = guided_sample(&bsdf, wo, &frame, &guide, &vs) {
                sum += s.weight;
                squares += s.weight * s.weight;
            }
        }
        let mean = sum / n as f32;
        let standard_error = ((squares / n as f32 - mean * mean) / n as f32).powf(0.5);
        assert!(
            (mean - albedo).cmple(5.0 * standard_error).all()
                && (albedo - mean).cmple(5.0 * standard_error).all(),
            "{mean} vs {albedo} (standard error {standard_error})"
        );
    }
}
