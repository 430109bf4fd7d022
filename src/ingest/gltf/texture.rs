//! Textures: images decoded once and shared, samplers' wrap modes, texture coordinate sets
//! and KHR_texture_transform.

use super::super::image as img;
use super::super::uri;
use super::Importer;
use crate::error::{Error, Result};
use crate::scene::{self, TextureRef, UvTransform, Wrap, texture_cache};
use glam::Vec2;
use std::sync::Arc;

impl<'a> Importer<'a> {
    /// The texture slot of a material's texture info, if present.
    pub(super) fn info_ref(
        &mut self,
        info: Option<gltf::texture::Info>,
    ) -> Result<Option<TextureRef>> {
        info.map(|t| {
            self.texture_ref(
                t.texture(),
                t.tex_coord(),
                t.texture_transform().map(TextureTransform::from),
            )
        })
        .transpose()
    }

    pub(super) fn texture_ref(
        &mut self,
        texture: gltf::Texture,
        tex_coord: u32,
        transform: Option<TextureTransform>,
    ) -> Result<TextureRef> {
        let index = self.texture(&texture)?;
        let (tex_coord, transform) = match transform {
            Some(t) => {
                if !(t.offset.is_finite() && t.rotation.is_finite() && t.scale.is_finite()) {
                    return Err(self.err(
                        format!("textures[{}]", texture.index()),
                        "KHR_texture_transform is not finite",
                    ));
                }
                (
                    t.tex_coord.unwrap_or(tex_coord),
                    Some(UvTransform::new(t.offset, t.rotation, t.scale)),
                )
            }
            None => (tex_coord, None),
        };
        if tex_coord > 1 {
            self.warn(
                format!("textures[{}]", texture.index()),
                format!("TEXCOORD_{tex_coord} is not supported; set 0 is used"),
            );
        }
        Ok(TextureRef {
            texture: index,
            tex_coord: tex_coord.min(1),
            transform,
        })
    }

    pub(super) fn texture(&mut self, texture: &gltf::Texture) -> Result<u32> {
        if let Some(&index) = self.textures.get(&texture.index()) {
            return Ok(index);
        }
        let image = self.texture_image(texture)?;
        let element = format!("images[{}]", image.index());
        let decoded = match self.images.get(&image.index()) {
            Some(d) => d.clone(),
            None => {
                let bytes = self.image_bytes(&image)?;
                let d = img::decode(&bytes).map_err(|r| self.err(&element, r))?;
                let texels = match self.texture_plan.cache_of(image.index()) {
                    Some(cache) => (d.texels)
                        .to_tiled(&element, d.width, d.height, cache)
                        .map_err(|e| {
                            Error::other(
                                &self.source,
                                &element,
                                format!("writing its tiled copy failed: {e}"),
                            )
                        })?,
                    None => d.texels,
                };
                let decoded = (d.width, d.height, Arc::new(texels));
                self.images.insert(image.index(), decoded.clone());
                decoded
            }
        };
        let sampler = texture.sampler();
        let wrap = |w: gltf::texture::WrappingMode| match w {
            gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
            gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
            gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
        };
        self.scene.textures.push(scene::Texture {
            name: image.name().map_or(element, str::to_string),
            width: decoded.0,
            height: decoded.1,
            texels: decoded.2,
            mips: Default::default(),
            wrap_u: wrap(sampler.wrap_s()),
            wrap_v: wrap(sampler.wrap_t()),
            nearest: sampler.mag_filter() == Some(gltf::texture::MagFilter::Nearest),
            // minFilter NEAREST or LINEAR: the author asks for no MIP levels.
            mipmaps: !matches!(
                sampler.min_filter(),
                Some(gltf::texture::MinFilter::Nearest | gltf::texture::MinFilter::Linear)
            ),
            udim: None,
        });
        let index = (self.scene.textures.len() - 1) as u32;
        self.textures.insert(texture.index(), index);
        Ok(index)
    }

