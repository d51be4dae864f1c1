use super::*;
use crate::screen::{Aggregate, ScreenBuilder, ScreenPart};

/// A batch of samples: positions (world frame) and normals.
type Samples<'a> = (&'a [[f64; 3]], &'a [[f32; 3]]);

/// In-place 3D FFT of an `n³` cube (x fastest) with the 1D plan `fft` along each axis.
fn fft3(data: &mut [Complex32], n: usize, fft: &Arc<dyn Fft<f32>>) {
    let scratch_len = fft.get_inplace_scratch_len();
    // x: rows are contiguous.
    data.par_chunks_mut(n * n).for_each_init(
        || vec![Complex32::new(0.0, 0.0); scratch_len],
        |s, slab| fft.process_with_scratch(slab, s),
    );
    // y: transpose each z-slab, transform rows, transpose back.
    data.par_chunks_mut(n * n).for_each_init(
        || vec![Complex32::new(0.0, 0.0); scratch_len],
        |s, slab| {
            transpose_square(slab, n);
            fft.process_with_scratch(slab, s);
            transpose_square(slab, n);
        },
    );
    // z: one (x, z) plane at a time, gathered into rows of z, transformed, scattered back;
    // the scratch is one plane, not a second cube.
    let mut plane = vec![Complex32::new(0.0, 0.0); n * n];
    for y in 0..n {
        for z in 0..n {
            let row = &data[(z * n + y) * n..(z * n + y) * n + n];
            for x in 0..n {
                plane[x * n + z] = row[x];
            }
        }
        plane
            .par_chunks_mut(n * (n / rayon::current_num_threads().max(1)).max(1))
            .for_each_init(
                || vec![Complex32::new(0.0, 0.0); scratch_len],
                |s, rows| fft.process_with_scratch(rows, s),
            );
        for z in 0..n {
            let row = &mut data[(z * n + y) * n..(z * n + y) * n + n];
            for x in 0..n {
                row[x] = plane[x * n + z];
            }
        }
    }
}

fn transpose_square(m: &mut [Complex32], n: usize) {
    for i in 0..n {
        for j in (i + 1)..n {
            m.swap(i * n + j, j * n + i);
        }
    }
}

fn naive_dft3(data: &[Complex32], n: usize) -> Vec<Complex32> {
    let mut out = vec![Complex32::new(0.0, 0.0); data.len()];
    for kz in 0..n {
        for ky in 0..n {
            for kx in 0..n {
                let mut acc = rustfft::num_complex::Complex64::new(0.0, 0.0);
                for z in 0..n {
                    for y in 0..n {
                        for x in 0..n {
                            let ph =
                                -2.0 * std::f64::consts::PI * ((kx * x + ky * y + kz * z) as f64)
                                    / n as f64;
                            let v = data[(z * n + y) * n + x];
                            acc += rustfft::num_complex::Complex64::new(v.re as f64, v.im as f64)
                                * rustfft::num_complex::Complex64::from_polar(1.0, ph);
                        }
                    }
                }
                out[(kz * n + ky) * n + kx] = Complex32::new(acc.re as f32, acc.im as f32);
            }
        }
    }
    out
}

#[test]
fn fft3_matches_naive_dft() {
    let n = 6;
    let data: Vec<Complex32> = (0..n * n * n)
        .map(|i| Complex32::new(((i * 37) % 11) as f32 - 5.0, ((i * 17) % 7) as f32))
        .collect();
    let mut d = data.clone();
    let fwd = FftPlanner::<f32>::new().plan_fft_forward(n);
    fft3(&mut d, n, &fwd);
    let want = naive_dft3(&data, n);
    for (a, b) in d.iter().zip(&want) {
        assert!((a - b).norm() < 1e-3, "{a} vs {b}");
    }
}

