//! Materials: metallic-roughness with the KHR_materials extensions lucerna implements
//! (clear coat, sheen, specular, transmission, volume, IOR, iridescence, anisotropy,
//! emissive strength, unlit), KHR_materials_variants, lucerna's BSDF selection in `extras`,
//! and one warning per unsupported extension.

use super::Importer;
use super::document::SUPPORTED_EXTENSIONS;
use super::texture::transform_from_json;
use super::{LucernaExtras, MediumExtras, SpecularValue};
use crate::error::Result;
use crate::scene::{self, AlphaMode, BsdfModel, Material, TextureRef};
use glam::{Vec3, Vec4};

impl<'a> Importer<'a> {
    pub(super) fn select_variant(&mut self, name: Option<&str>) -> Result<()> {
        let names: Vec<String> = self
            .doc
            .extension_value("KHR_materials_variants")
            .and_then(|e| e.get("variants"))
            .and_then(serde_json::Value::as_array)
            .map(|v| {
                v.iter()
                    .map(|v| {
                        v.get("name")
                            .and_then(serde_json::Value::as_str)
                            .unwrap_or("")
                            .to_string()
                    })
                    .collect()
            })
            .unwrap_or_default();
        match name {
            Some(name) => match names.iter().position(|n| n == name) {
                Some(i) => self.variant = Some(i),
                None if names.is_empty() => {
                    return Err(self.err(
                        "extensions.KHR_materials_variants",
                        format!("material variant {name:?} requested, but the file has no variants"),
                    ));
                }
                None => {
                    return Err(self.err(
                        "extensions.KHR_materials_variants",
                        format!(
                            "has no material variant {name:?} (it has {})",
                            names.join(", ")
                        ),
                    ));
                }
            },
            None if !names.is_empty() => self.warn(
                "extensions.KHR_materials_variants",
                format!(
                    "the file has material variants {}; the default materials are rendered (--material-variant NAME)",
                    names.join(", ")
                ),
            ),
            None => {}
        }
        Ok(())
    }

