//! Secrets (passwords, tokens) compared without leaking where they differ.

/// Whether `given` equals `configured`, in a time that depends on their lengths only, not
/// on where the first differing byte lies.
pub fn matches(configured: &[u8], given: &[u8]) -> bool {
    let differ = configured
        .iter()
        .zip(given)
        .fold(u8::from(configured.len() != given.len()), |acc, (x, y)| {
            acc | (x ^ y)
        });
    differ == 0
}

#[cfg(test)]
mod tests {
    use super::matches;

    #[test]
    fn only_the_same_bytes_match() {
        assert!(matches(b"s3cret", b"s3cret"));
        assert!(!matches(b"s3cret", b"s3creT"));
        assert!(!matches(b"s3cret", b"s3cre"));
        assert!(!matches(b"s3cret", b"s3crett"));
        assert!(!matches(b"s3cret", b""));
        assert!(matches(b"", b""));
    }
}
