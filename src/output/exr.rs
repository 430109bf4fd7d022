//! Writes a film as one multi-layer OpenEXR file (channels `layer.C`, the beauty
//! unprefixed), single-part unless [`Parts`] splits it, with lucerna's metadata and Nuke's
//! camera matrices; reads such files back, all parts as one image. Pixels are
//! 32-bit floats, ZIP-compressed, unless [`Storage`] says otherwise: light layers may be
//! half floats (data layers, Cryptomatte, sample counts and variance stay float, as their
//! values must survive exactly), and any OpenEXR compression may be chosen, lossy ones only
//! for files without data layers. The working colour space is stated as OpenEXR's
//! `chromaticities` (Rec.709 primaries, D65 white) and the Color Interop Forum's
//! `colorInteropID` `lin_rec709_scene`; `owner`, `capDate` and `comments` (a one-line
//! summary of the render) are set, `framesPerSecond` for frames of an animation.

use crate::camera::{MAX_OVERSCAN, Overscan};
use crate::error::{Error, Result};
use crate::film::aov::Aov;
use crate::film::planes::Planes;
use crate::film::{Film, Window};
pub use exr::compression::Compression;
use exr::meta::attribute::{Chromaticities, Rational};
use exr::prelude::*;
use std::path::Path;

/// A header attribute value lucerna writes.
#[derive(Clone, Debug)]
pub enum Attribute {
    Text(String),
    Int(i32),
    Float(f32),
    Double(f64),
}

/// How pixels are stored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Storage {
    pub compression: Compression,
    /// Light layers as 16-bit half floats (values beyond half's range clamp to ±65504).
    pub half_light_layers: bool,
    /// How the channels are split into the file's parts.
    pub parts: Parts,
    /// Also write the data layers under Karma's and RenderMan's names ([`ALIASES`]).
    pub aliases: bool,
}

/// Data channels and the names Karma, RenderMan and Nuke's tools know them by
/// (`--exr-aliases`): copies written beside lucerna's, dropped again on reading (they are
/// derived), so that merging and resuming see lucerna's layers only.
pub const ALIASES: [(&str, &str); 7] = [
    ("normal.X", "N.X"),
    ("normal.Y", "N.Y"),
    ("normal.Z", "N.Z"),
    ("position.X", "P.X"),
    ("position.Y", "P.Y"),
    ("position.Z", "P.Z"),
    ("depth.Z", "Z"),
];

fn is_alias(name: &str) -> bool {
    ALIASES.iter().any(|&(_, alias)| alias == name)
}

/// How a file's channels are split into OpenEXR parts (`--exr-parts`). Every channel keeps
/// its name (`layer.C`, the beauty `R G B A`) whatever the split, so that a reader that
/// ignores parts sees the same channels; each part is named after what it holds and carries
/// the whole header.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Parts {
    /// One part: every channel (the default; what every reader reads).
    #[default]
    Single,
    /// A part per layer: `rgba` for the beauty, the layer's name for every other (Karma's
    /// and RenderMan's multi-part output; Nuke reads only the parts a node asks for).
    Layer,
    /// A part per kind of layer: `light` (the beauty and every light layer), `data` (data
    /// layers, sample counts, variance), `cryptomatte`.
    Group,
}

/// The splits `--exr-parts` names: single, layer, group.
pub fn parse_parts(text: &str) -> std::result::Result<Parts, String> {
    match text {
        "single" => Ok(Parts::Single),
        "layer" => Ok(Parts::Layer),
        "group" => Ok(Parts::Group),
        other => Err(format!("unknown split {other:?} (single, layer, group)")),
    }
}

/// The part channel `name` goes to under `parts`.
fn part_of(name: &str, parts: Parts) -> &str {
    // The depth's alias `Z` has no layer: it goes with the depth.
    let layer = match name {
        "Z" => Some("depth"),
        _ => name.rsplit_once('.').map(|(layer, _)| layer),
    };
    match (parts, layer) {
        (Parts::Single, _) => "rgba",
        (Parts::Layer, None) => "rgba",
        (Parts::Layer, Some(layer)) => layer,
        (Parts::Group, _) if layer.is_some_and(|l| l.starts_with("Crypto")) => "cryptomatte",
        (Parts::Group, _) if is_data_channel(name) => "data",
        (Parts::Group, _) => "light",
    }
}

