//! The preview PNG: the beauty (or its denoised version) through an exposure and a view
//! transform, sRGB-encoded into 8 bits.
//!
//! View transforms: `standard` clips scene-linear values at 1 before the sRGB encoding (what
//! Blender calls Standard); `agx` compresses highlights smoothly and desaturates them
//! towards white, as Blender 4's default AgX view does, so that a bright light or a sunlit
//! wall is not a flat clipped patch. lucerna's AgX follows Troy Sobotka's AgX base: an
//! inset of the Rec.709 primaries, a log2 encoding over [-12.47, +4.03] stops around 0.18,
//! a sigmoid (the widely used 6th-order polynomial fit of AgX's contrast curve), the
//! outset, and the 2.2 display exponent undone before the sRGB encoding.
//!
//! `ocio` hands the image to OpenColorIO through OpenImageIO's Python module (in the
//! environment the USD plugin uses: `lucerna setup` installs it): a display and view of an
//! OCIO config (`--ocio-config`, else `$OCIO`, else OCIO's built-in default, the ACES 2.0
//! CG config), from lucerna's working space, linear Rec.709, which OCIO 2.5 configs name by
//! its interop id `lin_rec709_scene`.

use crate::color::linear_to_srgb;
use crate::error::{Error, Result};
use crate::film::Film;
use crate::film::aov::Aov;
use glam::{Mat3, Vec3};
use std::path::Path;

/// How scene-linear light becomes display values.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Curve {
    #[default]
    Standard,
    Agx,
    Ocio,
}

/// Exposure (stops) and curve of a preview, and the OCIO display and view of `ocio`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewTransform {
    pub exposure: f32,
    pub curve: Curve,
    /// An OCIO config file or `ocio://` URI (`None`: `$OCIO`, else OCIO's built-in default).
    pub ocio_config: Option<String>,
    /// Display and view (`None`: the config's defaults).
    pub ocio_display: Option<String>,
    pub ocio_view: Option<String>,
}

impl Curve {
    pub fn parse(text: &str) -> std::result::Result<Self, String> {
        match text {
            "standard" => Ok(Self::Standard),
            "agx" => Ok(Self::Agx),
            "ocio" => Ok(Self::Ocio),
            _ => Err(format!("standard, agx or ocio, got {text:?}")),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Standard => "standard",
            Self::Agx => "agx",
            Self::Ocio => "ocio",
        }
    }
}

/// AgX's inset matrix (columns), from Rec.709 to AgX's working primaries.
const AGX_INSET: Mat3 = Mat3::from_cols_array(&[
    0.842_479_06,
    0.042_328_24,
    0.042_375_655,
    0.078_433_6,
    0.878_468_6,
    0.078_433_6,
    0.079_223_745,
    0.079_166_13,
    0.879_143,
]);
/// Its outset, the inverse.
const AGX_OUTSET: Mat3 = Mat3::from_cols_array(&[
    1.196_879,
    -0.052_896_85,
    -0.052_971_635,
    -0.098_020_88,
    1.151_903_1,
    -0.098_043_45,
    -0.099_029_74,
    -0.098_961_18,
    1.151_073_7,
]);
const AGX_MIN_EV: f32 = -12.473_931;
const AGX_MAX_EV: f32 = 4.026_069;

/// AgX's contrast sigmoid on the normalised log encoding.
fn agx_contrast(x: f32) -> f32 {
    let x2 = x * x;
    let x4 = x2 * x2;
    15.5 * x4 * x2 - 40.14 * x4 * x + 31.96 * x4 - 6.868 * x2 * x + 0.4298 * x2 + 0.1191 * x
        - 0.00232
}

impl ViewTransform {
    /// The display-linear value in [0, 1] of scene-linear `rgb`.
    pub fn apply(&self, rgb: Vec3) -> Vec3 {
        let rgb = rgb * self.exposure.exp2();
        match self.curve {
            // OCIO's transforms run in OpenImageIO (see `write_rgb`); this is its fallback.
            Curve::Standard | Curve::Ocio => rgb.clamp(Vec3::ZERO, Vec3::ONE),
            Curve::Agx => {
                let v = AGX_INSET * rgb.max(Vec3::splat(1e-10));
                let log = v
                    .to_array()
                    .map(|c| c.log2().clamp(AGX_MIN_EV, AGX_MAX_EV) - AGX_MIN_EV);
                let encoded = Vec3::from(log.map(|c| agx_contrast(c / (AGX_MAX_EV - AGX_MIN_EV))));
                let display = AGX_OUTSET * encoded;
                display
                    .max(Vec3::ZERO)
                    .to_array()
                    .map(|c| c.powf(2.2).min(1.0))
                    .into()
            }
        }
    }
}

