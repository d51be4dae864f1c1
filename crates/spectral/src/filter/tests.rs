use super::*;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

/// A smooth non-periodic relief on an `nu × nv` grid over `[0, 1]²`, plus a tilt.
fn smooth(nu: usize, nv: usize) -> Vec<f64> {
    let mut h = vec![0.0; nu * nv];
    for j in 0..nv {
        for i in 0..nu {
            let (u, v) = (i as f64 / (nu - 1) as f64, j as f64 / (nv - 1) as f64);
            h[j * nu + i] =
                0.3 * u - 0.2 * v + 0.05 * (3.0 * u + 0.5).sin() * (2.0 * v).cos() + 0.02 * u * u;
        }
    }
    h
}

fn noisy(h: &[f64], sigma: f64, seed: u64) -> Vec<f64> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let n = Normal::new(0.0, sigma).unwrap_or_else(|_| unreachable!());
    h.iter().map(|&x| x + n.sample(&mut rng)).collect()
}

fn rms(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64).sqrt()
}

fn all_filters() -> Vec<Filter> {
    vec![
        Filter::Ideal { cut: 0.4 },
        Filter::Gauss { cut: 0.3 },
        Filter::BandStop {
            lo: 0.2,
            hi: 0.6,
            gain: 0.0,
        },
        Filter::Enhance {
            lo: 0.1,
            hi: 0.5,
            gain: 2.5,
        },
        Filter::Wiener { snr: None },
        Filter::Wiener { snr: Some(4.0) },
    ]
}

#[test]
fn parseval_rms_equals_the_measured_height_change() {
    let mut fft = Fft2::new();
    for mirror in [false, true] {
        let mut work = FilterWork::with_mirror(mirror);
        for &(nu, nv) in &[(30, 30), (17, 24), (9, 2)] {
            let h0 = noisy(&smooth(nu, nv), 0.01, 1);
            for f in all_filters() {
                let mut h = h0.clone();
                let a = filter_grid(&mut h, nu, nv, &f, &mut fft, &mut work);
                let direct = rms(&h, &h0);
                assert!(direct > 0.0, "{f:?} changed nothing");
                let rel = (a.parseval_rms - direct).abs() / direct;
                assert!(
                    rel < 1e-9,
                    "{f:?} mirror {mirror} {nu}x{nv}: {} vs {direct}",
                    a.parseval_rms
                );
            }
        }
    }
}

#[test]
fn ideal_lowpass_above_the_corner_is_the_identity() {
    let mut fft = Fft2::new();
    for mirror in [false, true] {
        let h0 = noisy(&smooth(23, 30), 0.01, 2);
        let mut h = h0.clone();
        let a = filter_grid(
            &mut h,
            23,
            30,
            &Filter::Ideal { cut: 1.5 },
            &mut fft,
            &mut FilterWork::with_mirror(mirror),
        );
        assert_eq!(a.parseval_rms, 0.0);
        assert!(rms(&h, &h0) < 1e-14, "mirror {mirror}");
    }
}

#[test]
fn gauss_with_a_tiny_cut_leaves_the_plane() {
    let (nu, nv) = (30, 20);
    let h0 = noisy(&smooth(nu, nv), 0.01, 3);
    let mut h = h0.clone();
    filter_grid(
        &mut h,
        nu,
        nv,
        &Filter::Gauss { cut: 1e-4 },
        &mut Fft2::new(),
        &mut FilterWork::new(),
    );
    let p = plane_of(&h0, nu, nv);
    let mut worst = 0.0f64;
    for j in 0..nv {
        for i in 0..nu {
            worst = worst.max((h[j * nu + i] - plane_at(p, i, j, nu, nv)).abs());
        }
    }
    assert!(worst < 1e-9, "{worst}");
    // The plane is the least-squares one: residuals orthogonal to 1, i and j.
    let r: Vec<f64> = h0.iter().zip(&h).map(|(a, b)| a - b).collect();
    let s0: f64 = r.iter().sum();
    let si: f64 = r.iter().enumerate().map(|(k, x)| (k % nu) as f64 * x).sum();
    let sj: f64 = r.iter().enumerate().map(|(k, x)| (k / nu) as f64 * x).sum();
    assert!(s0.abs() < 1e-9 && si.abs() < 1e-8 && sj.abs() < 1e-8);
}