impl Default for Storage {
    fn default() -> Self {
        Self {
            compression: Compression::ZIP16,
            half_light_layers: false,
            parts: Parts::Single,
            aliases: false,
        }
    }
}

/// The compressions `--exr-compression` names: none, rle, zips, zip, piz (lossless), pxr24,
/// b44, b44a, dwaa[:LEVEL], dwab[:LEVEL] (lossy; DWA's level 45 by default).
pub fn parse_compression(text: &str) -> std::result::Result<Compression, String> {
    let (name, level) = match text.split_once(':') {
        Some((n, l)) => (n, Some(l)),
        None => (text, None),
    };
    let level = level
        .map(|l| match l.parse::<f32>() {
            Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
            _ => Err(format!("DWA level {l:?} is not a positive number")),
        })
        .transpose()?;
    let compression = match name {
        "none" => Compression::Uncompressed,
        "rle" => Compression::RLE,
        "zips" => Compression::ZIP1,
        "zip" => Compression::ZIP16,
        "piz" => Compression::PIZ,
        "pxr24" => Compression::PXR24,
        "b44" => Compression::B44,
        "b44a" => Compression::B44A,
        "dwaa" => Compression::DWAA(level),
        "dwab" => Compression::DWAB(level),
        other => {
            return Err(format!(
                "unknown compression {other:?} (none, rle, zips, zip, piz, pxr24, b44, b44a, dwaa[:LEVEL], dwab[:LEVEL])"
            ));
        }
    };
    if level.is_some() && !matches!(compression, Compression::DWAA(_) | Compression::DWAB(_)) {
        return Err(format!("{name} takes no level"));
    }
    Ok(compression)
}

/// Whether `compression` changes values (PXR24 rounds floats to 24 bits, B44 and DWA are
/// lossy).
pub fn is_lossy(compression: Compression) -> bool {
    matches!(
        compression,
        Compression::PXR24
            | Compression::B44
            | Compression::B44A
            | Compression::DWAA(_)
            | Compression::DWAB(_)
    )
}

/// Whether channel `name` holds data rather than light: normals, depth, positions,
/// albedos, sample counts, variance and Cryptomatte must be stored exactly.
pub fn is_data_channel(name: &str) -> bool {
    if is_alias(name) {
        return true;
    }
    let Some((layer, _)) = name.rsplit_once('.') else {
        return false; // The beauty: R, G, B, A.
    };
    if layer.starts_with("Crypto") {
        return true;
    }
    Aov::parse(layer).is_some_and(|aov| !aov.is_light())
}

/// What goes into the EXR header besides the channels.
#[derive(Clone, Debug, Default)]
pub struct Header {
    /// How the pixels are stored.
    pub storage: Storage,
    /// OpenEXR's `framesPerSecond`, for a frame of an animation.
    pub frames_per_second: Option<f64>,
    /// OpenEXR's standard `worldToCamera` and `worldToNDC` matrices (Nuke reads them), in
    /// the Imath row-vector convention: the 16 values row by row.
    pub world_to_camera: Option<[f32; 16]>,
    pub world_to_ndc: Option<[f32; 16]>,
    /// Further named attributes (lucerna's use the `lucerna/` prefix).
    pub attributes: Vec<(String, Attribute)>,
}

/// A header string as UTF-8 bytes. OpenEXR's string attributes are byte strings that
/// OpenEXR, Nuke and OpenImageIO pass through as `std::string`, i.e. UTF-8 in practice.
fn text(s: &str) -> Text {
    Text::from_slice_unchecked(s.as_bytes())
}

