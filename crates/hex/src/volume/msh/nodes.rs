//! `$Nodes` of MSH 4.1 and 2.x, ASCII and binary: each node's tag mapped to its index in
//! file order, its coordinates checked finite.

use super::{Msh, NodeMap};
use crate::error::{Error, Location, Result};
use crate::volume::scan::{capacity, parse, words};

impl Msh<'_> {
    /// Add vertex `p` under `tag`; `at` locates it for errors.
    pub(super) fn add_node(&mut self, tag: u64, p: [f64; 3], at: Location) -> Result<()> {
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
    pub(super) fn nodes_v4(&mut self) -> Result<()> {
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
    pub(super) fn nodes_v2(&mut self) -> Result<()> {
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
}
