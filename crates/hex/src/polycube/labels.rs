//! The boundary labels of the module docs of [`super`] ("Labels"): each boundary triangle's
//! signed axis, the deviation of the deformed normals from their axes, and the clean-up of
//! the labels (small charts, teeth, triangles pinched between two planes, and the tongues of
//! borders that turn from convex to concave).

use nalgebra::Vector3;

use crate::mesh::{FACE_OPPOSITE, TetMesh};
use crate::topology::Topology;

/// The signed axis (0..6: +x −x +y −y +z −z) nearest the unit vector `n`, and the axis.
pub(super) fn label(n: &Vector3<f64>) -> (usize, Vector3<f64>) {
    let k = (0..3)
        .max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
        .expect("three axes");
    let l = 2 * k + usize::from(n[k] < 0.0);
    (l, axis(l as u8))
}

/// The unit vector of signed axis `l` (0..6: +x −x +y −y +z −z).
pub(super) fn axis(l: u8) -> Vector3<f64> {
    let mut a = Vector3::zeros();
    a[usize::from(l / 2)] = if l.is_multiple_of(2) { 1.0 } else { -1.0 };
    a
}

/// Outward normal and area of boundary face `k` at positions `y`.
pub(super) fn boundary_face(
    mesh: &TetMesh,
    topo: &Topology,
    y: &[[f64; 3]],
    k: usize,
) -> (Vector3<f64>, f64) {
    let (t, i) = topo.boundary[k];
    let f = FACE_OPPOSITE[i as usize].map(|j| Vector3::from(y[mesh.tets[t as usize][j] as usize]));
    let n = (f[1] - f[0]).cross(&(f[2] - f[0]));
    let a = n.norm();
    (if a > 0.0 { n / a } else { n }, a / 2.0)
}

/// Area-weighted mean deviation (degrees) of the boundary normals at `y` from their axes, the
/// fraction of area within 5° (the axes of `fixed` labels where given, else the nearest).
pub(super) fn deviation(
    mesh: &TetMesh,
    topo: &Topology,
    y: &[[f64; 3]],
    fixed: Option<&[u8]>,
) -> (f64, f64) {
    let (mut sum, mut within, mut area) = (0.0, 0.0, 0.0);
    for k in 0..topo.boundary.len() {
        let (n, a) = boundary_face(mesh, topo, y, k);
        let axis = match fixed {
            Some(f) => axis(f[k]),
            None => label(&n).1,
        };
        let angle = n.dot(&axis).clamp(-1.0, 1.0).acos().to_degrees();
        sum += a * angle;
        area += a;
        if angle <= 5.0 {
            within += a;
        }
    }
    let area = area.max(f64::MIN_POSITIVE);
    (sum / area, within / area)
}

/// Passes of the label clean-up before it gives up (each pass only relabels).
pub(super) const CLEANUP_PASSES: usize = 50;

/// Triangles a chart needs to stay a chart of its own.
pub(super) const MIN_CHART: usize = 3;

/// An edge two triangles share, and the two triangles.
pub(super) type SharedEdge = ([u32; 2], u32, u32);

/// The triangles across each triangle's edges, and the edges two triangles share (the edge,
/// the two triangles); an edge of one triangle only (an open patch) has no neighbour.
pub(super) fn triangle_graph(tris: &[[u32; 3]]) -> (Vec<Vec<u32>>, Vec<SharedEdge>) {
    let mut edges: Vec<([u32; 2], u32)> = Vec::with_capacity(3 * tris.len());
    for (k, t) in tris.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            edges.push(([a.min(b), a.max(b)], k as u32));
        }
    }
    edges.sort_unstable();
    let mut adj: Vec<Vec<u32>> = vec![Vec::new(); tris.len()];
    let mut shared = Vec::with_capacity(edges.len() / 2);
    let mut i = 0;
    while i < edges.len() {
        match edges.get(i + 1) {
            Some(&(e, b)) if e == edges[i].0 => {
                let a = edges[i].1;
                adj[a as usize].push(b);
                adj[b as usize].push(a);
                shared.push((e, a, b));
                i += 2;
            }
            _ => i += 1,
        }
    }
    (adj, shared)
}

/// The boundary faces' labels (`2 axis + [negative]`) from the deformed normals, cleaned up
/// (module docs): charts of fewer than [`MIN_CHART`] triangles take the label they share
/// the most edges with, and a triangle whose three vertices all lie on charts of another axis
/// (it would be flattened onto a line between two planes) takes that chart's label.
pub(super) fn clean_labels(mesh: &TetMesh, topo: &Topology, y: &[[f64; 3]]) -> Vec<u8> {
    let nf = topo.boundary.len();
    let tris = topo.boundary_triangles(mesh);
    let mut lab: Vec<u8> = (0..nf)
        .map(|k| label(&boundary_face(mesh, topo, y, k).0).0 as u8)
        .collect();
    let (adj, shared) = triangle_graph(&tris);
    let mut relabelled = vec![false; nf];
    clean_up(&tris, &adj, &mut lab, &mut relabelled, mesh.verts.len());
    for _ in 0..4 {
        let mut turned = false;
        for _ in 0..TURN_PASSES {
            if !remove_turns(&tris, &adj, &shared, &mut lab, y) {
                break;
            }
            turned = true;
        }
        if !turned {
            break;
        }
        clean_up(&tris, &adj, &mut lab, &mut relabelled, mesh.verts.len());
    }
    lab
}

