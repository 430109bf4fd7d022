//! The EXR header of a view's render: how it was made, for the compositor (camera matrices,
//! Cryptomatte manifests), `--resume`, `lucerna merge` and the batch runner.

use super::request::RenderJob;
use crate::film::Film;
use crate::output::exr::{Attribute, Header};
use crate::render::{RenderOptions, RenderStats};
use crate::world::World;

/// The EXR header of a view's render: how it was made, for the compositor, `--resume`,
/// `lucerna merge` and the batch runner.
pub(super) struct HeaderFacts<'a> {
    pub job: &'a RenderJob,
    pub options: &'a RenderOptions,
    pub world: &'a World,
    pub source: &'a str,
    pub identity: Option<&'a (String, String)>,
    pub frame: Option<f64>,
}

impl HeaderFacts<'_> {
    pub(super) fn header(&self, film: &Film, stats: &RenderStats) -> Header {
        // glam's column-major listing of a column-vector matrix is the row-major listing of
        // its transpose: exactly Imath's row-vector convention.
        let imath = |m: glam::DMat4| m.as_mat4().to_cols_array();
        let world = self.world;
        let mut header = Header {
            storage: self.job.storage,
            frames_per_second: self.frame.map(|_| self.job.load.fps),
            world_to_camera: Some(imath(world.camera.world_to_camera)),
            world_to_ndc: Some(imath(world.camera.world_to_ndc)),
            attributes: vec![
                (
                    "lucerna/renderer".into(),
                    Attribute::Text(crate::RENDERER.into()),
                ),
                ("lucerna/scene".into(), Attribute::Text(self.source.into())),
                (
                    "lucerna/settings".into(),
                    Attribute::Text(self.options.to_toml(stats.spp)),
                ),
                (
                    "lucerna/seed".into(),
                    Attribute::Int(self.options.settings.seed as i32),
                ),
                ("lucerna/spp".into(), Attribute::Int(stats.spp as i32)),
                (
                    "lucerna/samples".into(),
                    Attribute::Double(stats.samples as f64),
                ),
                (
                    "lucerna/render_seconds".into(),
                    Attribute::Double(stats.seconds),
                ),
                (
                    "lucerna/rays".into(),
                    Attribute::Double((stats.rays.closest + stats.rays.shadow) as f64),
                ),
                (
                    "lucerna/nan_inf_discarded".into(),
                    Attribute::Double(stats.discarded as f64),
                ),
                (
                    "lucerna/complete".into(),
                    Attribute::Int(!stats.interrupted as i32),
                ),
            ],
        };
        if let Some(host) = host_name() {
            header.set("lucerna/host", Attribute::Text(host));
        }
        if let Some((canonical, fingerprint)) = self.identity {
            header.set("lucerna/scene_path", Attribute::Text(canonical.clone()));
            header.set(
                "lucerna/scene_fingerprint",
                Attribute::Text(fingerprint.clone()),
            );
        }
        if let Some(f) = self.frame {
            header.set("lucerna/frame", Attribute::Double(f));
        }
        if let Some(shutter) = world.shutter {
            header.set("lucerna/shutter", Attribute::Text(shutter.describe()));
        }
        if let Some(split) = stats.learned_split {
            header.set("lucerna/split_learned", Attribute::Text(split.describe()));
        }
        if film.aovs.wants_crypto() {
            use crate::film::crypto::{Kind, header_attributes};
            let materials = world.material_names();
            for (kind, names) in [
                (Kind::Object, &world.objects.names),
                (Kind::Material, &materials),
            ] {
                for (name, value) in header_attributes(kind, names) {
                    header.set(&name, Attribute::Text(value));
                }
            }
        }
        header
    }
}

/// The name of the machine that renders (V-Ray's `computername`, Arnold's `host`), for the
/// render farm's bookkeeping: the kernel's on Linux, else the environment's.
fn host_name() -> Option<String> {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .or_else(|| std::env::var("COMPUTERNAME").ok())
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
}
