//! Combining the EXRs of a split render (`lucerna merge`): sample passes of the same pixels
//! and tiles of one image, in any mix. Where several parts hold a pixel, light and data
//! layers become sample-weighted means, `spp` the sum, `depth` the nearest, and `variance`
//! the variance of the pooled mean; where one part holds it, its values are copied. The
//! result is the image one render with all the samples gives, up to float rounding.

use crate::error::{Error, Result};
use crate::film::Window;
use crate::film::planes::Planes;
use crate::integrator::settings::read_settings_toml;
use crate::output::exr::{Attribute, Header};
use crate::render::RenderOptions;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// One partial render, read back.
pub struct Part {
    pub path: PathBuf,
    pub planes: Planes,
    pub header: Header,
}

/// Settings that may differ between the parts of one render (parts with different seeds
/// are independent estimates, and merge as well as passes of one seed).
const SPLIT_KEYS: [&str; 5] = ["spp", "pass", "crop", "time", "seed"];

/// The header's settings other than [`SPLIT_KEYS`].
fn shared_settings(header: &Header) -> BTreeMap<String, String> {
    header
        .text("lucerna/settings")
        .and_then(|t| read_settings_toml(t).ok())
        .unwrap_or_default()
        .into_iter()
        .filter(|(k, _)| !SPLIT_KEYS.contains(&k.as_str()))
        .collect()
}

fn overlap(a: &Window, b: &Window) -> bool {
    a.x < b.x + b.width && b.x < a.x + a.width && a.y < b.y + b.height && b.y < a.y + a.height
}

/// Whether two headers are renders of one scene: by the scene file's fingerprint where
/// both have one (any path may name the file), else by the scene as named.
fn same_scene(a: &Header, b: &Header) -> bool {
    match (
        a.text("lucerna/scene_fingerprint"),
        b.text("lucerna/scene_fingerprint"),
    ) {
        (Some(x), Some(y)) => x == y,
        _ => a.text("lucerna/scene") == b.text("lucerna/scene"),
    }
}

/// Checks that a part's values can be merged: finite everywhere, sample counts whole and
/// not negative, and a beauty wherever there is a variance to pool.
fn check_values(part: &Part) -> Result<()> {
    for (name, plane) in &part.planes.channels {
        if let Some(i) = plane.iter().position(|v| !v.is_finite()) {
            return Err(Error::bad_input(
                &part.path,
                name.as_str(),
                format!(
                    "holds {} at pixel {i}: a part to merge must be finite",
                    plane[i]
                ),
            ));
        }
    }
    if let Some(spp) = part.planes.channel("spp.Y")
        && let Some(i) = spp.iter().position(|v| *v < 0.0 || v.fract() != 0.0)
    {
        return Err(Error::bad_input(
            &part.path,
            "spp.Y",
            format!(
                "holds {} at pixel {i}: sample counts are whole and not negative",
                spp[i]
            ),
        ));
    }
    for c in ["R", "G", "B"] {
        if part.planes.channel(&format!("variance.{c}")).is_some()
            && part.planes.channel(c).is_none()
        {
            return Err(Error::bad_input(
                &part.path,
                format!("variance.{c}"),
                "a variance layer without the beauty it describes cannot be merged",
            ));
        }
    }
    Ok(())
}

