//! gmsh `.msh`: MSH 4.1 and 2.x, ASCII and binary. Node tags map to 0-based indices in file
//! order; sections other than `$MeshFormat`, `$Nodes`, `$Elements` (and, in binary 4.1,
//! `$Entities`, parsed to find its end) are skipped to their `$End…` line.
//!
//! This file holds the element types, the node map, the reader's state, `$MeshFormat`, the
//! section loop and the ASCII and binary helpers; `nodes.rs` reads `$Nodes`, `elements.rs`
//! `$Elements`, and `writer.rs` writes MSH 4.1 ASCII.

mod elements;
mod nodes;
mod writer;

use std::collections::HashMap;
use std::path::Path;

use super::VolumeMesh;
use super::scan::{Scan, Token, parse, show, words};
use crate::error::{Error, Location, Result};
pub(super) use writer::write;

/// What becomes of an element type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Tet,
    Hex,
    Tri,
    /// Skipped and counted under this name.
    Skip(&'static str),
    /// A higher-order volume element: an error.
    HighOrder(&'static str),
}

/// Nodes per element and what becomes of it, by gmsh element type.
fn element_type(t: i64) -> Option<(usize, Kind)> {
    use Kind::*;
    Some(match t {
        1 => (2, Skip("2-node line")),
        2 => (3, Tri),
        3 => (4, Skip("4-node quadrangle")),
        4 => (4, Tet),
        5 => (8, Hex),
        6 => (6, Skip("6-node prism")),
        7 => (5, Skip("5-node pyramid")),
        8 => (3, Skip("3-node line")),
        9 => (6, Skip("6-node triangle")),
        10 => (9, Skip("9-node quadrangle")),
        11 => (10, HighOrder("10-node tetrahedron")),
        12 => (27, HighOrder("27-node hexahedron")),
        13 => (18, Skip("18-node prism")),
        14 => (14, Skip("14-node pyramid")),
        15 => (1, Skip("point")),
        16 => (8, Skip("8-node quadrangle")),
        17 => (20, HighOrder("20-node hexahedron")),
        18 => (15, Skip("15-node prism")),
        19 => (13, Skip("13-node pyramid")),
        20 => (9, Skip("9-node triangle")),
        21 => (10, Skip("10-node triangle")),
        22 => (12, Skip("12-node triangle")),
        23 => (15, Skip("15-node triangle")),
        24 => (15, Skip("15-node incomplete triangle")),
        25 => (21, Skip("21-node triangle")),
        26 => (4, Skip("4-node line")),
        27 => (5, Skip("5-node line")),
        28 => (6, Skip("6-node line")),
        29 => (20, HighOrder("20-node tetrahedron")),
        30 => (35, HighOrder("35-node tetrahedron")),
        31 => (56, HighOrder("56-node tetrahedron")),
        92 => (64, HighOrder("64-node hexahedron")),
        93 => (125, HighOrder("125-node hexahedron")),
        _ => return None,
    })
}

/// The message for a higher-order volume element.
fn high_order_msg(t: i64, name: &str) -> String {
    format!(
        "element type {t} ({name}): only linear elements are supported (type 4, 4-node \
         tetrahedra, and type 5, 8-node hexahedra); mesh with order 1 (gmsh -order 1)"
    )
}

/// No node under this tag, in [`NodeMap`]'s dense table.
const NONE: u32 = u32::MAX;

/// Node tags to 0-based indices: a table for tags up to a limit set by the node count, a hash
/// map beyond.
struct NodeMap {
    dense: Vec<u32>,
    sparse: HashMap<u64, u32>,
    limit: u64,
}

impl NodeMap {
    fn new(expected: usize) -> NodeMap {
        NodeMap {
            dense: Vec::new(),
            sparse: HashMap::new(),
            limit: (expected as u64).saturating_mul(4).saturating_add(1024),
        }
    }

    /// Record `tag` as node `idx`; false when the tag was already there.
    fn insert(&mut self, tag: u64, idx: u32) -> bool {
        if tag < self.limit {
            let t = tag as usize;
            if t >= self.dense.len() {
                self.dense.resize((t + 1).max(self.dense.len() * 2), NONE);
            }
            if self.dense[t] != NONE {
                return false;
            }
            self.dense[t] = idx;
            true
        } else {
            self.sparse.insert(tag, idx).is_none()
        }
    }

    fn get(&self, tag: u64) -> Option<u32> {
        if tag < self.limit {
            self.dense.get(tag as usize).copied().filter(|&i| i != NONE)
        } else {
            self.sparse.get(&tag).copied()
        }
    }
}

/// The reader's state.
struct Msh<'a> {
    s: Scan<'a>,
    /// MSH 4.1 (else 2.x).
    v4: bool,
    /// Binary little-endian (binary files only).
    le: bool,
    nodes: Option<NodeMap>,
    mesh: VolumeMesh,
}

