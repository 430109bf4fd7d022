//! Resolution of URIs found in scene files. A scene may only read files inside its own
//! directory tree: absolute paths, `..` segments and URI schemes other than `data:` are
//! refused, so a downloaded scene cannot read arbitrary files or reach the network. A
//! symbolic link that leads out of the scene's directory is refused like `..`.

use base64::Engine;
use std::path::{Path, PathBuf};

/// Where a URI's bytes come from.
#[derive(Debug, PartialEq, Eq)]
pub enum Resolved {
    /// An embedded `data:` URI, decoded.
    Data(Vec<u8>),
    /// A file below the scene's directory.
    File(PathBuf),
}

/// Decodes RFC 3986 percent-escapes; `None` on a malformed escape or invalid UTF-8.
pub fn percent_decode(s: &str) -> Option<String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// Resolves `uri` relative to `base` (the scene's directory; `None` for scenes without
/// one, such as the embedded default scene). Errors are reasons for the user.
pub fn resolve(uri: &str, base: Option<&Path>) -> Result<Resolved, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (meta, payload) = rest
            .split_once(',')
            .ok_or_else(|| "malformed data URI (no comma)".to_string())?;
        if !meta.ends_with(";base64") {
            return Err("data URI is not base64-encoded".into());
        }
        return base64::engine::general_purpose::STANDARD
            .decode(payload.trim())
            .map(Resolved::Data)
            .map_err(|e| format!("invalid base64 in data URI: {e}"));
    }
    // A scheme is letters, digits, + - . before the first ':' (RFC 3986 §3.1); a single
    // letter followed by a path separator is a Windows drive, refused below.
    if let Some((scheme, _)) = uri.split_once(':')
        && !scheme.is_empty()
        && scheme
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
        && !(scheme.len() == 1 && uri[2..].starts_with(['/', '\\']))
    {
        return Err(format!(
            "URI scheme {scheme:?} is not allowed (only relative paths and data: URIs)"
        ));
    }
    let path =
        percent_decode(uri).ok_or_else(|| "malformed percent-encoding in URI".to_string())?;
    if path.is_empty() || path.contains('\0') {
        return Err("empty or invalid file name".into());
    }
    let looks_absolute = path.starts_with(['/', '\\'])
        || (path.len() > 1
            && path.as_bytes()[1] == b':'
            && path.as_bytes()[0].is_ascii_alphabetic());
    if looks_absolute || Path::new(&path).is_absolute() {
        return Err(format!(
            "absolute path {path:?} is not allowed (paths must be relative to the scene)"
        ));
    }
    if path.split(['/', '\\']).any(|segment| segment == "..") {
        return Err(format!(
            "path {path:?} leaves the scene's directory (\"..\")"
        ));
    }
    let base = base
        .ok_or_else(|| "external file referenced by a scene that has no directory".to_string())?;
    Ok(Resolved::File(base.join(path)))
}

/// Reads the bytes a URI refers to.
pub fn read(uri: &str, base: Option<&Path>) -> Result<Vec<u8>, String> {
    match resolve(uri, base)? {
        Resolved::Data(bytes) => Ok(bytes),
        Resolved::File(path) => {
            if let Some(base) = base {
                crate::files::check_inside(&path, base)?;
            }
            crate::files::read_input(&path).map_err(|e| format!("{}: {e}", path.display()))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_escapes_absolute_paths_and_schemes() {
        let base = Some(Path::new("/scenes/a"));
        assert_eq!(
            resolve("tex/wood%20dark.png", base),
            Ok(Resolved::File("/scenes/a/tex/wood dark.png".into()))
        );
        assert_eq!(
            resolve("data:application/octet-stream;base64,AAEC", None),
            Ok(Resolved::Data(vec![0, 1, 2]))
        );
        for bad in [
            "../secret.bin",
            "tex/../../x.bin",
            "..%2Fx.bin",
            "tex\\..\\x",
            "/etc/passwd",
            "%2Fetc%2Fpasswd",
            "C:\\x.bin",
            "http://example.com/a.bin",
            "https://example.com/a.bin",
            "file:///etc/passwd",
            "data:text/plain,hello",
            "a%zz.bin",
        ] {
            assert!(resolve(bad, base).is_err(), "{bad} accepted");
        }
        assert!(resolve("a.bin", None).is_err());
    }
}
