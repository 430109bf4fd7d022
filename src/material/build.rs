//! Building a material's BSDF at a surface point: which model it is there (the glTF
//! material reduced to Lambert or a plain conductor where its other lobes weigh nothing,
//! pure glass as a dielectric, the uncoated or coated glTF BRDF, or the layered model for
//! everything its extensions add) and its parameters from factors and textures.

use super::dielectric::{Dielectric, ThinDielectric};
use super::gltf_pbr::GltfPbr;
use super::lambert::Lambert;
use super::layered::{Film, Layered, LayeredParams};
use super::phong::Phong;
use super::{
    Bsdf, BsdfStorage, ShadingContext, SurfaceAttributes, base_color, decode_normal, fresnel,
    sheen, texture_lookup,
};
use crate::scene::{BsdfModel, Material, Texture, TextureRef};
use glam::{Vec2, Vec3, Vec4};

/// A texture slot's value at a surface point (white without the texture), linear.
#[inline]
fn slot(textures: &[Texture], slot: Option<&TextureRef>, attrs: &SurfaceAttributes) -> Vec4 {
    slot.map_or(Vec4::ONE, |t| texture_lookup(textures, t, attrs, false))
}

/// The BSDF of material `m` at a surface point seen from the front, in air (a layered one
/// built in `storage`).
pub fn bsdf<'s>(
    m: &Material,
    textures: &[Texture],
    attrs: &SurfaceAttributes,
    storage: &'s mut BsdfStorage,
) -> Bsdf<'s> {
    bsdf_in(m, textures, attrs, &ShadingContext::default(), storage)
}

/// The BSDF of material `m` at a surface point in context `ctx` (a layered one built in
/// `storage`).
pub fn bsdf_in<'s>(
    m: &Material,
    textures: &[Texture],
    attrs: &SurfaceAttributes,
    ctx: &ShadingContext,
    storage: &'s mut BsdfStorage,
) -> Bsdf<'s> {
    match build(m, textures, attrs, ctx) {
        Built::Compact(b) => b,
        Built::Layered(params) => Bsdf::Layered(storage.0.insert(Layered::new(params))),
    }
}

/// The BSDF of material `m` at a surface point in context `ctx` where it is not the
/// layered model (which needs a [`BsdfStorage`]).
pub fn compact_bsdf(
    m: &Material,
    textures: &[Texture],
    attrs: &SurfaceAttributes,
    ctx: &ShadingContext,
) -> Option<Bsdf<'static>> {
    match build(m, textures, attrs, ctx) {
        Built::Compact(b) => Some(b),
        Built::Layered(_) => None,
    }
}