/// A header string read back: UTF-8, or Latin-1 where the bytes are not UTF-8 (files of
/// other writers).
fn string_of(t: &Text) -> String {
    String::from_utf8(t.bytes().to_vec()).unwrap_or_else(|_| t.to_string())
}

impl Header {
    /// The value of attribute `name`, if present.
    pub fn get(&self, name: &str) -> Option<&Attribute> {
        self.attributes
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v)
    }

    /// Text attribute `name`, if present.
    pub fn text(&self, name: &str) -> Option<&str> {
        match self.get(name) {
            Some(Attribute::Text(t)) => Some(t),
            _ => None,
        }
    }

    /// Numeric attribute `name` as f64, if present.
    pub fn number(&self, name: &str) -> Option<f64> {
        match self.get(name)? {
            Attribute::Int(i) => Some(*i as f64),
            Attribute::Float(f) => Some(*f as f64),
            Attribute::Double(f) => Some(*f),
            Attribute::Text(_) => None,
        }
    }

    /// Sets attribute `name`, replacing any previous value.
    pub fn set(&mut self, name: &str, value: Attribute) {
        match self.attributes.iter_mut().find(|(n, _)| n == name) {
            Some((_, v)) => *v = value,
            None => self.attributes.push((name.into(), value)),
        }
    }
}

/// Longest channel or attribute name OpenEXR reads (its "long names" flag; 31 without it).
pub const MAX_NAME_BYTES: usize = 255;

/// Refuses channel names OpenEXR cannot hold: empty, or longer than [`MAX_NAME_BYTES`]
/// bytes (a file with one is written by some libraries and read by none).
pub fn check_names<'a>(
    names: impl IntoIterator<Item = &'a str>,
) -> std::result::Result<(), String> {
    for name in names {
        if name.is_empty() || name.len() > MAX_NAME_BYTES {
            return Err(format!(
                "channel name {:?} has {} bytes; OpenEXR holds 1 to {MAX_NAME_BYTES}",
                name.chars().take(48).collect::<String>()
                    + if name.len() > 48 { "…" } else { "" },
                name.len()
            ));
        }
    }
    Ok(())
}

/// Writes `film` to `path` atomically (a temporary file in the same directory, renamed
/// into place), with `header` in the header; `extra` AOVs (data layers the film can always
/// produce, such as `spp`) are written too even if the film's AOV set lacks them.
pub fn write(path: &Path, film: &Film, header: &Header, extra: &[Aov]) -> Result<()> {
    write_planes(path, film.to_planes(extra, |_| true), header)
}

/// Makes every value finite, as no NaN or infinity may reach a file: infinities (sums that
/// overflowed float range) become the largest float of their sign, NaN becomes 0. Returns
/// how many values were replaced.
pub fn make_finite(channels: &mut [(String, Vec<f32>)]) -> u64 {
    let mut replaced = 0;
    for (_, plane) in channels {
        for v in plane.iter_mut().filter(|v| !v.is_finite()) {
            *v = if v.is_nan() {
                0.0
            } else {
                f32::MAX.copysign(*v)
            };
            replaced += 1;
        }
    }
    replaced
}