#[test]
fn band_limit_bound_holds_and_is_monotone() {
    let mut fft = Fft2::new();
    for mirror in [false, true] {
        let mut work = FilterWork::with_mirror(mirror);
        let (nu, nv) = (30, 26);
        let h0 = noisy(&smooth(nu, nv), 0.003, 4);
        let mut last = f64::INFINITY;
        for &e in &[1e-5, 1e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1.0] {
            let b = band_limit(&h0, nu, nv, e, &mut fft, &mut work);
            assert!(
                b > 0.0 && b <= std::f64::consts::SQRT_2 && b <= last,
                "mirror {mirror}: {e} -> {b}"
            );
            last = b;
            let mut h = h0.clone();
            filter_grid(
                &mut h,
                nu,
                nv,
                &Filter::Ideal { cut: b },
                &mut fft,
                &mut work,
            );
            let change = h
                .iter()
                .zip(&h0)
                .map(|(a, c)| (a - c).abs())
                .fold(0.0, f64::max);
            assert!(
                change <= e + 1e-12,
                "mirror {mirror}: max_err {e}, b {b}, change {change}"
            );
        }
        assert!(
            last < 0.2,
            "everything removable at a huge tolerance: {last}"
        );
    }
}

#[test]
fn wiener_denoises_and_estimates_the_noise_of_scattered_points() {
    // White noise at scattered points, approximated on a κ = 1 grid by push-pull as the
    // patches are: the splat colours it, and the estimate reads the points' noise back
    // (12 to 26% over). On the mirror extension only, the patches' default: the periodic
    // one's wrap-around edge fills the tail (measured 56% over, and hardly any
    // denoising).
    use crate::sda;
    let f = |u: f64, v: f64| {
        0.3 * u - 0.2 * v + 0.05 * (3.0 * u + 0.5).sin() * (2.0 * v).cos() + 0.02 * u * u
    };
    let sigma = 0.004;
    let n = 1600;
    let mut fft = Fft2::new();
    let mut sw = sda::SdaWork::new();
    for mirror in [true] {
        for seed in 10..13 {
            let mut rng = Pcg64::seed_from_u64(seed);
            let noise = Normal::new(0.0, sigma).unwrap_or_else(|_| unreachable!());
            let pts: Vec<[f64; 3]> = (0..n)
                .map(|_| {
                    let (u, v) = (rng.random::<f64>(), rng.random::<f64>());
                    [u, v, f(u, v) + noise.sample(&mut rng)]
                })
                .collect();
            let mut g = sda::grid_for(n, [0.0; 2], [1.0; 2], 1.0);
            sda::push_pull(&mut g, &pts, &mut sw);
            let truth: Vec<f64> = (0..g.nu * g.nv)
                .map(|k| {
                    let (i, j) = (k % g.nu, k / g.nu);
                    f(i as f64 * g.step, j as f64 * g.step)
                })
                .collect();
            let h0 = g.h.clone();
            let mut h = h0.clone();
            let a = filter_grid(
                &mut h,
                g.nu,
                g.nv,
                &Filter::Wiener { snr: None },
                &mut fft,
                &mut FilterWork::with_mirror(mirror),
            );
            let est = a.noise_rms.unwrap_or(f64::NAN);
            let (before, after) = (rms(&h0, &truth), rms(&h, &truth));
            println!(
                "wiener mirror {mirror}: noise est {est:.5} (true {sigma}), rms to truth {before:.5} -> {after:.5}"
            );
            assert!(
                (est / sigma - 1.0).abs() < 0.35,
                "mirror {mirror}: estimate {est} vs {sigma}"
            );
            assert!(after < 0.7 * before, "mirror {mirror}: {before} -> {after}");
        }
    }
}

