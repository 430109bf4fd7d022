//! The render plan: what a scene and a request actually need, so that a render pays for
//! nothing else (see `../shared/design.md`).
//!
//! [`SceneFeatures`] is the analysis of a scene: its light kinds, the BSDF lobes its
//! materials can produce, textures, normal maps, alpha and vertex attributes. A
//! [`RenderPlan`] adds the request (AOVs, settings) and decides the integrator's
//! [`Kernel`]: the monomorphised variant of the path tracer that leaves out MIS and emitter
//! lookups where nothing can be found by BSDF sampling, first-hit data where no data AOV is
//! asked for, and AOV routing where the beauty is the only light layer. `--plan general`
//! forces every feature on: the baseline that benchmarks and tests compare the plan with;
//! `--plan packet` and `--plan scalar` specialise as `auto` but run the packet kernel
//! wherever it can run, or never.

use crate::film::aov::{Aov, AovSet};
use crate::material::microfacet::SMOOTH_ALPHA;
use crate::scene::{AlphaMode, BsdfModel, LightKind, Material, Scene};
use std::fmt;

/// Whether the integrator is specialised to the plan or runs with every feature on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PlanMode {
    /// Specialised to what the scene and the request use, with the packet kernel where
    /// it applies (the default).
    #[default]
    Auto,
    /// Specialised as `Auto`, with the packet kernel wherever it can run (also where
    /// `Auto` finds it does not pay).
    Packet,
    /// Specialised as `Auto`, but always the scalar kernel: the reference the packet
    /// kernel is compared with.
    Scalar,
    /// Every feature on, whatever the scene, in the scalar kernel: the reference for
    /// benchmarks and tests.
    General,
}

impl PlanMode {
    /// Parses `auto`, `packet`, `scalar` or `general`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(Self::Auto),
            "packet" => Ok(Self::Packet),
            "scalar" => Ok(Self::Scalar),
            "general" => Ok(Self::General),
            _ => Err(format!("plan: auto, packet, scalar or general, got {s:?}")),
        }
    }

    /// The textual form [`PlanMode::parse`] reads.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Packet => "packet",
            Self::Scalar => "scalar",
            Self::General => "general",
        }
    }
}

/// The BSDF lobes a scene's materials can produce.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Lobes {
    pub diffuse: bool,
    /// Non-delta specular reflection (rough metals, Phong lobes, rough coats).
    pub glossy: bool,
    /// Delta reflection (smooth metals and coats): only BSDF sampling follows it.
    pub specular: bool,
    /// Transmission (glass: rough or smooth dielectrics, thin walls).
    pub transmission: bool,
}

impl Lobes {
    /// The lobes material `m` can produce at some surface point.
    pub fn of(m: &Material) -> Self {
        let rough = |roughness: f32| roughness * roughness >= SMOOTH_ALPHA;
        match m.model {
            BsdfModel::Lambert => Self {
                diffuse: true,
                ..Self::default()
            },
            BsdfModel::Phong { specular, .. } => Self {
                diffuse: true,
                glossy: specular.max_element() > 0.0,
                ..Self::default()
            },
            BsdfModel::GltfPbr => {
                // A roughness texture can lower the roughness to 0 anywhere.
                let textured = m.metallic_roughness_texture.is_some();
                let coat = m.clearcoat > 0.0 || m.clearcoat_texture.is_some();
                // A transmission of 1 (untextured) leaves no diffuse base.
                let all_glass = m.transmission >= 1.0 && m.transmission_texture.is_none();
                Self {
                    diffuse: (m.metallic < 1.0 || textured) && !all_glass || m.sheen.is_some(),
                    glossy: rough(m.roughness) || (coat && rough(m.clearcoat_roughness)),
                    specular: !rough(m.roughness)
                        || textured
                        || (coat && !rough(m.clearcoat_roughness)),
                    transmission: m.transmits(),
                }
            }
        }
    }

    fn union(self, o: Self) -> Self {
        Self {
            diffuse: self.diffuse || o.diffuse,
            glossy: self.glossy || o.glossy,
            specular: self.specular || o.specular,
            transmission: self.transmission || o.transmission,
        }
    }
}

