//! Secrets: passwords and tokens compared without leaking where they differ, and numbers
//! no one outside the process can guess.

use std::sync::OnceLock;

/// 64 bits from the kernel's random source; without it, the time and the process id (still
/// unknown outside the machine).
pub fn unguessable() -> u64 {
    let mut bytes = [0u8; 8];
    // SAFETY: the buffer is 8 writable bytes, as the length says.
    let n = unsafe { libc::getrandom(bytes.as_mut_ptr().cast(), bytes.len(), 0) };
    if n != 8 {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        return nanos ^ u64::from(std::process::id()).rotate_left(32);
    }
    u64::from_ne_bytes(bytes)
}

/// 16 hex digits drawn once per process: the part of chassisd's MQTT client id no other
/// client can guess, the same for the link and the embedded broker that reserves it.
pub fn process_tag() -> &'static str {
    static TAG: OnceLock<String> = OnceLock::new();
    TAG.get_or_init(|| format!("{:016x}", unguessable()))
}

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
