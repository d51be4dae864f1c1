//! gmsh `.msh`: MSH 4.1 and 2.x, ASCII and binary. Node tags map to 0-based indices in file
//! order; sections other than `$MeshFormat`, `$Nodes`, `$Elements` (and, in binary 4.1,
//! `$Entities`, parsed to find its end) are skipped to their `$End…` line.

use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

use super::scan::{Scan, Token, capacity, parse, show, words};
use super::{Cell, VolumeMesh, fmt_f64};
use crate::error::{Error, Location, Result};

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

    // ----- sections -----

    /// Add vertex `p` under `tag`; `at` locates it for errors.
    fn add_node(&mut self, tag: u64, p: [f64; 3], at: Location) -> Result<()> {
        let idx = self.mesh.verts.len();
        let err = |msg: String| Error::format(self.s.path, at, msg);
        if let Some((axis, v)) = ["x", "y", "z"]
            .into_iter()
            .zip(p)
            .find(|(_, v)| !v.is_finite())
        {
            return Err(err(format!(
                "node {tag}: {axis} is {v}, expected a finite coordinate"
            )));
        }
        if idx >= u32::MAX as usize {
            return Err(err("more nodes than 32-bit indices address".into()));
        }
        let map = self.nodes.get_or_insert_with(|| NodeMap::new(0));
        if !map.insert(tag, idx as u32) {
            return Err(err(format!("node tag {tag} appears twice")));
        }
        self.mesh.verts.push(p);
        Ok(())
    }

    /// `$Nodes` of MSH 4.1.
    fn nodes_v4(&mut self) -> Result<()> {
        let (blocks, total) = if self.s.binary {
            let b = self.size_t("$Nodes")?;
            let n = self.size_t("$Nodes")?;
            self.size_t("$Nodes")?;
            self.size_t("$Nodes")?;
            (b, n)
        } else {
            let l = self.line("Nodes", "numEntityBlocks numNodes minNodeTag maxNodeTag")?;
            let [b, n, _, _] = self.numbers::<u64, 4>(
                &l,
                "Nodes",
                "4 numbers: numEntityBlocks numNodes minNodeTag maxNodeTag",
            )?;
            (b, n)
        };
        let cap = capacity(total, self.s.remaining(), 8);
        self.nodes = Some(NodeMap::new(cap));
        self.mesh.verts.reserve(cap);
        for _ in 0..blocks {
            if self.s.binary {
                let dim = self.int("$Nodes block header")?;
                self.int("$Nodes block header")?;
                let param = self.int("$Nodes block header")?;
                let n = self.size_t("$Nodes block header")?;
                let extra = if param == 1 {
                    dim.clamp(0, 3) as usize
                } else {
                    0
                };
                let tags = self.records(n, 8, "$Nodes tags")?;
                let coords_at = self.s.pos;
                let rec = 8 * (3 + extra);
                let coords = self.records(n, rec, "$Nodes coordinates")?;
                for (i, (t, c)) in tags
                    .chunks_exact(8)
                    .zip(coords.chunks_exact(rec))
                    .enumerate()
                {
                    let tag = self.u64_at(t);
                    let p = [
                        self.f64_at(&c[0..]),
                        self.f64_at(&c[8..]),
                        self.f64_at(&c[16..]),
                    ];
                    self.add_node(tag, p, Location::Byte((coords_at + i * rec) as u64))?;
                }
            } else {
                let h = self.line("Nodes", "a block header")?;
                let [dim, _, param, n] = self.numbers::<i64, 4>(
                    &h,
                    "Nodes",
                    "a block header of 4 numbers: entityDim entityTag parametric numNodesInBlock",
                )?;
                let extra = if param == 1 {
                    dim.clamp(0, 3) as usize
                } else {
                    0
                };
                let Ok(n) = u64::try_from(n) else {
                    return Err(self.s.err_at(
                        &h,
                        format!("$Nodes: block header: expected a node count >= 0, found {n}"),
                    ));
                };
                let mut tags = Vec::with_capacity(capacity(n, self.s.remaining(), 2));
                for _ in 0..n {
                    let l = self.line("Nodes", "a node tag")?;
                    let [t] = self.numbers::<u64, 1>(&l, "Nodes", "one node tag")?;
                    tags.push(t);
                }
                for &tag in &tags {
                    let l = self.line("Nodes", "node coordinates")?;
                    let ws: Vec<&[u8]> = words(l.text).collect();
                    let p = (ws.len() == 3 + extra)
                        .then(|| Some([parse::<f64>(ws[0])?, parse(ws[1])?, parse(ws[2])?]))
                        .flatten();
                    let Some(p) = p else {
                        return Err(self.s.err_at(
                            &l,
                            format!(
                                "$Nodes: node {tag}: expected {} numbers (x y z{}), found {}",
                                3 + extra,
                                [" ", " u", " u v", " u v w"][extra].trim_end(),
                                l.show()
                            ),
                        ));
                    };
                    self.add_node(tag, p, Location::Line(l.line))?;
                }
            }
        }
        if self.mesh.verts.len() as u64 != total {
            return Err(self.s.err(format!(
                "$Nodes: the header announces {total} nodes, the blocks hold {}",
                self.mesh.verts.len()
            )));
        }
        self.expect_end("Nodes")
    }

    /// `$Nodes` of MSH 2.x.
    fn nodes_v2(&mut self) -> Result<()> {
        // The count is a text line in ASCII and binary files alike.
        let l = self.line("Nodes", "the number of nodes")?;
        let [n] = self.numbers::<u64, 1>(&l, "Nodes", "the number of nodes")?;
        let cap = capacity(n, self.s.remaining(), 8);
        self.nodes = Some(NodeMap::new(cap));
        self.mesh.verts.reserve(cap);
        if self.s.binary {
            let at = self.s.pos;
            let recs = self.records(n, 28, "$Nodes")?;
            for (i, r) in recs.chunks_exact(28).enumerate() {
                let tag = self.i32_at(r);
                let p = [
                    self.f64_at(&r[4..]),
                    self.f64_at(&r[12..]),
                    self.f64_at(&r[20..]),
                ];
                let loc = Location::Byte((at + 28 * i) as u64);
                let Ok(tag) = u64::try_from(tag) else {
                    return Err(Error::format(
                        self.s.path,
                        loc,
                        format!("$Nodes: node tag {tag}: expected a positive tag"),
                    ));
                };
                self.add_node(tag, p, loc)?;
            }
        } else {
            for _ in 0..n {
                let l = self.line("Nodes", "a node: tag x y z")?;
                let ws: Vec<&[u8]> = words(l.text).collect();
                let node = (ws.len() == 4)
                    .then(|| {
                        Some((
                            parse::<u64>(ws[0])?,
                            [parse::<f64>(ws[1])?, parse(ws[2])?, parse(ws[3])?],
                        ))
                    })
                    .flatten();
                let Some((tag, p)) = node else {
                    return Err(self.s.err_at(
                        &l,
                        format!(
                            "$Nodes: expected a node as 4 numbers (tag x y z), found {}",
                            l.show()
                        ),
                    ));
                };
                self.add_node(tag, p, Location::Line(l.line))?;
            }
        }
        self.expect_end("Nodes")
    }

    /// Keep or count one element of type `kind` with node tags `tags`, tagged `tag`.
    fn add_element(&mut self, kind: Kind, tag: u64, tags: &[u64], at: Location) -> Result<()> {
        let map = self.nodes.as_ref();
        let mut idx = [0u32; 8];
        if matches!(kind, Kind::Tet | Kind::Hex | Kind::Tri) {
            for (k, &t) in tags.iter().enumerate() {
                match map.and_then(|m| m.get(t)) {
                    Some(i) => idx[k] = i,
                    None => {
                        return Err(Error::format(
                            self.s.path,
                            at,
                            format!(
                                "element {tag}: node {t} is not among the {} nodes of $Nodes",
                                self.mesh.verts.len()
                            ),
                        ));
                    }
                }
            }
        }
        match kind {
            Kind::Tet => self.mesh.tets.push([idx[0], idx[1], idx[2], idx[3]]),
            Kind::Hex => self.mesh.hexes.push(idx),
            Kind::Tri => self.mesh.triangles.push([idx[0], idx[1], idx[2]]),
            Kind::Skip(name) => self.mesh.skip(name, 1),
            Kind::HighOrder(_) => {}
        }
        Ok(())
    }

    /// `$Elements` of MSH 4.1.
    fn elements_v4(&mut self) -> Result<()> {
        let (blocks, total) = if self.s.binary {
            let b = self.size_t("$Elements")?;
            let n = self.size_t("$Elements")?;
            self.size_t("$Elements")?;
            self.size_t("$Elements")?;
            (b, n)
        } else {
            let l = self.line(
                "Elements",
                "numEntityBlocks numElements minElementTag maxElementTag",
            )?;
            let [b, n, _, _] = self.numbers::<u64, 4>(
                &l,
                "Elements",
                "4 numbers: numEntityBlocks numElements minElementTag maxElementTag",
            )?;
            (b, n)
        };
        let mut seen = 0u64;
        let mut tags = Vec::new();
        for _ in 0..blocks {
            let (etype, n, at) = if self.s.binary {
                let at = Location::Byte(self.s.pos as u64);
                self.int("$Elements block header")?;
                self.int("$Elements block header")?;
                let t = self.int("$Elements block header")?;
                let n = self.size_t("$Elements block header")?;
                (t as i64, n, at)
            } else {
                let h = self.line("Elements", "a block header")?;
                let [_, _, t, n] = self.numbers::<i64, 4>(
                    &h,
                    "Elements",
                    "a block header of 4 numbers: entityDim entityTag elementType \
                     numElementsInBlock",
                )?;
                let Ok(n) = u64::try_from(n) else {
                    return Err(self.s.err_at(
                        &h,
                        format!(
                            "$Elements: block header: expected an element count >= 0, found {n}"
                        ),
                    ));
                };
                (t, n, Location::Line(h.line))
            };
            let info = element_type(etype);
            if let Some((_, Kind::HighOrder(name))) = info {
                return Err(Error::format(self.s.path, at, high_order_msg(etype, name)));
            }
            seen = seen.saturating_add(n);
            if self.s.binary {
                let Some((nn, kind)) = info else {
                    return Err(Error::format(
                        self.s.path,
                        at,
                        format!(
                            "element type {etype} is unknown: its node count, hence the size of \
                             its binary records, is unknown"
                        ),
                    ));
                };
                let rec = 8 * (1 + nn);
                let start = self.s.pos;
                let data = self.records(n, rec, "$Elements")?;
                for (i, r) in data.chunks_exact(rec).enumerate() {
                    let tag = self.u64_at(r);
                    tags.clear();
                    tags.extend(r[8..].chunks_exact(8).map(|b| self.u64_at(b)));
                    let loc = Location::Byte((start + i * rec) as u64);
                    self.add_element(kind, tag, &tags, loc)?;
                }
            } else {
                for _ in 0..n {
                    let l = self.line("Elements", "an element")?;
                    let Some((nn, kind)) = info else {
                        self.mesh.skip(&format!("element type {etype}"), 1);
                        continue;
                    };
                    tags.clear();
                    let mut count = 0;
                    for w in words(l.text) {
                        count += 1;
                        match parse::<u64>(w) {
                            Some(v) => tags.push(v),
                            None => break,
                        }
                    }
                    if count != 1 + nn || tags.len() != 1 + nn {
                        return Err(self.s.err_at(
                            &l,
                            format!(
                                "$Elements: expected {} numbers for an element of type {etype} \
                                 (its tag and {nn} node tags), found {}",
                                1 + nn,
                                l.show()
                            ),
                        ));
                    }
                    let tag = tags[0];
                    let nodes: Vec<u64> = tags[1..].to_vec();
                    self.add_element(kind, tag, &nodes, Location::Line(l.line))?;
                }
            }
        }
        if seen != total {
            return Err(self.s.err(format!(
                "$Elements: the header announces {total} elements, the blocks hold {seen}"
            )));
        }
        self.expect_end("Elements")
    }

    /// `$Elements` of MSH 2.x.
    fn elements_v2(&mut self) -> Result<()> {
        let l = self.line("Elements", "the number of elements")?;
        let [total] = self.numbers::<u64, 1>(&l, "Elements", "the number of elements")?;
        let mut tags = Vec::new();
        if self.s.binary {
            let mut seen = 0u64;
            while seen < total {
                let at = Location::Byte(self.s.pos as u64);
                let etype = self.int("$Elements block header")? as i64;
                let n = self.int("$Elements block header")?;
                let ntags = self.int("$Elements block header")?;
                let (Ok(n), Ok(ntags)) = (u64::try_from(n), usize::try_from(ntags)) else {
                    return Err(Error::format(
                        self.s.path,
                        at,
                        format!(
                            "$Elements: block of type {etype}: expected non-negative counts, \
                             found {n} elements with {ntags} tags"
                        ),
                    ));
                };
                if n == 0 || n > total - seen {
                    return Err(Error::format(
                        self.s.path,
                        at,
                        format!(
                            "$Elements: block of type {etype} holds {n} elements, expected 1 to \
                             the {} left of the {total} announced",
                            total - seen
                        ),
                    ));
                }
                let (nn, kind) = match element_type(etype) {
                    Some((_, Kind::HighOrder(name))) => {
                        return Err(Error::format(self.s.path, at, high_order_msg(etype, name)));
                    }
                    Some(i) => i,
                    None => {
                        return Err(Error::format(
                            self.s.path,
                            at,
                            format!(
                                "element type {etype} is unknown: its node count, hence the \
                                 size of its binary records, is unknown"
                            ),
                        ));
                    }
                };
                let rec = 4 * (1 + ntags + nn);
                let start = self.s.pos;
                let data = self.records(n, rec, "$Elements")?;
                for (i, r) in data.chunks_exact(rec).enumerate() {
                    let tag = self.i32_at(r) as i64 as u64;
                    tags.clear();
                    tags.extend(
                        r[4 * (1 + ntags)..]
                            .chunks_exact(4)
                            .map(|b| self.i32_at(b) as i64 as u64),
                    );
                    let loc = Location::Byte((start + i * rec) as u64);
                    self.add_element(kind, tag, &tags, loc)?;
                }
                seen += n;
            }
        } else {
            for _ in 0..total {
                let l = self.line("Elements", "an element")?;
                let mut nums = Vec::new();
                let mut count = 0;
                for w in words(l.text) {
                    count += 1;
                    match parse::<i64>(w) {
                        Some(v) => nums.push(v),
                        None => break,
                    }
                }
                let bad = |what: String| {
                    self.s.err_at(
                        &l,
                        format!("$Elements: expected {what}, found {}", l.show()),
                    )
                };
                if count != nums.len() || nums.len() < 3 {
                    return Err(bad(
                        "an element: tag type number-of-tags tags... node tags...".into(),
                    ));
                }
                let (tag, etype, ntags) = (nums[0], nums[1], nums[2]);
                let Some((nn, kind)) = element_type(etype) else {
                    self.mesh.skip(&format!("element type {etype}"), 1);
                    continue;
                };
                if let Kind::HighOrder(name) = kind {
                    return Err(self.s.err_at(&l, high_order_msg(etype, name)));
                }
                let ntags = usize::try_from(ntags).unwrap_or(usize::MAX);
                if ntags.checked_add(3 + nn) != Some(nums.len()) {
                    return Err(bad(format!(
                        "{} numbers for an element of type {etype} with {ntags} tags (tag, type, \
                         number of tags, the tags, {nn} node tags)",
                        ntags.saturating_add(3 + nn)
                    )));
                }
                tags.clear();
                for &v in &nums[3 + ntags..] {
                    let Ok(v) = u64::try_from(v) else {
                        return Err(bad(format!("node tags of element {tag} to be positive")));
                    };
                    tags.push(v);
                }
                let tag = u64::try_from(tag).unwrap_or(0);
                self.add_element(kind, tag, &tags, Location::Line(l.line))?;
            }
        }
        self.expect_end("Elements")
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

/// Write `verts` and `cells` as gmsh MSH 4.1 ASCII: one volume entity, one node block, one
/// element block, one `$ElementData` per field of `cell_data`.
pub(super) fn write<const K: usize>(
    w: &mut impl Write,
    verts: &[[f64; 3]],
    cells: &[[u32; K]],
    kind: Cell,
    cell_data: &[(&str, &[f64])],
) -> std::io::Result<()> {
    let etype = match kind {
        Cell::Tet => 4,
        Cell::Hex => 5,
    };
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in verts {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if verts.is_empty() {
        lo = [0.0; 3];
        hi = [0.0; 3];
    }
    let (nv, nc) = (verts.len(), cells.len());
    writeln!(w, "$MeshFormat\n4.1 0 8\n$EndMeshFormat")?;
    writeln!(w, "$Entities\n0 0 0 1")?;
    writeln!(
        w,
        "1 {} {} {} {} {} {} 0 0",
        fmt_f64(lo[0]),
        fmt_f64(lo[1]),
        fmt_f64(lo[2]),
        fmt_f64(hi[0]),
        fmt_f64(hi[1]),
        fmt_f64(hi[2])
    )?;
    writeln!(w, "$EndEntities")?;
    writeln!(w, "$Nodes\n1 {nv} {} {nv}", nv.min(1))?;
    writeln!(w, "3 1 0 {nv}")?;
    for i in 1..=nv {
        writeln!(w, "{i}")?;
    }
    for p in verts {
        writeln!(w, "{} {} {}", fmt_f64(p[0]), fmt_f64(p[1]), fmt_f64(p[2]))?;
    }
    writeln!(w, "$EndNodes")?;
    writeln!(w, "$Elements\n1 {nc} {} {nc}", nc.min(1))?;
    writeln!(w, "3 1 {etype} {nc}")?;
    for (i, c) in cells.iter().enumerate() {
        write!(w, "{}", i + 1)?;
        for v in c {
            write!(w, " {}", v + 1)?;
        }
        writeln!(w)?;
    }
    writeln!(w, "$EndElements")?;
    for (name, values) in cell_data {
        writeln!(w, "$ElementData\n1\n\"{name}\"\n1\n0\n3\n0\n1\n{nc}")?;
        for (i, v) in values.iter().enumerate() {
            writeln!(w, "{} {}", i + 1, fmt_f64(*v))?;
        }
        writeln!(w, "$EndElementData")?;
    }
    Ok(())
}

#[cfg(test)]
pub(super) mod tests;
