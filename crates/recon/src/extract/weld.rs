//! Welding tile meshes into one indexed mesh, streaming (ARCHITECTURE.md step 5).
//!
//! A vertex is named by the grid edge it lies on ([`EdgeKey`]), and two tiles that hold the
//! same edge compute the same vertex ([module docs](super), "Seams"). The [`Welder`] takes
//! tiles in a fixed order and gives each new key the next global index, so the output does not
//! depend on which worker finished first. It only remembers the keys that a later tile may
//! still reference, the *frontier*: after tile `t`, a key whose last tile (given by the
//! caller, who knows the tiling) is `≤ t` is forgotten. Memory is then proportional to the
//! seams between done and pending tiles, not to the mesh.

use std::collections::BTreeMap;

use crate::error::{Error, Result};
use crate::types::{EdgeKey, KeyMap, TileMesh};

/// Assigns global vertex indices to edge keys across tiles processed in a fixed order; keeps
/// only keys that a later tile may still reference (the frontier).
#[derive(Debug, Default)]
pub struct Welder {
    /// Global index of each frontier key.
    frontier: KeyMap<EdgeKey, u64>,
    /// Frontier keys by the tile after which they are released.
    expiry: BTreeMap<u64, Vec<EdgeKey>>,
    /// Scratch: global index of each vertex of the tile being added.
    local: Vec<u64>,
    /// Vertices emitted so far (the next global index).
    next: u64,
    /// The last tile added.
    last: Option<u64>,
    /// Largest frontier seen.
    peak: usize,
    /// Global indices of the vertices the last tile completed: no later tile can name them.
    released: Vec<u64>,
}

impl Welder {
    /// A welder that has seen no tile.
    pub fn new() -> Welder {
        Welder::default()
    }

    /// Add tile number `t` (tiles are added in increasing `t`).
    ///
    /// `last_tile(key)` is the largest tile number that can contain `key` (the caller knows
    /// the tiling); keys with `last_tile(key) > t` are kept in the frontier, the others are
    /// released after this tile. Calls `emit_vertex(global_index, tile_index, position)` once per
    /// new vertex, in increasing index order, then `emit_triangle` for every triangle of the tile,
    /// with global indices; so a triangle only names vertices already emitted.
    ///
    /// Errors: those of the callbacks, and [`Error::Internal`] when `t` does not increase, the
    /// mesh is inconsistent, or a key's last tile is before `t` (a wrong `last_tile`). After an
    /// error the welder must not be used again.
    pub fn add_tile(
        &mut self,
        t: u64,
        mesh: &TileMesh,
        last_tile: impl Fn(EdgeKey) -> u64,
        mut emit_vertex: impl FnMut(u64, usize, [f64; 3]) -> Result<()>,
        mut emit_triangle: impl FnMut([u64; 3]) -> Result<()>,
    ) -> Result<()> {
        if let Some(prev) = self.last
            && t <= prev
        {
            return Err(Error::Internal(format!(
                "welder: tile {t} added after tile {prev}; tiles must come in increasing order"
            )));
        }
        self.last = Some(t);
        if mesh.keys.len() != mesh.positions.len() {
            return Err(Error::Internal(format!(
                "welder: tile {t} has {} keys but {} positions",
                mesh.keys.len(),
                mesh.positions.len()
            )));
        }
        self.local.clear();
        self.released.clear();
        for (i, (&key, &p)) in mesh.keys.iter().zip(&mesh.positions).enumerate() {
            if let Some(&g) = self.frontier.get(&key) {
                self.local.push(g);
                continue;
            }
            let lt = last_tile(key);
            if lt < t {
                return Err(Error::Internal(format!(
                    "welder: tile {t} holds edge key {} whose last tile is {lt}",
                    key.0
                )));
            }
            let g = self.next;
            self.next += 1;
            emit_vertex(g, i, p)?;
            if lt > t {
                self.frontier.insert(key, g);
                self.expiry.entry(lt).or_default().push(key);
            } else {
                self.released.push(g);
            }
            self.local.push(g);
        }
        self.peak = self.peak.max(self.frontier.len());
        for tri in &mesh.triangles {
            let mut out = [0u64; 3];
            for (o, &i) in out.iter_mut().zip(tri) {
                *o = *self.local.get(i as usize).ok_or_else(|| {
                    Error::Internal(format!(
                        "welder: tile {t}: triangle {tri:?} names vertex {i} of {}",
                        self.local.len()
                    ))
                })?;
            }
            emit_triangle(out)?;
        }
        while let Some(entry) = self.expiry.first_entry() {
            if *entry.key() > t {
                break;
            }
            for k in entry.remove() {
                if let Some(g) = self.frontier.remove(&k) {
                    self.released.push(g);
                }
            }
        }
        Ok(())
    }

    /// Vertices emitted so far.
    pub fn vertices(&self) -> u64 {
        self.next
    }

