//! What a render is asked to do ([`RenderOptions`]): samples or time, adaptive sampling,
//! the integrator's settings, AOVs, pixel filter, plan, crop and pass of a split render,
//! progress reporting; their textual forms (the command line's and settings files' keys),
//! and the film and plan a request makes for a world.

use super::plan::{PlanMode, RenderPlan};
use super::progress::ProgressLines;
use crate::camera::Overscan;
use crate::film::aov::AovSet;
use crate::film::filter::PixelFilter;
use crate::film::{Film, Window};
use crate::integrator::guiding::GuidingMode;
use crate::integrator::settings::{SETTING_NAMES, read_settings_toml, write_settings_toml};
use crate::integrator::{RussianRoulette, Settings, SplitChoice};
use crate::light::groups::LightGroups;
use crate::world::World;
use std::sync::atomic::AtomicBool;

/// Samples per pixel when neither a count nor a time is given.
pub const DEFAULT_SPP: u32 = 64;
/// Most samples per pixel a time budget may take.
pub(crate) const MAX_SPP: u32 = 1 << 24;
/// Most samples per pixel adaptive sampling takes when no sample count is given.
pub const ADAPTIVE_MAX_SPP: u32 = 1 << 16;
/// Samples every pixel takes before adaptive sampling decides (`min-spp`).
pub const DEFAULT_MIN_SPP: u32 = 16;

/// What to render: samples or time, integrator settings, AOVs, pixel filter, plan.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Samples per pixel; with a time budget or a noise threshold, the most to take.
    pub spp: Option<u32>,
    /// Time budget in seconds: passes continue until it is spent.
    pub time: Option<f64>,
    /// Adaptive sampling's target: the relative noise (square root of the predicted
    /// relMSE) at which sampling stops; `None` samples every pixel alike.
    pub noise_threshold: Option<f32>,
    /// Samples every pixel takes before adaptive sampling decides.
    pub min_spp: u32,
    /// Specialise the integrator to the scene and request, or force every feature on.
    pub plan: PlanMode,
    pub settings: Settings,
    pub aovs: AovSet,
    pub filter: PixelFilter,
    /// Light groups of the request (`--light-group`), before the scene's own.
    pub light_groups: Vec<crate::scene::LightGroup>,
    /// Render only these pixels of the image (a tile of a split render), in the image's
    /// coordinates (without overscan).
    pub crop: Option<Window>,
    /// Pixels rendered beyond the image's edges (the EXR's data window past its display
    /// window).
    pub overscan: Overscan,
    /// Take only pass K of N (1-based): the K-th of N disjoint ranges of each pixel's sample
    /// sequence, so that merging the N renders gives the render with all the samples.
    pub pass: Option<(u32, u32)>,
    /// Show a progress bar (only drawn when stderr is a terminal).
    pub progress: bool,
    /// Plain progress lines on stderr for logs (farm tasks, batch children), every
    /// `interval`: `None` prints none.
    pub progress_lines: Option<ProgressLines>,
    /// Set (by a signal handler) to stop the render early: what has accumulated is kept.
    pub interrupt: Option<std::sync::Arc<AtomicBool>>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            spp: None,
            time: None,
            noise_threshold: None,
            min_spp: DEFAULT_MIN_SPP,
            plan: PlanMode::Auto,
            settings: Settings::default(),
            aovs: AovSet::default(),
            filter: PixelFilter::blackman_harris(1.5),
            light_groups: Vec::new(),
            crop: None,
            overscan: Overscan::default(),
            pass: None,
            progress: false,
            progress_lines: None,
            interrupt: None,
        }
    }
}

impl RenderOptions {
    /// What `lucerna render` (and each render of a batch job) starts from before its
    /// settings file and flags: the defaults, writing the beauty only.
    pub fn command_line() -> Self {
        Self {
            aovs: AovSet::parse("beauty").expect("the beauty parses"),
            ..Default::default()
        }
    }