    /// The material the selected variant maps `primitive` to, if it maps it.
    pub(super) fn variant_material(
        &self,
        primitive: &gltf::Primitive,
    ) -> Option<gltf::Material<'a>> {
        let variant = self.variant? as u64;
        let mappings = primitive
            .extensions()?
            .get("KHR_materials_variants")?
            .get("mappings")?
            .as_array()?;
        let material = mappings.iter().find_map(|m| {
            let listed = m.get("variants")?.as_array()?;
            listed
                .iter()
                .any(|v| v.as_u64() == Some(variant))
                .then(|| m.get("material")?.as_u64())?
        })?;
        self.doc.materials().nth(material as usize)
    }

    pub(super) fn material(&mut self, m: gltf::Material) -> Result<u32> {
        if let Some(&index) = self.materials.get(&m.index()) {
            return Ok(index);
        }
        let converted = match m.index() {
            None => Material::default(),
            Some(i) => self.convert_material(&m, &format!("materials[{i}]"))?,
        };
        self.scene.materials.push(converted);
        let index = (self.scene.materials.len() - 1) as u32;
        self.materials.insert(m.index(), index);
        Ok(index)
    }

    pub(super) fn convert_material(
        &mut self,
        m: &gltf::Material,
        element: &str,
    ) -> Result<Material> {
        let pbr = m.pbr_metallic_roughness();
        let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
        let base_color = Vec4::from_array(pbr.base_color_factor());
        let emissive = Vec3::from_array(m.emissive_factor()) * m.emissive_strength().unwrap_or(1.0);
        if !finite(&base_color.to_array())
            || !emissive.is_finite()
            || !pbr.metallic_factor().is_finite()
            || !pbr.roughness_factor().is_finite()
        {
            return Err(self.err(element, "a factor is not finite"));
        }
        // Ranges of the specification's schema (glTF-Validator: VALUE_NOT_IN_RANGE, an error).
        let unit = |x: f32| (0.0..=1.0).contains(&x);
        for (key, ok) in [
            (
                "pbrMetallicRoughness.baseColorFactor",
                base_color.to_array().into_iter().all(unit),
            ),
            (
                "pbrMetallicRoughness.metallicFactor",
                unit(pbr.metallic_factor()),
            ),
            (
                "pbrMetallicRoughness.roughnessFactor",
                unit(pbr.roughness_factor()),
            ),
            ("emissiveFactor", m.emissive_factor().into_iter().all(unit)),
            ("alphaCutoff", m.alpha_cutoff().is_none_or(|c| c >= 0.0)),
            (
                "occlusionTexture.strength",
                m.occlusion_texture().is_none_or(|t| unit(t.strength())),
            ),
            (
                "KHR_materials_emissive_strength.emissiveStrength",
                m.emissive_strength().is_none_or(|s| s >= 0.0),
            ),
        ] {
            if !ok {
                return Err(self.err(element, format!("{key} is outside its range (factors are in [0, 1], strengths and cutoffs not negative)")));
            }
        }
        let extras = self.lucerna_extras(m, element)?;
        let (model, diffuse_roughness) = (extras.model, extras.diffuse_roughness);
        let base_color_texture = self.info_ref(pbr.base_color_texture())?;
        let metallic_roughness_texture = self.info_ref(pbr.metallic_roughness_texture())?;
        let normal = m.normal_texture();
        let normal_texture = normal
            .as_ref()
            .map(|t| {
                let transform = t
                    .extension_value("KHR_texture_transform")
                    .map(transform_from_json);
                self.texture_ref(t.texture(), t.tex_coord(), transform)
            })
            .transpose()?;
        let emissive_texture = self.info_ref(m.emissive_texture())?;
        if m.occlusion_texture().is_some() {
            self.warn(
                element,
                "occlusionTexture ignored (a path tracer computes occlusion)",
            );
        }
        let alpha_mode = match m.alpha_mode() {
            gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
            gltf::material::AlphaMode::Mask => AlphaMode::Mask {
                cutoff: m.alpha_cutoff().unwrap_or(0.5),
            },
            gltf::material::AlphaMode::Blend => AlphaMode::Blend,
        };
        let name = m.name().map_or_else(|| element.to_string(), str::to_string);
        let mut material = Material {
            name: name.clone(),
            model,
            base_color,
            base_color_texture,
            metallic: pbr.metallic_factor().clamp(0.0, 1.0),
            roughness: pbr.roughness_factor().clamp(0.0, 1.0),
            metallic_roughness_texture,
            normal_texture,
            normal_scale: normal.map_or(1.0, |n| n.scale()),
            emissive: emissive.max(Vec3::ZERO),
            emissive_texture,
            ior: m.ior().unwrap_or(1.5),
            alpha_mode,
            double_sided: m.double_sided(),
            diffuse_roughness,
            ..Material::default()
        };
        if !(material.ior == 0.0 || material.ior >= 1.0) || !material.ior.is_finite() {
            self.warn(
                element,
                format!(
                    "KHR_materials_ior.ior {} is outside [1, inf) and not 0; 1.5 is used",
                    material.ior
                ),
            );
            material.ior = 1.5;
        }
        let extensions = MaterialExtensions {
            element,
            json: m
                .extensions()
                .map(|e| e.iter().map(|(k, v)| (k.as_str(), v)).collect())
                .unwrap_or_default(),
        };
        self.material_extensions(&extensions, &mut material)?;
        if let Some(medium) = extras.medium {
            // The extension's absorption stays where the medium gives none.
            let absorption = material.volume.map_or(Vec3::ZERO, |v| v.absorption);
            let density = match &medium.density {
                Some(uri) => Some(self.density_grid(
                    uri,
                    (medium.density_grid.as_deref(), None),
                    element,
                    ("density", "density_grid"),
                )?),
                None => None,
            };
            let blackbody = match &medium.blackbody {
                Some(b) => {
                    let g = self.density_grid(
                        &b.temperature,
                        (b.temperature_grid.as_deref(), Some("temperature")),
                        element,
                        ("blackbody.temperature", "blackbody.temperature_grid"),
                    )?;
                    let blackbody = scene::Blackbody {
                        temperature: Some(g),
                        kelvin: b.kelvin,
                        intensity: b.intensity,
                        tint: b.tint.as_ref().map_or(Vec3::ONE, SpecularValue::rgb),
                    };
                    if let Some(reason) = blackbody.too_hot(&self.scene.grids[g as usize]) {
                        return Err(
                            self.err(format!("{element}.extras.lucerna.medium.blackbody"), reason)
                        );
                    }
                    Some(blackbody)
                }
                None => None,
            };
            let emission_field = match &medium.emission_field {
                Some(f) => Some(scene::EmissionField {
                    grid: Some(self.density_grid(
                        &f.file,
                        (f.grid.as_deref(), Some("emission")),
                        element,
                        ("emission_field.file", "emission_field.grid"),
                    )?),
                    tint: f.tint.as_ref().map_or(Vec3::ONE, SpecularValue::rgb),
                }),
                None => None,
            };
            let scatter_color = match &medium.scatter_color {
                Some(c) => Some(self.color_grids(&c.file, c.grid.as_deref(), element)?),
                None => None,
            };
            material.volume = Some(scene::Volume {
                absorption: medium.absorption.map_or(absorption, |a| a.rgb()),
                scattering: medium.scattering.map_or(Vec3::ZERO, |s| s.rgb()),
                anisotropy: medium.anisotropy,
                density,
                emission: medium.emission.map_or(Vec3::ZERO, |e| e.rgb()),
                blackbody,
                emission_field,
                scatter_color,
            });
        } else if model == BsdfModel::Interface && material.volume.is_none() {
            self.warn(
                element,
                "an interface without extras.lucerna.medium bounds nothing and is invisible",
            );
        }
        for name in extensions.json.keys() {
            if !SUPPORTED_EXTENSIONS.contains(name) {
                self.unsupported_material_extensions
                    .entry(name.to_string())
                    .or_default()
                    .push(material.name.clone());
            }
        }
        if material.unlit && material.emissive_texture.is_some() {
            self.warn(element, "KHR_materials_unlit: the emission is ignored");
        }
        Ok(material)
    }

    /// Reads the material extensions lucerna implements into `material`: clear coat (with
    /// its textures and normal map), transmission, volume, specular, sheen, iridescence,
    /// anisotropy, unlit. Factors must be finite numbers (an error names the one that is
    /// not); values outside the specification's range are clamped into it with a warning.
    pub(super) fn material_extensions(
        &mut self,
        ext: &MaterialExtensions,
        material: &mut Material,
    ) -> Result<()> {
        if let Some(e) = ext.get("KHR_materials_clearcoat") {
            let name = "KHR_materials_clearcoat";
            material.clearcoat = self.unit_factor(ext, name, e, "clearcoatFactor", 0.0)?;
            material.clearcoat_texture = self.json_texture(ext, e, "clearcoatTexture")?;
            material.clearcoat_roughness =
                self.unit_factor(ext, name, e, "clearcoatRoughnessFactor", 0.0)?;
            material.clearcoat_roughness_texture =
                self.json_texture(ext, e, "clearcoatRoughnessTexture")?;
            material.clearcoat_normal_texture =
                self.json_texture(ext, e, "clearcoatNormalTexture")?;
            if let Some(n) = e.get("clearcoatNormalTexture") {
                material.clearcoat_normal_scale = ext.number(self, name, n, "scale", 1.0)?;
            }
        }
        if let Some(e) = ext.get("KHR_materials_transmission") {
            let name = "KHR_materials_transmission";
            material.transmission = self.unit_factor(ext, name, e, "transmissionFactor", 0.0)?;
            material.transmission_texture = self.json_texture(ext, e, "transmissionTexture")?;
        }
        if let Some(e) = ext.get("KHR_materials_volume") {
            let name = "KHR_materials_volume";
            let thickness = ext.number(self, name, e, "thicknessFactor", 0.0)?;
            let distance = ext.number(self, name, e, "attenuationDistance", f32::INFINITY)?;
            let color = ext.color(self, name, e, "attenuationColor", Vec3::ONE)?;
            if thickness < 0.0 || distance <= 0.0 {
                self.warn(
                    ext.element,
                    format!("{name}: thicknessFactor must be >= 0 and attenuationDistance > 0; the volume is ignored"),
                );
            } else if thickness > 0.0 {
                // σ = -ln(c) / d per world unit (Beer-Lambert), zero where c is 1 or d infinite.
                let color = color.clamp(Vec3::splat(1e-6), Vec3::ONE);
                let absorption = if distance.is_finite() {
                    -Vec3::new(color.x.ln(), color.y.ln(), color.z.ln()) / distance
                } else {
                    Vec3::ZERO
                };
                material.volume = Some(scene::Volume::absorbing(absorption.max(Vec3::ZERO)));
            }
        }
        if let Some(e) = ext.get("KHR_materials_diffuse_transmission") {
            let name = "KHR_materials_diffuse_transmission";
            let factor = self.unit_factor(ext, name, e, "diffuseTransmissionFactor", 0.0)?;
            let color = ext.color(self, name, e, "diffuseTransmissionColorFactor", Vec3::ONE)?;
            if color.min_element() < 0.0 || color.max_element() > 1.0 {
                return Err(self.err(
                    ext.element,
                    format!("{name}.diffuseTransmissionColorFactor = {color} is outside [0, 1]"),
                ));
            }
            let texture = self.json_texture(ext, e, "diffuseTransmissionTexture")?;
            let color_texture = self.json_texture(ext, e, "diffuseTransmissionColorTexture")?;
            if factor > 0.0 {
                material.diffuse_transmission = Some(scene::DiffuseTransmission {
                    factor,
                    texture,
                    color,
                    color_texture,
                });
            }
        }
        if let Some(e) = ext.get("KHR_materials_specular") {
            let name = "KHR_materials_specular";
            let weight = ext.number(self, name, e, "specularFactor", 1.0)?;
            let color = ext.color(self, name, e, "specularColorFactor", Vec3::ONE)?;
            if weight < 0.0 || color.min_element() < 0.0 {
                self.warn(
                    ext.element,
                    format!("{name}: negative factors are taken as 0"),
                );
            }
            material.specular = scene::Specular {
                weight: weight.clamp(0.0, 1.0),
                weight_texture: self.json_texture(ext, e, "specularTexture")?,
                color: color.max(Vec3::ZERO),
                color_texture: self.json_texture(ext, e, "specularColorTexture")?,
            };
        }
        if let Some(e) = ext.get("KHR_materials_sheen") {
            let name = "KHR_materials_sheen";
            let color = ext.color(self, name, e, "sheenColorFactor", Vec3::ZERO)?;
            let color_texture = self.json_texture(ext, e, "sheenColorTexture")?;
            let roughness = self.unit_factor(ext, name, e, "sheenRoughnessFactor", 0.0)?;
            let roughness_texture = self.json_texture(ext, e, "sheenRoughnessTexture")?;
            // A black sheen colour disables the layer.
            if color.max_element() > 0.0 {
                material.sheen = Some(scene::Sheen {
                    color: color.clamp(Vec3::ZERO, Vec3::ONE),
                    color_texture,
                    roughness,
                    roughness_texture,
                });
            }
        }
        if let Some(e) = ext.get("KHR_materials_iridescence") {
            let name = "KHR_materials_iridescence";
            let factor = self.unit_factor(ext, name, e, "iridescenceFactor", 0.0)?;
            let ior = ext.number(self, name, e, "iridescenceIor", 1.3)?;
            let thickness_min = ext.number(self, name, e, "iridescenceThicknessMinimum", 100.0)?;
            let thickness_max = ext.number(self, name, e, "iridescenceThicknessMaximum", 400.0)?;
            if ior < 1.0 || thickness_min < 0.0 || thickness_max < 0.0 {
                self.warn(
                    ext.element,
                    format!("{name}: iridescenceIor must be >= 1 and thicknesses >= 0; clamped"),
                );
            }
            let texture = self.json_texture(ext, e, "iridescenceTexture")?;
            let thickness_texture = self.json_texture(ext, e, "iridescenceThicknessTexture")?;
            if factor > 0.0 {
                material.iridescence = Some(scene::Iridescence {
                    factor,
                    texture,
                    ior: ior.max(1.0),
                    thickness_min: thickness_min.max(0.0),
                    thickness_max: thickness_max.max(0.0),
                    thickness_texture,
                });
            }
        }
        if let Some(e) = ext.get("KHR_materials_anisotropy") {
            let name = "KHR_materials_anisotropy";
            let strength = self.unit_factor(ext, name, e, "anisotropyStrength", 0.0)?;
            let rotation = ext.number(self, name, e, "anisotropyRotation", 0.0)?;
            let texture = self.json_texture(ext, e, "anisotropyTexture")?;
            if strength > 0.0 {
                material.anisotropy = Some(scene::Anisotropy {
                    strength,
                    rotation,
                    texture,
                });
            }
        }
        material.unlit = ext.get("KHR_materials_unlit").is_some();
        Ok(())
    }

    /// A factor in [0, 1] of extension `name`'s JSON `e` (default `default`); a number
    /// outside the range is an error, as glTF-Validator classifies it (VALUE_NOT_IN_RANGE).
    pub(super) fn unit_factor(
        &mut self,
        ext: &MaterialExtensions,
        name: &str,
        e: &serde_json::Value,
        key: &str,
        default: f32,
    ) -> Result<f32> {
        let x = ext.number(self, name, e, key, default)?;
        if !(0.0..=1.0).contains(&x) {
            return Err(self.err(ext.element, format!("{name}.{key} = {x} is outside [0, 1]")));
        }
        Ok(x)
    }

    /// The texture slot of a textureInfo in an extension's JSON (`e[key]`), if present.
    pub(super) fn json_texture(
        &mut self,
        ext: &MaterialExtensions,
        e: &serde_json::Value,
        key: &str,
    ) -> Result<Option<TextureRef>> {
        let Some(info) = e.get(key) else {
            return Ok(None);
        };
        let element = format!("{}.{key}", ext.element);
        let index = info
            .get("index")
            .and_then(serde_json::Value::as_u64)
            .ok_or_else(|| self.err(&element, "textureInfo needs an integer \"index\""))?;
        let Some(texture) = usize::try_from(index)
            .ok()
            .and_then(|i| self.doc.textures().nth(i))
        else {
            return Err(self.err(&element, format!("texture {index} does not exist")));
        };
        let tex_coord = match info.get("texCoord") {
            None => 0,
            Some(v) => v
                .as_u64()
                .map(|x| x.min(u32::MAX as u64) as u32)
                .ok_or_else(|| self.err(&element, "texCoord is not an integer"))?,
        };
        let transform = info
            .get("extensions")
            .and_then(|x| x.get("KHR_texture_transform"))
            .map(transform_from_json);
        self.texture_ref(texture, tex_coord, transform).map(Some)
    }

    /// One warning for each unsupported extension, naming the materials that use it.
    pub(super) fn warn_unsupported_extensions(&mut self) {
        let by_material = std::mem::take(&mut self.unsupported_material_extensions);
        for ext in self.doc.extensions_used() {
            if SUPPORTED_EXTENSIONS.contains(&ext) {
                continue;
            }
            let detail = match ext {
                "KHR_materials_dispersion" => {
                    ": refraction uses the material's ior at every wavelength"
                }
                "KHR_materials_pbrSpecularGlossiness" => {
                    ": the metallic-roughness parameters are rendered"
                }
                _ => "",
            };
            let users = match by_material.get(ext) {
                Some(names) => format!(" (materials: {})", names.join(", ")),
                None => String::new(),
            };
            self.warn(
                "extensionsUsed",
                format!("extension {ext} is not supported and is ignored{detail}{users}"),
            );
        }
    }

    /// The scene grid of the file at `uri` (a `.vol` file, or grid `name` of a `.vdb`
    /// file, by default `vdb_default` or else its `density` or only grid; read once however
    /// many materials use it); `element` is the material's, `field` the medium's property
    /// that names the file and `grid_field` the one that names the grid, for messages.
    fn density_grid(
        &mut self,
        uri: &str,
        (name, vdb_default): (Option<&str>, Option<&str>),
        element: &str,
        (field, grid_field): (&str, &str),
    ) -> Result<u32> {
        let key = format!("{uri}\u{1e}{}", name.or(vdb_default).unwrap_or_default());
        if let Some(&g) = self.grids.get(&key) {
            return Ok(g);
        }
        let e = format!("{element}.extras.lucerna.medium.{field}");
        let bytes = crate::ingest::uri::read(uri, self.base).map_err(|r| self.err(&e, r))?;
        let grid = if crate::ingest::vdb::is_vdb(&bytes) {
            let read = crate::ingest::vdb::parse(&bytes, uri, name.or(vdb_default))
                .map_err(|r| self.err(&e, format!("{uri}: {r}")))?;
            for warning in &read.warnings {
                self.warn(&e, warning);
            }
            read.grid
        } else if name.is_some() {
            return Err(self.err(
                format!("{element}.extras.lucerna.medium.{grid_field}"),
                format!("{uri} is not an OpenVDB file, whose grids could be named"),
            ));
        } else {
            crate::ingest::vol::parse(&bytes, uri)
                .map_err(|r| self.err(&e, format!("{uri}: {r}")))?
        };
        let g = self.scene.grids.len() as u32;
        self.scene.grids.push(grid);
        self.grids.insert(key, g);
        Ok(g)
    }

    /// The scene grids (red, green, blue) of colour grid `name` of the OpenVDB file at `uri`
    /// (read once however many materials use it); `element` is the material's.
    fn color_grids(&mut self, uri: &str, name: Option<&str>, element: &str) -> Result<[u32; 3]> {
        let key = format!("{uri}\u{1e}{}\u{1e}rgb", name.unwrap_or_default());
        if let Some(&g) = self.grids.get(&key) {
            return Ok([g, g + 1, g + 2]);
        }
        let e = format!("{element}.extras.lucerna.medium.scatter_color.file");
        let bytes = crate::ingest::uri::read(uri, self.base).map_err(|r| self.err(&e, r))?;
        if !crate::ingest::vdb::is_vdb(&bytes) {
            return Err(self.err(&e, format!("{uri} is not an OpenVDB file")));
        }
        let read = crate::ingest::vdb::parse_color(&bytes, uri, name)
            .map_err(|r| self.err(&e, format!("{uri}: {r}")))?;
        for warning in &read.warnings {
            self.warn(&e, warning);
        }
        let g = self.scene.grids.len() as u32;
        self.scene.grids.extend(read.channels);
        self.grids.insert(key, g);
        Ok([g, g + 1, g + 2])
    }

    /// The BSDF model, the diffuse roughness and the medium from `extras.lucerna` (default:
    /// the glTF BRDF, a Lambertian base, no medium).
    pub(super) fn lucerna_extras(&self, m: &gltf::Material, element: &str) -> Result<Extras> {
        let none = Extras {
            model: BsdfModel::GltfPbr,
            diffuse_roughness: 0.0,
            medium: None,
        };
        let Some(raw) = m.extras() else {
            return Ok(none);
        };
        let e = format!("{element}.extras.lucerna");
        let value: serde_json::Value =
            serde_json::from_str(raw.get()).map_err(|err| self.err(&e, err.to_string()))?;
        let Some(section) = value.get("lucerna") else {
            return Ok(none);
        };
        let extras: LucernaExtras =
            serde_json::from_value(section.clone()).map_err(|err| self.err(&e, err.to_string()))?;
        let diffuse_roughness = extras.diffuse_roughness.unwrap_or(0.0);
        if !(0.0..=1.0).contains(&diffuse_roughness) {
            return Err(self.err(
                &e,
                format!("diffuse_roughness {diffuse_roughness} must be in [0, 1]"),
            ));
        }
        if let Some(medium) = &extras.medium {
            let coefficient = |v: &Option<SpecularValue>| {
                v.as_ref().is_none_or(|v| {
                    let c = v.rgb();
                    c.is_finite() && c.min_element() >= 0.0 && c.max_element() <= MAX_COEFFICIENT
                })
            };
            if !(coefficient(&medium.absorption)
                && coefficient(&medium.scattering)
                && coefficient(&medium.emission))
            {
                return Err(self.err(
                    format!("{e}.medium"),
                    format!(
                        "absorption, scattering and emission must be in [0, {MAX_COEFFICIENT:e}] per metre"
                    ),
                ));
            }
            if !(medium.anisotropy.abs() < 1.0) {
                return Err(self.err(
                    format!("{e}.medium.anisotropy"),
                    format!("{} must be in (-1, 1)", medium.anisotropy),
                ));
            }
            if let Some(b) = &medium.blackbody {
                let eb = format!("{e}.medium.blackbody");
                if medium.density.is_none() {
                    return Err(self.err(
                        eb,
                        "a blackbody needs the medium's density grid (medium.density)",
                    ));
                }
                if !(b.kelvin.is_finite() && b.kelvin > 0.0) {
                    return Err(self.err(
                        format!("{eb}.kelvin"),
                        format!("{} must be positive and finite", b.kelvin),
                    ));
                }
                let intensity_ok =
                    b.intensity.is_finite() && (0.0..=MAX_COEFFICIENT).contains(&b.intensity);
                if !(intensity_ok && coefficient(&b.tint)) {
                    return Err(self.err(
                        eb,
                        format!("intensity and tint must be in [0, {MAX_COEFFICIENT:e}]"),
                    ));
                }
            }
            if medium.scatter_color.is_some() && medium.density.is_none() {
                return Err(self.err(
                    format!("{e}.medium.scatter_color"),
                    "a scatter colour grid needs the medium's density grid (medium.density)",
                ));
            }
            if let Some(f) = &medium.emission_field {
                let ef = format!("{e}.medium.emission_field");
                if medium.density.is_none() {
                    return Err(self.err(
                        ef,
                        "an emission field needs the medium's density grid (medium.density)",
                    ));
                }
                if medium.blackbody.is_some() {
                    return Err(self.err(
                        ef,
                        "a medium glows by one field: a blackbody or an emission field",
                    ));
                }
                if !coefficient(&f.tint) {
                    return Err(self.err(
                        format!("{ef}.tint"),
                        format!("must be in [0, {MAX_COEFFICIENT:e}]"),
                    ));
                }
            }
        }
        Ok(Extras {
            model: self.bsdf_of(&extras, &e)?,
            diffuse_roughness,
            medium: extras.medium,
        })
    }

    /// The BSDF model `extras` name (`e`: their element, for messages).
    fn bsdf_of(&self, extras: &LucernaExtras, e: &str) -> Result<BsdfModel> {
        match extras.bsdf.as_str() {
            "gltf" => Ok(BsdfModel::GltfPbr),
            "lambert" => Ok(BsdfModel::Lambert),
            "interface" => Ok(BsdfModel::Interface),
            "phong" => {
                let exponent = extras
                    .exponent
                    .ok_or_else(|| self.err(e, "phong needs an \"exponent\""))?;
                if !(exponent.is_finite() && (0.0..=1e7).contains(&exponent)) {
                    return Err(self.err(e, format!("exponent {exponent} must be in [0, 1e7]")));
                }
                let specular = match extras.specular {
                    None => Vec3::splat(0.04),
                    Some(SpecularValue::Grey(g)) => Vec3::splat(g),
                    Some(SpecularValue::Rgb(c)) => Vec3::from_array(c),
                };
                if !(specular.is_finite()
                    && specular.min_element() >= 0.0
                    && specular.max_element() <= 1.0)
                {
                    return Err(self.err(e, "specular must be in [0, 1]"));
                }
                Ok(BsdfModel::Phong { exponent, specular })
            }
            other => Err(self.err(
                e,
                format!("unknown bsdf {other:?} (expected gltf, lambert, phong or interface)"),
            )),
        }
    }
}

