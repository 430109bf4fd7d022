//! The textual form settings with a number share: `name[:parameter]` (`power:2`,
//! `throughput:0.1`, `cutoff:0.05`).

/// Splits a setting value `name[:number]` into its name and optional parameter.
pub(crate) fn name_and_parameter(s: &str) -> Result<(&str, Option<f32>), String> {
    match s.split_once(':') {
        Some((name, p)) => {
            let value = p
                .parse::<f32>()
                .map_err(|_| format!("invalid number in {s:?}"))?;
            Ok((name, Some(value)))
        }
        None => Ok((s, None)),
    }
}