/// A BSDF as built: one that fits in [`Bsdf`], or the layered model's parameters.
enum Built {
    Compact(Bsdf<'static>),
    Layered(LayeredParams),
}

fn build(
    m: &Material,
    textures: &[Texture],
    attrs: &SurfaceAttributes,
    ctx: &ShadingContext,
) -> Built {
    let base = base_color(m, textures, attrs).truncate();
    // A clear filter: every ray (but the camera's, at an unlit surface) passes (see
    // `integrator::path`).
    let clear = || {
        Built::Compact(Bsdf::ThinDielectric(ThinDielectric::new(
            1.0,
            0.0,
            Vec3::ONE,
        )))
    };
    if m.unlit {
        return clear();
    }
    match m.model {
        BsdfModel::Interface => clear(),
        BsdfModel::Lambert => Built::Compact(Bsdf::Lambert(Lambert {
            albedo: base.clamp(Vec3::ZERO, Vec3::ONE),
        })),
        BsdfModel::Phong { exponent, specular } => Built::Compact(Bsdf::Phong(Phong {
            // kd + ks <= 1 keeps the lobe pair energy-conserving.
            kd: base.min(Vec3::ONE - specular).max(Vec3::ZERO),
            ks: specular,
            exponent,
        })),
        BsdfModel::GltfPbr => {
            let (mut metallic, mut roughness) = (m.metallic, m.roughness);
            if let Some(t) = &m.metallic_roughness_texture {
                let mr = texture_lookup(textures, t, attrs, false);
                roughness *= mr.y;
                metallic *= mr.z;
            }
            let transmission = if m.transmits_specularly() {
                m.transmission * slot(textures, m.transmission_texture.as_ref(), attrs).x
            } else {
                0.0
            };
            if let Some(b) = reduced_bsdf(m, base, metallic, roughness, transmission) {
                return Built::Compact(b);
            }
            if m.transmits_specularly()
                && let Some(b) = dielectric_bsdf(m, base, metallic, roughness, transmission, ctx)
            {
                return Built::Compact(b);
            }
            if m.transmits() || needs_layers(m) {
                let point = Point {
                    textures,
                    attrs,
                    ctx,
                };
                let params = layered_params(m, &point, base, metallic, roughness, transmission);
                return Built::Layered(params);
            }
            let coat = slot(textures, m.clearcoat_texture.as_ref(), attrs).x * m.clearcoat;
            let coat_roughness = slot(textures, m.clearcoat_roughness_texture.as_ref(), attrs).y
                * m.clearcoat_roughness;
            let mut pbr =
                GltfPbr::new(base, metallic, roughness, m.ior).with_clearcoat(coat, coat_roughness);
            if let Some(color) = m.specular_color {
                pbr = pbr.with_specular_color(color);
            }
            Built::Compact(Bsdf::GltfPbr(
                pbr.with_multiscatter(m.multiscatter)
                    .with_diffuse_roughness(m.diffuse_roughness),
            ))
        }
    }
}

/// The simpler BSDF a glTF material is at a point where its other lobes weigh nothing, or
/// `None`: where the specular layer's weight is zero (KHR_materials_specular
/// `specularFactor` 0) and the point is neither metal nor transmitting (specularly or
/// diffusely) nor coated nor sheened, the layered model is exactly Lambert's (its diffuse
/// base, under a layer that reflects nothing); where the point is all metal, uncoated, without sheen, iridescence or
/// anisotropy, it is exactly `gltf_pbr`'s conductor (the specular extension does not apply
/// to metals). Factors multiply their textures, so a zero factor is zero everywhere; the
/// unit tests compare each reduction with the model it replaces.
fn reduced_bsdf(
    m: &Material,
    base: Vec3,
    metallic: f32,
    roughness: f32,
    transmission: f32,
) -> Option<Bsdf<'static>> {
    let uncoated = m.clearcoat == 0.0;
    let unsheened = m.sheen.is_none_or(|s| s.color == Vec3::ZERO);
    if !(uncoated && unsheened) {
        return None;
    }
    if m.specular.weight == 0.0
        && metallic <= 0.0
        && transmission <= 0.0
        && !m.translucent()
        && m.diffuse_roughness == 0.0
    {
        return Some(Bsdf::Lambert(Lambert {
            albedo: base.clamp(Vec3::ZERO, Vec3::ONE),
        }));
    }
    let plain_metal = metallic >= 1.0
        && !m.transmits()
        && m.iridescence.is_none_or(|i| i.factor == 0.0)
        && m.anisotropy.is_none();
    if plain_metal && (!m.specular.is_default() || needs_layers(m)) {
        let metal = GltfPbr::new(base, 1.0, roughness, m.ior).with_multiscatter(m.multiscatter);
        return Some(Bsdf::GltfPbr(metal));
    }
    None
}

/// True if material `m` needs the layered model (beyond `gltf_pbr`'s base and coat) even
/// where it does not transmit.
fn needs_layers(m: &Material) -> bool {
    m.sheen.is_some_and(|s| s.color != Vec3::ZERO)
        || m.iridescence.is_some_and(|i| i.factor != 0.0)
        || m.anisotropy.is_some()
        || !m.specular.is_default()
        || (m.clearcoat_normal_texture.is_some() && m.clearcoat != 0.0)
}

/// Where a BSDF is built: the textures, the point's attributes and its context.
struct Point<'p> {
    textures: &'p [Texture],
    attrs: &'p SurfaceAttributes,
    ctx: &'p ShadingContext,
}

impl Point<'_> {
    /// A texture slot's value (white without one), linear or sRGB-decoded.
    fn read(&self, slot: Option<&TextureRef>, srgb: bool) -> Vec4 {
        slot.map_or(Vec4::ONE, |t| {
            texture_lookup(self.textures, t, self.attrs, srgb)
        })
    }

    /// A vector of the tangent frame (tangent-space coordinates) in the local shading frame.
    fn tangent_to_local(&self, v: Vec3) -> Option<Vec3> {
        let [t, b, n] = self.ctx.tangents?;
        Some(t * v.x + b * v.y + n * v.z)
    }
}