/// The solve written out node by node on a complex transform, with the filter evaluated
/// at every frequency: the oracle for [`Solver`]'s real transform and tabulated filter.
fn reference_solve(grid: &LocalGrid, v: &[[f32; 3]], sigma_vox: f64) -> Vec<f32> {
    let n = grid.n;
    let at = |x: usize, y: usize, z: usize| (z * n + y) * n + x;
    let half_inv_h = (0.5 * grid.unit / grid.h) as f32;
    let mut buf = vec![Complex32::new(0.0, 0.0); grid.len()];
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let (xp, yp, zp) = ((x + 1) % n, (y + 1) % n, (z + 1) % n);
                let (xm, ym, zm) = ((x + n - 1) % n, (y + n - 1) % n, (z + n - 1) % n);
                let d = (v[at(xp, y, z)][0] - v[at(xm, y, z)][0])
                    + (v[at(x, yp, z)][1] - v[at(x, ym, z)][1])
                    + (v[at(x, y, zp)][2] - v[at(x, y, zm)][2]);
                buf[at(x, y, z)] = Complex32::new(d * half_inv_h, 0.0);
            }
        }
    }
    let mut planner = FftPlanner::<f32>::new();
    fft3(&mut buf, n, &planner.plan_fft_forward(n));
    let h_u = grid.h / grid.unit;
    let two_pi_over_l = 2.0 * std::f64::consts::PI / (n as f64 * h_u);
    let sigma = sigma_vox * h_u;
    let k2 = |m: usize| {
        let s = if m <= n / 2 {
            m as f64
        } else {
            m as f64 - n as f64
        };
        (s * two_pi_over_l).powi(2)
    };
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let kk = k2(x) + k2(y) + k2(z);
                let c = &mut buf[at(x, y, z)];
                if kk == 0.0 {
                    *c = Complex32::new(0.0, 0.0);
                } else {
                    *c *= -(((-(0.5 * sigma * sigma * kk)).exp() / kk) as f32);
                }
            }
        }
    }
    fft3(&mut buf, n, &planner.plan_fft_inverse(n));
    let norm = 1.0 / grid.len() as f32;
    buf.iter().map(|c| c.re * norm).collect()
}

#[test]
fn real_tabulated_solver_matches_the_complex_node_by_node_solve() {
    // Odd and even sizes (the Nyquist row exists only for even n), several spacings.
    for (n, h, sigma) in [
        (7, 0.3, 1.0),
        (8, 0.125, 1.5),
        (12, 2.0, 0.7),
        (15, 1.0, 1.0),
    ] {
        let grid = LocalGrid {
            n,
            h,
            origin: [-1.0, 0.5, 2.0],
            unit: 1.0,
        };
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        let v: Vec<[f32; 3]> = (0..grid.len()).map(|_| [rnd(), rnd(), rnd()]).collect();
        let want = reference_solve(&grid, &v, sigma);
        let scale = want.iter().fold(0f32, |m, w| m.max(w.abs()));
        assert!(scale > 0.0);
        let solver = Solver::new(&grid, sigma);
        // Two solves with one solver: nothing carries over between them.
        let first = solver.solve_splatted(&grid, v.clone());
        let second = solver.solve_splatted(&grid, v.clone());
        assert_eq!(first, second);
        assert_eq!(first.len(), want.len());
        for (i, (g, w)) in first.iter().zip(&want).enumerate() {
            assert!(
                (g - w).abs() <= 1e-5 * scale,
                "n = {n}, node {i}: {g} vs {w} (largest value {scale})"
            );
        }
    }
}