    /// Sets `name` (a render or integrator setting) from its textual value: the one path
    /// for the command line and settings files.
    pub fn set(&mut self, name: &str, value: &str) -> Result<(), String> {
        match name {
            "spp" => {
                let spp = value.parse().ok().filter(|s| (1..=MAX_SPP).contains(s));
                self.spp =
                    Some(spp.ok_or_else(|| {
                        format!("spp: an integer in 1..={MAX_SPP}, got {value:?}")
                    })?);
            }
            "time" => {
                let t = value
                    .parse::<f64>()
                    .ok()
                    .filter(|t| t.is_finite() && *t > 0.0);
                self.time =
                    Some(t.ok_or_else(|| {
                        format!("time: a positive number of seconds, got {value:?}")
                    })?);
            }
            "noise-threshold" => {
                let t = value
                    .parse::<f32>()
                    .ok()
                    .filter(|t| t.is_finite() && *t > 0.0);
                self.noise_threshold = Some(t.ok_or_else(|| {
                    format!(
                        "noise-threshold: a positive relative noise level, e.g. 0.01, got {value:?}"
                    )
                })?);
            }
            "min-spp" => {
                let n = value.parse().ok().filter(|s| (2..=MAX_SPP).contains(s));
                self.min_spp = n.ok_or_else(|| {
                    format!("min-spp: an integer in 2..={MAX_SPP}, got {value:?}")
                })?;
            }
            "plan" => self.plan = PlanMode::parse(value)?,
            "filter" => {
                self.filter = PixelFilter::parse(value).ok_or_else(|| {
                    format!(
                        "unknown filter {value:?} (box, blackman-harris, blackman-harris:WIDTH)"
                    )
                })?
            }
            "aov" => self.aovs = AovSet::parse(value)?,
            "crop" => self.crop = Some(Window::parse(value)?),
            "overscan" => self.overscan = Overscan::parse(value)?,
            "light-groups" => self.light_groups = crate::light::groups::parse(value)?,
            "pass" => {
                let pass = value
                    .split_once('/')
                    .and_then(|(k, n)| Some((k.trim().parse().ok()?, n.trim().parse().ok()?)))
                    .filter(|&(k, n): &(u32, u32)| (1..=n).contains(&k));
                self.pass = Some(pass.ok_or_else(|| {
                    format!("pass: K/N with 1 <= K <= N, e.g. 2/4, got {value:?}")
                })?);
            }
            _ => self.settings.set(name, value)?,
        }
        Ok(())
    }

    /// Applies a TOML settings file's keys.
    pub fn load_settings(&mut self, text: &str) -> Result<(), String> {
        self.apply(read_settings_toml(text)?)
    }

    /// Sets each (name, value) pair.
    fn apply(&mut self, pairs: Vec<(String, String)>) -> Result<(), String> {
        for (name, value) in pairs {
            self.set(&name, &value)
                .map_err(|e| format!("{name}: {e}"))?;
        }
        Ok(())
    }

    /// Applies the settings an EXR header records (`lucerna/settings`): as
    /// [`RenderOptions::load_settings`], with what the absence of a setting meant when the
    /// file was written: a file without `microfacet` was rendered before the setting
    /// existed, with single-scattering GGX, so that checkpoints, merges and batch reruns do
    /// not take it for today's default.
    pub fn load_recorded_settings(&mut self, text: &str) -> Result<(), String> {
        let pairs = read_settings_toml(text)?;
        if !pairs.iter().any(|(name, _)| name == "microfacet") {
            self.settings.microfacet = crate::integrator::settings::MicrofacetModel::Single;
        }
        self.apply(pairs)
    }

