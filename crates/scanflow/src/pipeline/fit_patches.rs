//! `scanflow fit --patches`: a closed object (or any surface that is not a disc) fitted as one
//! hierarchical B-spline surface per patch, and the gaps between neighbouring patches'
//! surfaces measured along their shared boundary.
//!
//! # Patches
//!
//! The store's points and normals are laid out by the spectral patch layout
//! ([`crate::spectral::layout`], Pauly & Gross 2001, §3): a binary space partition into
//! clusters, then greedy merging while the merged patch has at most `--patch-points` points
//! and its normals fit in a cone of full aperture `--patch-angle` ([`PATCH_ANGLE`] = 120°; the
//! spectral filters use 90°). A patch whose normals lie within 60° of one axis is a height
//! field over the plane normal to it wherever it is connected, so it maps onto a disc: the
//! condition Greiner & Hormann's parameterisation (§4) needs; each patch is parameterised
//! over the plane normal to its mean normal (not its best-fit plane, which a patch wrapped
//! around a rim folds over). Patches under [`MIN_PATCH_POINTS`] points (slivers the greedy
//! merge leaves between large patches) join
//! the neighbour they share the most nearest-neighbour links with (links between points whose
//! normals agree).
//!
//! # Overlap and gaps
//!
//! Each patch is fitted to its own points and to their [`KNN`] nearest neighbours in other
//! patches whose normals agree ([`SAME_SIDE_COS`]; across a thin part the nearest points lie
//! on the other side, and fitting them would fold the surface): one ring of overlap, so that
//! neighbouring surfaces both approximate the points along their shared boundary. For every point in two patches' overlap, with feet `a` on
//! surface `A` and `b` on surface `B`, the gap is `max(d(a, B), d(b, A))` (each by projection
//! onto the other surface from that point's own foot there). Both surfaces are within the
//! tolerance `T` of the point, so the gap at those points is at most `2T`; between them it
//! follows the surfaces' smoothness. The report lists, per pair of neighbouring patches, the
//! shared points and the largest and RMS gap. The surfaces are separate: they meet within the
//! gap, not exactly (no shared boundary curve, no trimming).
//!
//! # Memory and determinism
//!
//! The points, normals, neighbour lists and layout are admitted up front
//! ([`BYTES_PER_POINT`]); patches are fitted in waves of at most one per thread whose
//! [`fit::bytes_per_point`] admissions fit in the budget together. Each fit's sparse
//! factorisations are checked (symbolically, before any is computed) against an equal share of
//! what the budget had left when the fits began, one share per thread; a patch whose system
//! needs more fails with a message naming it and the bytes. The layout, the overlap and every
//! fit depend only on the store's points, so the file is the same for any thread count (only
//! a patch near its share can fit with fewer threads and fail with more).

use std::collections::BTreeMap;
use std::num::NonZero;
use std::path::Path;
use std::time::Instant;

use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use rayon::prelude::*;

use super::fit::{self, FitJob, FitStats, KNN, Surface, fit_one};
use crate::error::{Error, Result, Setting};
use crate::exec::Ctx;
use crate::spectral::layout::{LayoutParams, layout};
use crate::spline::graph::knn;
use crate::spline::tensor;
use crate::store::Store;
use crate::types::Aabb;

/// Most points in a patch, by default (before its overlap).
pub const PATCH_POINTS: usize = 100_000;

/// The full aperture of a patch's normal cone by default, degrees: normals within 60° of the
/// patch's axis, so slopes up to `tan 60° ≈ 1.7` over its plane.
pub const PATCH_ANGLE: f64 = 120.0;

/// Patches with fewer points join a neighbour.
pub const MIN_PATCH_POINTS: usize = 200;

/// Bytes a point holds for the whole run: position and normal, neighbour list, layout
/// workspace (about 120), patch membership and overlap.
pub const BYTES_PER_POINT: u64 = 24 + 12 + 4 * KNN as u64 + 120 + 16;

/// The size and flatness of the patches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchShape {
    /// Most points in a patch (before its overlap).
    pub points: usize,
    /// Full aperture of a patch's normal cone, degrees (below 180).
    pub angle: f64,
}