    /// The global index of each vertex of the last tile added, by its index in the tile.
    pub fn tile_indices(&self) -> &[u64] {
        &self.local
    }

    /// The vertices the last tile completed (no later tile can name them), by global index.
    pub fn released(&self) -> &[u64] {
        &self.released
    }

    /// The vertices still held (their last tiles were never added), by global index, in no
    /// particular order.
    pub fn held(&self) -> impl Iterator<Item = u64> + '_ {
        self.frontier.values().copied()
    }

    /// Keys held now.
    pub fn frontier_len(&self) -> usize {
        self.frontier.len()
    }

    /// The most keys held at once (after adding a tile's new keys, before releasing).
    pub fn peak_frontier(&self) -> usize {
        self.peak
    }
}

#[cfg(test)]
mod tests {
    use super::super::cpu::McWorkspace;
    use super::super::cpu::tests::{canonical, check_closed_oriented, key_triangles};
    use std::collections::HashMap;

    use super::*;
    use crate::types::GridGeom;

    /// A sphere-ish blob field over `nodes` nodes: a long capsule along x, so every tile of a
    /// row holds part of the surface.
    fn capsule(nodes: [usize; 3], g: &GridGeom) -> Vec<f32> {
        let mut v = Vec::with_capacity(nodes[0] * nodes[1] * nodes[2]);
        let cy = g.h * (nodes[1] - 1) as f64 / 2.0;
        let cz = g.h * (nodes[2] - 1) as f64 / 2.0;
        let len = g.h * (nodes[0] - 1) as f64;
        for z in 0..nodes[2] {
            for y in 0..nodes[1] {
                for x in 0..nodes[0] {
                    let p = g.node_position([x as u64, y as u64, z as u64]);
                    let px = p[0].clamp(2.0 * cy, len - 2.0 * cy);
                    let d =
                        ((p[0] - px).powi(2) + (p[1] - cy).powi(2) + (p[2] - cz).powi(2)).sqrt();
                    // Wavy radius, so the surface is not a plain cylinder.
                    let r = 0.6 * cy * (1.0 + 0.2 * (p[0] * 1.3).sin());
                    v.push((d - r) as f32);
                }
            }
        }
        v
    }

    /// Extract a row of tiles along x (each `w` cells wide, sharing a face of nodes) and weld.
    fn weld_row(
        v: &[f32],
        nodes: [usize; 3],
        w: usize,
        g: &GridGeom,
    ) -> (Welder, Vec<[f64; 3]>, Vec<[u64; 3]>, usize) {
        let cells = nodes[0] - 1;
        let tiles = cells.div_ceil(w);
        let last_tile = |k: EdgeKey| {
            let (node, axis) = g.decode_edge(k);
            // An x-edge from node x lies in tile x / w; other edges at node x in the tiles
            // whose node range [t·w, (t+1)·w] holds x, the last being x / w (capped).
            let t = node[0] / w as u64;
            if axis == 0 {
                t
            } else {
                t.min(tiles as u64 - 1)
            }
        };
        let mut welder = Welder::new();
        let mut ws = McWorkspace::new();
        let mut mesh = TileMesh::default();
        let mut verts = Vec::new();
        let mut tris = Vec::new();
        let mut total_tile_vertices = 0;
        let emitted = std::cell::Cell::new(0usize);
        for t in 0..tiles {
            let x0 = t * w;
            let x1 = ((t + 1) * w).min(cells);
            let d = [x1 - x0 + 1, nodes[1], nodes[2]];
            let mut sub = Vec::with_capacity(d[0] * d[1] * d[2]);
            for z in 0..d[2] {
                for y in 0..d[1] {
                    let r = (z * nodes[1] + y) * nodes[0];
                    sub.extend_from_slice(&v[r + x0..r + x1 + 1]);
                }
            }
            ws.extract(&sub, d, [x0 as u64, 0, 0], 0.0, g, &mut mesh)
                .unwrap();
            total_tile_vertices += mesh.keys.len();
            welder
                .add_tile(
                    t as u64,
                    &mesh,
                    last_tile,
                    |i, _, p| {
                        assert_eq!(i as usize, verts.len(), "vertices out of order");
                        verts.push(p);
                        emitted.set(verts.len());
                        Ok(())
                    },
                    |tri| {
                        assert!(tri.iter().all(|&i| (i as usize) < emitted.get()));
                        tris.push(tri);
                        Ok(())
                    },
                )
                .unwrap();
        }
        (welder, verts, tris, total_tile_vertices)
    }

