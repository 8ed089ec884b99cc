//! HTTP/1.1 chunked transfer encoding, decoded as it streams (NTRIP 2.0 casters send their
//! corrections this way). Nothing is buffered but a chunk-size line; a chunk's data passes
//! straight through, however large its declared size.

/// The longest chunk-size line (hex size and extensions), bytes.
const MAX_SIZE_LINE: usize = 256;

/// Where the decoder is.
#[derive(Debug, Clone, PartialEq, Eq)]
enum State {
    /// Reading a size line (kept here).
    Size(Vec<u8>),
    /// Inside a chunk: bytes left.
    Data(u64),
    /// After a chunk's data: its CR LF.
    DataEnd { seen_cr: bool },
    /// After the last chunk: trailer lines up to a blank one (the length of the current one).
    Trailer(usize),
    /// The body is over.
    Done,
}

/// A broken chunked body.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ChunkError {
    /// A size line that is not hexadecimal, or too long.
    #[error("bad chunk size line {0:?}")]
    BadSize(String),
    /// A chunk's data not followed by CR LF.
    #[error("a chunk's data is not followed by CR LF")]
    MissingCrLf,
}

/// The decoder.
#[derive(Debug, Clone)]
pub struct Dechunker {
    state: State,
}

impl Default for Dechunker {
    fn default() -> Self {
        Self {
            state: State::Size(Vec::new()),
        }
    }
}

impl Dechunker {
    /// At the start of a body.
    pub fn new() -> Self {
        Self::default()
    }

    /// Whether the last chunk and its trailer have been read.
    pub fn is_done(&self) -> bool {
        self.state == State::Done
    }

    /// Decodes `input`, appending the body's bytes to `out`. After an error the decoder stays
    /// broken (the connection must be dropped).
    pub fn push(&mut self, mut input: &[u8], out: &mut Vec<u8>) -> Result<(), ChunkError> {
        while !input.is_empty() {
            match &mut self.state {
                State::Size(line) => {
                    let Some(lf) = input.iter().position(|&b| b == b'\n') else {
                        line.extend_from_slice(input);
                        if line.len() > MAX_SIZE_LINE {
                            return Err(bad_size(line));
                        }
                        return Ok(());
                    };
                    line.extend_from_slice(&input[..lf]);
                    input = &input[lf + 1..];
                    if line.len() > MAX_SIZE_LINE {
                        return Err(bad_size(line));
                    }
                    let size = parse_size(line)?;
                    self.state = if size == 0 {
                        State::Trailer(0)
                    } else {
                        State::Data(size)
                    };
                }
                State::Data(left) => {
                    let take = input
                        .len()
                        .min(usize::try_from(*left).unwrap_or(usize::MAX));
                    out.extend_from_slice(&input[..take]);
                    input = &input[take..];
                    *left -= take as u64;
                    if *left == 0 {
                        self.state = State::DataEnd { seen_cr: false };
                    }
                }
                State::DataEnd { seen_cr } => {
                    match (input[0], *seen_cr) {
                        (b'\r', false) => *seen_cr = true,
                        (b'\n', _) => self.state = State::Size(Vec::new()),
                        _ => return Err(ChunkError::MissingCrLf),
                    }
                    input = &input[1..];
                }
                State::Trailer(len) => {
                    match input[0] {
                        b'\n' if *len == 0 => self.state = State::Done,
                        b'\n' => *len = 0,
                        b'\r' => {}
                        _ => *len += 1,
                    }
                    input = &input[1..];
                }
                // Bytes after the body: none belong to it.
                State::Done => return Ok(()),
            }
        }
        Ok(())
    }
}

fn bad_size(line: &[u8]) -> ChunkError {
    ChunkError::BadSize(String::from_utf8_lossy(&line[..line.len().min(40)]).into_owned())
}

/// The size of a size line: hex digits, then optional `;extensions`, a CR.
fn parse_size(line: &[u8]) -> Result<u64, ChunkError> {
    let text = std::str::from_utf8(line).map_err(|_| bad_size(line))?;
    let text = text.strip_suffix('\r').unwrap_or(text);
    let hex = text.split(';').next().unwrap_or("").trim();
    if hex.is_empty() || hex.len() > 15 {
        return Err(bad_size(line));
    }
    u64::from_str_radix(hex, 16).map_err(|_| bad_size(line))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode(chunks: &[&[u8]]) -> Result<(Vec<u8>, bool), ChunkError> {
        let mut d = Dechunker::new();
        let mut out = Vec::new();
        for c in chunks {
            d.push(c, &mut out)?;
        }
        Ok((out, d.is_done()))
    }

    #[test]
    fn chunks_split_anywhere_decode_the_same() {
        let body = b"5\r\nhello\r\n7;ext=1\r\n, world\r\n0\r\nX-Trailer: 1\r\n\r\n";
        for cut in 0..=body.len() {
            let (out, done) = decode(&[&body[..cut], &body[cut..]]).unwrap();
            assert_eq!(out, b"hello, world", "cut at {cut}");
            assert!(done);
        }
        let (out, done) = decode(&[b"A\r\n0123456789\r\n"]).unwrap();
        assert_eq!(out, b"0123456789");
        assert!(!done);
    }

    #[test]
    fn broken_bodies_fail() {
        assert!(matches!(decode(&[b"zz\r\n"]), Err(ChunkError::BadSize(_))));
        assert!(matches!(decode(&[b"\r\n"]), Err(ChunkError::BadSize(_))));
        assert!(matches!(
            decode(&[b"3\r\nabcX"]),
            Err(ChunkError::MissingCrLf)
        ));
        assert!(matches!(
            decode(&[&[b'1'; 300]]),
            Err(ChunkError::BadSize(_))
        ));
        assert!(matches!(
            decode(&[b"fffffffffffffffff\r\n"]),
            Err(ChunkError::BadSize(_))
        ));
    }
}
