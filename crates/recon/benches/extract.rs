//! Marching cubes per tile: CPU (one core, all cores) against the GPU path, in cells per
//! second, the GPU time split into upload, kernels, download and host work, with ratios.
//!
//! ```text
//! cargo bench --bench extract                          # tiles of 256³ and 512³ cells
//! SIZES="32 64" REPS=2 cargo bench --bench extract     # small, e.g. on lavapipe
//! GPU=auto cargo bench --bench extract                 # only a real GPU (default: on, any)
//! ```
//!
//! Fairness: the same field and iso-value for all. "CPU 1" is `McWorkspace::extract` on the
//! whole tile, the reference; the GPU mesh is checked identical to it (keys, positions bit for
//! bit, triangles) before any time is taken. "CPU N" runs N slabs of the tile at once on all
//! cores (rayon), one workspace each, without joining their meshes: an upper bound of what the
//! CPU path gives with all cores, so it favours the CPU. GPU "e2e" is what
//! `GpuExtractor::extract` costs the caller (upload, kernels, download, host renumbering and
//! positions); "kernel" is the compute passes alone (with a 16-byte totals read-back). Each time
//! is the best of REPS runs after one warm-up.
//!
//! A second table does the same for *blended* tiles, the reconstruction's case
//! (`extract::field`): a coarse grid (every 4 voxels) plus detail grids of 32-voxel leaves near
//! a bumpy sphere. "CPU" blends the field and extracts (as `reconstruct --gpu off` does per
//! tile), on one core and in slabs on all cores; the GPU builds the field on the device from
//! the leaf grids ("cold": every leaf sent; "warm": leaves already resident, as for a tile
//! whose neighbours sent them) and extracts. "MB up" is what crossed the bus, against "dense
//! MB", the tile's node values.

use std::time::Instant;

use rayon::prelude::*;
use scanflow_core::types::{Axis, Blend, Detail, GridGeom, Leaf, TileMesh};
use scanflow_recon::extract::field::BlendEval;
use scanflow_recon::extract::{GpuExtractor, GpuMode, GpuStats, McWorkspace};
use scanflow_recon::pou::{quantise, quantise_detail, unit_for};

/// A tile of `n + 1` nodes per axis: a sphere of radius `0.4·n` (few active cells) or a
/// gyroid of period 16 cells (many).
fn field(kind: &str, n: usize) -> Vec<f32> {
    let m = n + 1;
    let mut v = vec![0.0f32; m * m * m];
    let c = n as f32 / 2.0;
    let w = std::f32::consts::TAU / 16.0;
    v.par_chunks_mut(m * m).enumerate().for_each(|(z, layer)| {
        for y in 0..m {
            for x in 0..m {
                let p = [x as f32, y as f32, z as f32];
                layer[y * m + x] = match kind {
                    "sphere" => {
                        let d = p.map(|q| q - c);
                        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - 0.4 * n as f32
                    }
                    _ => {
                        let [a, b, q] = p.map(|q| q * w);
                        a.sin() * b.cos() + b.sin() * q.cos() + q.sin() * a.cos()
                    }
                };
            }
        }
    });
    v
}

/// Leaf edge, overlap and coarse spacing of the blended tiles (depth-10 defaults).
const E: i64 = 32;
const OV: i64 = 8;
const R: i64 = 4;

/// The bumpy sphere of the blended tiles, in voxels: `|p − c| − 0.4·n` plus bumps of 1.5
/// voxels, period 12.
fn bumpy(n: usize, p: [f64; 3]) -> f64 {
    let c = n as f64 / 2.0;
    let d = p.map(|v| v - c);
    let k = std::f64::consts::TAU / 12.0;
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - 0.4 * n as f64
        + 1.5 * (k * p[0]).sin() * (k * p[1]).sin() * (k * p[2]).sin()
}

/// Storage of a blended tile of `n` cells per axis at node 0.
struct BlendData {
    coarse: Vec<i32>,
    cn: usize,
    unit: f32,
    own: Vec<i32>,
    leaves: Vec<([i64; 3], Detail)>,
}

