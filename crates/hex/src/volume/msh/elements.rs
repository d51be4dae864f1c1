//! `$Elements` of MSH 4.1 and 2.x, ASCII and binary: linear tetrahedra, hexahedra and
//! triangles kept with their node tags mapped to indices, other types skipped and counted,
//! higher-order volume elements refused.

use super::{Kind, Msh, element_type, high_order_msg};
use crate::error::{Error, Location, Result};
use crate::volume::scan::{parse, words};

impl Msh<'_> {
    /// Keep or count one element of type `kind` with node tags `tags`, tagged `tag`.
    pub(super) fn add_element(
        &mut self,
        kind: Kind,
        tag: u64,
        tags: &[u64],
        at: Location,
    ) -> Result<()> {
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
    pub(super) fn elements_v4(&mut self) -> Result<()> {
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
    pub(super) fn elements_v2(&mut self) -> Result<()> {
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
}
