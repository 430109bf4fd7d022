//! Writes a film as ONE single-part, multi-layer, 32-bit float OpenEXR file (channels
//! `layer.C`, the beauty unprefixed), with lucerna's metadata and Nuke's camera matrices.

use super::Film;
use crate::error::{Error, Result};
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

/// What goes into the EXR header besides the channels.
#[derive(Clone, Debug, Default)]
pub struct Header {
    /// OpenEXR's standard `worldToCamera` and `worldToNDC` matrices (Nuke reads them), in
    /// the Imath row-vector convention: the 16 values row by row.
    pub world_to_camera: Option<[f32; 16]>,
    pub world_to_ndc: Option<[f32; 16]>,
    /// Further named attributes (lucerna's use the `lucerna/` prefix).
    pub attributes: Vec<(String, Attribute)>,
}

fn text(s: &str) -> Text {
    // EXR text is Latin-1; anything else is replaced.
    Text::new_or_none(s).unwrap_or_else(|| {
        let latin: String = s
            .chars()
            .map(|c| if (c as u32) < 256 { c } else { '?' })
            .collect();
        Text::new_or_panic(latin)
    })
}

/// Writes `film` to `path` atomically (a temporary file in the same directory, renamed
/// into place), with `header` in the header.
pub fn write(path: &Path, film: &Film, header: &Header) -> Result<()> {
    let mut channels = SmallVec::<[AnyChannel<FlatSamples>; 4]>::new();
    for aov in film.aovs.iter() {
        for (name, plane) in aov.channel_names().into_iter().zip(film.planes(aov)) {
            channels.push(AnyChannel::new(text(&name), FlatSamples::F32(plane)));
        }
    }
    let mut layer_attributes = LayerAttributes {
        software_name: Some(text(crate::RENDERER)),
        world_to_camera: header.world_to_camera,
        world_to_normalized_device: header.world_to_ndc,
        ..Default::default()
    };
    for (name, value) in &header.attributes {
        let value = match value {
            Attribute::Text(s) => AttributeValue::Text(text(s)),
            Attribute::Int(i) => AttributeValue::I32(*i),
            Attribute::Float(f) => AttributeValue::F32(*f),
            Attribute::Double(f) => AttributeValue::F64(*f),
        };
        layer_attributes.other.insert(text(name), value);
    }
    let layer = Layer::new(
        (film.width as usize, film.height as usize),
        layer_attributes,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels),
    );
    let image = Image::from_layer(layer);
    super::write_atomically(path, |file| {
        image
            .write()
            .to_buffered(file)
            .map_err(|e| Error::other(path, "EXR", e.to_string()))
    })
}