/// The lights of a scene by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LightKinds {
    /// Emissive triangles and analytic shapes (found by BSDF sampling too).
    pub area: usize,
    /// Point, spot and parallel directional lights (light sampling only).
    pub delta: usize,
    /// Directional lights with an angular size (reached by escaping rays).
    pub distant_cones: usize,
    pub environment: bool,
    /// Punctual lights of zero intensity: never sampled.
    pub zero_power: usize,
}

impl LightKinds {
    /// True if a BSDF-sampled ray can find an emitter, so that emitter lookups and MIS
    /// weights are needed.
    pub fn reachable_by_bsdf_sampling(&self) -> bool {
        self.area > 0 || self.distant_cones > 0 || self.environment
    }
}

/// What a scene contains that costs work or memory to render.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SceneFeatures {
    pub lights: LightKinds,
    /// Union of the lobes of every material some geometry uses.
    pub lobes: Lobes,
    /// Materials in use that read a texture (base colour, metal-roughness, emission).
    pub textured_materials: usize,
    pub normal_mapped_materials: usize,
    /// Materials in use with alpha cut-outs or blending (tested during traversal).
    pub alpha_materials: usize,
    /// Meshes that carry texture coordinates, tangents, vertex colours: interpolated at
    /// every hit on them.
    pub meshes_with_uvs: usize,
    pub meshes_with_tangents: usize,
    pub meshes_with_colors: usize,
    /// Materials in use whose BSDF has a GGX lobe (a rough glTF surface): work the packet
    /// kernel's lanes speed up.
    pub microfacet_materials: usize,
    /// Meshes placed once whose material is the same at every point and does not emit (no
    /// texture, no vertex colours): the packet kernel's lanes compute their shading points
    /// (`world::lanes`).
    pub uniform_meshes: usize,
}

impl SceneFeatures {
    /// Analyses `scene`: only materials that some geometry uses count.
    pub fn of(scene: &Scene) -> Self {
        let mut used = vec![false; scene.materials.len()];
        let mut mark = |m: u32| {
            if let Some(u) = used.get_mut(m as usize) {
                *u = true;
            }
        };
        let mut placements = vec![0usize; scene.meshes.len()];
        for inst in &scene.instances {
            placements[inst.mesh as usize] += 1;
        }
        let instanced: Vec<bool> = placements.iter().map(|&n| n > 0).collect();
        let meshes: Vec<_> = scene
            .meshes
            .iter()
            .zip(&instanced)
            .filter(|(_, i)| **i)
            .map(|(m, _)| m)
            .collect();
        meshes.iter().for_each(|m| mark(m.material));
        scene.spheres.iter().for_each(|s| mark(s.material));
        scene.disks.iter().for_each(|d| mark(d.material));
        scene.cylinders.iter().for_each(|c| mark(c.material));
        let in_use = || {
            scene
                .materials
                .iter()
                .zip(&used)
                .filter(|(_, u)| **u)
                .map(|(m, _)| m)
        };
        let count = |f: &dyn Fn(&Material) -> bool| in_use().filter(|m| f(m)).count();
        let emissive = |material: u32| scene.materials[material as usize].is_emissive();
        let area = scene
            .instances
            .iter()
            .map(|i| &scene.meshes[i.mesh as usize])
            .filter(|m| emissive(m.material))
            .map(|m| m.triangles.len())
            .sum::<usize>()
            + scene
                .spheres
                .iter()
                .filter(|s| emissive(s.material))
                .count()
            + scene.disks.iter().filter(|d| emissive(d.material)).count()
            + scene
                .cylinders
                .iter()
                .filter(|c| emissive(c.material))
                .count();
        let mut lights = LightKinds {
            area,
            environment: scene.environment.is_some(),
            ..LightKinds::default()
        };
        for l in &scene.lights {
            let power = match &l.kind {
                LightKind::Point { intensity, .. } | LightKind::Spot { intensity, .. } => {
                    lights.delta += 1;
                    *intensity
                }
                LightKind::Directional {
                    irradiance, angle, ..
                } => {
                    if *angle > 0.0 {
                        lights.distant_cones += 1;
                    } else {
                        lights.delta += 1;
                    }
                    *irradiance
                }
            };
            if !(power.max_element() > 0.0) {
                lights.zero_power += 1;
            }
        }
        Self {
            lights,
            lobes: in_use().map(Lobes::of).fold(Lobes::default(), Lobes::union),
            textured_materials: count(&|m| {
                m.texture_slots().any(|(name, _)| name != "normal_texture")
            }),
            normal_mapped_materials: count(&|m| m.normal_texture.is_some()),
            alpha_materials: count(&|m| m.alpha_mode != AlphaMode::Opaque),
            meshes_with_uvs: meshes
                .iter()
                .filter(|m| m.uvs.iter().any(Option::is_some))
                .count(),
            meshes_with_tangents: meshes.iter().filter(|m| m.tangents.is_some()).count(),
            meshes_with_colors: meshes.iter().filter(|m| m.colors.is_some()).count(),
            microfacet_materials: count(&|m| m.model == BsdfModel::GltfPbr && Lobes::of(m).glossy),
            uniform_meshes: scene
                .meshes
                .iter()
                .zip(&placements)
                .filter(|&(mesh, &n)| n == 1 && mesh.uniform_material(&scene.materials).is_some())
                .count(),
        }
    }
}