impl BlendData {
    fn new(n: usize) -> BlendData {
        let cn = n / R as usize + 2;
        let smooth = |p: [f64; 3]| {
            let d = p.map(|v| v - n as f64 / 2.0);
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - 0.4 * n as f64
        };
        let mut coarse = Vec::with_capacity(cn * cn * cn);
        for z in 0..cn {
            for y in 0..cn {
                for x in 0..cn {
                    coarse.push(smooth([x, y, z].map(|v| (v as i64 * R) as f64)) as f32);
                }
            }
        }
        let unit = unit_for(coarse.iter().fold(0f64, |m, v| m.max(v.abs() as f64)));
        let trilinear = |g: [i64; 3]| {
            let mut acc = 0.0;
            for k in 0..8 {
                let mut w = 1.0;
                let mut i = [0usize; 3];
                for a in 0..3 {
                    let d = (k >> a) & 1;
                    let f = (g[a] % R) as f64 / R as f64;
                    w *= if d == 1 { f } else { 1.0 - f };
                    i[a] = (g[a] / R) as usize + d;
                }
                acc += w * coarse[(i[2] * cn + i[1]) * cn + i[0]] as f64;
            }
            acc
        };
        let dm = (E + 2 * OV + 1) as usize;
        let cells: Vec<[i64; 3]> = (0..(n as i64 / E).pow(3))
            .map(|i| {
                let s = n as i64 / E;
                [i % s, (i / s) % s, i / (s * s)]
            })
            .filter(|c| smooth(c.map(|v| ((v as f64) + 0.5) * E as f64)).abs() < E as f64)
            .collect();
        let leaves = cells
            .into_par_iter()
            .map(|c| {
                let mut d = Vec::with_capacity(dm * dm * dm);
                for s in 0..dm * dm * dm {
                    let o = [s % dm, (s / dm) % dm, s / (dm * dm)];
                    let g = [0, 1, 2].map(|a| (E * c[a] - OV + o[a] as i64).clamp(0, n as i64));
                    d.push((bumpy(n, g.map(|v| v as f64)) - trilinear(g)) as f32);
                }
                (c, quantise_detail(&d, unit))
            })
            .collect();
        let own = scanflow_recon::pou::leaf_weights(E, OV);
        BlendData {
            coarse: quantise(&coarse, unit),
            cn,
            unit,
            own,
            leaves,
        }
    }

    /// The blend of nodes `z0..=z1` (all x and y) of the tile.
    fn blend(&self, n: usize, z0: usize, z1: usize) -> Blend<'_> {
        let axis = |from: usize, to: usize| {
            let mut a = Axis::default();
            for g in from as i64..=to as i64 {
                a.c0.push((g / R) as u32);
                a.w0.push((R - g % R) as i32);
                a.w1.push((g % R) as i32);
            }
            a
        };
        Blend {
            lo: [0, 0, z0 as i64],
            dims: [n + 1, n + 1, z1 - z0 + 1],
            axes: [axis(0, n), axis(0, n), axis(z0, z1)],
            coarse: self.coarse.clone(),
            coarse_dims: [self.cn; 3],
            coarse_bits: R.trailing_zeros(),
            e: E,
            ov: OV,
            own: self.own.clone(),
            unit: self.unit,
            leaves: self
                .leaves
                .iter()
                .enumerate()
                .map(|(i, (c, d))| Leaf {
                    cell: *c,
                    id: i as u64,
                    detail: &d.values,
                    shift: d.shift,
                })
                .collect(),
        }
    }
}

/// Same keys, triangles and positions bit for bit.
fn same_mesh(a: &TileMesh, b: &TileMesh) -> bool {
    a.keys == b.keys
        && a.triangles == b.triangles
        && a.positions.len() == b.positions.len()
        && a.positions
            .iter()
            .zip(&b.positions)
            .all(|(p, q)| p.map(f64::to_bits) == q.map(f64::to_bits))
}

fn best<T>(reps: usize, mut f: impl FnMut() -> (f64, T)) -> (f64, T) {
    let mut out = f();
    for _ in 1..reps {
        let r = f();
        if r.0 < out.0 {
            out = r;
        }
    }
    out
}