/// The gap between two neighbouring patches' surfaces.
#[derive(Clone, Debug, PartialEq)]
pub struct PatchGap {
    /// The two patches (indices of the surfaces), ascending.
    pub patches: [usize; 2],
    /// Points in both patches' overlap, where the gap is measured.
    pub points: usize,
    /// Largest gap.
    pub max_gap: f64,
    /// Root mean square gap.
    pub rms_gap: f64,
}

/// Positions and their unit normals, index for index.
type Oriented = (Vec<[f64; 3]>, Vec<[f32; 3]>);

/// Reads every point and normal of `store`, in cell order.
fn read_store(store: &Store) -> Result<Oriented> {
    let n: u64 = store.manifest.cells.iter().map(|c| c.count).sum();
    let mut pos = Vec::with_capacity(n as usize);
    let mut nor = Vec::with_capacity(n as usize);
    for i in 0..store.manifest.cells.len() {
        let b = store.read_cell(i)?;
        if b.normal.len() != b.pos.len() {
            return Err(Error::input(
                &store.dir,
                format!(
                    "the store has no normals, which the patch layout groups points by: ingest with {} auto or estimate",
                    Setting::Normals
                ),
            ));
        }
        pos.extend_from_slice(&b.pos);
        nor.extend_from_slice(&b.normal);
    }
    Ok((pos, nor))
}

/// The patches' members (ascending indices), patches ordered by their smallest member, after
/// the small ones joined a neighbour.
fn patches(pos: &[[f64; 3]], nor: &[[f32; 3]], nbrs: &[u32], shape: PatchShape) -> Vec<Vec<u32>> {
    let params = LayoutParams {
        patch_max: shape.points,
        max_aperture: shape.angle.to_radians(),
        ..LayoutParams::default()
    };
    let mut members: Vec<Vec<u32>> = layout(pos, nor, &params)
        .into_iter()
        .map(|s| s.members)
        .collect();
    let mut patch_of = vec![0u32; pos.len()];
    for (p, m) in members.iter().enumerate() {
        for &i in m {
            patch_of[i as usize] = p as u32;
        }
    }
    let mut order: Vec<usize> = (0..members.len()).collect();
    order.sort_by_key(|&p| (members[p].len(), p));
    for p in order {
        let size = members[p].len();
        if size == 0 || size >= MIN_PATCH_POINTS {
            continue;
        }
        let mut links: BTreeMap<u32, usize> = BTreeMap::new();
        for &i in &members[p] {
            for &j in &nbrs[i as usize * KNN..(i as usize + 1) * KNN] {
                if j != u32::MAX && patch_of[j as usize] != p as u32 && same_side(nor, i, j) {
                    *links.entry(patch_of[j as usize]).or_default() += 1;
                }
            }
        }
        // Most links; among equals the smallest patch index (the map is ascending).
        let Some((&q, _)) = links.iter().rev().max_by_key(|(_, c)| **c) else {
            continue;
        };
        let moved = std::mem::take(&mut members[p]);
        for &i in &moved {
            patch_of[i as usize] = q;
        }
        let target = &mut members[q as usize];
        target.extend(moved);
        target.sort_unstable();
    }
    members.retain(|m| !m.is_empty());
    members.sort_by_key(|m| m[0]);
    members
}

/// The least cosine between two neighbours' normals for them to count as one sheet of the
/// surface: neighbours across a thin part (the two sides of an ear) face apart and are
/// neither overlap nor links.
pub const SAME_SIDE_COS: f32 = 0.5;

/// Whether points `i` and `j` face the same way ([`SAME_SIDE_COS`]); a point without a
/// normal agrees with any.
fn same_side(nor: &[[f32; 3]], i: u32, j: u32) -> bool {
    let (a, b) = (nor[i as usize], nor[j as usize]);
    let d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let z = |n: [f32; 3]| n == [0.0; 3];
    z(a) || z(b) || d >= SAME_SIDE_COS
}

