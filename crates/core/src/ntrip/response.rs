//! The caster's answer to a request, read tolerantly: `ICY 200 OK` (NTRIP 1.0),
//! `HTTP/1.x 200 OK` (2.0, perhaps chunked), `SOURCETABLE 200 OK`, or an error status. Real
//! casters bend the format: pygnssutils runs its status line into a header
//! (`HTTP/1.1 200 OKNtrip-Version: Ntrip/2.0`), and 1.0 casters may or may not send headers
//! and a blank line after `ICY 200 OK`.

/// The longest head read before giving up, bytes: a caster that sends more is not one.
pub const MAX_HEAD: usize = 16 * 1024;

/// What the status line says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Status {
    /// Corrections follow (`ICY 200 OK`: NTRIP 1.0, raw).
    Icy,
    /// Corrections follow (`HTTP/1.x 200`: NTRIP 2.0).
    Http,
    /// The caster's table follows (`SOURCETABLE 200 OK`, or a 2.0 reply of type
    /// `gnss/sourcetable`).
    Sourcetable,
    /// An error status: the code and the reason the caster gave.
    Error(u16, String),
}

/// A parsed head.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Head {
    /// The status.
    pub status: Status,
    /// Whether the body is in chunked transfer encoding.
    pub chunked: bool,
    /// The body's content encoding, when not identity (gzip is not supported).
    pub content_encoding: Option<String>,
    /// Bytes of the input the head took.
    pub length: usize,
}

/// Why a head cannot be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HeadError {
    /// The first line is no status line a caster sends.
    #[error("the caster's answer does not start with a status line: {0:?}")]
    NotAStatus(String),
    /// More than [`MAX_HEAD`] bytes without the end of the head.
    #[error("the caster's answer has no end of its head within {MAX_HEAD} bytes")]
    TooLong,
}

/// Reads a head from the start of `input`: `Ok(None)` when more bytes are needed.
pub fn parse_head(input: &[u8]) -> Result<Option<Head>, HeadError> {
    let Some(first_end) = find_line_end(input) else {
        return too_long_or_wait(input);
    };
    let line = String::from_utf8_lossy(&input[..first_end.0]).into_owned();
    let status = parse_status(&line)?;
    let mut at = first_end.1;
    let mut chunked = false;
    let mut content_encoding = None;
    let mut sourcetable_type = false;
    // Headers: up to a blank line. After ICY, a line that is not a header is the data.
    loop {
        let rest = &input[at..];
        // After ICY, nothing yet (a VRS waits for the GGA) or data: the head is done. A
        // header that comes later reaches the framer, which drops it as invalid bytes.
        if status == Status::Icy && (rest.is_empty() || !looks_like_header_or_blank(rest)) {
            break;
        }
        let Some((end, next)) = find_line_end(rest) else {
            return too_long_or_wait(input);
        };
        let header = &rest[..end];
        at += next;
        if header.is_empty() {
            break;
        }
        let header = String::from_utf8_lossy(header);
        if let Some((name, value)) = header.split_once(':') {
            let (name, value) = (name.trim(), value.trim());
            if name.eq_ignore_ascii_case("transfer-encoding") {
                chunked = value
                    .split(',')
                    .any(|v| v.trim().eq_ignore_ascii_case("chunked"));
            } else if name.eq_ignore_ascii_case("content-encoding")
                && !value.eq_ignore_ascii_case("identity")
            {
                content_encoding = Some(value.to_owned());
            } else if name.eq_ignore_ascii_case("content-type")
                && value.eq_ignore_ascii_case("gnss/sourcetable")
            {
                sourcetable_type = true;
            }
        }
        if at > MAX_HEAD {
            return Err(HeadError::TooLong);
        }
    }
    let status = match status {
        Status::Http if sourcetable_type => Status::Sourcetable,
        s => s,
    };
    Ok(Some(Head {
        status,
        chunked,
        content_encoding,
        length: at,
    }))
}

fn too_long_or_wait(input: &[u8]) -> Result<Option<Head>, HeadError> {
    if input.len() > MAX_HEAD {
        Err(HeadError::TooLong)
    } else {
        Ok(None)
    }
}

/// The end of the first line: (where its text ends, where the next line starts). A bare LF
/// ends a line too.
fn find_line_end(input: &[u8]) -> Option<(usize, usize)> {
    let lf = input.iter().position(|&b| b == b'\n')?;
    let end = if lf > 0 && input[lf - 1] == b'\r' {
        lf - 1
    } else {
        lf
    };
    Some((end, lf + 1))
}