/// Passes that remove turning borders before the labels are taken as they are.
pub(super) const TURN_PASSES: usize = 24;

/// The charts (connected runs of one label across edges) of the labelled triangles.
pub(super) fn charts(adj: &[Vec<u32>], lab: &[u8]) -> Vec<u32> {
    let mut chart = vec![u32::MAX; lab.len()];
    let mut stack = Vec::new();
    for s in 0..lab.len() {
        if chart[s] != u32::MAX {
            continue;
        }
        chart[s] = s as u32;
        stack.push(s as u32);
        while let Some(f) = stack.pop() {
            for &g in &adj[f as usize] {
                if chart[g as usize] == u32::MAX && lab[g as usize] == lab[s] {
                    chart[g as usize] = s as u32;
                    stack.push(g);
                }
            }
        }
    }
    chart
}

/// A border between two charts that is convex along part of its length and concave along
/// the rest turns. Where one chart runs as a tongue between two levels of the other (a step
/// in a plane that fades out), no polycube has it: the parameterisation squeezes the tongue
/// flat and its tetrahedra invert. The tongue is the chart whose two border runs with the
/// other lie apart along the other's axis `a`; its triangles next to the shorter (minority)
/// run, and those reached from them within the tongue (between the runs' levels along `a`,
/// widened by half their distance, and within the minority run's extent along the border's
/// own axis), take the other chart's
/// label at once, when they are at most half their chart. Returns whether a label changed.
pub(super) fn remove_turns(
    tris: &[[u32; 3]],
    adj: &[Vec<u32>],
    shared: &[SharedEdge],
    lab: &mut [u8],
    y: &[[f64; 3]],
) -> bool {
    let chart = charts(adj, lab);
    let p = |v: u32| Vector3::from(y[v as usize]);
    let centre = |k: u32| tris[k as usize].iter().map(|&v| p(v)).sum::<Vector3<f64>>() / 3.0;
    // Per border (chart pair, lower id first), per kind (0 convex, 1 concave): the edges, as
    // (triangle on the lower chart, triangle on the higher, midpoint).
    type Run = Vec<(u32, u32, Vector3<f64>, [u32; 2])>;
    let mut borders: std::collections::BTreeMap<(u32, u32), [Run; 2]> =
        std::collections::BTreeMap::new();
    for &(e, f, g) in shared {
        let (f, g) = if chart[f as usize] <= chart[g as usize] {
            (f, g)
        } else {
            (g, f)
        };
        if chart[f as usize] == chart[g as usize] || lab[f as usize] / 2 == lab[g as usize] / 2 {
            continue;
        }
        // Convex where each side lies behind the other's plane (the planes of the labels,
        // not of the triangles).
        let mid = (p(e[0]) + p(e[1])) / 2.0;
        let kind = usize::from(
            (centre(g) - mid).dot(&axis(lab[f as usize]))
                + (centre(f) - mid).dot(&axis(lab[g as usize]))
                >= 0.0,
        );
        borders
            .entry((chart[f as usize], chart[g as usize]))
            .or_default()[kind]
            .push((f, g, mid, e));
    }
    let mut size = vec![0usize; lab.len()];
    for &c in &chart {
        size[c as usize] += 1;
    }
    // Charts relabelled in this pass: their borders are stale until the next pass
    // recomputes the charts.
    let mut touched = std::collections::BTreeSet::new();
    for (&(c0, c1), runs) in &borders {
        if runs[0].is_empty()
            || runs[1].is_empty()
            || touched.contains(&c0)
            || touched.contains(&c1)
        {
            continue;
        }
        let minority = usize::from(runs[1].len() < runs[0].len());
        // How far the minority run lies from the majority run next to it, per axis: each
        // minority edge against its nearest majority edge (a long run's mean would mix in
        // levels far away).
        let near: Vec<Vector3<f64>> = runs[minority]
            .iter()
            .map(|x| {
                runs[1 - minority]
                    .iter()
                    .map(|m| m.2)
                    .min_by(|p, q| {
                        (p - x.2)
                            .norm_squared()
                            .total_cmp(&(q - x.2).norm_squared())
                    })
                    .expect("a border run is not empty")
            })
            .collect();
        let mean = |v: &mut dyn Iterator<Item = Vector3<f64>>| {
            let (sum, n) = v.fold((Vector3::zeros(), 0usize), |(s, n), p| (s + p, n + 1));
            sum / n.max(1) as f64
        };
        let level_min = mean(&mut runs[minority].iter().map(|x| x.2));
        let level_maj = mean(&mut near.iter().copied());
        let apart = mean(
            &mut runs[minority]
                .iter()
                .zip(&near)
                .map(|(x, m)| (x.2 - m).abs()),
        );
        let (f0, g0, _, _) = runs[minority][0];
        let (af, ag) = (
            usize::from(lab[f0 as usize] / 2),
            usize::from(lab[g0 as usize] / 2),
        );
        // The tongue is the chart whose runs lie apart along the other chart's axis.
        let (tongue_side, a) = if apart[af] >= apart[ag] {
            (1, af)
        } else {
            (0, ag)
        };
        let other_side =
            |x: &(u32, u32, Vector3<f64>, [u32; 2])| if tongue_side == 1 { x.0 } else { x.1 };
        let along = 3 - af - ag;
        let margin = apart[a] / 2.0;
        let (lo_a, hi_a) = (
            level_min[a].min(level_maj[a]) - margin,
            level_min[a].max(level_maj[a]) + margin,
        );
        let (lo_e, hi_e) = runs[minority]
            .iter()
            .flat_map(|x| x.3)
            .fold((f64::MAX, f64::MIN), |(lo, hi), v| {
                (lo.min(p(v)[along]), hi.max(p(v)[along]))
            });
        let tongue_of =
            |x: &(u32, u32, Vector3<f64>, [u32; 2])| if tongue_side == 1 { x.1 } else { x.0 };
        let tongue_chart = chart[tongue_of(&runs[minority][0]) as usize];
        let label = lab[other_side(&runs[minority][0]) as usize];
        let inside = |k: u32| {
            let c = centre(k);
            chart[k as usize] == tongue_chart
                && (lo_a..=hi_a).contains(&c[a])
                && (lo_e..=hi_e).contains(&c[along])
        };
        let mut seen = std::collections::BTreeSet::new();
        let mut stack: Vec<u32> = runs[minority]
            .iter()
            .map(tongue_of)
            .filter(|&k| inside(k))
            .collect();
        while let Some(k) = stack.pop() {
            if !seen.insert(k) {
                continue;
            }
            stack.extend(
                adj[k as usize]
                    .iter()
                    .copied()
                    .filter(|&g| !seen.contains(&g) && inside(g)),
            );
        }
        if seen.is_empty() || 2 * seen.len() > size[tongue_chart as usize] {
            continue;
        }
        for k in seen {
            lab[k as usize] = label;
        }
        touched.extend([c0, c1]);
    }
    !touched.is_empty()
}