/// Checks that `parts` belong to one render and hold no sample twice.
fn check(parts: &[Part]) -> Result<()> {
    for part in parts {
        check_values(part)?;
    }
    let first = &parts[0];
    // The same channels in any order (files split into parts differently list them so).
    let names = |p: &Part| {
        let mut names: Vec<String> = p.planes.channels.iter().map(|(n, _)| n.clone()).collect();
        names.sort();
        names
    };
    let settings = shared_settings(&first.header);
    for part in &parts[1..] {
        let bad = |element: &str, reason: String| Error::bad_input(&part.path, element, reason);
        if part.planes.display != first.planes.display {
            return Err(bad(
                "displayWindow",
                format!(
                    "{}x{}, but {} is {}x{}",
                    part.planes.display.0,
                    part.planes.display.1,
                    first.path.display(),
                    first.planes.display.0,
                    first.planes.display.1
                ),
            ));
        }
        if names(part) != names(first) {
            return Err(bad(
                "channels",
                format!(
                    "{} differ from {}'s {}",
                    names(part).join(" "),
                    first.path.display(),
                    names(first).join(" ")
                ),
            ));
        }
        if !same_scene(&part.header, &first.header) {
            return Err(bad(
                "lucerna/scene",
                format!("a render of another scene than {}", first.path.display()),
            ));
        }
        if part.header.text("lucerna/shutter") != first.header.text("lucerna/shutter") {
            return Err(bad(
                "lucerna/shutter",
                format!(
                    "rendered with another shutter than {}",
                    first.path.display()
                ),
            ));
        }
        let other = shared_settings(&part.header);
        if let Some(key) = settings
            .keys()
            .chain(other.keys())
            .find(|k| settings.get(*k) != other.get(*k))
        {
            return Err(bad(
                "lucerna/settings",
                format!(
                    "{key} = {:?}, but {} has {:?}: the parts of one render share their settings",
                    other.get(key),
                    first.path.display(),
                    settings.get(key)
                ),
            ));
        }
    }
    // Which samples of which sequence each part holds.
    let samples = parts
        .iter()
        .map(|p| {
            let mut options = RenderOptions::default();
            options
                .load_recorded_settings(p.header.text("lucerna/settings").unwrap_or_default())
                .map(|()| (options.settings.seed, options.sample_range()))
                .map_err(|e| Error::bad_input(&p.path, "lucerna/settings", e))
        })
        .collect::<Result<Vec<_>>>()?;
    for (i, a) in parts.iter().enumerate() {
        for (j, b) in parts.iter().enumerate().skip(i + 1) {
            if !overlap(&a.planes.window, &b.planes.window) {
                continue;
            }
            if let Some((name, _)) = a
                .planes
                .channels
                .iter()
                .find(|(n, _)| n.starts_with("Crypto"))
            {
                return Err(Error::bad_input(
                    &b.path,
                    name.as_str(),
                    format!(
                        "it overlaps {}: Cryptomatte ranks of overlapping parts cannot be combined (split renders with crypto layers by --crop only)",
                        a.path.display()
                    ),
                ));
            }
            let ((seed_a, range_a), (seed_b, range_b)) = (&samples[i], &samples[j]);
            if seed_a == seed_b && range_a.start < range_b.end && range_b.start < range_a.end {
                return Err(Error::bad_input(
                    &b.path,
                    "lucerna/settings",
                    format!(
                        "it holds the same samples as {} (samples {range_b:?} and {range_a:?} of seed {seed_a}): parts to merge must be different passes or seeds",
                        a.path.display()
                    ),
                ));
            }
            for part in [a, b] {
                if part.planes.channel("spp.Y").is_none() {
                    return Err(Error::bad_input(
                        &part.path,
                        "spp",
                        "it overlaps another part, and weighting their samples needs its spp layer (render with --aov ...,spp)",
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The merged image of `parts` and its header: the first part's, with the sample counts,
/// render seconds and NaN/Inf counts summed and the settings made those of the whole.
pub fn merge(parts: &[Part]) -> Result<(Planes, Header)> {
    if parts.is_empty() {
        return Err(Error::bad_input("", "merge", "no input files"));
    }
    check(parts)?;
    let display = parts[0].planes.display;
    let x0 = parts.iter().map(|p| p.planes.window.x).min().unwrap_or(0);
    let y0 = parts.iter().map(|p| p.planes.window.y).min().unwrap_or(0);
    let x1 = parts
        .iter()
        .map(|p| p.planes.window.x + p.planes.window.width)
        .max()
        .unwrap_or(0);
    let y1 = parts
        .iter()
        .map(|p| p.planes.window.y + p.planes.window.height)
        .max()
        .unwrap_or(0);
    let window = Window {
        x: x0,
        y: y0,
        width: x1 - x0,
        height: y1 - y0,
    };
    let n = window.pixel_count();
    // Per output pixel: how many parts hold it, and their samples.
    let mut cover = vec![0u32; n];
    let mut samples = vec![0f64; n];
    for part in parts {
        let spp = part.planes.channel("spp.Y");
        for_each_pixel(&part.planes.window, &window, |i, o| {
            cover[o] += 1;
            samples[o] += spp.map_or(1.0, |s| s[i] as f64);
        });
    }
    let uncovered = cover.iter().filter(|&&c| c == 0).count();
    if uncovered > 0 {
        log::warn!(
            "merge: {uncovered} pixels of the window {} are in no input; they are black",
            window.describe()
        );
    }
    let mut channels = Vec::new();
    let denoised = format!("{}.", crate::output::denoise::LAYER);
    if parts[0]
        .planes
        .channels
        .iter()
        .any(|(n, _)| n.starts_with(&denoised))
    {
        log::info!(
            "merge: the parts' denoised layers are left out (a mean of denoised parts is not the denoised whole): run `lucerna denoise` on the merged file"
        );
    }
    for (name, _) in &parts[0].planes.channels {
        if name.starts_with(&denoised) {
            continue;
        }
        let mut out = vec![0f64; n];
        let mut seen = vec![false; n];
        let beauty = name
            .strip_prefix("variance.")
            .filter(|c| ["R", "G", "B"].contains(c));
        // For the pooled variance: per pixel, the sum of samples and of their squares.
        let mut squares = vec![0f64; if beauty.is_some() { n } else { 0 }];
        for part in parts {
            let plane = part.planes.channel(name).expect("checked: same channels");
            let spp = part.planes.channel("spp.Y");
            let mean = beauty.map(|c| part.planes.channel(c).expect("the beauty is written"));
            for_each_pixel(&part.planes.window, &window, |i, o| {
                let v = plane[i] as f64;
                if cover[o] == 1 {
                    out[o] = v;
                    return;
                }
                let k = spp.map_or(1.0, |s| s[i] as f64);
                match (name.as_str(), mean) {
                    ("spp.Y", _) => out[o] += v,
                    ("depth.Z", _) => out[o] = if seen[o] { out[o].min(v) } else { v },
                    (_, Some(mean)) => {
                        let sum = mean[i] as f64 * k;
                        out[o] += sum;
                        if k > 0.0 {
                            squares[o] += v * k * (k - 1.0) + sum * sum / k;
                        }
                    }
                    _ => out[o] += v * k,
                }
                seen[o] = true;
            });
        }
        for o in 0..n {
            if cover[o] < 2 || name == "spp.Y" || name == "depth.Z" {
                continue;
            }
            let total = samples[o];
            out[o] = match beauty {
                Some(_) if total > 1.0 => {
                    ((squares[o] - out[o] * out[o] / total) / (total * (total - 1.0))).max(0.0)
                }
                Some(_) => 0.0,
                None if total > 0.0 => out[o] / total,
                None => 0.0,
            };
        }
        channels.push((name.clone(), out.into_iter().map(|v| v as f32).collect()));
    }
    let planes = Planes {
        display,
        window,
        overscan: parts[0].planes.overscan,
        channels,
    };
    let header = merged_header(parts, &planes)?;
    Ok((planes, header))
}

/// Calls `f(index in part, index in out)` for every pixel of window `part` inside `out`.
fn for_each_pixel(part: &Window, out: &Window, mut f: impl FnMut(usize, usize)) {
    for y in part.y..part.y + part.height {
        for x in part.x..part.x + part.width {
            f(part.index(x, y), out.index(x, y));
        }
    }
}

fn merged_header(parts: &[Part], planes: &Planes) -> Result<Header> {
    let mut header = parts[0].header.clone();
    let sum = |name: &str| {
        parts
            .iter()
            .filter_map(|p| p.header.number(name))
            .sum::<f64>()
    };
    header.set("lucerna/samples", Attribute::Double(sum("lucerna/samples")));
    if parts
        .iter()
        .any(|p| p.header.number("lucerna/rays").is_some())
    {
        header.set("lucerna/rays", Attribute::Double(sum("lucerna/rays")));
    }
    // The machines that rendered the parts, each once, in part order.
    let mut hosts: Vec<&str> = Vec::new();
    for host in parts.iter().filter_map(|p| p.header.text("lucerna/host")) {
        if !hosts.contains(&host) {
            hosts.push(host);
        }
    }
    if !hosts.is_empty() {
        header.set("lucerna/host", Attribute::Text(hosts.join(", ")));
    }
    header.set(
        "lucerna/render_seconds",
        Attribute::Double(sum("lucerna/render_seconds")),
    );
    header.set(
        "lucerna/nan_inf_discarded",
        Attribute::Double(sum("lucerna/nan_inf_discarded")),
    );
    let complete = parts
        .iter()
        .all(|p| p.header.number("lucerna/complete") != Some(0.0));
    header.set("lucerna/complete", Attribute::Int(complete as i32));
    header.set("lucerna/merged_parts", Attribute::Int(parts.len() as i32));
    let spp = planes
        .channel("spp.Y")
        .map(|s| s.iter().fold(0f32, |a, &b| a.max(b)) as u32);
    if let Some(spp) = spp {
        header.set("lucerna/spp", Attribute::Int(spp as i32));
    }
    if let Some(text) = parts[0].header.text("lucerna/settings") {
        let mut options = RenderOptions::default();
        options
            .load_recorded_settings(text)
            .map_err(|e| Error::bad_input(&parts[0].path, "lucerna/settings", e))?;
        options.pass = None;
        // The crop in the image's coordinates: the merged window without the overscan.
        let o = planes.overscan;
        options.overscan = o;
        options.crop =
            (planes.window != Window::full(planes.display.0, planes.display.1)).then(|| Window {
                x: planes.window.x.saturating_sub(o.left),
                y: planes.window.y.saturating_sub(o.top),
                ..planes.window
            });
        let taken = spp.unwrap_or(options.spp.unwrap_or(0));
        header.set("lucerna/settings", Attribute::Text(options.to_toml(taken)));
    }
    Ok(header)
}