fn main() {
    let sizes: Vec<usize> = std::env::var("SIZES")
        .unwrap_or_else(|_| "256 512".into())
        .split_whitespace()
        .map(|s| s.parse().expect("SIZES: cells per axis, e.g. \"256 512\""))
        .collect();
    let reps: usize = std::env::var("REPS").map_or(3, |s| s.parse().expect("REPS: a count"));
    let mode: GpuMode = std::env::var("GPU")
        .unwrap_or_else(|_| "on".into())
        .parse()
        .expect("GPU: auto, on or off");
    let threads = rayon::current_num_threads();
    let mut gpu = match GpuExtractor::new(mode) {
        Ok(Some(g)) => Some(g),
        Ok(None) => None,
        Err(e) => {
            println!("no GPU: {e}");
            None
        }
    };
    match &gpu {
        Some(g) => println!(
            "GPU: {} (buffers up to {} MiB); CPU: {threads} threads",
            g.adapter_name(),
            g.max_buffer_bytes() >> 20
        ),
        None => println!("GPU: none, CPU only; CPU: {threads} threads"),
    }
    println!(
        "{:>5} {:>7} {:>6} | {:>8} {:>8} | {:>8} {:>8} {:>8} {:>8} {:>8} | {:>9} {:>9} {:>9} | {:>7} {:>7}",
        "cells",
        "field",
        "act%",
        "cpu1 s",
        "cpuN s",
        "up s",
        "kern s",
        "down s",
        "host s",
        "e2e s",
        "cpuN c/s",
        "kern c/s",
        "e2e c/s",
        "kern/N",
        "e2e/N"
    );
    for &n in &sizes {
        let m = n + 1;
        let geom = GridGeom::new([0.0; 3], 1.0 / n as f64, n as u64).expect("a valid grid");
        for kind in ["sphere", "gyroid"] {
            let v = field(kind, n);
            let cells = (n * n * n) as f64;
            let mut ws = McWorkspace::new();
            let mut want = TileMesh::default();
            let (cpu1, active) = best(reps, || {
                let t = Instant::now();
                let s = ws
                    .extract(&v, [m; 3], [0; 3], 0.0, &geom, &mut want)
                    .expect("valid tile");
                (t.elapsed().as_secs_f64(), s.active_cells)
            });
            let slabs = threads.min(n);
            let (cpun, _) = best(reps, || {
                let t = Instant::now();
                (0..slabs).into_par_iter().for_each(|i| {
                    let (z0, z1) = (i * n / slabs, (i + 1) * n / slabs);
                    let mut out = TileMesh::default();
                    McWorkspace::new()
                        .extract(
                            &v[z0 * m * m..(z1 + 1) * m * m],
                            [m, m, z1 - z0 + 1],
                            [0, 0, z0 as u64],
                            0.0,
                            &geom,
                            &mut out,
                        )
                        .expect("valid slab");
                });
                (t.elapsed().as_secs_f64(), ())
            });
            let act = 100.0 * active as f64 / cells;
            let Some(g) = gpu.as_mut() else {
                println!(
                    "{n:>5} {kind:>7} {act:>6.2} | {cpu1:>8.4} {cpun:>8.4} | {:>8} {:>8} {:>8} {:>8} {:>8} | {:>9.3e} {:>9} {:>9} | {:>7} {:>7}",
                    "-",
                    "-",
                    "-",
                    "-",
                    "-",
                    cells / cpun,
                    "-",
                    "-",
                    "-",
                    "-"
                );
                continue;
            };
            let mut got = TileMesh::default();
            let first = g
                .extract(&v, [m; 3], [0; 3], 0.0, &geom, &mut got)
                .expect("valid tile");
            assert!(!first.fell_back, "the GPU path fell back to the CPU");
            assert!(
                same_mesh(&got, &want),
                "GPU mesh differs from the CPU mesh ({n}³ {kind})"
            );
            let (e2e, s): (f64, GpuStats) = best(reps, || {
                let t = Instant::now();
                let s = g
                    .extract(&v, [m; 3], [0; 3], 0.0, &geom, &mut got)
                    .expect("valid tile");
                (t.elapsed().as_secs_f64(), s)
            });
            println!(
                "{n:>5} {kind:>7} {act:>6.2} | {cpu1:>8.4} {cpun:>8.4} | {:>8.4} {:>8.4} {:>8.4} {:>8.4} {e2e:>8.4} | {:>9.3e} {:>9.3e} {:>9.3e} | {:>7.2} {:>7.2}{}",
                s.upload_secs,
                s.kernel_secs,
                s.download_secs,
                s.host_secs,
                cells / cpun,
                cells / s.kernel_secs,
                cells / e2e,
                cpun / s.kernel_secs,
                cpun / e2e,
                if s.sub_blocks > 1 {
                    format!("  ({} sub-blocks)", s.sub_blocks)
                } else {
                    String::new()
                }
            );
        }
    }
    println!(
        "kern/N, e2e/N: speed-up of the GPU kernels alone and of the whole GPU call over the CPU \
         on all {threads} cores (above 1: GPU faster). Same mesh checked; CPU N skips joining \
         its slabs, which favours the CPU."
    );
    blended(&sizes, reps, threads, gpu.as_mut());
}

