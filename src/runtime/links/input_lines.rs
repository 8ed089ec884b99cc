//! Lines from an outside byte stream (standard input) that cannot take a channel down: a line
//! that is not UTF-8, or longer than the bound, is reported and skipped, and the next line is
//! read as usual. A line never holds more than the bound in memory, however long it runs.

use tokio::io::{AsyncBufRead, AsyncBufReadExt};

/// The longest command line taken, bytes: a trajectory of some thousand points fits.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// One line read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum InputLine {
    /// A line of text, without its line end.
    Text(String),
    /// A line that is not UTF-8: its number (from 1).
    NotUtf8(u64),
    /// A line longer than the bound: its number and its length in bytes.
    TooLong(u64, usize),
}

/// Reads bounded lines from `R`.
#[derive(Debug)]
pub struct InputLines<R> {
    reader: R,
    max: usize,
    line: Vec<u8>,
    /// Bytes of the current line, kept or not.
    length: usize,
    number: u64,
}

impl<R: AsyncBufRead + Unpin> InputLines<R> {
    /// Lines of at most `max` bytes from `reader`.
    pub fn new(reader: R, max: usize) -> Self {
        Self {
            reader,
            max,
            line: Vec::new(),
            length: 0,
            number: 0,
        }
    }

    /// The next line, or `None` at the end of the stream.
    pub async fn next(&mut self) -> std::io::Result<Option<InputLine>> {
        loop {
            let chunk = self.reader.fill_buf().await?;
            if chunk.is_empty() {
                // The end: a last line without its line end still counts.
                return Ok((self.length > 0).then(|| self.finish()));
            }
            let (part, used, ends) = match chunk.iter().position(|&b| b == b'\n') {
                Some(i) => (&chunk[..i], i + 1, true),
                None => (chunk, chunk.len(), false),
            };
            self.length += part.len();
            if self.length <= self.max {
                self.line.extend_from_slice(part);
            } else {
                // Past the bound nothing more is kept.
                self.line = Vec::new();
            }
            self.reader.consume(used);
            if ends {
                return Ok(Some(self.finish()));
            }
        }
    }

    fn finish(&mut self) -> InputLine {
        self.number += 1;
        let length = std::mem::take(&mut self.length);
        let mut bytes = std::mem::take(&mut self.line);
        if length > self.max {
            return InputLine::TooLong(self.number, length);
        }
        if bytes.last() == Some(&b'\r') {
            bytes.pop();
        }
        match String::from_utf8(bytes) {
            Ok(text) => InputLine::Text(text),
            Err(_) => InputLine::NotUtf8(self.number),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    async fn read_all(input: &[u8], max: usize) -> Vec<InputLine> {
        // A small buffer, so lines span several reads.
        let reader = tokio::io::BufReader::with_capacity(4, input);
        let mut lines = InputLines::new(reader, max);
        let mut out = Vec::new();
        while let Some(line) = lines.next().await.expect("in-memory reads do not fail") {
            out.push(line);
        }
        out
    }

    #[tokio::test]
    async fn a_bad_line_is_reported_and_the_next_is_read() {
        let input = b"cmd_vel {}\r\nbad \xff\xfe line\n0123456789abcdef\nstop\nlast";
        assert_eq!(
            read_all(input, 12).await,
            vec![
                InputLine::Text("cmd_vel {}".into()),
                InputLine::NotUtf8(2),
                InputLine::TooLong(3, 16),
                InputLine::Text("stop".into()),
                InputLine::Text("last".into()),
            ]
        );
        assert_eq!(read_all(b"", 12).await, vec![]);
        assert_eq!(
            read_all(b"\n\n", 12).await,
            vec![
                InputLine::Text(String::new()),
                InputLine::Text(String::new())
            ]
        );
    }

    #[tokio::test]
    async fn a_line_at_the_bound_is_taken() {
        assert_eq!(
            read_all(b"0123456789ab\n", 12).await,
            vec![InputLine::Text("0123456789ab".into())]
        );
    }
}