#[test]
fn sphere_indicator_is_lower_inside_and_level_set_is_the_sphere() {
    // Dense exact samples of a sphere of radius 0.5 in a periodic box of side 2.
    let n = 64;
    let grid = LocalGrid {
        n,
        h: 2.0 / n as f64,
        origin: [-1.0; 3],
        unit: 1.0,
    };
    let mut pos = Vec::new();
    let mut nrm = Vec::new();
    let m = 300;
    for i in 0..m {
        for j in 0..(2 * m) {
            let th = std::f64::consts::PI * (i as f64 + 0.5) / m as f64;
            let ph = std::f64::consts::PI * j as f64 / m as f64;
            let d = [th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()];
            // Area weight by repetition is not needed: sin(θ) density; keep uniform in area
            // by subsampling near the poles.
            if (i * 7919 + j * 104729) % 1000 >= (th.sin() * 1000.0) as usize {
                continue;
            }
            pos.push([0.5 * d[0], 0.5 * d[1], 0.5 * d[2]]);
            nrm.push([d[0] as f32, d[1] as f32, d[2] as f32]);
        }
    }
    let f = solve(&grid, &pos, &nrm, 1.0);
    let iso: f64 = pos.iter().map(|p| grid.eval(&f, *p)).sum::<f64>() / pos.len() as f64;
    let inside = grid.eval(&f, [0.0, 0.0, 0.0]);
    let outside = grid.eval(&f, [0.9, 0.9, 0.9]);
    assert!(inside < iso && outside > iso, "{inside} {iso} {outside}");
    // Along a ray the field crosses iso within a fraction of a voxel of r = 0.5.
    for d in [[1.0, 0.0, 0.0], [0.0, 0.6, 0.8], [0.577, 0.577, 0.577]] {
        let mut lo = 0.3;
        let mut hi = 0.7;
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            let v = grid.eval(&f, [mid * d[0], mid * d[1], mid * d[2]]);
            if v < iso { lo = mid } else { hi = mid }
        }
        assert!((lo - 0.5).abs() < 0.3 * grid.h, "crossing at {lo}");
    }
}

/// Samples of a sphere of radius 0.5 carrying a relief `1 + a·sin(k θ)` (unit normals of
/// the sphere, not of the relief, as a smoothed scan would give), about 6 per voxel.
fn relief_sphere(n_theta: usize, a: f64, k: f64) -> (Vec<[f64; 3]>, Vec<[f32; 3]>) {
    let mut pos = Vec::new();
    let mut nrm = Vec::new();
    for i in 0..n_theta {
        let th = std::f64::consts::PI * (i as f64 + 0.5) / n_theta as f64;
        let m = ((2 * n_theta) as f64 * th.sin()).ceil() as usize;
        for j in 0..m {
            let ph = 2.0 * std::f64::consts::PI * j as f64 / m as f64;
            let d = [th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()];
            let r = 0.5 * (1.0 + a * (k * th).sin());
            pos.push(d.map(|c| r * c));
            nrm.push(d.map(|c| c as f32));
        }
    }
    (pos, nrm)
}