/// Read a gmsh MSH file held in `data`.
pub(super) fn read(path: &Path, data: &[u8]) -> Result<VolumeMesh> {
    let mut s = Scan::new(path, data);
    let first = s.nonblank_line();
    match first {
        Some(t) if t.text == b"$MeshFormat" => {}
        Some(t) if t.text.starts_with(b"$NOD") => {
            return Err(s.err_at(
                &t,
                "MSH version 1 ($NOD) is not supported: expected MSH 4.1 or 2.2 (re-save \
                 with gmsh -format msh41)",
            ));
        }
        Some(t) => {
            return Err(s.err_at(
                &t,
                format!(
                    "not a gmsh MSH file: expected $MeshFormat, found {}",
                    t.show()
                ),
            ));
        }
        None => return Err(s.err("not a gmsh MSH file: expected $MeshFormat")),
    }
    let Some(fl) = s.nonblank_line() else {
        return Err(s.err("file ends in $MeshFormat: expected `version file-type data-size`"));
    };
    let w: Vec<&[u8]> = words(fl.text).collect();
    let bad_format = || {
        s.err_at(
            &fl,
            format!(
                "$MeshFormat: expected `version file-type data-size` such as `4.1 0 8`, found {}",
                fl.show()
            ),
        )
    };
    if w.len() != 3 {
        return Err(bad_format());
    }
    let (Some(version), Some(ftype), Some(dsize)) =
        (parse::<f64>(w[0]), parse::<u32>(w[1]), parse::<u32>(w[2]))
    else {
        return Err(bad_format());
    };
    let v4 = if version == 4.1 {
        true
    } else if (2.0..2.3).contains(&version) {
        false
    } else {
        return Err(s.err_at(
            &fl,
            format!(
                "MSH version {}: expected 4.1 or 2.x (2.2); re-save with gmsh -format msh41",
                show(w[0])
            ),
        ));
    };
    let binary = match ftype {
        0 => false,
        1 => true,
        _ => {
            return Err(s.err_at(
                &fl,
                format!("$MeshFormat: file type {ftype}: expected 0 (ASCII) or 1 (binary)"),
            ));
        }
    };
    if binary && dsize != 8 {
        return Err(s.err_at(
            &fl,
            format!("$MeshFormat: data size {dsize}: only 8 (64-bit size_t) is supported"),
        ));
    }
    let mut le = true;
    if binary {
        s.binary = true;
        let one = s.take(4, "$MeshFormat")?;
        let b = [one[0], one[1], one[2], one[3]];
        le = if u32::from_le_bytes(b) == 1 {
            true
        } else if u32::from_be_bytes(b) == 1 {
            false
        } else {
            return Err(Error::format(
                path,
                Location::Byte(s.pos as u64 - 4),
                format!(
                    "$MeshFormat: expected the integer 1 (which tells the byte order), found \
                     bytes {b:02x?}"
                ),
            ));
        };
    }
    let mut m = Msh {
        s,
        v4,
        le,
        nodes: None,
        mesh: VolumeMesh::default(),
    };
    m.expect_end("MeshFormat")?;
    while let Some(t) = m.s.nonblank_line() {
        let Some(name) = t.text.strip_prefix(b"$") else {
            return Err(m.s.err_at(
                &t,
                format!(
                    "expected a section such as $Nodes or $Elements, found {}",
                    t.show()
                ),
            ));
        };
        let name = String::from_utf8_lossy(name).into_owned();
        match name.as_str() {
            "Nodes" => {
                if m.nodes.is_some() {
                    return Err(m.s.err_at(&t, "a second $Nodes section: expected one"));
                }
                if m.v4 { m.nodes_v4()? } else { m.nodes_v2()? }
            }
            "Elements" => {
                if m.nodes.is_none() {
                    return Err(m
                        .s
                        .err_at(&t, "$Elements before $Nodes: expected $Nodes first"));
                }
                if m.v4 {
                    m.elements_v4()?
                } else {
                    m.elements_v2()?
                }
            }
            "Entities" if m.v4 && m.s.binary => m.entities_binary()?,
            n if n.starts_with("End") => {
                return Err(m.s.err_at(&t, format!("{} without its section", t.show())));
            }
            _ => m.skip_section(&t, &name)?,
        }
    }
    if m.nodes.is_none() {
        return Err(m.s.err("no $Nodes section: expected $Nodes and $Elements"));
    }
    Ok(m.mesh)
}

impl<'a> Msh<'a> {
    /// The next line must be `$End{name}`.
    fn expect_end(&mut self, name: &str) -> Result<()> {
        let want = format!("$End{name}");
        match self.s.nonblank_line() {
            Some(t) if t.text == want.as_bytes() => Ok(()),
            Some(t) => Err(self.s.err_at(
                &t,
                format!(
                    "expected {want}, found {}: do the counts of ${name} match its entries?",
                    t.show()
                ),
            )),
            None => Err(self.s.err(format!("file ends in ${name}: expected {want}"))),
        }
    }