/// The layered model's parameters of material `m` at a point, given its base colour,
/// metallic, roughness and transmission there.
fn layered_params(
    m: &Material,
    at: &Point,
    base: Vec3,
    metallic: f32,
    roughness: f32,
    transmission: f32,
) -> LayeredParams {
    let ctx = at.ctx;
    let r = roughness.clamp(0.0, 1.0);
    let alpha = r * r;
    // Anisotropy: alpha along the direction rises towards 1 with the strength squared.
    let (alpha, anisotropy_direction) = match &m.anisotropy {
        Some(a) => {
            let texel = a.texture.map_or(Vec4::new(1.0, 0.5, 1.0, 1.0), |t| {
                texture_lookup(at.textures, &t, at.attrs, false)
            });
            let strength = (a.strength * texel.z).clamp(0.0, 1.0);
            let d = Vec2::new(texel.x * 2.0 - 1.0, texel.y * 2.0 - 1.0).normalize_or(Vec2::X);
            let (s, c) = a.rotation.sin_cos();
            let d = Vec2::new(c * d.x - s * d.y, s * d.x + c * d.y);
            let direction = at
                .tangent_to_local(d.extend(0.0))
                .map(|v| Vec2::new(v.x, v.y).normalize_or(Vec2::X))
                .unwrap_or(Vec2::X);
            let along = alpha + (1.0 - alpha) * strength * strength;
            (Vec2::new(along, alpha), direction)
        }
        None => (Vec2::splat(alpha), Vec2::X),
    };
    let ior = if m.ior > 0.0 { m.ior } else { f32::INFINITY };
    let mut specular_weight =
        m.specular.weight * at.read(m.specular.weight_texture.as_ref(), false).w;
    let mut relative = ior / ctx.outside_ior;
    if m.volume.is_some()
        && m.transmits_specularly()
        && specular_weight != 1.0
        && relative.is_finite()
    {
        // A refracting boundary weakened by its specular weight: OpenPBR's effective IOR,
        // whose F0 is the weight times the IOR's, so that refraction and total internal
        // reflection follow the weaker reflection. Scaling the reflection alone would lose
        // the rest of what total internal reflection returns, at every hit from inside (a
        // subsurface walk meets its boundary many times).
        relative = fresnel::weighted_ior(relative, specular_weight);
        specular_weight = 1.0;
    }
    let eta = match (m.volume, ctx.front) {
        (Some(_), false) => 1.0 / relative,
        _ => relative,
    };
    let f0 = match m.specular_color {
        Some(color) => color,
        None => {
            let f0_ior = if relative.is_finite() {
                fresnel::normal_reflectance(relative)
            } else {
                1.0
            };
            let color =
                m.specular.color * at.read(m.specular.color_texture.as_ref(), true).truncate();
            (color * f0_ior).min(Vec3::ONE)
        }
    };
    let sheen = m.sheen.map(|s| {
        sheen::Sheen::new(
            s.color * at.read(s.color_texture.as_ref(), true).truncate(),
            s.roughness * at.read(s.roughness_texture.as_ref(), false).w,
        )
    });
    let coat = m.clearcoat * at.read(m.clearcoat_texture.as_ref(), false).x;
    let coat_roughness =
        m.clearcoat_roughness * at.read(m.clearcoat_roughness_texture.as_ref(), false).y;
    let coat_normal = m
        .clearcoat_normal_texture
        .as_ref()
        .and_then(|t| decode_normal(at.textures, t, m.clearcoat_normal_scale, at.attrs))
        .and_then(|n| at.tangent_to_local(n))
        .unwrap_or(Vec3::Z);
    let film = m.iridescence.map(|i| {
        let thickness_texel = i
            .thickness_texture
            .map_or(1.0, |t| texture_lookup(at.textures, &t, at.attrs, false).y);
        Film {
            factor: (i.factor * at.read(i.texture.as_ref(), false).x).clamp(0.0, 1.0),
            thickness: i.thickness_min + (i.thickness_max - i.thickness_min) * thickness_texel,
            ior: i.ior,
        }
    });
    LayeredParams {
        base,
        metallic,
        alpha,
        anisotropy_direction,
        transmission,
        transmission_tint: m.transmission_color.unwrap_or(base),
        thin: m.volume.is_none(),
        eta,
        exact: m.transmits_specularly(),
        f0,
        specular_weight,
        sheen,
        coat,
        coat_alpha: coat_roughness * coat_roughness,
        coat_normal,
        film: film.filter(|f| f.factor > 0.0),
        multiscatter: m.multiscatter,
        diffuse_roughness: m.diffuse_roughness,
        translucency: m
            .diffuse_transmission
            .map_or(0.0, |d| d.factor * at.read(d.texture.as_ref(), false).w),
        translucency_color: m.diffuse_transmission.map_or(Vec3::ONE, |d| {
            d.color * at.read(d.color_texture.as_ref(), true).truncate()
        }),
    }
}

