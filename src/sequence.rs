//! Frame sequences: the frame lists of `--frames` and of batch jobs, and the output name
//! patterns (`{frame}`, `{scene}`, `{camera}`) that give every frame its file.

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

/// The file of `frame` of `scene` through `camera`: `pattern` with `{frame}` (four digits
/// for whole frames), `{scene}` and `{camera}` replaced.
pub fn output_path(
    pattern: &Path,
    frame: Option<f64>,
    scene: &str,
    camera: &str,
) -> Result<PathBuf, String> {
    let text = pattern.to_string_lossy();
    let frame_text = match frame {
        Some(f) if f.fract() == 0.0 => format!("{:04}", f as i64),
        Some(f) => format!("{f}"),
        None if text.contains("{frame}") => {
            return Err(format!(
                "{text:?} has {{frame}} but no frame was given (--frame or --frames)"
            ));
        }
        None => String::new(),
    };
    Ok(PathBuf::from(
        text.replace("{frame}", &frame_text)
            .replace("{scene}", &file_name_part(scene))
            .replace("{camera}", &file_name_part(camera)),
    ))
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
}