    /// Skip section `name` (its `$name` line just read) to the line after `$End{name}`.
    fn skip_section(&mut self, t: &Token, name: &str) -> Result<()> {
        let end = format!("$End{name}");
        let rest = &self.s.data[self.s.pos..];
        let mut from = 0;
        loop {
            let Some(i) = memchr::memmem::find(&rest[from..], end.as_bytes()) else {
                return Err(self.s.err_at(
                    t,
                    format!("section ${name} has no {end}: the file ends inside it"),
                ));
            };
            let at = from + i;
            let before_ok = at == 0 || rest[at - 1] == b'\n';
            let after = rest.get(at + end.len()).copied();
            let after_ok = after.is_none_or(|b| b.is_ascii_whitespace());
            if before_ok && after_ok {
                self.s.line += memchr::memchr_iter(b'\n', &rest[..at]).count() as u64;
                self.s.pos += at;
                self.s.line_rest();
                return Ok(());
            }
            from = at + 1;
        }
    }

    // ----- ASCII helpers -----

    /// The next non-blank line of section `sec`, which must hold `what`.
    fn line(&mut self, sec: &str, what: &str) -> Result<Token<'a>> {
        self.s
            .nonblank_line()
            .ok_or_else(|| self.s.err(format!("file ends in ${sec}: expected {what}")))
    }

    /// The numbers of `line`, which must be exactly `n` (`what` describes them).
    fn numbers<T: std::str::FromStr + Copy + Default, const N: usize>(
        &self,
        line: &Token,
        sec: &str,
        what: &str,
    ) -> Result<[T; N]> {
        let mut out = [T::default(); N];
        let mut k = 0;
        for w in words(line.text) {
            let v = (k < N).then(|| parse::<T>(w)).flatten();
            match v {
                Some(v) => out[k] = v,
                None => break,
            }
            k += 1;
        }
        if k != N || words(line.text).count() != N {
            return Err(self.s.err_at(
                line,
                format!("${sec}: expected {what}, found {}", line.show()),
            ));
        }
        Ok(out)
    }

    // ----- binary helpers -----

    fn size_t(&mut self, what: &str) -> Result<u64> {
        let b = self.s.take(8, what)?;
        let a = [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
        Ok(if self.le {
            u64::from_le_bytes(a)
        } else {
            u64::from_be_bytes(a)
        })
    }

    fn int(&mut self, what: &str) -> Result<i32> {
        let b = self.s.take(4, what)?;
        let a = [b[0], b[1], b[2], b[3]];
        Ok(if self.le {
            i32::from_le_bytes(a)
        } else {
            i32::from_be_bytes(a)
        })
    }

    fn u64_at(&self, b: &[u8]) -> u64 {
        let a = [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
        if self.le {
            u64::from_le_bytes(a)
        } else {
            u64::from_be_bytes(a)
        }
    }

    fn f64_at(&self, b: &[u8]) -> f64 {
        f64::from_bits(self.u64_at(b))
    }

    fn i32_at(&self, b: &[u8]) -> i32 {
        let a = [b[0], b[1], b[2], b[3]];
        if self.le {
            i32::from_le_bytes(a)
        } else {
            i32::from_be_bytes(a)
        }
    }

    /// `n` records of `size` bytes each, for `what`.
    fn records(&mut self, n: u64, size: usize, what: &str) -> Result<&'a [u8]> {
        let total = usize::try_from(n)
            .ok()
            .and_then(|n| n.checked_mul(size))
            .filter(|&t| t <= self.s.remaining());
        match total {
            Some(t) => self.s.take(t, what),
            None => Err(Error::format(
                self.s.path,
                Location::Byte(self.s.pos as u64),
                format!(
                    "file ends in {what}: expected {n} records of {size} bytes, found {} bytes",
                    self.s.remaining()
                ),
            )),
        }
    }

    /// `$Entities` of binary MSH 4.1, parsed to its end (its binary content could hold any
    /// byte sequence, so it is not searched for `$EndEntities`).
    fn entities_binary(&mut self) -> Result<()> {
        let mut counts = [0u64; 4];
        for c in &mut counts {
            *c = self.size_t("$Entities")?;
        }
        for (dim, &n) in counts.iter().enumerate() {
            for _ in 0..n {
                self.int("$Entities")?;
                self.s.take(if dim == 0 { 24 } else { 48 }, "$Entities")?;
                let np = self.size_t("$Entities")?;
                self.records(np, 4, "$Entities")?;
                if dim > 0 {
                    let nb = self.size_t("$Entities")?;
                    self.records(nb, 4, "$Entities")?;
                }
            }
        }
        self.expect_end("Entities")
    }
}

#[cfg(test)]
pub(super) mod tests;