#[test]
fn boxes_splat_and_screen_the_same_bits_for_any_thread_count() {
    // A sphere of radius 0.5 in batches of uneven sizes, the third reaching past the
    // grid (its weights wrap).
    let (mut pos, nrm) = relief_sphere(60, 0.1, 7.0);
    pos[5][2] = 1.01;
    let g = sphere_grid();
    let cuts = [0, 1000, 4000, 4001, pos.len()];
    let batches: Vec<Samples> = cuts
        .windows(2)
        .map(|w| (&pos[w[0]..w[1]], &nrm[w[0]..w[1]]))
        .collect();
    // One batch's box on a zero grid is its splat.
    let (p, n) = batches[2];
    let mut want = vec![[0f32; 3]; g.len()];
    splat(&g, p, n, &mut want);
    let mut got = vec![[0f32; 3]; g.len()];
    add_boxes(&g, &[&splat_box(&g, p, n)], &mut got);
    assert!(got == want, "a box is not its batch's splat");
    let boxes: Vec<SplatBox> = batches.iter().map(|(p, n)| splat_box(&g, p, n)).collect();
    let boxes: Vec<&SplatBox> = boxes.iter().collect();
    let parts: Vec<ScreenPart> = batches
        .iter()
        .map(|(p, _)| ScreenBuilder::part(&g, p))
        .collect();
    let parts: Vec<&[(u64, Aggregate)]> = parts.iter().map(|p| &p[..]).collect();
    // In sequence, one box and one part after the other.
    let mut want = vec![[0f32; 3]; g.len()];
    let mut one = ScreenBuilder::new(&g);
    for (b, s) in boxes.iter().zip(&parts) {
        add_boxes(&g, &[b], &mut want);
        one.add_parts(&[s]);
    }
    let want_screen = one.finish(2.0);
    // Every sample splatted, to the rounding of the sums' grouping.
    let mut direct = vec![[0f32; 3]; g.len()];
    splat(&g, &pos, &nrm, &mut direct);
    let err = want
        .iter()
        .zip(&direct)
        .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
        .fold(0f32, f32::max);
    let top = direct.iter().flatten().fold(0f32, |m, v| m.max(v.abs()));
    assert!(
        err <= 1e-5 * top,
        "boxes stray {err} from the splat (of {top})"
    );
    for threads in [1, 2, 3, 7] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let mut got = vec![[0f32; 3]; g.len()];
        let mut sb = ScreenBuilder::with_slabs(&g, threads);
        pool.install(|| {
            add_boxes(&g, &boxes, &mut got);
            sb.add_parts(&parts);
        });
        assert!(got == want, "{threads} threads: another splat");
        let s = sb.finish(2.0);
        assert!(
            s.nodes() == want_screen.nodes()
                && s.weights() == want_screen.weights()
                && s.gamma() == want_screen.gamma(),
            "{threads} threads: another screening"
        );
    }
}

fn sphere_grid() -> LocalGrid {
    LocalGrid {
        n: 32,
        h: 2.0 / 32.0,
        origin: [-1.0; 3],
        unit: 2.0,
    }
}

/// `‖L(x0 − x) − Sᵀ Γ (S x − c)‖ / ‖Sᵀ Γ (S x0 − c)‖`: the residual of the screened normal
/// equations for `x`, given the unscreened `x0` (`L x0 = b`), with `L` applied by the
/// node-by-node complex transform of [`reference_solve`]'s oracle.
fn screened_residual(grid: &LocalGrid, x0: &[f32], x: &[f32], s: &Screen) -> f64 {
    let n = grid.n;
    let mut buf: Vec<Complex32> = x0
        .iter()
        .zip(x)
        .map(|(a, b)| Complex32::new(a - b, 0.0))
        .collect();
    let mut planner = FftPlanner::<f32>::new();
    fft3(&mut buf, n, &planner.plan_fft_forward(n));
    let two_pi_over_l = 2.0 * std::f64::consts::PI / (n as f64 * grid.h / grid.unit);
    let k2 = |m: usize| {
        let s = if m <= n / 2 {
            m as f64
        } else {
            m as f64 - n as f64
        };
        (s * two_pi_over_l).powi(2)
    };
    for z in 0..n {
        for y in 0..n {
            for xx in 0..n {
                buf[(z * n + y) * n + xx] *= (k2(xx) + k2(y) + k2(z)) as f32;
            }
        }
    }
    fft3(&mut buf, n, &planner.plan_fft_inverse(n));
    let g = s.gamma();
    let term = |v: &[f32]| {
        let at = s.gather(v);
        let c = g.iter().zip(&at).map(|(g, v)| g * v).sum::<f64>() / s.gamma_sum();
        let coef: Vec<f64> = g.iter().zip(&at).map(|(g, v)| g * (v - c)).collect();
        let mut out = vec![0f32; v.len()];
        s.scatter_add(&coef, &mut out);
        out
    };
    let (tx, t0) = (term(x), term(x0));
    let norm = 1.0 / grid.len() as f64;
    let res: f64 = buf
        .iter()
        .zip(&tx)
        .map(|(l, t)| (l.re as f64 * norm - *t as f64).powi(2))
        .sum();
    let start: f64 = t0.iter().map(|t| (*t as f64).powi(2)).sum();
    (res / start).sqrt()
}