/// Each patch's points and one ring of their nearest neighbours on the same sheet,
/// ascending.
fn with_overlap(members: &[Vec<u32>], nbrs: &[u32], nor: &[[f32; 3]]) -> Vec<Vec<u32>> {
    members
        .par_iter()
        .map(|m| {
            let mut v = m.clone();
            for &i in m {
                v.extend(
                    nbrs[i as usize * KNN..(i as usize + 1) * KNN]
                        .iter()
                        .filter(|&&j| j != u32::MAX && same_side(nor, i, j)),
                );
            }
            v.sort_unstable();
            v.dedup();
            v
        })
        .collect()
}

/// The direction of the sum of the members' normals (unit), the axis each patch is a height
/// field about; `None` when they cancel.
fn mean_normal(members: &[u32], nor: &[[f32; 3]]) -> Option<[f64; 3]> {
    let mut s = [0.0f64; 3];
    for &i in members {
        for x in 0..3 {
            s[x] += f64::from(nor[i as usize][x]);
        }
    }
    let l = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
    (l > 1e-9 * members.len() as f64).then(|| s.map(|x| x / l))
}

/// Fits every patch, in waves the budget admits together.
fn fit_all(
    pos: &[[f64; 3]],
    ext: &[Vec<u32>],
    facing: &[Option<[f64; 3]>],
    job: &FitJob,
    tolerance: f64,
    dir: &Path,
    ctx: &Ctx,
) -> Result<Vec<Surface>> {
    let stage = ctx.progress.stage("fit", Some(ext.len() as u64), "patches");
    let threads = ctx.pool.current_num_threads().max(1);
    // Each fit of a wave may factor within an equal share of what the budget has left.
    let share =
        ctx.budget.total().saturating_sub(ctx.budget.used()) / threads.min(ext.len()).max(1) as u64;
    let mut out: Vec<Surface> = Vec::with_capacity(ext.len());
    let mut next = 0;
    while next < ext.len() {
        let mut permits = Vec::new();
        let mut end = next;
        while end < ext.len() && end - next < threads {
            let bytes = ext[end].len() as u64 * fit::bytes_per_point(job.method);
            let permit = if end == next {
                // This thread holds the run's other permits, so nothing frees while it waits:
                // the patch fits in what is left now, or the run stops saying so.
                let what = format!(
                    "the fit of patch {end} ({} points; {} bounds a patch)",
                    ext[end].len(),
                    Setting::PatchPoints
                );
                Some(ctx.budget.acquire_now(bytes, &what)?)
            } else {
                ctx.budget.try_acquire(bytes)
            };
            match permit {
                Some(p) => permits.push(p),
                None => break,
            }
            end += 1;
        }
        let wave: Vec<Result<Surface>> = ctx.pool.install(|| {
            (next..end)
                .into_par_iter()
                .map(|k| {
                    let pts: Vec<[f64; 3]> = ext[k].iter().map(|&i| pos[i as usize]).collect();
                    let factor =
                        share.saturating_sub(pts.len() as u64 * fit::bytes_per_point(job.method));
                    fit_one(&pts, &[], facing[k], job, tolerance, factor, dir)
                        .map_err(|e| in_patch(e, k, &pts))
                })
                .collect()
        });
        drop(permits);
        for s in wave {
            out.push(s?);
            stage.inc(1);
        }
        next = end;
    }
    stage.finish(None);
    Ok(out)
}

/// An error of patch `k`'s fit, saying which patch and where.
fn in_patch(e: Error, k: usize, pts: &[[f64; 3]]) -> Error {
    let mut b = Aabb::EMPTY;
    for &p in pts {
        b.add(p);
    }
    let at = format!(
        "patch {k} ({} points in [{:.6}, {:.6}, {:.6}]..[{:.6}, {:.6}, {:.6}])",
        pts.len(),
        b.min[0],
        b.min[1],
        b.min[2],
        b.max[0],
        b.max[1],
        b.max[2]
    );
    match e {
        Error::Input { path, msg } => Error::Input {
            path,
            msg: format!("{at}: {msg}"),
        },
        e => e,
    }
}