    /// The encoded bytes of `image`: borrowed from its buffer view, or read from its URI.
    fn image_bytes(&self, image: &gltf::Image) -> Result<std::borrow::Cow<'_, [u8]>> {
        let element = format!("images[{}]", image.index());
        match image.source() {
            gltf::image::Source::View { view, .. } => {
                let data = self
                    .buffers
                    .get(view.buffer().index())
                    .map(Vec::as_slice)
                    .unwrap_or(&[]);
                let end = view.offset().checked_add(view.length());
                match end.and_then(|end| data.get(view.offset()..end)) {
                    Some(slice) => Ok(slice.into()),
                    None => Err(self.err(&element, "bufferView runs past the end of its buffer")),
                }
            }
            gltf::image::Source::Uri { uri: u, .. } => (uri::read(u, self.base))
                .map(Into::into)
                .map_err(|r| self.err(format!("{element}.uri"), r)),
        }
    }

    /// Chooses how the file's images are held before any is decoded: in memory, or (when
    /// the images its textures show need more than the texture memory, decoded and with
    /// their MIP levels, as their headers say) the largest on disk through a tile cache,
    /// which the scene's warnings then report ([`texture_cache::TexturePlan`]).
    pub(super) fn plan_texture_memory(&mut self) {
        if crate::memory::texture_memory().is_none() {
            return; // No limit: every image stays in memory, unmeasured.
        }
        let mut shown = std::collections::BTreeSet::new();
        for texture in self.doc.textures() {
            if let Ok(image) = self.texture_image(&texture) {
                shown.insert(image.index());
            }
        }
        let sizes: Vec<u64> = (self.doc.images())
            .map(|image| match shown.contains(&image.index()) {
                true => (self.image_bytes(&image).ok())
                    .and_then(|b| img::decoded_bytes(&b))
                    .unwrap_or(0),
                false => 0,
            })
            .collect();
        self.texture_plan = texture_cache::TexturePlan::new(&sizes, &[]);
        if let Some(notice) = self.texture_plan.notice(&self.source) {
            self.scene.warnings.push(notice);
        }
    }

    /// The image a texture shows: its EXT_texture_webp or KHR_texture_basisu (KTX2) image
    /// where it has one, else its core `source` (for those extensions, the fallback PNG or
    /// JPEG that clients without them read).
    pub(super) fn texture_image(&mut self, texture: &gltf::Texture) -> Result<gltf::Image<'a>> {
        let element = format!("textures[{}]", texture.index());
        let extension_source = |name: &str| {
            texture
                .extensions()
                .and_then(|e| e.get(name))
                .and_then(|e| e.get("source"))
                .and_then(serde_json::Value::as_u64)
        };
        for extension in ["EXT_texture_webp", "KHR_texture_basisu"] {
            if let Some(i) = extension_source(extension) {
                return self.doc.images().nth(i as usize).ok_or_else(|| {
                    self.err(
                        format!("{element}.extensions.{extension}.source"),
                        format!("image {i} does not exist"),
                    )
                });
            }
        }
        match texture
            .source()
            .and_then(|i| self.doc.images().nth(i.index()))
        {
            Some(image) => Ok(image),
            None => Err(self.err(&element, "has no image (no source)")),
        }
    }
}

/// A KHR_texture_transform's values.
pub(super) struct TextureTransform {
    offset: Vec2,
    rotation: f32,
    scale: Vec2,
    tex_coord: Option<u32>,
}

impl From<gltf::texture::TextureTransform<'_>> for TextureTransform {
    fn from(t: gltf::texture::TextureTransform) -> Self {
        Self {
            offset: Vec2::from_array(t.offset()),
            rotation: t.rotation(),
            scale: Vec2::from_array(t.scale()),
            tex_coord: t.tex_coord(),
        }
    }
}

/// Reads a KHR_texture_transform from raw JSON (normal textures do not expose it typed).
pub(super) fn transform_from_json(v: &serde_json::Value) -> TextureTransform {
    let pair = |key: &str, default: f32| {
        let get = |i: usize| {
            v.get(key)
                .and_then(|a| a.get(i))
                .and_then(|x| x.as_f64())
                .map_or(default, |x| x as f32)
        };
        Vec2::new(get(0), get(1))
    };
    TextureTransform {
        offset: pair("offset", 0.0),
        rotation: v
            .get("rotation")
            .and_then(|x| x.as_f64())
            .map_or(0.0, |x| x as f32),
        scale: pair("scale", 1.0),
        tex_coord: v
            .get("texCoord")
            .and_then(|x| x.as_u64())
            .map(|x| x.min(u32::MAX as u64) as u32),
    }
}