/// Whether `rest` starts with a blank line or a `Name: value` header (printable ASCII up to a
/// colon), as opposed to correction data.
fn looks_like_header_or_blank(rest: &[u8]) -> bool {
    match rest.first() {
        Some(b'\r' | b'\n') => true,
        _ => {
            let name_len = rest
                .iter()
                .take_while(|&&b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
                .count();
            // Too short to tell yet: wait for more, unless it is already not a name.
            if name_len == rest.len() {
                return name_len > 0;
            }
            name_len > 0 && rest[name_len] == b':'
        }
    }
}

fn parse_status(line: &str) -> Result<Status, HeadError> {
    let not = || HeadError::NotAStatus(line.chars().take(80).collect());
    let (proto, rest) = line.split_once(' ').ok_or_else(not)?;
    let code_text: String = rest.trim_start().chars().take(3).collect();
    let code: u16 = code_text.parse().map_err(|_| not())?;
    let reason: String = rest
        .trim_start()
        .chars()
        .skip(3)
        .take(80)
        .collect::<String>()
        .trim()
        .to_owned();
    let ok = (200..300).contains(&code);
    match proto {
        "ICY" if ok => Ok(Status::Icy),
        "SOURCETABLE" if ok => Ok(Status::Sourcetable),
        p if p.starts_with("HTTP/1.") && ok => Ok(Status::Http),
        "ICY" | "SOURCETABLE" => Ok(Status::Error(code, reason)),
        p if p.starts_with("HTTP/") || p == "RTSP/1.0" => Ok(Status::Error(code, reason)),
        _ => Err(not()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn head(text: &[u8]) -> Head {
        parse_head(text).unwrap().unwrap()
    }

    #[test]
    fn ntrip_1_with_and_without_headers() {
        let h = head(b"ICY 200 OK\r\n\r\n\xD3\x00");
        assert_eq!((h.status, h.length), (Status::Icy, 14));
        // gpsd's log: no headers, data at once.
        let h = head(b"ICY 200 OK\r\n\xD3\x00\x13");
        assert_eq!((h.status, h.length), (Status::Icy, 12));
        // A VRS sends nothing more until it has a GGA.
        let h = head(b"ICY 200 OK\r\n");
        assert_eq!((h.status, h.length), (Status::Icy, 12));
        let h = head(b"ICY 200 OK\r\nServer: x\r\n\r\nYFh|bk");
        assert_eq!(h.length, 25);
        // RTCM 2 after the status line is data, not a header.
        let h = head(b"ICY 200 OK\r\nYFh|bk\\_dHpa}pK@@@hF");
        assert_eq!(h.length, 12);
    }

    #[test]
    fn ntrip_2_chunked_and_the_malformed_status_line() {
        let h = head(
            b"HTTP/1.1 200 OK\r\nNtrip-Version: Ntrip/2.0\r\nTransfer-Encoding: chunked\r\n\r\n64\r\n",
        );
        assert_eq!(h.status, Status::Http);
        assert!(h.chunked);
        // pygnssutils' gnssserver.
        let h =
            head(b"HTTP/1.1 200 OKNtrip-Version: Ntrip/2.0\r\nTransfer-Encoding: chunked\r\n\r\n");
        assert_eq!(h.status, Status::Http);
        assert!(h.chunked);
        let h = head(b"HTTP/1.1 200 OK\r\nContent-Type: gnss/sourcetable\r\n\r\nSTR;");
        assert_eq!(h.status, Status::Sourcetable);
        let h = head(b"HTTP/1.1 200 OK\r\nContent-Encoding: gzip\r\n\r\n");
        assert_eq!(h.content_encoding.as_deref(), Some("gzip"));
    }

    #[test]
    fn errors_keep_their_code_and_reason() {
        assert_eq!(
            head(b"HTTP/1.1 401 Unauthorized\r\n\r\n").status,
            Status::Error(401, "Unauthorized".into())
        );
        assert_eq!(
            head(b"ICY 404 Not Found\r\n\r\n").status,
            Status::Error(404, "Not Found".into())
        );
        assert!(matches!(
            parse_head(b"SSH-2.0-OpenSSH\r\n"),
            Err(HeadError::NotAStatus(_))
        ));
        assert!(matches!(
            parse_head(b"\xD3\x00\x13 junk\n"),
            Err(HeadError::NotAStatus(_))
        ));
    }

    #[test]
    fn partial_heads_wait_and_endless_ones_fail() {
        assert_eq!(
            parse_head(b"HTTP/1.1 200 OK\r\nTransfer-Enc").unwrap(),
            None
        );
        assert_eq!(parse_head(b"ICY 200").unwrap(), None);
        let endless = [b"HTTP/1.1 200 OK\r\n".as_slice(), &[b'a'; MAX_HEAD + 1]].concat();
        assert_eq!(parse_head(&endless), Err(HeadError::TooLong));
        let many: Vec<u8> = std::iter::once(b"HTTP/1.1 200 OK\r\n".to_vec())
            .chain(std::iter::repeat_n(b"X: y\r\n".to_vec(), MAX_HEAD / 6 + 10))
            .flatten()
            .collect();
        assert_eq!(parse_head(&many), Err(HeadError::TooLong));
    }
}