/// The label clean-up passes of [`clean_labels`] (module docs): small charts, teeth and
/// triangles pinched between two planes.
pub(super) fn clean_up(
    tris: &[[u32; 3]],
    adj: &[Vec<u32>],
    lab: &mut [u8],
    relabelled: &mut [bool],
    nv: usize,
) {
    let nf = lab.len();
    for _ in 0..CLEANUP_PASSES {
        let mut changed = false;
        // Small charts (relabelled in order of their first triangle, each seeing the labels
        // the charts before it were given).
        let chart = charts(adj, lab);
        let mut size = vec![0usize; nf];
        for &c in &chart {
            size[c as usize] += 1;
        }
        let mut small: Vec<Vec<u32>> = vec![Vec::new(); nf];
        for (k, &c) in chart.iter().enumerate() {
            if size[c as usize] < MIN_CHART {
                small[c as usize].push(k as u32);
            }
        }
        for (s, members) in small.iter().enumerate() {
            if members.is_empty() {
                continue;
            }
            let mut border = [0usize; 6];
            for &f in members {
                for &g in &adj[f as usize] {
                    if lab[g as usize] != lab[s] {
                        border[lab[g as usize] as usize] += 1;
                    }
                }
            }
            let best = (0..6).max_by_key(|&l| (border[l], std::cmp::Reverse(l)));
            if let Some(best) = best.filter(|&l| border[l] > 0) {
                for &f in members {
                    lab[f as usize] = best as u8;
                }
                changed = true;
            }
        }
        // Teeth: a triangle two of whose neighbours share another label takes it.
        for k in 0..nf {
            let n = &adj[k];
            for (i, &a) in n.iter().enumerate() {
                let l = lab[a as usize];
                if l != lab[k] && n[i + 1..].iter().any(|&b| lab[b as usize] == l) {
                    lab[k] = l;
                    changed = true;
                    break;
                }
            }
        }
        // Triangles on a line between two planes.
        let mut on = vec![0u8; nv];
        for (k, t) in tris.iter().enumerate() {
            for &v in t {
                on[v as usize] |= 1 << lab[k];
            }
        }
        for (k, t) in tris.iter().enumerate() {
            let common = t.iter().fold(0x3f, |m, &v| m & on[v as usize]);
            let axis = lab[k] / 2;
            if let Some(other) = (0..6u8).find(|&l| l / 2 != axis && common & (1 << l) != 0)
                && adj[k].iter().any(|&g| lab[g as usize] == other)
                && !relabelled[k]
            {
                lab[k] = other;
                relabelled[k] = true;
                for &v in t {
                    on[v as usize] |= 1 << other;
                }
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
}
