//! The read buffer and the line tokenizer under the PLY parsers, shared with the STL importer:
//! records and lines are decoded in place from the buffer, without a copy or an allocation per
//! record.

use std::io::{self, Read};
use std::ops::Range;

use crate::input::Input;

/// Bytes at the start of the remaining stream: the largest buffer a [`ByteReader`] may grow to.
const MAX_BUFFER: usize = 64 << 20;
/// The first size of a [`ByteReader`]'s buffer: larger than [`crate::input::READ_BUFFER`], so
/// that reads go straight from the file's reader into it rather than through the `BufReader`.
const CHUNK: usize = 4 * crate::input::READ_BUFFER;

/// A read buffer under the parsers (shared by the PLY and STL importers): records and lines are
/// parsed in place from [`ByteReader::available`]; [`ByteReader::fill_more`] moves the unread
/// tail to the front and reads more behind it, so a record or line that straddles two reads is
/// still contiguous.
pub(crate) struct ByteReader {
    inner: Box<dyn Read + Send>,
    buf: Vec<u8>,
    pos: usize,
    end: usize,
    /// Stream offset of `buf[0]`.
    base: u64,
    eof: bool,
    /// Set by every read; parsers clear it to report progress about once per [`CHUNK`].
    refilled: bool,
}

/// A line found by [`ByteReader::read_line`]: a range valid until the reader moves on.
pub(crate) enum Line {
    Text(Range<usize>),
    Eof,
    TooLong,
}

impl ByteReader {
    pub(crate) fn new(input: Input) -> ByteReader {
        ByteReader {
            inner: Box::new(input.into_reader()),
            buf: vec![0; CHUNK],
            pos: 0,
            end: 0,
            base: 0,
            eof: false,
            refilled: false,
        }
    }

    /// The buffered bytes not consumed yet.
    #[inline]
    pub(crate) fn available(&self) -> &[u8] {
        &self.buf[self.pos..self.end]
    }

    /// Bytes of a range [`ByteReader::read_line`] returned.
    #[inline]
    pub(crate) fn bytes(&self, r: Range<usize>) -> &[u8] {
        &self.buf[r]
    }

    /// Marks `n` available bytes as used; `n <= available().len()`.
    #[inline]
    pub(crate) fn consume(&mut self, n: usize) {
        debug_assert!(n <= self.end - self.pos);
        self.pos += n;
    }

    /// Stream offset of the first available byte: bytes consumed so far.
    #[inline]
    pub(crate) fn position(&self) -> u64 {
        self.base + self.pos as u64
    }

    /// True once after each read from the stream: time to report progress.
    #[inline]
    pub(crate) fn take_refilled(&mut self) -> bool {
        std::mem::take(&mut self.refilled)
    }

    /// Reads more bytes behind the available ones; returns how many (0 at the end of the stream).
    /// Grows the buffer when the available bytes fill it, up to 64 MiB.
    pub(crate) fn fill_more(&mut self) -> io::Result<usize> {
        if self.eof {
            return Ok(0);
        }
        if self.pos > 0 {
            self.buf.copy_within(self.pos..self.end, 0);
            self.base += self.pos as u64;
            self.end -= self.pos;
            self.pos = 0;
        }
        if self.end == self.buf.len() {
            if self.buf.len() >= MAX_BUFFER {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    "a record or line is larger than 64 MiB",
                ));
            }
            self.buf.resize(self.buf.len() * 2, 0);
        }
        loop {
            match self.inner.read(&mut self.buf[self.end..]) {
                Ok(0) => {
                    self.eof = true;
                    return Ok(0);
                }
                Ok(n) => {
                    self.end += n;
                    self.refilled = true;
                    return Ok(n);
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
    }

    /// Makes at least `n` bytes available; false when the stream ends first.
    pub(crate) fn ensure(&mut self, n: usize) -> io::Result<bool> {
        while self.end - self.pos < n {
            if self.fill_more()? == 0 {
                return Ok(false);
            }
        }
        Ok(true)
    }

    /// Skips `n` bytes; returns how many were there to skip.
    pub(crate) fn skip(&mut self, n: u64) -> io::Result<u64> {
        let mut left = n;
        loop {
            let take = ((self.end - self.pos) as u64).min(left);
            self.pos += take as usize;
            left -= take;
            if left == 0 || self.fill_more()? == 0 {
                return Ok(n - left);
            }
        }
    }

    /// The next line without its `\n` or `\r\n`; the last line may lack the terminator.
    pub(crate) fn read_line(&mut self, max: usize) -> io::Result<Line> {
        let mut scanned = 0;
        loop {
            let avail = &self.buf[self.pos..self.end];
            if let Some(i) = avail[scanned..].iter().position(|&b| b == b'\n') {
                let start = self.pos;
                let mut end = start + scanned + i;
                self.pos = end + 1;
                if end > start && self.buf[end - 1] == b'\r' {
                    end -= 1;
                }
                return Ok(if end - start > max { Line::TooLong } else { Line::Text(start..end) });
            }
            scanned = avail.len();
            if scanned > max {
                return Ok(Line::TooLong);
            }
            if self.fill_more()? == 0 {
                if self.pos == self.end {
                    return Ok(Line::Eof);
                }
                let start = self.pos;
                let mut end = self.end;
                self.pos = end;
                if self.buf[end - 1] == b'\r' {
                    end -= 1;
                }
                return Ok(Line::Text(start..end));
            }
        }
    }

    /// True when nothing but ASCII whitespace is left in the stream (reads to find out).
    pub(crate) fn only_whitespace_left(&mut self) -> io::Result<bool> {
        loop {
            if !self.available().iter().all(u8::is_ascii_whitespace) {
                return Ok(false);
            }
            let n = self.end - self.pos;
            self.consume(n);
            if self.fill_more()? == 0 {
                return Ok(true);
            }
        }
    }
}

/// Whitespace-separated tokens of a line.
pub(crate) struct Tokens<'a> {
    rest: &'a [u8],
}

impl<'a> Tokens<'a> {
    pub(crate) fn new(line: &'a [u8]) -> Self {
        Tokens { rest: line }
    }
}

impl<'a> Iterator for Tokens<'a> {
    type Item = &'a [u8];
    #[inline]
    fn next(&mut self) -> Option<&'a [u8]> {
        let start = self.rest.iter().position(|b| !b.is_ascii_whitespace())?;
        let rest = &self.rest[start..];
        let len = rest.iter().position(|b| b.is_ascii_whitespace()).unwrap_or(rest.len());
        self.rest = &rest[len..];
        Some(&rest[..len])
    }
}

/// A decimal number (as `str::parse` reads it; `inf`/`nan` parse and are rejected by callers).
#[inline]
pub(crate) fn parse_f64(t: &[u8]) -> Option<f64> {
    std::str::from_utf8(t).ok()?.parse().ok()
}

#[inline]
pub(super) fn parse_i64(t: &[u8]) -> Option<i64> {
    std::str::from_utf8(t).ok()?.parse().ok()
}

/// A token for messages, shortened and made printable.
pub(crate) fn show(t: &[u8]) -> String {
    let s = String::from_utf8_lossy(&t[..t.len().min(40)]).into_owned();
    if t.len() > 40 {
        s + "…"
    } else {
        s
    }
}
