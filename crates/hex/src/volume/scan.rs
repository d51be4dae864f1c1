//! The byte cursor the three readers share: whitespace tokens and lines with their 1-based
//! line numbers, and raw binary runs, over a file held in memory. Locations are lines in text
//! files and bytes in binary ones ([`Scan::binary`]), counted from the start of the file.

use std::path::Path;

use crate::error::{Error, Location, Result};

/// One whitespace-delimited token and where it starts.
#[derive(Clone, Copy, Debug)]
pub(super) struct Token<'a> {
    /// Its bytes.
    pub text: &'a [u8],
    /// 1-based line.
    pub line: u64,
    /// Byte offset from the start of the file.
    pub byte: u64,
}

impl Token<'_> {
    /// The token as `f64`, if it is a number.
    pub fn f64(&self) -> Option<f64> {
        std::str::from_utf8(self.text).ok()?.parse().ok()
    }

    /// The token as a whole number (an optional sign, then digits), if it is one.
    pub fn i64(&self) -> Option<i64> {
        std::str::from_utf8(self.text).ok()?.parse().ok()
    }

    /// The token as a non-negative whole number, if it is one.
    pub fn u64(&self) -> Option<u64> {
        let t = self.text.strip_prefix(b"+").unwrap_or(self.text);
        std::str::from_utf8(t).ok()?.parse().ok()
    }

    /// Whether the token equals `word`, ignoring ASCII case.
    pub fn is(&self, word: &str) -> bool {
        self.text.eq_ignore_ascii_case(word.as_bytes())
    }

    /// The token quoted for a message.
    pub fn show(&self) -> String {
        show(self.text)
    }
}

/// `bytes` quoted for a message: lossy UTF-8, cut after 40 characters.
pub(super) fn show(bytes: &[u8]) -> String {
    let s = String::from_utf8_lossy(bytes);
    let mut out: String = s.chars().take(40).collect();
    if s.chars().nth(40).is_some() {
        out.push('…');
    }
    format!("{out:?}")
}

/// A cursor over a whole file.
pub(super) struct Scan<'a> {
    /// The file, for messages.
    pub path: &'a Path,
    /// Its bytes.
    pub data: &'a [u8],
    /// The next byte to read.
    pub pos: usize,
    /// 1-based line of `pos` (exact while only text was read).
    pub line: u64,
    /// Locations are bytes rather than lines.
    pub binary: bool,
    /// The byte after the last token [`Scan::token`] returned, and that token's line.
    pub last_token: Option<(usize, u64)>,
}