#[test]
fn mirror_extension_is_closer_to_the_truth_after_a_lowpass() {
    // The measurement behind FilterWork::mirror's default.
    let (nu, nv) = (30, 30);
    let truth = smooth(nu, nv);
    let mut fft = Fft2::new();
    let (mut on, mut off) = (0.0, 0.0);
    for seed in 20..25 {
        let h0 = noisy(&truth, 0.004, seed);
        let best = |mirror: bool, fft: &mut Fft2| {
            [0.15, 0.2, 0.3, 0.4, 0.5]
                .iter()
                .map(|&cut| {
                    let mut h = h0.clone();
                    filter_grid(
                        &mut h,
                        nu,
                        nv,
                        &Filter::Gauss { cut },
                        fft,
                        &mut FilterWork::with_mirror(mirror),
                    );
                    rms(&h, &truth)
                })
                .fold(f64::INFINITY, f64::min)
        };
        on += best(true, &mut fft);
        off += best(false, &mut fft);
    }
    println!(
        "best gauss lowpass rms to truth: mirror {:.5}, periodic {:.5}",
        on / 5.0,
        off / 5.0
    );
    assert!(on < off, "mirror {on} vs periodic {off}");
}

#[test]
fn band_energy_sums_to_the_detrended_mean_square() {
    let (nu, nv) = (24, 18);
    let h = noisy(&smooth(nu, nv), 0.01, 5);
    let p = plane_of(&h, nu, nv);
    let mut ms = 0.0;
    for j in 0..nv {
        for i in 0..nu {
            ms += (h[j * nu + i] - plane_at(p, i, j, nu, nv)).powi(2);
        }
    }
    ms /= (nu * nv) as f64;
    let mut fft = Fft2::new();
    for mirror in [false, true] {
        let e = band_energy(
            &h,
            nu,
            nv,
            &[0.0, 0.25, 0.5, 1.0, 1.5],
            &mut fft,
            &mut FilterWork::with_mirror(mirror),
        );
        assert_eq!(e.len(), 4);
        let total: f64 = e.iter().sum();
        assert!(
            (total - ms).abs() < 1e-10 * ms,
            "mirror {mirror}: {total} vs {ms}"
        );
    }
}

#[test]
fn check_rejects_what_is_not_a_filter() {
    for f in all_filters() {
        assert!(f.check().is_ok(), "{f:?}");
    }
    for f in [
        Filter::Ideal { cut: 0.0 },
        Filter::Gauss { cut: f64::NAN },
        Filter::BandStop {
            lo: 0.5,
            hi: 0.2,
            gain: 0.0,
        },
        Filter::BandStop {
            lo: 0.1,
            hi: 0.2,
            gain: 1.5,
        },
        Filter::Enhance {
            lo: 0.1,
            hi: 0.2,
            gain: 0.5,
        },
        Filter::Wiener { snr: Some(-1.0) },
    ] {
        assert!(f.check().is_err(), "{f:?}");
    }
}

#[test]
#[ignore = "timing; run with --ignored --nocapture"]
fn filter_grid_speed() {
    let (nu, nv) = (30, 30);
    let h0 = noisy(&smooth(nu, nv), 0.01, 6);
    let mut fft = Fft2::new();
    for mirror in [true, false] {
        let mut work = FilterWork::with_mirror(mirror);
        for f in [Filter::Gauss { cut: 0.3 }, Filter::Wiener { snr: None }] {
            let reps = 3000;
            let mut h = h0.clone();
            let t = std::time::Instant::now();
            for _ in 0..reps {
                h.copy_from_slice(&h0);
                filter_grid(&mut h, nu, nv, &f, &mut fft, &mut work);
            }
            let ns = t.elapsed().as_nanos() as f64 / (reps * nu * nv) as f64;
            println!("filter_grid {f:?} mirror {mirror}: {ns:.1} ns per grid node (30 x 30)");
        }
        let reps = 3000;
        let t = std::time::Instant::now();
        for _ in 0..reps {
            band_limit(&h0, nu, nv, 1e-3, &mut fft, &mut work);
        }
        let ns = t.elapsed().as_nanos() as f64 / (reps * nu * nv) as f64;
        println!("band_limit mirror {mirror}: {ns:.1} ns per grid node (30 x 30)");
    }
}
