//! Frame sequences: the frame lists of `--frames` and of batch jobs, and the output name
//! patterns (`{frame}`, `####`, `%04d`, `$F4`, `<F4>`, `{scene}`, `{camera}`) that give every
//! frame its file.

use std::path::{Path, PathBuf};

/// Frames to render, in the order given.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameList(pub Vec<f64>);

/// Most frames one list may hold (a typo such as 1-1000000 fails early).
const MAX_FRAMES: usize = 100_000;

impl FrameList {
    /// Parses comma-separated frames `A` and ranges `A-B` or `A-BxS` (every S-th frame from
    /// A to B), e.g. `1-24`, `1-24x2`, `1,5,10-12`.
    pub fn parse(text: &str) -> Result<Self, String> {
        let number = |v: &str| {
            v.trim()
                .parse::<u32>()
                .map_err(|_| format!("{v:?} is not a frame number (a non-negative integer)"))
        };
        let mut frames = Vec::new();
        for item in text.split(',') {
            let (range, step) = match item.split_once('x') {
                Some((r, step)) => (r, number(step)?),
                None => (item, 1),
            };
            let (a, b) = match range.split_once('-') {
                Some((a, b)) => (number(a)?, number(b)?),
                None => (number(range)?, number(range)?),
            };
            if b < a || step == 0 {
                return Err(format!("{item:?}: a range A-B[xS] needs A <= B and S >= 1"));
            }
            if (b - a) as usize / step as usize + frames.len() >= MAX_FRAMES {
                return Err(format!("more than {MAX_FRAMES} frames"));
            }
            frames.extend((a..=b).step_by(step as usize).map(f64::from));
        }
        Ok(Self(frames))
    }
}

/// The file of `frame` of `scene` through `camera`: `pattern` with its frame tokens (see
/// [`expand_frame`]), `{scene}` and `{camera}` replaced. A still (no frame) keeps the other
/// tools' tokens as written (`take#2.exr` names a file, as before they were tokens) and
/// refuses `{frame}`, lucerna's own.
pub fn output_path(
    pattern: &Path,
    frame: Option<f64>,
    scene: &str,
    camera: &str,
) -> Result<PathBuf, String> {
    let text = pattern.to_string_lossy();
    let text = match frame {
        Some(f) => expand_frame(&text, f),
        None if text.contains("{frame}") => {
            return Err(format!(
                "{text:?} has {{frame}} but no frame was given (--frame or --frames)"
            ));
        }
        None => text.into_owned(),
    };
    Ok(PathBuf::from(
        text.replace("{scene}", &file_name_part(scene))
            .replace("{camera}", &file_name_part(camera)),
    ))
}

/// The frame tokens an output name may hold, as messages list them.
pub const FRAME_TOKENS: &str = "{frame}, ####, %04d, $F4 or <F4>";

/// A frame token at the start of `text`: its length in bytes and the frame's width (0 for
/// unpadded). `{frame}` is four digits wide; a run of N `#` is N wide (Nuke, RenderMan);
/// `%0Nd` and `%Nd` are N wide (printf, Nuke); `$F` and `$FN` (Houdini, husk) and `<F>` and
/// `<FN>` (RenderMan) are N wide, unpadded without N.
fn frame_token(text: &str) -> Option<(usize, usize)> {
    let b = text.as_bytes();
    let digit = |i: usize| {
        b.get(i)
            .filter(|c| c.is_ascii_digit())
            .map(|c| (c - b'0') as usize)
    };
    if text.starts_with("{frame}") {
        return Some((7, 4));
    }
    match b.first()? {
        b'#' => {
            let n = b.iter().take_while(|&&c| c == b'#').count();
            Some((n, n))
        }
        b'%' => {
            let at = if b.get(1) == Some(&b'0') { 2 } else { 1 };
            let width = digit(at)?;
            (b.get(at + 1) == Some(&b'd')).then_some((at + 2, width))
        }
        b'$' if b.get(1) == Some(&b'F') => Some(match digit(2) {
            Some(width) => (3, width),
            None => (2, 0),
        }),
        b'<' if b.get(1) == Some(&b'F') => match (digit(2), b.get(2), b.get(3)) {
            (Some(width), _, Some(b'>')) => Some((4, width)),
            (None, Some(b'>'), _) => Some((3, 0)),
            _ => None,
        },
        _ => None,
    }
}

/// True if `text` holds a frame token.
pub fn has_frame_token(text: &str) -> bool {
    text.char_indices()
        .any(|(i, _)| frame_token(&text[i..]).is_some())
}