/// Every point's places: `(point, patch, index in the patch)` sorted by point, so that a point
/// in several patches' overlap appears in a run.
fn places(ext: &[Vec<u32>]) -> Vec<(u32, u32, u32)> {
    let mut at: Vec<(u32, u32, u32)> = ext
        .iter()
        .enumerate()
        .flat_map(|(p, v)| {
            v.iter()
                .enumerate()
                .map(move |(l, &i)| (i, p as u32, l as u32))
        })
        .collect();
    at.par_sort_unstable();
    at
}

/// Samples per knot span along each axis of a surface, for [`deviation`]'s starting points,
/// and the most samples per axis.
const SAMPLES_PER_SPAN: usize = 4;
const SAMPLES_MAX: usize = 256;

/// Nearest samples [`deviation`] looks at per point.
const SAMPLES_NEAR: usize = 8;

/// The largest and the RMS deviation over the points, each point measured to the nearest
/// surface of the model: the least of its distances to the surfaces fitted to it (its own
/// patch's, and its neighbours' where it is in their overlap) and of its projections onto the
/// surfaces of its [`SAMPLES_NEAR`] nearest surface samples (a grid of [`SAMPLES_PER_SPAN`]
/// per knot span), which catches a neighbour's surface reaching past its overlap. This is what
/// an independent check that projects every point onto every surface measures.
fn deviation(pos: &[[f64; 3]], at: &[(u32, u32, u32)], surfaces: &[Surface]) -> [f64; 2] {
    let mut samples: Vec<[f64; 3]> = Vec::new();
    let mut whose: Vec<(u32, [f64; 2])> = Vec::new();
    for (k, s) in surfaces.iter().enumerate() {
        let t = &s.fit.surface;
        let dom = t.domain();
        let n = [0, 1].map(|d| {
            let spans = t.knots[d].windows(2).filter(|w| w[1] > w[0]).count();
            (spans * SAMPLES_PER_SPAN).clamp(2, SAMPLES_MAX)
        });
        for j in 0..=n[1] {
            let v = dom[1][0] + (dom[1][1] - dom[1][0]) * j as f64 / n[1] as f64;
            for i in 0..=n[0] {
                let u = dom[0][0] + (dom[0][1] - dom[0][0]) * i as f64 / n[0] as f64;
                samples.push(tensor::eval(t, [u, v])[0]);
                whose.push((k as u32, [u, v]));
            }
        }
    }
    let tree: ImmutableKdTree<f64, u32, 3, 32> = ImmutableKdTree::new_from_slice(&samples);
    let want =
        NonZero::new(SAMPLES_NEAR.min(samples.len()).max(1)).unwrap_or(NonZero::<usize>::MIN);
    let runs: Vec<&[(u32, u32, u32)]> = at.chunk_by(|a, b| a.0 == b.0).collect();
    let d: Vec<f64> = runs
        .par_iter()
        .map(|run| {
            let p = pos[run[0].0 as usize];
            let mut d = run
                .iter()
                .map(|&(_, s, l)| surfaces[s as usize].fit.distance[l as usize])
                .fold(f64::INFINITY, f64::min);
            let mut near = tree.nearest_n::<SquaredEuclidean>(&p, want);
            near.sort_by(|a, b| a.distance.total_cmp(&b.distance).then(a.item.cmp(&b.item)));
            let mut seen: Vec<u32> = run.iter().map(|r| r.1).collect();
            for nb in near {
                let (k, uv) = whose[nb.item as usize];
                if !seen.contains(&k) {
                    seen.push(k);
                    d = d.min(tensor::project(&surfaces[k as usize].fit.surface, p, uv).1);
                }
            }
            d
        })
        .collect();
    let max = d.iter().fold(0.0, |a: f64, &b| a.max(b));
    let sq: f64 = d.iter().map(|x| x * x).sum();
    [max, (sq / d.len().max(1) as f64).sqrt()]
}