/// Writes `planes` to `path` atomically, with `header` in the header. The planes move into
/// the encoder: no copy of the image is made.
pub fn write_planes(path: &Path, planes: Planes, header: &Header) -> Result<()> {
    check_names(planes.channels.iter().map(|(n, _)| n.as_str()))
        .and_then(|()| check_names(header.attributes.iter().map(|(n, _)| n.as_str())))
        .map_err(|reason| Error::bad_input(path, "channels", reason))?;
    // The display window is the image without its overscan; the data window, in its
    // coordinates, may start left of and above its origin.
    let display = planes.overscan.display(planes.display);
    let window = planes.window;
    let origin = (
        window.x as i64 - planes.overscan.left as i64,
        window.y as i64 - planes.overscan.top as i64,
    );
    let mut planes = planes;
    if header.storage.aliases {
        for (from, to) in ALIASES {
            if let Some(plane) = planes.channel(from).map(<[f32]>::to_vec) {
                planes.channels.push((to.to_string(), plane));
            }
        }
    }
    let replaced = make_finite(&mut planes.channels);
    let mut header = header.clone();
    if replaced > 0 {
        log::warn!(
            "{}: {replaced} values beyond float range written as the largest float (NaN as 0); lucerna/non_finite_replaced counts them",
            path.display()
        );
        header.set(
            "lucerna/non_finite_replaced",
            Attribute::Double(replaced as f64),
        );
    }
    let header = &header;
    let mut compression = header.storage.compression;
    if is_lossy(compression)
        && let Some((name, _)) = planes.channels.iter().find(|(n, _)| is_data_channel(n))
    {
        // A checkpoint's sample counts, or a data layer: never stored lossily.
        log::info!(
            "note: {}: written with ZIP compression: channel {name} holds data that {} would change",
            path.display(),
            compression
        );
        compression = Compression::ZIP16;
    }
    let half = header.storage.half_light_layers;
    // The channels of each part, parts in the order their first channel comes.
    let mut parts: Vec<(String, SmallVec<[AnyChannel<FlatSamples>; 4]>)> = Vec::new();
    for (name, plane) in planes.channels {
        let samples = if half && !is_data_channel(&name) {
            let max = exr::prelude::f16::MAX.to_f32();
            FlatSamples::F16(
                plane
                    .iter()
                    .map(|v| exr::prelude::f16::from_f32(v.clamp(-max, max)))
                    .collect(),
            )
        } else {
            FlatSamples::F32(plane)
        };
        let part = part_of(&name, header.storage.parts).to_string();
        let channel = AnyChannel::new(text(&name), samples);
        match parts.iter_mut().find(|(p, _)| *p == part) {
            Some((_, channels)) => channels.push(channel),
            None => parts.push((part, SmallVec::from_elem(channel, 1))),
        }
    }
    let mut layer_attributes = LayerAttributes {
        software_name: Some(text(crate::RENDERER)),
        world_to_camera: header.world_to_camera,
        world_to_normalized_device: header.world_to_ndc,
        layer_position: Vec2(origin.0 as i32, origin.1 as i32),
        owner: owner().map(|o| text(&o)),
        comments: summary(header).map(|c| text(&c)),
        capture_date: Some(text(&capture_date(std::time::SystemTime::now()))),
        utc_offset: Some(0.0),
        frames_per_second: header.frames_per_second.and_then(rational),
        ..Default::default()
    };
    layer_attributes.other.insert(
        text("colorInteropID"),
        AttributeValue::Text(text("lin_rec709_scene")),
    );
    for (name, value) in &header.attributes {
        let value = match value {
            Attribute::Text(s) => AttributeValue::Text(text(s)),
            Attribute::Int(i) => AttributeValue::I32(*i),
            Attribute::Float(f) => AttributeValue::F32(*f),
            Attribute::Double(f) => AttributeValue::F64(*f),
        };
        layer_attributes.other.insert(text(name), value);
    }
    let encoding = Encoding {
        compression,
        ..Encoding::SMALL_LOSSLESS
    };
    let single = parts.len() == 1;
    let layers: Layers<AnyChannels<FlatSamples>> = parts
        .into_iter()
        .map(|(part, channels)| {
            let attributes = LayerAttributes {
                // A single-part file keeps no part name, as before.
                layer_name: (!single).then(|| text(&part)),
                ..layer_attributes.clone()
            };
            Layer::new(
                (window.width as usize, window.height as usize),
                attributes,
                encoding,
                AnyChannels::sort(channels),
            )
        })
        .collect();
    let display = IntegerBounds::new((0, 0), (display.0 as usize, display.1 as usize));
    let mut image_attributes = ImageAttributes::new(display);
    image_attributes.chromaticities = Some(REC709_D65);
    let image = Image::from_layers(image_attributes, layers);
    crate::files::write_atomically(path, |file| {
        image
            .write()
            .to_buffered(file)
            .map_err(|e| Error::other(path, "EXR", e.to_string()))
    })
}