/// `text` with every frame token replaced by `frame`: a whole frame zero-padded to the
/// token's width (the sign before the digits), a fractional one as it is (`7.5`), as the
/// USD plugin expands a RenderProduct's name.
pub fn expand_frame(text: &str, frame: f64) -> String {
    let formatted = |width: usize| {
        if frame.fract() != 0.0 {
            return format!("{frame}");
        }
        let whole = frame as i64;
        let digits = format!("{:0width$}", whole.unsigned_abs());
        if whole < 0 {
            format!("-{digits}")
        } else {
            digits
        }
    };
    let mut out = String::with_capacity(text.len() + 8);
    let mut i = 0;
    while i < text.len() {
        if let Some((length, width)) = frame_token(&text[i..]) {
            out.push_str(&formatted(width));
            i += length;
        } else {
            let c = text[i..].chars().next().expect("i is a char boundary");
            out.push(c);
            i += c.len_utf8();
        }
    }
    out
}

/// A scene-controlled name (a camera's, a file stem) made safe to put in a file name: path
/// separators, control characters and a leading dot become `_`, so a name can neither
/// leave the output's directory (`../x`, `/etc/x`) nor hide the file; empty becomes `_`.
pub fn file_name_part(name: &str) -> String {
    let mut part: String = name
        .chars()
        .map(|c| {
            if c == '/' || c == '\\' || c.is_control() {
                '_'
            } else {
                c
            }
        })
        .collect();
    if part.starts_with('.') || part.is_empty() {
        part.replace_range(0..part.find(|c| c != '.').unwrap_or(part.len()), "_");
        if part.is_empty() {
            part.push('_');
        }
    }
    part
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_names_cannot_leave_the_output_directory() {
        for (name, safe) in [
            ("../../etc/passwd", "__.._etc_passwd"),
            ("/abs/cam", "_abs_cam"),
            ("..", "_"),
            ("", "_"),
            (".hidden", "_hidden"),
            ("a\\b\nc", "a_b_c"),
            ("Camera.001", "Camera.001"),
            ("カメラ", "カメラ"),
        ] {
            assert_eq!(file_name_part(name), safe, "{name:?}");
        }
        let p = output_path(Path::new("out/{camera}.exr"), None, "s", "../../x").unwrap();
        assert_eq!(p, Path::new("out/__.._x.exr"));
    }

    #[test]
    fn frame_lists_and_patterns() {
        assert_eq!(FrameList::parse("3").unwrap().0, [3.0]);
        assert_eq!(
            FrameList::parse("1-7x3,10").unwrap().0,
            [1.0, 4.0, 7.0, 10.0]
        );
        for bad in ["5-1", "1-4x0", "a", "-1", "1-2000000"] {
            assert!(FrameList::parse(bad).is_err(), "{bad}");
        }
        let p = output_path(
            Path::new("o/{scene}.{camera}.{frame}.exr"),
            Some(7.0),
            "s",
            "c",
        );
        assert_eq!(p.unwrap(), PathBuf::from("o/s.c.0007.exr"));
        let half = output_path(Path::new("{frame}.exr"), Some(7.5), "s", "c").unwrap();
        assert_eq!(half, PathBuf::from("7.5.exr"));
        assert!(output_path(Path::new("{frame}.exr"), None, "s", "c").is_err());
    }

    /// The frame tokens of Nuke, printf, Houdini and RenderMan, as the USD plugin expands a
    /// product name's (plugins/usd/lucerna_usd/render_settings.py).
    #[test]
    fn frame_tokens_of_other_tools() {
        for (pattern, frame, expected) in [
            ("out.####.exr", 7.0, "out.0007.exr"),
            ("out.#.exr", 12.0, "out.12.exr"),
            ("out.%04d.exr", 7.0, "out.0007.exr"),
            ("out.%4d.exr", 7.0, "out.0007.exr"),
            ("out.$F4.exr", 7.0, "out.0007.exr"),
            ("out.$F.exr", 7.0, "out.7.exr"),
            ("out.<F3>.exr", 7.0, "out.007.exr"),
            ("out.<F>.exr", 7.0, "out.7.exr"),
            ("out.{frame}.exr", -3.0, "out.-0003.exr"),
            ("a.##.b.%03d.exr", 5.0, "a.05.b.005.exr"),
            ("out.####.exr", 7.5, "out.7.5.exr"),
            ("$Fx%dy<G>#", 1.0, "1x%dy<G>1"),
            ("résumé.####.exr", 1.0, "résumé.0001.exr"),
        ] {
            assert_eq!(expand_frame(pattern, frame), expected, "{pattern}");
        }
        for (text, has) in [
            ("out.exr", false),
            ("out.####.exr", true),
            ("out.%04d.exr", true),
            ("out.%d.exr", false),
            ("$HOME/out.exr", false),
            ("out.$F.exr", true),
            ("out.<F>.exr", true),
            ("out.{frame}.exr", true),
        ] {
            assert_eq!(has_frame_token(text), has, "{text}");
        }
        // A still keeps them as written; {frame} needs a frame.
        let still = output_path(Path::new("take#2.%04d.exr"), None, "s", "c").unwrap();
        assert_eq!(still, PathBuf::from("take#2.%04d.exr"));
    }
}