/// Writes the beauty of `film` as an sRGB PNG at `path`, atomically.
pub fn write(path: &Path, film: &Film, view: &ViewTransform) -> Result<()> {
    let planes = film.planes(Aov::Beauty);
    write_rgb(
        path,
        (film.width, film.height),
        [&planes[0], &planes[1], &planes[2]],
        view,
    )
}

/// Writes the image of three row-major planes of `width` x `height` as an sRGB PNG.
pub fn write_rgb(
    path: &Path,
    (width, height): (u32, u32),
    planes: [&[f32]; 3],
    view: &ViewTransform,
) -> Result<()> {
    let n = (width * height) as usize;
    if view.curve == Curve::Ocio {
        return write_ocio(path, (width, height), planes, view);
    }
    let mut bytes = Vec::with_capacity(n * 3);
    let pixels = planes[0].iter().zip(planes[1]).zip(planes[2]).take(n);
    for ((&r, &g), &b) in pixels {
        let rgb = Vec3::new(r, g, b);
        // NaN never reaches a film, but a preview must not panic on one either.
        let display = view.apply(if rgb.is_finite() { rgb } else { Vec3::ZERO });
        for c in display.to_array() {
            bytes.push((linear_to_srgb(c) * 255.0 + 0.5) as u8);
        }
    }
    crate::files::write_atomically(path, |file| {
        let err = |e: png::EncodingError| Error::other(path, "PNG", e.to_string());
        let mut encoder = png::Encoder::new(file, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = encoder.write_header().map_err(err)?;
        writer.write_image_data(&bytes).map_err(err)?;
        writer.finish().map_err(err)
    })
}

/// The OpenImageIO program that applies an OCIO display/view: argv are the source EXR, the
/// PNG, the config ("" for `$OCIO` or the built-in default), display and view ("" for the
/// config's defaults).
const OCIO_SCRIPT: &str = r#"
import sys
try:
    import OpenImageIO as oiio
except ImportError:
    sys.exit("OpenImageIO is not installed in this Python: run `lucerna setup`")
src, dst, config, display, view = sys.argv[1:6]
colors = oiio.ColorConfig(config)
if colors.geterror():
    sys.exit("OCIO config: " + colors.geterror())
display = display or colors.getDefaultDisplayName()
if display not in colors.getDisplayNames():
    sys.exit("no display %r in the config (it has: %s)" % (display, ", ".join(colors.getDisplayNames())))
view = view or colors.getDefaultViewName(display)
if view not in colors.getViewNames(display):
    sys.exit("no view %r for display %r (it has: %s)" % (view, display, ", ".join(colors.getViewNames(display))))
source = colors.resolve("lin_rec709_scene")
if source not in colors.getColorSpaceNames():
    sys.exit("the config has no colour space for lin_rec709_scene (linear Rec.709, lucerna's working space)")
if not src:
    sys.exit(0)  # only checking the config, display and view
image = oiio.ImageBufAlgo.ociodisplay(oiio.ImageBuf(src), display, view, fromspace=source, colorconfig=config)
if image.has_error or not image.write(dst, "uint8"):
    sys.exit(image.geterror() or oiio.geterror())
print("%s / %s" % (display, view))
"#;

/// Runs the OCIO program; `source` and `png` empty only check the config, display and
/// view. Returns what it printed, or its last error line.
fn run_ocio(
    source: &Path,
    png: &Path,
    view: &ViewTransform,
) -> std::result::Result<String, String> {
    let python = crate::install::python();
    let out = std::process::Command::new(&python)
        .arg("-c")
        .arg(OCIO_SCRIPT)
        .arg(source)
        .arg(png)
        .arg(view.ocio_config.as_deref().unwrap_or(""))
        .arg(view.ocio_display.as_deref().unwrap_or(""))
        .arg(view.ocio_view.as_deref().unwrap_or(""))
        .output()
        .map_err(|e| format!("cannot run {}: {e}; run `lucerna setup`", python.display()))?;
    if out.status.success() {
        Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
    } else {
        let said = String::from_utf8_lossy(&out.stderr);
        Err(said
            .lines()
            .last()
            .unwrap_or("OpenImageIO failed")
            .to_string())
    }
}

/// Checks an `ocio` view's config, display and view before a render, so that a mistake
/// fails at once (exit 2) rather than after the render.
pub fn check(view: &ViewTransform) -> Result<()> {
    if view.curve != Curve::Ocio {
        return Ok(());
    }
    run_ocio(Path::new(""), Path::new(""), view)
        .map(|_| ())
        .map_err(|reason| Error::bad_input("", "--view-transform ocio", reason))
}

/// [`write_rgb`] through an OCIO display and view (OpenImageIO in Python).
fn write_ocio(
    path: &Path,
    (width, height): (u32, u32),
    planes: [&[f32]; 3],
    view: &ViewTransform,
) -> Result<()> {
    let failed = |reason: String| Error::other(path, "--view-transform ocio", reason);
    let scratch = tempfile::Builder::new()
        .prefix("lucerna-ocio-")
        .tempdir()
        .map_err(|e| failed(e.to_string()))?;
    let scale = view.exposure.exp2();
    let scaled: Vec<Vec<f32>> = planes
        .iter()
        .map(|p| {
            p.iter()
                .map(|v| if v.is_finite() { v * scale } else { 0.0 })
                .collect()
        })
        .collect();
    let source = scratch.path().join("beauty.exr");
    let planes = crate::film::planes::Planes {
        display: (width, height),
        window: crate::film::Window::full(width, height),
        overscan: Default::default(),
        channels: ["R", "G", "B"]
            .iter()
            .map(|c| c.to_string())
            .zip(scaled)
            .collect(),
    };
    super::exr::write_planes(&source, planes, &super::exr::Header::default())?;
    let png = scratch.path().join("preview.png");
    let applied = run_ocio(&source, &png, view).map_err(failed)?;
    log::info!("preview through OCIO {applied}");
    // Moved into place whole, as every output is.
    crate::files::write_atomically(path, |file| {
        let bytes = std::fs::read(&png).map_err(|e| failed(e.to_string()))?;
        std::io::Write::write_all(file, &bytes).map_err(|e| failed(e.to_string()))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn agx() -> ViewTransform {
        ViewTransform {
            curve: Curve::Agx,
            ..Default::default()
        }
    }

    #[test]
    fn agx_is_monotonic_and_keeps_highlights_apart() {
        let mut last = -1.0;
        for i in 0..200 {
            let v = 1e-4 * 1.1f32.powi(i);
            let y = agx().apply(Vec3::splat(v)).x;
            assert!(y >= last, "{v}: {y} < {last}");
            assert!((0.0..=1.0).contains(&y));
            last = y;
        }
        // Where the standard view clips, AgX still tells 2 from 8.
        let (two, eight) = (
            agx().apply(Vec3::splat(2.0)).x,
            agx().apply(Vec3::splat(8.0)).x,
        );
        assert!(eight - two > 0.05, "{two} {eight}");
        // Middle grey lands near the middle of the display range, as in Blender's AgX
        // (0.18 shows as about 0.46 sRGB-encoded).
        let grey = linear_to_srgb(agx().apply(Vec3::splat(0.18)).x);
        assert!((0.40..0.52).contains(&grey), "{grey}");
    }

    #[test]
    fn agx_desaturates_bright_colours_towards_white() {
        let saturated = agx().apply(Vec3::new(64.0, 0.0, 0.0));
        assert!(saturated.y > 0.2 && saturated.x > 0.9, "{saturated}");
    }

    #[test]
    fn exposure_is_in_stops_and_standard_clamps() {
        let view = ViewTransform {
            exposure: 1.0,
            ..Default::default()
        };
        assert_eq!(view.apply(Vec3::splat(0.25)), Vec3::splat(0.5));
        assert_eq!(view.apply(Vec3::splat(4.0)), Vec3::ONE);
    }
}
