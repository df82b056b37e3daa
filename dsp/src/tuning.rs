//! `name=value` override lists (`a=1, b=0.5`) by which tuning runs set a component's
//! parameters from the command line.

use crate::DspError;

/// The `(name, value)` pairs of a comma-separated override list, names trimmed; an item that
/// is not `name=value` or whose value is not a number is reported back.
pub fn overrides(spec: &str) -> Result<Vec<(&str, f64)>, DspError> {
    spec.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|item| {
            let (k, v) = item
                .split_once('=')
                .ok_or_else(|| DspError::Tuning(format!("expected name=value, got {item:?}")))?;
            let x: f64 = v
                .trim()
                .parse()
                .map_err(|_| DspError::Tuning(format!("{k}: not a number: {v:?}")))?;
            Ok((k.trim(), x))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_pairs_and_names_what_is_wrong() {
        assert_eq!(
            overrides(" a=1, b = 0.5 ,").unwrap(),
            [("a", 1.0), ("b", 0.5)]
        );
        let message = |spec| overrides(spec).unwrap_err().to_string();
        assert!(message("a").contains("name=value"));
        assert!(message("a=x").contains("not a number"));
        assert!(overrides("").unwrap().is_empty());
    }
}