/// Removes vertex attributes that no material reads: texture coordinate sets no texture
/// of the mesh's material samples, and tangents without a normal map. They would only be
/// stored, copied and interpolated at every hit. Returns the number of arrays dropped.
pub fn strip_unused_attributes(scene: &mut Scene) -> usize {
    let mut dropped = 0;
    for mesh in &mut scene.meshes {
        let Some(m) = scene.materials.get(mesh.material as usize) else {
            continue;
        };
        for (set, uvs) in mesh.uvs.iter_mut().enumerate() {
            let read = m
                .texture_slots()
                .any(|(_, t)| (t.tex_coord as usize).min(1) == set);
            if !read && uvs.take().is_some() {
                dropped += 1;
            }
        }
        if !m.needs_tangents() && mesh.tangents.take().is_some() {
            dropped += 1;
        }
    }
    dropped
}

/// The variant of the path tracer a render runs: each flag off removes that work from the
/// inner loop at compile time (the render loop dispatches to one of the monomorphised
/// variants).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Kernel {
    /// Rays that leave a surface look up the emitter they hit (area lights, environment,
    /// distant cones) and weigh it against light sampling by MIS. Off when only delta lights
    /// exist: light samples then take weight 1 and no BSDF density is evaluated for them.
    pub emitter_hits: bool,
    /// The first hit computes albedo, normal, depth and position (data AOVs); off, it only
    /// records coverage.
    pub first_hit_data: bool,
    /// Contributions are routed by their tags to every light AOV; off when the beauty is
    /// the only light layer.
    pub routing: bool,
    /// Eight paths at a time in SIMD lanes (`integrator::packet`): where neither routing
    /// nor first-hit data is needed, the CPU has AVX2 and FMA, roulette does not learn
    /// (`rr = efficiency`), and (in `auto`) some material has a GGX lobe or some mesh a
    /// uniform material ([`SceneFeatures::uniform_meshes`]), which is what the lanes speed
    /// up: the packet kernel takes 18 % fewer instructions than the scalar one on the MIS
    /// plates, 22 % on the all-Lambert Cornell box (17 % less time) and 24 % on the
    /// indirect room. Where no surface is uniform and none glossy, the lanes would shade
    /// nothing (the Cornell box before they shaded: 1 % more instructions, about 5 % more
    /// time), so `auto` keeps the scalar kernel (`--plan packet` runs it there too).
    /// Passes that learn the first vertex's split (`--split auto`) run in it too.
    pub packet: bool,
}

impl Kernel {
    /// Every feature on, in the scalar kernel.
    pub const GENERAL: Self = Self {
        emitter_hits: true,
        first_hit_data: true,
        routing: true,
        packet: false,
    };
}

/// The analysis of a scene and a request, and the integrator variant chosen from it.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderPlan {
    pub mode: PlanMode,
    pub features: SceneFeatures,
    /// Light AOVs (beauty included) whose sums the film keeps per pixel.
    pub light_layers: usize,
    /// Data AOVs requested (albedo, normal, depth, position).
    pub data_layers: Vec<Aov>,
    /// Whether the unweighted single-technique direct layers are computed.
    pub single_technique: bool,
    /// Whether per-pixel sums of squares are kept (variance AOV or adaptive sampling).
    pub squares: bool,
    pub kernel: Kernel,
}