/// lucerna's working colour space: Rec.709 (sRGB) primaries, D65 white point.
pub const REC709_D65: Chromaticities = Chromaticities {
    red: Vec2(0.64, 0.33),
    green: Vec2(0.30, 0.60),
    blue: Vec2(0.15, 0.06),
    white: Vec2(0.3127, 0.3290),
};

/// OpenEXR's `comments` (what Nuke's metadata viewer shows as `exr/comments`): one line
/// saying how the image was made, from lucerna's attributes ("lucerna 0.1.0: scene.usda,
/// 256 spp, 16777216 samples, 1.2e9 rays in 93.4 s on host"); `None` for a header without
/// them (an image that is not a render).
pub fn summary(header: &Header) -> Option<String> {
    let renderer = header.text("lucerna/renderer")?;
    let scene = header.text("lucerna/scene").map(|s| {
        Path::new(s)
            .file_name()
            .map_or(s.to_string(), |n| n.to_string_lossy().into_owned())
    });
    let mut line = format!(
        "{renderer}: {}",
        scene.as_deref().unwrap_or("the default scene")
    );
    if let Some(spp) = header.number("lucerna/spp") {
        line += &format!(", {spp} spp");
    }
    if let Some(samples) = header.number("lucerna/samples") {
        line += &format!(", {samples} samples");
    }
    if let Some(rays) = header.number("lucerna/rays") {
        line += &format!(", {rays:.3e} rays");
    }
    if let Some(seconds) = header.number("lucerna/render_seconds") {
        line += &format!(" in {seconds:.1} s");
    }
    if let Some(host) = header.text("lucerna/host") {
        line += &format!(" on {host}");
    }
    if let Some(parts) = header.number("lucerna/merged_parts") {
        line += &format!(", merged from {parts} parts");
    }
    if header.number("lucerna/complete") == Some(0.0) {
        line += " (interrupted: incomplete)";
    }
    Some(line)
}

/// The user running the render, for OpenEXR's `owner`.
fn owner() -> Option<String> {
    ["USER", "LOGNAME", "USERNAME"]
        .iter()
        .find_map(|v| std::env::var(v).ok())
        .filter(|o| !o.is_empty())
}

