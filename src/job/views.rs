//! The views of a frame: the command line's output, or the render products a USD stage
//! declares (products that share camera, size and data window rendered once, each file
//! with its own layers).

use super::request::RenderJob;
use crate::error::{Error, Result};
use crate::film::Window;
use crate::film::aov::AovSet;
use crate::render::RenderOptions;
use crate::scene::{RenderSettings, Scene};
use crate::sequence::output_path;
use std::path::PathBuf;

/// One render of a frame: the camera, size and AOVs it takes (in its options) and the files
/// it writes. The first output is where a checkpoint goes and what `--resume` continues.
pub(super) struct View {
    pub(super) camera: Option<String>,
    pub(super) resolution: Option<(u32, u32)>,
    pub(super) options: RenderOptions,
    pub(super) outputs: Vec<ViewOutput>,
}

/// A file a view writes: `aovs` selects its layers (`None`: all the render's).
pub(super) struct ViewOutput {
    pub(super) path: PathBuf,
    pub(super) aovs: Option<AovSet>,
}

/// The views of one frame of `job` (`frame`, one of several or not) of `scene`, whose render
/// settings are `settings`.
pub(super) fn frame_views(
    job: &RenderJob,
    options: &RenderOptions,
    scene: &Scene,
    settings: &RenderSettings,
    frame: Option<f64>,
    several_frames: bool,
) -> Result<Vec<View>> {
    Ok(match &job.output {
        None if !settings.products.is_empty() => declared_views(job, options, settings)?,
        _ => {
            let pattern = job.output.clone().unwrap_or_else(|| "render.exr".into());
            if several_frames && !crate::sequence::has_frame_token(&pattern.to_string_lossy()) {
                return Err(Error::bad_input(
                    "",
                    "--output",
                    format!(
                        "several frames need a frame token ({}) in the output name",
                        crate::sequence::FRAME_TOKENS
                    ),
                ));
            }
            // The settings' camera, size and window apply where the job gives none.
            let camera = job.camera.clone().or(settings.camera.clone());
            let camera_name = match &camera {
                Some(name) => name.clone(),
                None => scene
                    .cameras
                    .first()
                    .map_or("default".into(), |c| c.name.clone()),
            };
            let path = output_path(&pattern, frame, &job.stem(), &camera_name)
                .map_err(|e| Error::bad_input("", "--output", e))?;
            let mut view_options = options.clone();
            if let (None, None, Some(crop)) = (options.crop, job.resolution, settings.crop) {
                view_options.crop = Some(pixel_window(crop));
            }
            if let (true, None, Some(o)) = (
                options.overscan.is_none(),
                job.resolution,
                settings.overscan,
            ) {
                view_options.overscan = overscan(o);
            }
            vec![View {
                camera,
                resolution: job.resolution.or(settings.resolution.map(|[w, h]| (w, h))),
                options: view_options,
                outputs: vec![ViewOutput { path, aovs: None }],
            }]
        }
    })
}

/// The views of a scene's declared render products: products that share camera, size and
/// data window are rendered once, with the union of their AOVs, and each file gets its own
/// layers. The job's camera, resolution, crop and AOVs apply to all.
fn declared_views(
    job: &RenderJob,
    options: &RenderOptions,
    settings: &RenderSettings,
) -> Result<Vec<View>> {
    type Shared = (
        Option<String>,
        Option<(u32, u32)>,
        Option<[u32; 4]>,
        Option<[u32; 4]>,
    );
    let mut groups: Vec<(Shared, View, Vec<&str>)> = Vec::new();
    for (i, product) in settings.products.iter().enumerate() {
        let element = format!("{}: product {i}", settings.path);
        let camera = job.camera.clone().or_else(|| product.camera.clone());
        let resolution = job.resolution.or(product.resolution.map(|[w, h]| (w, h)));
        // A declared window is in the declared resolution's pixels.
        let crop = if options.crop.is_some() || job.resolution.is_some() {
            None
        } else {
            product.crop
        };
        let declared_overscan = if !options.overscan.is_none() || job.resolution.is_some() {
            None
        } else {
            product.overscan
        };
        let own = if job.aov_given {
            None
        } else {
            Some(AovSet::parse(&product.aovs).map_err(|e| Error::bad_input("", &element, e))?)
        };
        let output = ViewOutput {
            path: PathBuf::from(&product.output),
            aovs: own,
        };
        let key = (camera.clone(), resolution, crop, declared_overscan);
        match groups.iter_mut().find(|(k, ..)| *k == key) {
            Some((_, view, aovs)) => {
                view.outputs.push(output);
                aovs.push(&product.aovs);
            }
            None => {
                let mut view_options = options.clone();
                if let Some(window) = crop.map(pixel_window) {
                    view_options.crop = Some(window);
                }
                if let Some(o) = declared_overscan {
                    view_options.overscan = overscan(o);
                }
                let view = View {
                    camera,
                    resolution,
                    options: view_options,
                    outputs: vec![output],
                };
                groups.push((key, view, vec![&product.aovs]));
            }
        }
    }
    let mut views = Vec::with_capacity(groups.len());
    for (_, mut view, aovs) in groups {
        if !job.aov_given {
            let mut names = aovs.join(",");
            if job.denoise {
                names.push_str(",albedo,normal");
            }
            view.options.aovs = AovSet::parse(&names)
                .map_err(|e| Error::bad_input("", settings.path.as_str(), e))?;
        }
        views.push(view);
    }
    if (job.resume || job.checkpoint_interval.is_some())
        && views.iter().any(|v| v.outputs.len() > 1)
    {
        return Err(Error::bad_input(
            "",
            "--resume",
            "render products that share one render cannot be resumed (each file holds only its own layers)",
        ));
    }
    Ok(views)
}

/// The film window of a declared pixel window `[x0, y0, x1, y1]` (ends excluded; the scene
/// file guarantees x0 < x1 and y0 < y1).
fn pixel_window([x0, y0, x1, y1]: [u32; 4]) -> Window {
    Window {
        x: x0,
        y: y0,
        width: x1 - x0,
        height: y1 - y0,
    }
}

/// A declared overscan, `[left, top, right, bottom]` pixels.
fn overscan([left, top, right, bottom]: [u32; 4]) -> crate::camera::Overscan {
    crate::camera::Overscan {
        left,
        top,
        right,
        bottom,
    }
}
