//! A leaf made ready for the device on its worker: its divergence, and its screening
//! operator as the device reads it (per aggregate its 8 nodes, 8 weights and γ), with the
//! transposed lists the scatter `Sᵀ` walks (per touched node, its entries in aggregate order).

use crate::screen::Screen;

/// One leaf, ready for the device: its divergence and its screening operator with the
/// transposed lists.
pub(super) struct Prepared {
    pub(super) div: Vec<f32>,
    /// Per aggregate, its 8 nodes.
    pub(super) nodes: Vec<[u32; 8]>,
    /// Per aggregate, its 8 weights and its γ.
    pub(super) weights: Vec<[f32; 9]>,
    /// Touched nodes, ascending.
    pub(super) t_node: Vec<u32>,
    /// Start of each touched node's entries (one more than nodes).
    pub(super) t_start: Vec<u32>,
    /// Entries `8a + c`, in aggregate order per node.
    pub(super) t_ent: Vec<u32>,
}

impl Prepared {
    pub(super) fn new(div: Vec<f32>, screen: &Screen) -> Prepared {
        let nodes = screen.nodes().to_vec();
        let weights: Vec<[f32; 9]> = screen
            .weights()
            .iter()
            .zip(screen.gamma())
            .map(|(w, &g)| {
                let mut o = [0f32; 9];
                o[..8].copy_from_slice(w);
                o[8] = g as f32;
                o
            })
            .collect();
        let mut ent: Vec<(u32, u32)> = Vec::with_capacity(nodes.len() * 8);
        for (a, ns) in nodes.iter().enumerate() {
            for (c, &j) in ns.iter().enumerate() {
                ent.push((j, (a * 8 + c) as u32));
            }
        }
        ent.sort_unstable();
        let (mut t_node, mut t_start, mut t_ent) = (Vec::new(), Vec::new(), Vec::new());
        for (j, e) in ent {
            if t_node.last() != Some(&j) {
                t_node.push(j);
                t_start.push(t_ent.len() as u32);
            }
            t_ent.push(e);
        }
        t_start.push(t_ent.len() as u32);
        Prepared {
            div,
            nodes,
            weights,
            t_node,
            t_start,
            t_ent,
        }
    }
}