impl RenderPlan {
    /// The plan for a scene with `features` rendered with `aovs`; `squares` says whether
    /// sums of squares are needed besides the variance AOV (adaptive sampling needs them),
    /// `roulette_learns` whether roulette learns from every vertex (`rr = efficiency`,
    /// which only the scalar kernel does).
    pub fn new(
        features: &SceneFeatures,
        aovs: &AovSet,
        mode: PlanMode,
        squares: bool,
        roulette_learns: bool,
    ) -> Self {
        let data_layers: Vec<Aov> = aovs
            .iter()
            .filter(|a| *a == Aov::Depth || crate::film::MEAN_DATA.contains(a))
            .collect();
        let light_layers = aovs.iter().filter(|a| a.is_light()).count();
        let first_hit_data = !data_layers.is_empty() || aovs.wants_crypto();
        let routing = light_layers > 1 || aovs.wants_light_groups();
        let specialised = Kernel {
            emitter_hits: features.lights.reachable_by_bsdf_sampling(),
            first_hit_data,
            routing,
            packet: (mode == PlanMode::Packet
                || mode == PlanMode::Auto
                    && (features.microfacet_materials > 0 || features.uniform_meshes > 0))
                && !first_hit_data
                && !routing
                && !roulette_learns
                && crate::integrator::packet_kernel_available(),
        };
        Self {
            mode,
            features: features.clone(),
            light_layers,
            single_technique: aovs.contains(Aov::DirectNeeUnweighted)
                || aovs.contains(Aov::DirectBsdfUnweighted),
            squares: squares || aovs.contains(Aov::Variance),
            data_layers,
            kernel: match mode {
                PlanMode::Auto | PlanMode::Packet | PlanMode::Scalar => specialised,
                PlanMode::General => Kernel::GENERAL,
            },
        }
    }
}

fn yes_no(b: bool) -> &'static str {
    if b { "yes" } else { "no" }
}

fn on_off(b: bool) -> &'static str {
    if b { "on" } else { "off" }
}

impl fmt::Display for RenderPlan {
    /// The plan as `lucerna inspect` prints it.
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let s = &self.features;
        let l = &s.lights;
        writeln!(f, "render plan ({}):", self.mode.name())?;
        let light_kind = if l.area + l.delta + l.distant_cones == 0 && !l.environment {
            "none"
        } else if l.reachable_by_bsdf_sampling() {
            "area or infinite"
        } else {
            "delta only"
        };
        writeln!(
            f,
            "  lights: {light_kind} ({} area, {} delta, {} distant with a size, environment {}; {} of zero power, never sampled)",
            l.area,
            l.delta,
            l.distant_cones,
            yes_no(l.environment),
            l.zero_power
        )?;
        writeln!(
            f,
            "  lobes: diffuse {}, glossy {}, specular {}, transmission {}",
            yes_no(s.lobes.diffuse),
            yes_no(s.lobes.glossy),
            yes_no(s.lobes.specular),
            yes_no(s.lobes.transmission)
        )?;
        writeln!(
            f,
            "  materials in use: {} textured, {} normal-mapped, {} with alpha (tested during traversal only for their primitives)",
            s.textured_materials, s.normal_mapped_materials, s.alpha_materials
        )?;
        writeln!(
            f,
            "  vertex attributes interpolated: uvs on {} meshes, tangents on {}, colours on {}; {} meshes of a uniform material (shaded in SIMD lanes by the packet kernel)",
            s.meshes_with_uvs, s.meshes_with_tangents, s.meshes_with_colors, s.uniform_meshes
        )?;
        let data: Vec<String> = self.data_layers.iter().map(|a| a.name()).collect();
        writeln!(
            f,
            "  film: {} light layers, data layers: {}, single-technique layers {}, sums of squares {}",
            self.light_layers,
            if data.is_empty() {
                "none".to_string()
            } else {
                data.join(", ")
            },
            on_off(self.single_technique),
            on_off(self.squares)
        )?;
        let k = &self.kernel;
        write!(
            f,
            "  integrator: emitter lookups and MIS at BSDF hits {}, first-hit data {}, AOV routing {}, {} kernel",
            on_off(k.emitter_hits),
            on_off(k.first_hit_data),
            on_off(k.routing),
            if k.packet {
                "packet (8 lanes, AVX2)"
            } else {
                "scalar"
            }
        )
    }
}