    /// Every setting as TOML, with `spp` the samples actually taken (a pass's total): the
    /// header's record of how an image was made, readable back as a settings file.
    pub fn to_toml(&self, spp_taken: u32) -> String {
        // A pass is recorded by its total and its index, which fix its range of samples.
        let spp = if self.pass.is_some() {
            self.target_spp()
        } else {
            spp_taken
        };
        let mut pairs: Vec<(String, String)> = vec![("spp".into(), spp.to_string())];
        if let Some(t) = self.time {
            pairs.push(("time".into(), t.to_string()));
        }
        if let Some(t) = self.noise_threshold {
            pairs.push(("noise-threshold".into(), t.to_string()));
            pairs.push(("min-spp".into(), self.min_spp.to_string()));
        }
        pairs.push(("filter".into(), self.filter.describe()));
        pairs.push(("aov".into(), self.aovs.describe()));
        pairs.push(("plan".into(), self.plan.name().into()));
        if !self.light_groups.is_empty() {
            pairs.push((
                "light-groups".into(),
                crate::light::groups::describe(&self.light_groups),
            ));
        }
        if let Some(window) = self.crop {
            pairs.push(("crop".into(), window.describe()));
        }
        if !self.overscan.is_none() {
            pairs.push(("overscan".into(), self.overscan.describe()));
        }
        if let Some((k, n)) = self.pass {
            pairs.push(("pass".into(), format!("{k}/{n}")));
        }
        for name in SETTING_NAMES {
            pairs.push((
                name.into(),
                self.settings.get(name).expect("listed settings exist"),
            ));
        }
        write_settings_toml(&pairs)
    }

    /// The sample count when no time budget or noise threshold stops earlier (of all
    /// passes, with `pass`).
    fn target_spp(&self) -> u32 {
        match (self.spp, self.time, self.noise_threshold) {
            (Some(s), _, _) => s,
            (None, Some(_), _) => MAX_SPP,
            (None, None, Some(_)) => ADAPTIVE_MAX_SPP,
            (None, None, None) => DEFAULT_SPP,
        }
    }

    /// The range of each pixel's sample sequence this render takes: all of it, or pass
    /// K of N's share, samples ⌊(K−1)·S/N⌋ up to ⌊K·S/N⌋.
    pub fn sample_range(&self) -> std::ops::Range<u32> {
        let total = self.target_spp();
        match self.pass {
            None => 0..total,
            Some((k, n)) => {
                let at = |i: u32| (i as u64 * total as u64 / n as u64) as u32;
                at(k - 1)..at(k)
            }
        }
    }

    /// Whether the render decides from the whole image and all its samples, keeping state
    /// an EXR does not hold (adaptive sampling, efficiency-aware roulette, learned
    /// splitting): such a render cannot be cropped, split into passes or resumed.
    pub fn decides_from_whole_image(&self) -> bool {
        self.noise_threshold.is_some()
            || matches!(self.settings.rr, RussianRoulette::Efficiency(_))
            || self.settings.split == SplitChoice::Auto
            || self.settings.guiding != GuidingMode::Off
    }

    /// Rejects combinations a split render cannot honour: a pass must be a fixed range of
    /// samples, and a window must render exactly the pixels of the whole image (adaptive
    /// sampling and learned roulette decide from the whole image).
    pub fn validate(&self) -> Result<(), String> {
        if let Some((_, n)) = self.pass {
            if self.time.is_some() || self.noise_threshold.is_some() {
                return Err("pass: a pass is a fixed range of samples; it takes --spp, not --time or --noise-threshold".into());
            }
            if self.target_spp() < n {
                return Err(format!(
                    "pass: {} samples per pixel cannot be split into {n} passes",
                    self.target_spp()
                ));
            }
        }
        if (self.pass.is_some() || self.crop.is_some()) && self.decides_from_whole_image() {
            return Err("crop and pass: adaptive sampling, rr = efficiency, split = auto and guiding decide from the whole image and all its samples, so a split render would differ from the whole one".into());
        }
        Ok(())
    }

    /// The light groups of this request in `world`: the request's, the scene's, and
    /// `default`.
    pub fn light_groups(&self, world: &World) -> LightGroups {
        LightGroups::assign(&world.light_names, &self.light_groups, &world.light_groups)
    }