impl<'a> Scan<'a> {
    /// A cursor at the start of `data`.
    pub fn new(path: &'a Path, data: &'a [u8]) -> Scan<'a> {
        Scan {
            path,
            data,
            pos: 0,
            line: 1,
            binary: false,
            last_token: None,
        }
    }

    /// The location of the cursor.
    pub fn loc(&self) -> Location {
        if self.binary {
            Location::Byte(self.pos as u64)
        } else {
            Location::Line(self.line)
        }
    }

    /// The location of `tok`.
    pub fn loc_of(&self, tok: &Token) -> Location {
        if self.binary {
            Location::Byte(tok.byte)
        } else {
            Location::Line(tok.line)
        }
    }

    /// A format error at the cursor.
    pub fn err(&self, msg: impl Into<String>) -> Error {
        Error::format(self.path, self.loc(), msg)
    }

    /// A format error at `tok`.
    pub fn err_at(&self, tok: &Token, msg: impl Into<String>) -> Error {
        Error::format(self.path, self.loc_of(tok), msg)
    }

    /// Bytes left to read.
    pub fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    /// Skip whitespace and, with `comments`, `#` comments to the end of their line.
    pub fn skip_space(&mut self, comments: bool) {
        while let Some(&b) = self.data.get(self.pos) {
            if b == b'\n' {
                self.line += 1;
            } else if comments && b == b'#' {
                while self.data.get(self.pos).is_some_and(|&c| c != b'\n') {
                    self.pos += 1;
                }
                continue;
            } else if !b.is_ascii_whitespace() {
                return;
            }
            self.pos += 1;
        }
    }

    /// The next token (`#` comments skipped with `comments`), or `None` at the end.
    pub fn token(&mut self, comments: bool) -> Option<Token<'a>> {
        self.skip_space(comments);
        let start = self.pos;
        if start >= self.data.len() {
            return None;
        }
        while self
            .data
            .get(self.pos)
            .is_some_and(|&b| !(b.is_ascii_whitespace() || (comments && b == b'#')))
        {
            self.pos += 1;
        }
        self.last_token = Some((self.pos, self.line));
        Some(Token {
            text: &self.data[start..self.pos],
            line: self.line,
            byte: start as u64,
        })
    }

    /// The rest of the current line (without its `\r\n` or `\n`), the cursor moved past its
    /// end; `None` at the end of the file.
    pub fn line_rest(&mut self) -> Option<Token<'a>> {
        if self.pos >= self.data.len() {
            return None;
        }
        let start = self.pos;
        let end = memchr::memchr(b'\n', &self.data[start..]).map_or(self.data.len(), |i| start + i);
        let tok = Token {
            text: trim_cr(&self.data[start..end]),
            line: self.line,
            byte: start as u64,
        };
        self.pos = end;
        if self.pos < self.data.len() {
            self.pos += 1;
            self.line += 1;
        }
        Some(tok)
    }

    /// The next line that is not blank, trimmed of surrounding whitespace; `None` at the end.
    pub fn nonblank_line(&mut self) -> Option<Token<'a>> {
        self.skip_space(false);
        let mut t = self.line_rest()?;
        t.text = t.text.trim_ascii();
        Some(t)
    }

    /// Move past the end of the current line (the `\n` that ends a keyword line before binary
    /// data); only spaces, tabs and `\r` may come before it.
    pub fn end_line(&mut self) -> Result<()> {
        while let Some(&b) = self.data.get(self.pos) {
            match b {
                b'\n' => {
                    self.pos += 1;
                    self.line += 1;
                    return Ok(());
                }
                b' ' | b'\t' | b'\r' => self.pos += 1,
                _ => {
                    return Err(self.err(format!(
                        "expected the end of the line, found {}",
                        show(&self.data[self.pos..(self.pos + 20).min(self.data.len())])
                    )));
                }
            }
        }
        Ok(())
    }

    /// An error when the last token read ends the file with no whitespace after it: in a
    /// text format that ends its lines, the file was most likely cut inside that token (a
    /// number cut short still reads as a number, so nothing else would notice).
    pub fn check_not_cut(&self, format: &str) -> Result<()> {
        match self.last_token {
            Some((end, line)) if end == self.data.len() => Err(Error::format(
                self.path,
                Location::Line(line),
                format!(
                    "the file ends inside {}, with no line end after it: expected a complete                      {format} file (is it truncated?)",
                    show(
                        self.data[..end]
                            .rsplit(|b| b.is_ascii_whitespace())
                            .next()
                            .unwrap_or(b"")
                    )
                ),
            )),
            _ => Ok(()),
        }
    }

    /// The next `n` bytes, or an error saying that the file ends in `what`.
    pub fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        if n > self.remaining() {
            return Err(Error::format(
                self.path,
                Location::Byte(self.data.len() as u64),
                format!(
                    "file ends in {what}: expected {n} bytes from byte {}, found {}",
                    self.pos,
                    self.remaining()
                ),
            ));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
}

/// `s` without a trailing `\r`.
fn trim_cr(s: &[u8]) -> &[u8] {
    s.strip_suffix(b"\r").unwrap_or(s)
}

/// The whitespace-separated tokens of one line's bytes.
pub(super) fn words(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|w| !w.is_empty())
}

/// Capacity to reserve for `count` entries announced by a file of which `remaining` bytes are
/// left, each taking at least `min_bytes`: never more than the file can hold, so a lying
/// count cannot exhaust memory.
pub(super) fn capacity(count: u64, remaining: usize, min_bytes: usize) -> usize {
    let most = remaining / min_bytes.max(1) + 1;
    usize::try_from(count).map_or(most, |c| c.min(most))
}

/// Parse `w` as a number of type `T` (no error: the caller names the place).
pub(super) fn parse<T: std::str::FromStr>(w: &[u8]) -> Option<T> {
    std::str::from_utf8(w).ok()?.parse().ok()
}
