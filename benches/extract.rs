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

use std::time::Instant;

use rayon::prelude::*;
use scanflow::extract::{GpuExtractor, GpuMode, GpuStats, GridGeom, McWorkspace, TileMesh};

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
                got.keys == want.keys
                    && got.triangles == want.triangles
                    && got
                        .positions
                        .iter()
                        .zip(&want.positions)
                        .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits)),
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
}