    /// What makes an image rendered with `self` differ from one rendered with `other`
    /// besides the samples taken: the first differing group of settings, if any. A
    /// checkpoint continues only under equal settings; a batch re-renders an output whose
    /// settings differ from its job's.
    pub fn differs_from(&self, other: &RenderOptions) -> Option<&'static str> {
        [
            ("integrator settings", self.settings != other.settings),
            ("AOVs", self.aovs != other.aovs),
            (
                "pixel filter",
                self.filter.describe() != other.filter.describe(),
            ),
            ("crop", self.crop != other.crop),
            ("overscan", self.overscan != other.overscan),
            ("light groups", self.light_groups != other.light_groups),
            ("pass", self.pass != other.pass),
            (
                "adaptive sampling",
                self.noise_threshold != other.noise_threshold,
            ),
        ]
        .into_iter()
        .find_map(|(what, differs)| differs.then_some(what))
    }

    /// The empty film this request renders into, for `world`'s camera, with a layer for
    /// each light group if they are requested.
    pub fn film(&self, world: &World) -> Film {
        // The image rendered: overscan included, a crop within the image moved into it.
        let display = (world.camera.width(), world.camera.height());
        let overscan = world.camera.overscan();
        let groups = self
            .aovs
            .wants_light_groups()
            .then(|| self.light_groups(world));
        let aovs = match &groups {
            Some(g) => self.aovs.with_light_groups(&g.names),
            None => self.aovs.clone(),
        };
        let mut film = Film::cropped(
            display,
            self.crop
                .map_or(Window::full(display.0, display.1), |c| c.beyond(overscan)),
            aovs,
            self.noise_threshold.is_some(),
        );
        film.overscan = overscan;
        if let Some(g) = groups {
            film.router.set_light_groups(&g.of_light);
        }
        if film.aovs.wants_crypto() {
            film.crypto_ids =
                crate::film::crypto::Ids::new(&world.objects.names, &world.material_names());
        }
        film
    }

    /// The render plan for `world` with these options.
    pub fn render_plan(&self, world: &World) -> RenderPlan {
        RenderPlan::new(
            &world.features,
            &self.aovs,
            self.plan,
            self.noise_threshold.is_some(),
            matches!(self.settings.rr, RussianRoulette::Efficiency(_)),
        )
        .with_guiding(self.settings.guiding)
        .with_light_selection(self.settings.light_select)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A header from before `microfacet` existed records a single-scattering render: read
    /// back, it differs from today's default, so it is neither continued nor skipped as if
    /// it were one; a recorded value is taken as it is.
    #[test]
    fn headers_without_the_microfacet_setting_were_single_scattering() {
        use crate::integrator::settings::MicrofacetModel;
        let mut old = RenderOptions::default();
        old.load_recorded_settings("spp = 16\nmis = \"power:2\"\n")
            .unwrap();
        assert_eq!(old.settings.microfacet, MicrofacetModel::Single);
        assert!(
            old.differs_from(&RenderOptions {
                spp: Some(16),
                ..Default::default()
            })
            .is_some()
        );
        let mut new = RenderOptions::default();
        new.load_recorded_settings(&RenderOptions::default().to_toml(16))
            .unwrap();
        assert_eq!(new.settings.microfacet, MicrofacetModel::Multiscatter);
        // A settings file the user writes keeps the default.
        let mut file = RenderOptions::default();
        file.load_settings("spp = 16\n").unwrap();
        assert_eq!(file.settings.microfacet, MicrofacetModel::Multiscatter);
    }

    /// Every render setting a header records reads back to the same options.
    #[test]
    fn settings_round_trip_through_the_header() {
        let mut options = RenderOptions::default();
        for (name, value) in [
            ("time", "2.5"),
            ("noise-threshold", "0.02"),
            ("min-spp", "8"),
            ("plan", "general"),
            ("filter", "box"),
            ("aov", "albedo,spp,lobes,lightgroups"),
            ("mis", "balance"),
            ("light-groups", "key=lamp_*,sun;sky=environment"),
            ("crop", "1,2,30,40"),
            ("overscan", "4,0,4,8"),
        ] {
            options.set(name, value).unwrap();
        }
        let mut read = RenderOptions::default();
        read.load_settings(&options.to_toml(40)).unwrap();
        assert_eq!(read.spp, Some(40));
        assert_eq!(read.time, options.time);
        assert_eq!(read.noise_threshold, options.noise_threshold);
        assert_eq!(read.min_spp, 8);
        assert_eq!(read.plan, PlanMode::General);
        assert_eq!(read.aovs, options.aovs);
        assert_eq!(read.filter.describe(), "box");
        assert_eq!(read.settings, options.settings);
        assert_eq!(read.light_groups, options.light_groups);
        assert_eq!(read.crop, options.crop);
        assert_eq!(read.overscan, options.overscan);
    }
}
