//! OSC address prefixes as users configure them.

use crate::error::ProtocolError;

/// The prefix normalised (no trailing '/'), or an error when it cannot be an OSC address.
///
/// An empty prefix is allowed (addresses then start at the root, e.g. `/frame`).
pub fn normalise_prefix(prefix: &str) -> Result<String, ProtocolError> {
    let trimmed = prefix.trim_end_matches('/');
    if trimmed.is_empty() {
        return Ok(String::new());
    }
    let bad_char = |c: char| c.is_whitespace() || c.is_control() || "#*,?[]{}".contains(c);
    if !trimmed.starts_with('/') || trimmed.contains("//") || trimmed.chars().any(bad_char) {
        return Err(ProtocolError::BadPrefix(prefix.to_string()));
    }
    Ok(trimmed.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accepts_and_normalises_prefixes() {
        assert_eq!(normalise_prefix("/danced").unwrap(), "/danced");
        assert_eq!(normalise_prefix("/a/b/").unwrap(), "/a/b");
        assert_eq!(normalise_prefix("/").unwrap(), "");
        assert!(normalise_prefix("danced").is_err());
        assert!(normalise_prefix("/dan ced").is_err());
        assert!(normalise_prefix("/dan*").is_err());
        assert!(normalise_prefix("/a//b").is_err());
    }
}