/// The glass of a glTF material that is all transmission at a point (transmission 1,
/// metallic 0, no other layer): a [`Dielectric`] bounding its volume, or a
/// [`ThinDielectric`] wall, tinted by the base colour; `None` where the material mixes
/// other lobes in.
fn dielectric_bsdf(
    m: &Material,
    base: Vec3,
    metallic: f32,
    roughness: f32,
    transmission: f32,
    ctx: &ShadingContext,
) -> Option<Bsdf<'static>> {
    let pure = transmission >= 1.0
        && metallic <= 0.0
        && m.clearcoat == 0.0
        && m.sheen.is_none()
        && m.iridescence.is_none()
        && m.anisotropy.is_none()
        && m.specular.is_default()
        && m.specular_color.is_none();
    if !pure {
        return None;
    }
    let r = roughness.clamp(0.0, 1.0);
    let alpha = r * r;
    let ior = if m.ior > 0.0 { m.ior } else { f32::INFINITY };
    let tint = m.transmission_color.unwrap_or(base);
    Some(match m.volume {
        Some(_) => {
            let eta = if ctx.front {
                ior / ctx.outside_ior
            } else {
                ctx.outside_ior / ior
            };
            Bsdf::Dielectric(Dielectric::new(eta, alpha, tint).with_multiscatter(m.multiscatter))
        }
        None => {
            let wall = ThinDielectric::new(ior / ctx.outside_ior, alpha, tint);
            Bsdf::ThinDielectric(wall.with_multiscatter(m.multiscatter))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Specular;

    /// `is_black` holds exactly for the surfaces that reflect nothing: their f · cos θi and
    /// sample weights vanish in every direction, while every surface it rejects reflects
    /// something in some direction (a black glTF surface at grazing angles, by Fresnel).
    #[test]
    fn black_surfaces_are_the_ones_that_reflect_nothing() {
        let phong = |kd: Vec3, ks: Vec3| {
            Bsdf::Phong(Phong {
                kd,
                ks,
                exponent: 20.0,
            })
        };
        let cases = [
            Bsdf::Lambert(Lambert { albedo: Vec3::ZERO }),
            Bsdf::Lambert(Lambert {
                albedo: Vec3::new(0.0, 0.0, 0.1),
            }),
            phong(Vec3::ZERO, Vec3::ZERO),
            phong(Vec3::ZERO, Vec3::splat(0.2)),
            Bsdf::GltfPbr(GltfPbr::new(Vec3::ZERO, 0.0, 0.5, 1.5)),
            Bsdf::GltfPbr(GltfPbr::new(Vec3::ZERO, 1.0, 0.5, 1.5)),
        ];
        let directions: Vec<Vec3> = (1..12)
            .flat_map(|i| {
                let z = i as f32 / 12.0;
                let r = (1.0 - z * z).sqrt();
                (0..8).map(move |k| {
                    let phi = k as f32 * 0.785;
                    Vec3::new(r * phi.cos(), r * phi.sin(), z)
                })
            })
            .collect();
        for (i, bsdf) in cases.iter().enumerate() {
            let reflects = directions.iter().any(|&wo| {
                directions.iter().any(|&wi| bsdf.eval(wo, wi) != Vec3::ZERO)
                    || [0.1, 0.5, 0.9].iter().any(|&u| {
                        bsdf.sample(wo, u, Vec2::new(u, 1.0 - u))
                            .is_some_and(|s| s.weight != Vec3::ZERO)
                    })
            });
            assert_eq!(bsdf.is_black(), !reflects, "case {i}");
        }
    }

    /// Directions over the upper hemisphere, grazing ones included.
    fn hemisphere() -> Vec<Vec3> {
        (1..12)
            .flat_map(|i| {
                let z = i as f32 / 12.0;
                let r = (1.0 - z * z).sqrt();
                (0..8).map(move |k| {
                    let phi = k as f32 * 0.785 + 0.1;
                    Vec3::new(r * phi.cos(), r * phi.sin(), z)
                })
            })
            .collect()
    }

    /// The layered model of `m` at a point, built whatever the reductions say.
    fn layered(m: &Material) -> Layered {
        let attrs = SurfaceAttributes {
            uv: [Vec2::ZERO; 2],
            color: Vec4::ONE,
            footprint: [[glam::Vec2::ZERO; 2]; 2],
        };
        let ctx = ShadingContext::default();
        let at = Point {
            textures: &[],
            attrs: &attrs,
            ctx: &ctx,
        };
        let base = m.base_color.truncate();
        Layered::new(layered_params(m, &at, base, m.metallic, m.roughness, 0.0))
    }

    /// A glTF material whose specular layer weighs nothing and that is neither metal nor
    /// coated reduces to Lambert, and an uncoated all-metal one to `gltf_pbr`'s conductor,
    /// and each reduction is the layered model it replaces: the same f · cos θi in every
    /// pair of directions (to float rounding: the two compute GGX in another order), and the
    /// material-level classification that the render plan reports agrees.
    #[test]
    fn zero_weight_lobes_reduce_to_the_same_bsdf() {
        let colour = Vec4::new(0.8, 0.4, 0.2, 1.0);
        let lambertian = Material {
            base_color: colour,
            metallic: 0.0,
            roughness: 0.4,
            specular: Specular {
                weight: 0.0,
                ..Specular::default()
            },
            sheen: Some(crate::scene::Sheen {
                color: Vec3::ZERO,
                color_texture: None,
                roughness: 0.5,
                roughness_texture: None,
            }),
            ..Material::default()
        };
        let metal = Material {
            base_color: colour,
            metallic: 1.0,
            roughness: 0.3,
            specular: Specular {
                weight: 0.5,
                color: Vec3::new(1.0, 0.5, 0.5),
                ..Specular::default()
            },
            ..Material::default()
        };
        let mut storage = BsdfStorage::default();
        let attrs = SurfaceAttributes {
            uv: [Vec2::ZERO; 2],
            color: Vec4::ONE,
            footprint: [[glam::Vec2::ZERO; 2]; 2],
        };
        for (m, reduced) in [
            (&lambertian, crate::scene::Reduced::Lambert),
            (&metal, crate::scene::Reduced::Conductor),
        ] {
            assert_eq!(m.reduced(), Some(reduced));
            let simple = bsdf(m, &[], &attrs, &mut storage);
            match (reduced, &simple) {
                (crate::scene::Reduced::Lambert, Bsdf::Lambert(_))
                | (crate::scene::Reduced::Conductor, Bsdf::GltfPbr(_)) => {}
                _ => panic!("{reduced:?}: built {simple:?}"),
            }
            let full = layered(m);
            for &wo in &hemisphere() {
                for &wi in &hemisphere() {
                    let (a, b) = (simple.eval(wo, wi), full.eval(wo, wi));
                    assert!(
                        (a - b).abs().max_element() <= 1e-4 * b.max_element().max(1e-3),
                        "{reduced:?} at {wo} {wi}: {a} against {b}"
                    );
                }
            }
        }
        // A specular layer of some weight, a coat, a sheen or a metallic texture keep the
        // full model.
        for m in [
            Material {
                specular: Specular {
                    weight: 0.1,
                    ..lambertian.specular
                },
                ..lambertian.clone()
            },
            Material {
                clearcoat: 0.5,
                ..lambertian.clone()
            },
            Material {
                sheen: Some(crate::scene::Sheen {
                    color: Vec3::splat(0.5),
                    ..lambertian.sheen.unwrap()
                }),
                ..lambertian.clone()
            },
            Material {
                metallic: 0.5,
                ..metal.clone()
            },
        ] {
            assert_eq!(m.reduced(), None, "{m:?}");
            assert!(matches!(
                bsdf(&m, &[], &attrs, &mut storage),
                Bsdf::Layered(_)
            ));
        }
    }
}
