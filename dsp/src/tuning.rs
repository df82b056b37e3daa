//! `name=value` override lists (`a=1, b=0.5`) by which tuning runs set a component's
//! parameters from the command line.

/// The `(name, value)` pairs of a comma-separated override list, names trimmed; an item that
/// is not `name=value` or whose value is not a number is reported back.
pub fn overrides(spec: &str) -> Result<Vec<(&str, f64)>, String> {
    spec.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|item| {
            let (k, v) = item
                .split_once('=')
                .ok_or_else(|| format!("expected name=value, got {item:?}"))?;
            let x: f64 = v
                .trim()
                .parse()
                .map_err(|_| format!("{k}: not a number: {v:?}"))?;
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
        assert!(overrides("a").unwrap_err().contains("name=value"));
        assert!(overrides("a=x").unwrap_err().contains("not a number"));
        assert!(overrides("").unwrap().is_empty());
    }
}
