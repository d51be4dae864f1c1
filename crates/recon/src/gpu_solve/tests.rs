//! The device solve against the CPU solve (needs a wgpu adapter: Mesa's lavapipe in CI;
//! skipped, saying so, without one).

use super::*;
use crate::fft_solve::{SCREEN_TOLERANCE, Solver};

fn no_adapter() -> bool {
    if crate::extract::gpu::adapter_names().is_empty() {
        eprintln!("skipped: wgpu finds no adapter (install mesa-vulkan-drivers for lavapipe)");
        return true;
    }
    false
}

fn grid(n: usize, shift: f64) -> LocalGrid {
    LocalGrid {
        n,
        h: 2.0 / n as f64,
        origin: [-1.0 + shift, -1.0, -1.0 - shift],
        unit: 4.0,
    }
}

/// Points on a bumpy sphere of radius `r` with outward normals (deterministic).
fn sphere(count: usize, r: f64) -> (Vec<[f64; 3]>, Vec<[f32; 3]>) {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let (mut pos, mut nrm) = (Vec::new(), Vec::new());
    for i in 0..count {
        let y = 1.0 - 2.0 * (i as f64 + 0.5) / count as f64;
        let rad = (1.0 - y * y).sqrt();
        let th = golden * i as f64;
        let d = [rad * th.cos(), y, rad * th.sin()];
        let rr = r * (1.0 + 0.04 * (7.0 * d[0]).sin() * (5.0 * d[1]).cos());
        pos.push([rr * d[0], rr * d[1], rr * d[2]]);
        nrm.push([d[0] as f32, d[1] as f32, d[2] as f32]);
    }
    (pos, nrm)
}

/// A sphere of `count` points on `grid(16, shift)`, splatted, with its screen of weight 8.
fn prepared(solver: &Solver, shift: f64, count: usize) -> Prepared {
    let g = grid(16, shift);
    let (pos, nrm) = sphere(count, 0.6);
    Prepared::new(
        solver.divergence(&g, splatted(&g, &pos, &nrm)),
        &Screen::from_points(&g, &pos, 8.0),
    )
}

fn splatted(g: &LocalGrid, pos: &[[f64; 3]], nrm: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let mut v = vec![[0f32; 3]; g.len()];
    splat(g, pos, nrm, &mut v);
    v
}

/// The device of the first adapter, for `solver`'s grids.
fn device(solver: &Solver) -> Device {
    let (ad, _) = adapter::select(GpuMode::On);
    Device::open(&ad.unwrap(), solver).unwrap()
}

fn rel_diff(a: &[f32], b: &[f32]) -> f64 {
    let range = a.iter().fold(0f32, |m, v| m.max(v.abs())) as f64;
    let d = a
        .iter()
        .zip(b)
        .fold(0f64, |m, (x, y)| m.max((*x as f64 - *y as f64).abs()));
    d / range
}

/// The device solve on `grid(n)` within rounding of the CPU's, unscreened and screened.
fn matches_the_cpu(n: usize) {
    let g = grid(n, 0.0);
    let solver = Solver::new(&g, 1.0);
    let gpu = GpuSolver::new(GpuMode::On, &solver).unwrap().unwrap();
    let (pos, nrm) = sphere(6000, 0.55);
    for alpha in [0.0, 4.0, 32.0] {
        let (c, cc) = solver.solve_points(&g, &pos, &nrm, alpha);
        let (d, dc) = gpu.solve_points(&solver, &g, &pos, &nrm, alpha);
        let rd = rel_diff(&c, &d);
        eprintln!(
            "{n}³, alpha {alpha}: relative difference {rd:.2e}, iterations {} and {}, residuals {:.3} and {:.3}",
            cc.iterations, dc.iterations, cc.residual, dc.residual
        );
        assert!(rd < 1e-5, "{n}³, alpha {alpha}: {rd}");
        assert!(cc.iterations.abs_diff(dc.iterations) <= 1, "{cc:?} {dc:?}");
        if alpha > 0.0 {
            assert!(
                dc.iterations > 0 && dc.residual <= SCREEN_TOLERANCE,
                "{dc:?}"
            );
        } else {
            assert_eq!(dc.iterations, 0);
        }
    }
    assert_eq!(gpu.stats().failed, 0);
}

#[test]
fn the_device_solve_matches_the_cpu_solve() {
    if no_adapter() {
        return;
    }
    matches_the_cpu(32);
}

/// Lines of three times a power of two (a leaf's grid of `1.5E` nodes: 48³ at `E = 32`) take
/// a radix-3 stage after the radix-2 ones; 512/n lines a workgroup do not divide n² for
/// any of these, so the last workgroup of each transform is partly idle.
#[test]
fn the_device_solve_matches_the_cpu_solve_on_lines_of_three_times_a_power_of_two() {
    if no_adapter() {
        return;
    }
    for n in [12, 24, 48] {
        matches_the_cpu(n);
    }
    assert_eq!(fft_radix(48), Some(3));
    assert_eq!(fft_radix(64), Some(1));
    assert_eq!(fft_radix(3), None);
    assert_eq!(fft_radix(40), None);
    assert_eq!(fft_radix(2 * MAX_N), None);
}

#[test]
fn a_leaf_gets_the_same_bits_in_any_batch() {
    if no_adapter() {
        return;
    }
    let solver = Solver::new(&grid(16, 0.0), 1.0);
    let mut dev = device(&solver);
    let leaves: Vec<Prepared> = [0.0, 0.25, 0.5]
        .iter()
        .map(|&s| prepared(&solver, s, 1500 + (s * 4000.0) as usize))
        .collect();
    let (all, _) = dev.run(leaves.iter().collect()).unwrap();
    for (i, l) in leaves.iter().enumerate() {
        let (one, _) = dev.run(vec![l]).unwrap();
        assert_eq!(one[0].0, all[i].0, "leaf {i}");
        assert_eq!(one[0].1, all[i].1, "leaf {i}");
    }
    // Reversed order, and a leaf without samples among them.
    let empty = Prepared::new(leaves[0].div.clone(), &Screen::default());
    let (rev, _) = dev
        .run(vec![&leaves[2], &empty, &leaves[1], &leaves[0]])
        .unwrap();
    assert_eq!(rev[0].0, all[2].0);
    assert_eq!(rev[3].0, all[0].0);
    assert_eq!(rev[1].1.iterations, 0);
    let g = grid(16, 0.0);
    let (pos, nrm) = sphere(1500, 0.6);
    let plain = solver.solve_splatted(&g, splatted(&g, &pos, &nrm));
    assert!(rel_diff(&plain, &rev[1].0) < 1e-4);
}

/// Dispatch grids cut into two dimensions (as for the node-wise kernels of a 256³ grid,
/// 65536 workgroups a leaf) run the workgroups beyond the work as no-ops: the same bits as
/// one dimension.
#[test]
fn two_dimensional_dispatches_give_the_same_bits() {
    if no_adapter() {
        return;
    }
    let solver = Solver::new(&grid(16, 0.0), 1.0);
    let mut dev = device(&solver);
    let leaves = [prepared(&solver, 0.0, 3000), prepared(&solver, 0.3, 2000)];
    let (one, _) = dev.run(leaves.iter().collect()).unwrap();
    // 16³ nodes: 8 line groups of 32 lines, 16 node groups, ~40 sample groups; 5 a row
    // leaves a partial last row in each.
    dev.max_dim = 5;
    let (two, _) = dev.run(leaves.iter().collect()).unwrap();
    assert_eq!(one[0].0, two[0].0);
    assert_eq!(one[1].0, two[1].0);
    assert_eq!(one[0].1, two[0].1);
}