    #[test]
    fn row_of_tiles_welds_to_the_whole_mesh_with_a_small_frontier() {
        let nodes = [97, 13, 13];
        let g = GridGeom::new([0.0; 3], 0.25, 96).unwrap();
        let v = capsule(nodes, &g);
        let (welder, verts, tris, tile_vertices) = weld_row(&v, nodes, 8, &g);

        let mut whole = TileMesh::default();
        McWorkspace::new()
            .extract(&v, nodes, [0; 3], 0.0, &g, &mut whole)
            .unwrap();
        assert_eq!(welder.vertices() as usize, whole.keys.len());
        assert_eq!(verts.len(), whole.keys.len());
        // Seam vertices were shared, not duplicated.
        assert!(tile_vertices > verts.len());
        check_closed_oriented(&tris).unwrap();
        // Same triangles: map global indices to keys through positions of the whole mesh.
        let by_pos: HashMap<[u64; 3], u64> = whole
            .keys
            .iter()
            .zip(&whole.positions)
            .map(|(k, p)| (p.map(f64::to_bits), k.0))
            .collect();
        let mut got: Vec<[u64; 3]> = tris
            .iter()
            .map(|t| canonical(t.map(|i| by_pos[&verts[i as usize].map(f64::to_bits)])))
            .collect();
        got.sort_unstable();
        assert_eq!(got, key_triangles(&whole));

        assert_eq!(welder.frontier_len(), 0);
        assert!(welder.peak_frontier() > 0);
        assert!(
            welder.peak_frontier() * 8 < verts.len(),
            "peak frontier {} of {} vertices",
            welder.peak_frontier(),
            verts.len()
        );
    }

    #[test]
    fn out_of_order_tiles_and_bad_last_tile_are_internal_errors() {
        let g = GridGeom::new([0.0; 3], 1.0, 4).unwrap();
        let mut mesh = TileMesh::default();
        let mut v = [1.0f32; 8];
        v[0] = -1.0;
        McWorkspace::new()
            .extract(&v, [2, 2, 2], [0; 3], 0.0, &g, &mut mesh)
            .unwrap();
        let mut w = Welder::new();
        w.add_tile(3, &mesh, |_| 5, |_, _, _| Ok(()), |_| Ok(()))
            .unwrap();
        assert_eq!(w.frontier_len(), 3);
        let e = w.add_tile(3, &mesh, |_| 5, |_, _, _| Ok(()), |_| Ok(()));
        assert!(matches!(e, Err(Error::Internal(_))));

        let mut w = Welder::new();
        let e = w.add_tile(3, &mesh, |_| 2, |_, _, _| Ok(()), |_| Ok(()));
        assert!(matches!(e, Err(Error::Internal(_))));

        let mut bad = mesh.clone();
        bad.triangles.push([0, 1, 9]);
        let mut w = Welder::new();
        let e = w.add_tile(0, &bad, |_| 0, |_, _, _| Ok(()), |_| Ok(()));
        assert!(matches!(e, Err(Error::Internal(_))));
    }

    #[test]
    fn frontier_keys_are_released_even_when_no_later_tile_names_them() {
        let g = GridGeom::new([0.0; 3], 1.0, 4).unwrap();
        let mut mesh = TileMesh::default();
        let mut v = [1.0f32; 8];
        v[7] = -1.0;
        McWorkspace::new()
            .extract(&v, [2, 2, 2], [0; 3], 0.0, &g, &mut mesh)
            .unwrap();
        let mut w = Welder::new();
        let mut n = 0;
        w.add_tile(
            0,
            &mesh,
            |_| 4,
            |_, _, _| {
                n += 1;
                Ok(())
            },
            |_| Ok(()),
        )
        .unwrap();
        assert_eq!((n, w.frontier_len()), (3, 3));
        // Held, not released: their last tile (4) is still to come.
        assert!(w.released().is_empty());
        let mut held: Vec<u64> = w.held().collect();
        held.sort_unstable();
        assert_eq!(held, [0, 1, 2]);
        // Tile 5 is empty but comes after every key's last tile: it releases all three.
        w.add_tile(5, &TileMesh::default(), |_| 5, |_, _, _| Ok(()), |_| Ok(()))
            .unwrap();
        let mut released = w.released().to_vec();
        released.sort_unstable();
        assert_eq!(released, [0, 1, 2]);
        assert_eq!(w.held().count(), 0);
        assert_eq!(w.frontier_len(), 0);
        assert_eq!(w.peak_frontier(), 3);
        assert_eq!(w.vertices(), 3);
    }

    #[test]
    fn callback_errors_propagate() {
        let g = GridGeom::new([0.0; 3], 1.0, 4).unwrap();
        let mut mesh = TileMesh::default();
        let mut v = [1.0f32; 8];
        v[2] = -1.0;
        McWorkspace::new()
            .extract(&v, [2, 2, 2], [0; 3], 0.0, &g, &mut mesh)
            .unwrap();
        let mut w = Welder::new();
        let e = w.add_tile(
            0,
            &mesh,
            |_| 0,
            |_, _, _| Ok(()),
            |_| Err(Error::Usage("disk full".into())),
        );
        assert!(matches!(e, Err(Error::Usage(_))));
    }
}