/// OpenEXR's `capDate` format, "YYYY:MM:DD hh:mm:ss", in UTC (`utcOffset` 0).
pub fn capture_date(time: std::time::SystemTime) -> String {
    let secs = time
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() as i64);
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Days since 1970-01-01 to a civil date (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + (month <= 2) as i64;
    format!(
        "{year:04}:{month:02}:{day:02} {:02}:{:02}:{:02}",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

/// Frames per second as OpenEXR's rational (thousandths: 23.976 is 23976/1000).
fn rational(fps: f64) -> Option<Rational> {
    (fps.is_finite() && fps > 0.0 && fps < 1e6).then(|| (((fps * 1000.0).round()) as i32, 1000))
}

/// The attributes lucerna reads back from a layer's header.
fn header_of(attributes: &LayerAttributes) -> Header {
    Header {
        storage: Storage::default(),
        frames_per_second: None,
        world_to_camera: attributes.world_to_camera,
        world_to_ndc: attributes.world_to_normalized_device,
        attributes: attributes
            .other
            .iter()
            .filter_map(|(name, value)| {
                let value = match value {
                    AttributeValue::Text(t) => Attribute::Text(string_of(t)),
                    AttributeValue::I32(i) => Attribute::Int(*i),
                    AttributeValue::F32(f) => Attribute::Float(*f),
                    AttributeValue::F64(f) => Attribute::Double(*f),
                    _ => return None,
                };
                Some((name.to_string(), value))
            })
            .collect(),
    }
}

/// Reads only the header of an EXR's first layer (no pixels).
pub fn read_header(path: &Path) -> Result<Header> {
    crate::files::check_input(path).map_err(|e| Error::bad_input(path, "file", e))?;
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| Error::bad_input(path, "EXR", e.to_string()))?;
    let first = meta
        .headers
        .first()
        .ok_or_else(|| Error::bad_input(path, "EXR", "no header"))?;
    Ok(header_of(&first.own_attributes))
}

/// Reads an EXR's first layer: every channel as f32 planes, its windows, and the header
/// attributes lucerna writes (text and numbers; others are skipped).
pub fn read(path: &Path) -> Result<(Planes, Header)> {
    let bad = |element: &str, reason: String| Error::bad_input(path, element, reason);
    crate::files::check_input(path).map_err(|e| bad("file", e))?;
    // The data window and channels decide what reading allocates: checked first.
    let meta =
        exr::meta::MetaData::read_from_file(path, false).map_err(|e| bad("EXR", e.to_string()))?;
    let bytes: u64 = meta
        .headers
        .iter()
        .map(|h| {
            h.layer_size.area() as u64
                * h.channels
                    .list
                    .iter()
                    .map(|c| c.sample_type.bytes_per_sample() as u64 + 4)
                    .sum::<u64>()
        })
        .sum();
    crate::memory::check_allocation(bytes, "its pixels").map_err(|e| bad("dataWindow", e))?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_file(path)
        .map_err(|e| bad("EXR", e.to_string()))?;
    let display_window = image.attributes.display_window;
    if display_window.position != Vec2(0, 0) {
        return Err(bad(
            "displayWindow",
            format!(
                "starts at {:?}; lucerna reads images whose display window starts at 0, 0",
                display_window.position
            ),
        ));
    }
    // The parts of a multi-part file (`Parts`) hold the same window: their channels are
    // read as one image, the header from the first.
    let mut layers = image.layer_data.into_iter();
    let layer = layers
        .next()
        .ok_or_else(|| bad("EXR", "no image part".into()))?;
    let (position, size) = (layer.attributes.layer_position, layer.size);
    let mut channels: Vec<(String, Vec<f32>)> = planes_of(layer.channel_data);
    for other in layers {
        if other.attributes.layer_position != position || other.size != size {
            return Err(bad(
                "dataWindow",
                "the file's parts cover different windows; lucerna reads parts of one window"
                    .into(),
            ));
        }
        for channel in planes_of(other.channel_data) {
            if channels.iter().any(|(n, _)| *n == channel.0) {
                return Err(bad(
                    "channels",
                    format!("channel {} is in more than one part", channel.0),
                ));
            }
            channels.push(channel);
        }
    }
    // A data window beyond the display window is overscan: the planes cover the display
    // window grown by it, and the window is placed in that.
    let (x, y) = (position.x() as i64, position.y() as i64);
    let (w, h) = (size.width() as i64, size.height() as i64);
    let (dw, dh) = (
        display_window.size.width() as i64,
        display_window.size.height() as i64,
    );
    let beyond = |v: i64| u32::try_from(v.max(0)).ok().filter(|&v| v <= MAX_OVERSCAN);
    let edges = [-x, -y, x + w - dw, y + h - dh].map(beyond);
    let [Some(left), Some(top), Some(right), Some(bottom)] = edges else {
        return Err(bad(
            "dataWindow",
            format!("it reaches more than {MAX_OVERSCAN} pixels beyond the display window"),
        ));
    };
    let header = header_of(&layer.attributes);
    // A crop of an overscanned render need not reach into the overscan: the render's own
    // record of it, where it covers the data window, says how large the image rendered was.
    let recorded = header.text("lucerna/settings").and_then(|text| {
        let mut options = crate::render::options::RenderOptions::default();
        options.load_recorded_settings(text).ok()?;
        Some(options.overscan)
    });
    let overscan = match recorded {
        Some(o) if o.left >= left && o.top >= top && o.right >= right && o.bottom >= bottom => o,
        _ => Overscan {
            left,
            top,
            right,
            bottom,
        },
    };
    let display = overscan.extend((dw as u32, dh as u32));
    let window = Window {
        x: (x + overscan.left as i64) as u32,
        y: (y + overscan.top as i64) as u32,
        width: w as u32,
        height: h as u32,
    };
    Ok((
        Planes {
            display,
            window,
            overscan,
            channels,
        },
        header,
    ))
}

/// A part's channels as f32 planes, without the aliases (derived from the others).
fn planes_of(channels: AnyChannels<FlatSamples>) -> Vec<(String, Vec<f32>)> {
    channels
        .list
        .into_iter()
        .filter(|c| !is_alias(&c.name.to_string()))
        .map(|c| {
            let plane = match c.sample_data {
                FlatSamples::F32(v) => v,
                FlatSamples::F16(v) => v.iter().map(|h| h.to_f32()).collect(),
                FlatSamples::U32(v) => v.iter().map(|&u| u as f32).collect(),
            };
            (c.name.to_string(), plane)
        })
        .collect()
}

#[cfg(test)]
mod storage_tests {
    use super::*;
    use std::time::{Duration, UNIX_EPOCH};

    /// The `comments` line says what made the image from lucerna's attributes, with the
    /// scene's file name (not its directories), and says when parts were merged or the render
    /// was interrupted; an image without lucerna's attributes gets none.
    #[test]
    fn comments_summarise_the_render() {
        let mut header = Header::default();
        assert_eq!(summary(&header), None);
        for (name, value) in [
            ("lucerna/renderer", Attribute::Text("lucerna 0.1.0".into())),
            (
                "lucerna/scene",
                Attribute::Text("/shots/sq010/shot.usda".into()),
            ),
            ("lucerna/spp", Attribute::Int(256)),
            ("lucerna/samples", Attribute::Double(16_777_216.0)),
            ("lucerna/rays", Attribute::Double(1.25e9)),
            ("lucerna/render_seconds", Attribute::Double(93.44)),
            ("lucerna/host", Attribute::Text("farm07".into())),
            ("lucerna/complete", Attribute::Int(1)),
        ] {
            header.set(name, value);
        }
        assert_eq!(
            summary(&header).unwrap(),
            "lucerna 0.1.0: shot.usda, 256 spp, 16777216 samples, 1.250e9 rays in 93.4 s on farm07"
        );
        header.set("lucerna/merged_parts", Attribute::Int(4));
        header.set("lucerna/complete", Attribute::Int(0));
        assert!(
            summary(&header)
                .unwrap()
                .ends_with("on farm07, merged from 4 parts (interrupted: incomplete)")
        );
    }

    #[test]
    fn capture_dates_are_civil_utc() {
        assert_eq!(capture_date(UNIX_EPOCH), "1970:01:01 00:00:00");
        // 2000-02-29 12:34:56 UTC (a leap day) and 2026-12-03 19:19:40 UTC.
        assert_eq!(
            capture_date(UNIX_EPOCH + Duration::from_secs(951_827_696)),
            "2000:02:29 12:34:56"
        );
        assert_eq!(
            capture_date(UNIX_EPOCH + Duration::from_secs(1_796_325_580)),
            "2026:12:03 19:19:40"
        );
    }

    #[test]
    fn compressions_parse_and_classify() {
        assert_eq!(parse_compression("zip"), Ok(Compression::ZIP16));
        assert_eq!(
            parse_compression("dwaa:45"),
            Ok(Compression::DWAA(Some(45.0)))
        );
        assert!(parse_compression("zip:3").is_err());
        assert!(parse_compression("dwaa:-1").is_err());
        assert!(parse_compression("jpeg").unwrap_err().contains("piz"));
        assert!(is_lossy(Compression::PXR24) && !is_lossy(Compression::PIZ));
        assert!(is_data_channel("normal.X") && is_data_channel("CryptoObject00.R"));
        assert!(is_data_channel("spp.Y") && is_data_channel("variance.R"));
        assert!(
            !is_data_channel("R") && !is_data_channel("direct.G") && !is_data_channel("lg_key.B")
        );
    }
}