/// What a material's `extras.lucerna` says.
pub(super) struct Extras {
    model: BsdfModel,
    diffuse_roughness: f32,
    medium: Option<MediumExtras>,
}

/// The largest absorption or scattering coefficient accepted (per metre): light crosses
/// 10 nm of such a medium on average, denser than any real one.
const MAX_COEFFICIENT: f32 = 1e8;

/// A material's `extensions` object, for reading the extensions that the `gltf` crate does
/// not type.
pub(super) struct MaterialExtensions<'j> {
    /// The material's element, for messages.
    element: &'j str,
    json: std::collections::BTreeMap<&'j str, &'j serde_json::Value>,
}

impl MaterialExtensions<'_> {
    fn get(&self, name: &str) -> Option<&serde_json::Value> {
        self.json.get(name).copied()
    }

    /// `e[key]` of extension `name` as a finite number (`default` when absent).
    fn number(
        &self,
        importer: &Importer,
        name: &str,
        e: &serde_json::Value,
        key: &str,
        default: f32,
    ) -> Result<f32> {
        match e.get(key) {
            None => Ok(default),
            Some(v) => v
                .as_f64()
                .map(|x| x as f32)
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    importer.err(self.element, format!("{name}.{key} is not a finite number"))
                }),
        }
    }

    /// `e[key]` of extension `name` as an RGB triple of finite numbers.
    fn color(
        &self,
        importer: &Importer,
        name: &str,
        e: &serde_json::Value,
        key: &str,
        default: Vec3,
    ) -> Result<Vec3> {
        let Some(v) = e.get(key) else {
            return Ok(default);
        };
        let values: Option<Vec<f32>> = v.as_array().and_then(|a| {
            (a.len() == 3)
                .then(|| a.iter().map(|x| x.as_f64().map(|x| x as f32)).collect())
                .flatten()
        });
        match values {
            Some(c) if c.iter().all(|x| x.is_finite()) => Ok(Vec3::new(c[0], c[1], c[2])),
            _ => Err(importer.err(
                self.element,
                format!("{name}.{key} is not three finite numbers"),
            )),
        }
    }
}
