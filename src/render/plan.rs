//! The render plan: what a scene and a request actually need, so that a render pays for
//! nothing else.
//!
//! [`SceneFeatures`] (`scene::features`) is the analysis of a scene: its light kinds, the
//! BSDF lobes its materials can produce, textures, normal maps, alpha and vertex
//! attributes. A [`RenderPlan`] adds the request (AOVs, settings) and decides the integrator's
//! [`Kernel`]: the monomorphised variant of the path tracer that leaves out MIS and emitter
//! lookups where nothing can be found by BSDF sampling, first-hit data where no data AOV is
//! asked for, and AOV routing where the beauty is the only light layer. `--plan general`
//! forces every feature on: the baseline that benchmarks and tests compare the plan with;
//! `--plan packet` and `--plan scalar` specialise as `auto` but run the packet kernel
//! wherever it can run, or never.

use crate::film::aov::{Aov, AovSet, MEAN_DATA};
use crate::integrator::guiding::GuidingMode;
use crate::light::LightSelect;
use crate::scene::features::SceneFeatures;
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
    /// (`rr = efficiency`), no participating medium and nothing moving is in the scene
    /// (media and motion blur are scalar only), and (in `auto`) some material has a GGX lobe or some mesh a uniform material
    /// ([`SceneFeatures::uniform_meshes`]), which is what the lanes speed up. Where no surface is uniform and none glossy, the lanes would shade nothing and
    /// only add their bookkeeping, so `auto` keeps the scalar kernel (`--plan packet` runs
    /// it there too). Passes that learn the first vertex's split (`--split auto`) run in it
    /// too. A technique the packet kernel does not have yet keeps it out of the render
    /// here (see `integrator::estimator`).
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
    /// Path guiding (`integrator::guiding`) learns and guides this render's paths; in
    /// `--guiding auto` the first training pass may still turn it off.
    pub guiding: bool,
    /// Light selection learns what each group of lights brings where
    /// (`light::learned`), in training passes of its own.
    pub learned_lights: bool,
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
            .filter(|a| *a == Aov::Depth || MEAN_DATA.contains(a))
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
                && features.participating_media == 0
                && !features.moves()
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
            guiding: false,
            learned_lights: false,
        }
    }

    /// The plan with lights selected as `select` says: learned selection runs in the
    /// scalar kernel, which alone has it.
    pub fn with_light_selection(mut self, select: LightSelect) -> Self {
        self.learned_lights = select == LightSelect::Learned;
        if self.learned_lights {
            self.kernel.packet = false;
        }
        self
    }

    /// The plan with path guiding as `mode` asks: `on` guides (in the scalar kernel, which
    /// alone has it), `auto` guides only where the scalar kernel runs anyway (light layers,
    /// data AOVs, learning roulette, or a scene the lanes do not speed up) and some lobe is
    /// not a delta: against the packet kernel, guided paths lose at equal time (see
    /// `integrator::guiding`).
    pub fn with_guiding(mut self, mode: GuidingMode) -> Self {
        let scatters = self.features.lobes.diffuse || self.features.lobes.glossy;
        self.guiding = match mode {
            GuidingMode::Off => false,
            GuidingMode::On => true,
            GuidingMode::Auto => !self.kernel.packet && scatters,
        };
        if self.guiding {
            self.kernel.packet = false;
        }
        self
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
        if s.moves() {
            writeln!(
                f,
                "  motion blur: {} moving instance{}{}{} (rendered by the scalar kernel)",
                s.moving_instances,
                if s.moving_instances == 1 { "" } else { "s" },
                match s.deforming_meshes {
                    0 => String::new(),
                    1 => ", 1 deforming mesh".into(),
                    n => format!(", {n} deforming meshes"),
                },
                if s.moving_camera {
                    ", the camera moves"
                } else {
                    ""
                },
            )?;
        }
        if s.participating_media > 0 {
            writeln!(
                f,
                "  participating media: inside {} material{}{} (rendered by the scalar kernel)",
                s.participating_media,
                if s.participating_media == 1 { "" } else { "s" },
                if s.emitting_media > 0 {
                    format!(", {} emitting", s.emitting_media)
                } else {
                    String::new()
                }
            )?;
        }
        writeln!(
            f,
            "  materials in use: {} textured, {} normal-mapped, {} with alpha (tested during traversal only for their primitives); glTF PBR with zero-weight lobes skipped: {} rendered as Lambert, {} as a conductor",
            s.textured_materials,
            s.normal_mapped_materials,
            s.alpha_materials,
            s.reduced_to_lambert,
            s.reduced_to_conductor
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
            "  integrator: emitter lookups and MIS at BSDF hits {}, first-hit data {}, AOV routing {}, path guiding {}, learned light selection {}, {} kernel",
            on_off(k.emitter_hits),
            on_off(k.first_hit_data),
            on_off(k.routing),
            on_off(self.guiding),
            on_off(self.learned_lights),
            if k.packet {
                "packet (8 lanes, AVX2)"
            } else {
                "scalar"
            }
        )
    }
}