#[test]
fn screened_conjugate_gradients_solve_the_normal_equations() {
    let grid = sphere_grid();
    let (pos, nrm) = relief_sphere(120, 0.04, 12.0);
    let solver = Solver::new(&grid, 1.0);
    let mut v = vec![[0f32; 3]; grid.len()];
    splat(&grid, &pos, &nrm, &mut v);
    let x0 = solver.solve_splatted(&grid, v.clone());
    let screen = Screen::from_points(&grid, &pos, 4.0);
    // The iteration count follows from the residual asked for, and each stop meets it.
    let mut last = 0;
    for tol in [0.3, 0.1, 1e-2, 1e-3] {
        let (x, conv) = solver.solve_screened_to(&grid, v.clone(), &screen, tol);
        assert!(conv.residual <= tol, "{tol}: {conv:?}");
        assert!(conv.iterations > last, "{tol}: {conv:?} after {last}");
        last = conv.iterations;
        // The true residual of (L + SᵀΓS) x = b + SᵀΓc, measured independently, falls
        // with the tolerance.
        let r = screened_residual(&grid, &x0, &x, &screen);
        assert!(r < 3.0 * tol, "{tol}: true residual {r} ({conv:?})");
    }
    // The default stops within its tolerance, and with no weight the solve is the
    // unscreened one, bit for bit.
    let (_, conv) = solver.solve_screened(&grid, v.clone(), &screen);
    assert!(conv.residual <= SCREEN_TOLERANCE && conv.iterations > 0);
    let none = Screen::from_points(&grid, &pos, 0.0);
    let (x, conv) = solver.solve_screened(&grid, v, &none);
    assert_eq!((x, conv), (x0, Convergence::default()));
}

#[test]
fn screening_pulls_the_level_set_onto_the_samples() {
    // A relief of 8% of the radius and 4.2 voxels' wavelength (2π·0.5/12 over h = 1/16):
    // smoothed by the Gaussian and the splat, the unscreened level set misses the
    // samples; the larger α, the closer they lie to the level set through their mean.
    // Measured: 0.42, 0.35, 0.24 and 0.11 voxels for α = 0, 1, 4, 16.
    let grid = sphere_grid();
    let (pos, nrm) = relief_sphere(150, 0.08, 12.0);
    let solver = Solver::new(&grid, 1.0);
    let miss = |alpha: f64| {
        let (f, _) = solver.solve_points(&grid, &pos, &nrm, alpha);
        let vals: Vec<f64> = pos.iter().map(|p| grid.eval(&f, *p)).collect();
        let iso = vals.iter().sum::<f64>() / vals.len() as f64;
        // To first order, distance = |f − iso| / |∇f|, the gradient by central differences.
        let d = 0.5 * grid.h;
        pos.iter()
            .zip(&vals)
            .map(|(p, v)| {
                let g2: f64 = (0..3)
                    .map(|a| {
                        let (mut hi, mut lo) = (*p, *p);
                        hi[a] += d;
                        lo[a] -= d;
                        ((grid.eval(&f, hi) - grid.eval(&f, lo)) / (2.0 * d)).powi(2)
                    })
                    .sum();
                (v - iso).abs() / g2.sqrt()
            })
            .sum::<f64>()
            / pos.len() as f64
            / grid.h
    };
    let m: Vec<f64> = [0.0, 1.0, 4.0, 16.0].into_iter().map(miss).collect();
    eprintln!("mean distance of the samples to the level set, in voxels: {m:?}");
    for w in m.windows(2) {
        assert!(w[1] < 0.9 * w[0], "{m:?}");
    }
    assert!(m[2] < 0.65 * m[0] && m[3] < 0.35 * m[0], "{m:?}");
}