/// The blended-tile table; see the module docs.
fn blended(sizes: &[usize], reps: usize, threads: usize, mut gpu: Option<&mut GpuExtractor>) {
    println!();
    println!(
        "blended tiles: field + marching cubes (bumpy sphere, leaves of {E} voxels, coarse every {R})"
    );
    println!(
        "{:>5} {:>6} {:>6} | {:>8} {:>8} | {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} | {:>7} {:>7} | {:>7} {:>7}",
        "cells",
        "leaves",
        "act%",
        "cpu1 s",
        "cpuN s",
        "cold s",
        "up s",
        "kern s",
        "down s",
        "host s",
        "warm s",
        "MB up",
        "dense",
        "cold/N",
        "warm/N"
    );
    for &n in sizes {
        let m = n + 1;
        let geom = GridGeom::new([0.0; 3], 1.0 / n as f64, n as u64).expect("a valid grid");
        let data = BlendData::new(n);
        let whole = data.blend(n, 0, n);
        let mut want = TileMesh::default();
        let (cpu1, active) = best(reps, || {
            let t = Instant::now();
            let v = whole.eval();
            let s = McWorkspace::new()
                .extract(&v, [m; 3], [0; 3], 0.0, &geom, &mut want)
                .expect("valid tile");
            (t.elapsed().as_secs_f64(), s.active_cells)
        });
        let slabs = threads.min(n);
        let (cpun, _) = best(reps, || {
            let t = Instant::now();
            (0..slabs).into_par_iter().for_each(|i| {
                let (z0, z1) = (i * n / slabs, (i + 1) * n / slabs);
                let b = data.blend(n, z0, z1);
                let v = b.eval();
                let mut out = TileMesh::default();
                McWorkspace::new()
                    .extract(&v, b.dims, [0, 0, z0 as u64], 0.0, &geom, &mut out)
                    .expect("valid slab");
            });
            (t.elapsed().as_secs_f64(), ())
        });
        let act = 100.0 * active as f64 / (n * n * n) as f64;
        let dense_mb = 4.0 * (m * m * m) as f64 / 1e6;
        let Some(g) = gpu.as_deref_mut() else {
            println!(
                "{n:>5} {:>6} {act:>6.2} | {cpu1:>8.4} {cpun:>8.4} | {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} | {:>7} {dense_mb:>7.1} | {:>7} {:>7}",
                data.leaves.len(),
                "-",
                "-",
                "-",
                "-",
                "-",
                "-",
                "-",
                "-",
                "-"
            );
            continue;
        };
        let mut got = TileMesh::default();
        g.forget_leaves();
        let first = g
            .extract_blend(&whole, 0.0, &geom, &mut got)
            .expect("valid tile");
        assert!(!first.fell_back, "the GPU path fell back to the CPU");
        assert!(first.field_on_gpu, "the field was blended on the host");
        assert!(
            same_mesh(&got, &want),
            "GPU mesh differs from the CPU mesh ({n}³ blended)"
        );
        let (cold, s): (f64, GpuStats) = best(reps, || {
            g.forget_leaves();
            let t = Instant::now();
            let s = g
                .extract_blend(&whole, 0.0, &geom, &mut got)
                .expect("valid tile");
            (t.elapsed().as_secs_f64(), s)
        });
        let (warm, _) = best(reps, || {
            let t = Instant::now();
            let s = g
                .extract_blend(&whole, 0.0, &geom, &mut got)
                .expect("valid tile");
            (t.elapsed().as_secs_f64(), s)
        });
        println!(
            "{n:>5} {:>6} {act:>6.2} | {cpu1:>8.4} {cpun:>8.4} | {cold:>8.4} {:>8.4} {:>8.4} {:>8.4} {:>8.4} {warm:>8.4} | {:>7.1} {dense_mb:>7.1} | {:>7.2} {:>7.2}",
            data.leaves.len(),
            s.upload_secs,
            s.kernel_secs,
            s.download_secs,
            s.host_secs,
            s.upload_bytes as f64 / 1e6,
            cpun / cold,
            cpun / warm,
        );
    }
    println!(
        "cold/N, warm/N: speed-up of the whole GPU call (field built on the device) over \
         blending and extracting on all {threads} cores; cold sends every leaf, warm none."
    );
}