/// The gaps between the surfaces of patches that share overlap points.
fn gaps(at: &[(u32, u32, u32)], surfaces: &[Surface]) -> Vec<PatchGap> {
    let mut shared: Vec<[(u32, u32); 2]> = Vec::new();
    for run in at.chunk_by(|a, b| a.0 == b.0) {
        for (x, a) in run.iter().enumerate() {
            for b in &run[x + 1..] {
                shared.push([(a.1, a.2), (b.1, b.2)]);
            }
        }
    }
    let gap: Vec<f64> = shared
        .par_iter()
        .map(|&[(pa, la), (pb, lb)]| {
            let (sa, sb) = (&surfaces[pa as usize].fit, &surfaces[pb as usize].fit);
            let (fa, fb) = (sa.foot[la as usize], sb.foot[lb as usize]);
            let a = tensor::eval(&sa.surface, fa)[0];
            let b = tensor::eval(&sb.surface, fb)[0];
            let dab = tensor::project(&sb.surface, a, fb).1;
            let dba = tensor::project(&sa.surface, b, fa).1;
            dab.max(dba)
        })
        .collect();
    let mut pairs: BTreeMap<[usize; 2], (usize, f64, f64)> = BTreeMap::new();
    for (s, g) in shared.iter().zip(gap) {
        let e = pairs
            .entry([s[0].0 as usize, s[1].0 as usize])
            .or_insert((0, 0.0, 0.0));
        e.0 += 1;
        e.1 = e.1.max(g);
        e.2 += g * g;
    }
    pairs
        .into_iter()
        .map(|(patches, (points, max_gap, sq))| PatchGap {
            patches,
            points,
            max_gap,
            rms_gap: (sq / points as f64).sqrt(),
        })
        .collect()
}

/// Fits the store's points patch by patch; writes nothing (the caller writes the outputs).
pub fn fit_patches(store: &Store, job: &FitJob, shape: PatchShape, ctx: &Ctx) -> Result<FitStats> {
    let t0 = Instant::now();
    let mut b = Aabb::EMPTY;
    let mut n = 0u64;
    for c in &store.manifest.cells {
        b = b.union(&c.bounds);
        n += c.count;
    }
    if n <= KNN as u64 {
        return Err(Error::input(
            &store.dir,
            format!(
                "{n} points: fitting patches needs more than {KNN} (each point's {KNN} nearest neighbours)"
            ),
        ));
    }
    let _points = ctx.budget.acquire(
        n * BYTES_PER_POINT,
        "the points, normals and layout of the patches",
    )?;
    let stage = ctx.progress.stage("read", None, "points");
    let (pos, nor) = read_store(store)?;
    stage.finish(None);
    let secs_read = t0.elapsed().as_secs_f64();
    let diag = b.diagonal();
    let tolerance = job.tolerance.resolve(diag);
    let stage = ctx.progress.stage("layout", None, "patches");
    let (members, nbrs) = ctx.pool.install(|| {
        let nbrs = knn(&pos, KNN);
        (patches(&pos, &nor, &nbrs, shape), nbrs)
    });
    let ext = ctx.pool.install(|| with_overlap(&members, &nbrs, &nor));
    let facing: Vec<Option<[f64; 3]>> = members.iter().map(|m| mean_normal(m, &nor)).collect();
    drop(nor);
    drop(nbrs);
    stage.finish(None);
    log::info!(
        "{} patches of {} points ({} with their overlap)",
        members.len(),
        n,
        ext.iter().map(Vec::len).sum::<usize>()
    );
    let surfaces = fit_all(&pos, &ext, &facing, job, tolerance, &store.dir, ctx)?;
    let at = ctx.pool.install(|| places(&ext));
    let gaps = ctx.pool.install(|| gaps(&at, &surfaces));
    let point_deviation = Some(ctx.pool.install(|| deviation(&pos, &at, &surfaces)));
    let seam_gap = gaps
        .iter()
        .map(|g| g.max_gap)
        .fold(None, |a: Option<f64>, g| Some(a.map_or(g, |a| a.max(g))));
    Ok(FitStats {
        surfaces,
        input_points: n as usize,
        diagonal: diag,
        tolerance,
        secs_read,
        secs: t0.elapsed().as_secs_f64(),
        seam_gap,
        gaps,
        point_deviation,
    })
}
