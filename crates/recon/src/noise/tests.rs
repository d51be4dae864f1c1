use super::*;
use crate::weight::{BASE_POINT_WEIGHT, auto_point_weight};

#[test]
fn noise_is_read_back_from_samples_of_a_plane() {
    // 40K samples on the plane through the middle of a layer of fine voxels (h = 0.01)
    // with offsets of known spread s along z, normals up: the estimate reads s back (a
    // spread near a voxel is read low, cut by the voxels' faces).
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;
    let h = 0.01;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(12345);
    for s in [0.0, 0.05, 0.15] {
        let mut pos = Vec::new();
        for _ in 0..40_000 {
            let g: f64 = rng.sample(StandardNormal);
            let (x, y) = (0.5 * rng.random::<f64>(), 0.5 * rng.random::<f64>());
            pos.push([x, y, 0.5 + (0.5 + s * g) * h]);
        }
        let nrm = vec![[0.0, 0.0, 1.0]; pos.len()];
        let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
        let got = st.sigma_voxels().unwrap();
        assert!((got - s).abs() <= 0.1 * s + 1e-9, "{s}: {got}");
        // The weight: 4 for noise at the reference, up to 32 for precise samples.
        let w = auto_point_weight(Some(got));
        assert!((BASE_POINT_WEIGHT..=32.0).contains(&w));
    }
    assert_eq!(auto_point_weight(None), BASE_POINT_WEIGHT);
    assert_eq!(auto_point_weight(Some(0.0)), 32.0);
    assert_eq!(auto_point_weight(Some(1.0)), BASE_POINT_WEIGHT);
    assert!((auto_point_weight(Some(0.1)) - 16.0).abs() < 1e-12);
}

/// `n` samples of the plane `z = 0.5 + s·h·g` over `[0, 0.5]²` (normals up), `g`
/// standard normal.
fn noisy_plane(n: usize, s: f64, h: f64, seed: u64) -> (Vec<[f64; 3]>, Vec<[f32; 3]>) {
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let pos: Vec<[f64; 3]> = (0..n)
        .map(|_| {
            let g: f64 = rng.sample(StandardNormal);
            [
                0.5 * rng.random::<f64>(),
                0.5 * rng.random::<f64>(),
                0.5 + s * h * g,
            ]
        })
        .collect();
    (pos, vec![[0.0, 0.0, 1.0]; n])
}

#[test]
fn jets_read_the_noise_a_voxel_cannot_hold() {
    // 20K samples on 2,500 voxels of a plane (8 a voxel): within a voxel the spread is
    // cut at 1/√12 voxel, about quadrics it is read back up to 1.6 voxels.
    let h = 0.01;
    for (seed, s) in [(1, 0.0), (2, 0.5), (3, 1.0), (4, 1.6)] {
        let (pos, nrm) = noisy_plane(20_000, s, h, seed);
        let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
        let jet = st.jet_sigma_voxels().unwrap();
        assert!((jet - s).abs() <= 0.1 * s + 1e-9, "{s}: {jet}");
        if s >= 1.0 {
            assert!(st.sigma_voxels().unwrap() < 0.3, "{s}: {st:?}");
        }
        assert!(st.jets[0].fits >= JET_MIN_FITS, "{st:?}");
    }
}

/// `n` samples of the relief `z = 0.5 + a h sin(2πx/λh) sin(2πy/λh)` over a 0.5-wide
/// square (`λ` and `a` in voxels of `h`), with its exact normals, moved by noise of `s`
/// voxels along each axis (as `scanflow synth` draws it: `s` across the surface
/// wherever it faces).
fn relief(n: usize, a: f64, lambda: f64, s: f64, h: f64) -> (Vec<[f64; 3]>, Vec<[f32; 3]>) {
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    let k = std::f64::consts::TAU / (lambda * h);
    (0..n)
        .map(|_| {
            let (x, y): (f64, f64) = (0.5 * rng.random::<f64>(), 0.5 * rng.random::<f64>());
            let g: [f64; 3] = [0; 3].map(|_| rng.sample(StandardNormal));
            let z = 0.5 + a * h * (k * x).sin() * (k * y).sin() + s * h * g[2];
            let gx = a * h * k * (k * x).cos() * (k * y).sin();
            let gy = a * h * k * (k * x).sin() * (k * y).cos();
            let l = (1.0 + gx * gx + gy * gy).sqrt();
            (
                [x + s * h * g[0], y + s * h * g[1], z],
                [(-gx / l) as f32, (-gy / l) as f32, (1.0 / l) as f32],
            )
        })
        .unzip()
}

#[test]
fn pairs_read_the_noise_and_not_the_relief() {
    // 40K samples on 2,500 voxels (16 a voxel) of a relief of 1.5 voxels' amplitude and
    // 5 voxels' wavelength, tighter than a quadric on 1.5 voxels follows: the quadrics
    // read it as noise (1.01 voxel noise-free, 1.25 and 1.58 with noise of 0.5 and 1),
    // the pairs of close samples do not (0.00, 0.49, 1.02).
    let h = 0.01;
    for s in [0.0, 0.5, 1.0] {
        let (pos, nrm) = relief(40_000, 1.5, 5.0, s, h);
        let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
        let pairs = st.pair_sigma_voxels().unwrap();
        let jet = st.jet_sigma_voxels().unwrap();
        assert!((pairs - s).abs() <= 0.08 * s + 0.03, "{s}: pairs {pairs}");
        assert!(jet > s + 0.2, "{s}: jet {jet}");
        assert_eq!(st.noise_voxels(), Some(pairs));
        let share = st.noise_share().unwrap();
        assert!(
            (share - (pairs / jet).powi(2)).abs() < 1e-12 && share < 0.9,
            "{share}"
        );
    }
    // On a plane the pairs and the quadrics agree.
    let (pos, nrm) = noisy_plane(20_000, 0.8, h, 9);
    let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
    let pairs = st.pair_sigma_voxels().unwrap();
    assert!((pairs - 0.8).abs() < 0.06, "{pairs}");
    assert!(st.noise_share().unwrap() > 0.9, "{st:?}");
    // 64 samples a voxel of area: every fourth of a disc's 450 is paired, and they read
    // the same noise.
    let (pos, nrm) = noisy_plane(160_000, 0.8, h, 12);
    let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
    let dense = st.pair_sigma_voxels().unwrap();
    assert!((dense - 0.8).abs() < 0.06, "{dense}");
    // Too few samples for the pairs: the quadrics' figure stands in.
    let (pos, nrm) = noisy_plane(300, 0.8, h, 10);
    let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
    assert_eq!(st.pair_sigma_voxels(), None);
    assert_eq!(st.noise_voxels(), st.jet_sigma_voxels());
}

#[test]
fn pairs_of_two_sheets_of_a_fold_do_not_read_as_noise() {
    // Two noisy planes 5 voxels apart, both facing up, as the sheets of a relief that
    // folds within a disc, the second with a fifteenth of the samples (as a fold's
    // far sheet holds a minority of a disc's): the pairs across the sheets differ by 5
    // voxels, and read as noise they would nearly double it. Cut at 2.5 standard deviations,
    // the estimate reads the noise of one sheet.
    let h = 0.01;
    for s in [0.3, 0.5, 0.7] {
        let (mut pos, mut nrm) = noisy_plane(20_000, s, h, 21);
        let (upper, up_nrm) = noisy_plane(1_300, s, h, 22);
        pos.extend(upper.iter().map(|p| [p[0], p[1], p[2] + 5.0 * h]));
        nrm.extend(up_nrm);
        let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
        let pairs = st.pair_sigma_voxels().unwrap();
        assert!((pairs - s).abs() < 0.06 * s, "{s}: {pairs}");
        let all = line(st.pairs.below(|_| f64::MAX)).unwrap().0.sqrt();
        assert!(all > 1.8 * s, "{s}: untrimmed {all}");
    }
}

#[test]
fn a_volume_of_returns_reads_as_noise() {
    // A precise ground (0.05 voxel) under as many returns again scattered through the
    // 5 voxels above it, as airborne LiDAR over vegetation: most pairs lie beyond any
    // cut near the ground's noise, and the line through all of them stands.
    let h = 0.01;
    let (mut pos, mut nrm) = noisy_plane(20_000, 0.05, h, 23);
    let (canopy, up) = noisy_plane(20_000, 0.0, h, 24);
    let mut z = 0.0f64;
    pos.extend(canopy.iter().map(|p| {
        z = (z + 0.618_033_988_749_895) % 1.0;
        [p[0], p[1], p[2] + 5.0 * h * z]
    }));
    nrm.extend(up);
    let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
    let all = line(st.pairs.below(|_| f64::MAX)).unwrap().0.sqrt();
    let pairs = st.pair_sigma_voxels().unwrap();
    assert!(all > 1.0, "{all}");
    assert!((pairs - all).abs() < 1e-9 * all, "{pairs} against {all}");
}

#[test]
fn the_trimmed_share_of_a_normal_variance() {
    // 1 − 2kφ(k)/(2Φ(k) − 1), from scipy.stats.norm.
    assert!((trimmed_variance_share(2.5) - 0.911_256_360_935_392).abs() < 1e-9);
    assert!((trimmed_variance_share(3.0) - 0.973_336_924_662_541_5).abs() < 1e-9);
    assert!((trimmed_variance_share(12.0) - 1.0).abs() < 1e-9);
    // The bins: each height difference in the bin whose edges hold it.
    for dh in [0.0, 0.009, 0.01, 0.0101, 0.3, 1.0, 4.7, 11.0] {
        let i = pair_bin(dh);
        let lo = if i == 0 { 0.0 } else { pair_bin_edge(i - 1) };
        assert!(lo <= dh && dh < pair_bin_edge(i), "{dh}: bin {i}");
    }
    assert_eq!(pair_bin(1e6), PAIR_BINS - 1);
    assert_eq!(pair_bin(f64::NAN), 0);
}

#[test]
fn the_fit_allows_for_the_pairs_noise_where_samples_are_not_precise() {
    let h = 0.01;
    // Noise of 0.8 voxel: the spread within voxels stops near 0.29, the pairs read it.
    let (pos, nrm) = noisy_plane(20_000, 0.8, h, 11);
    let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
    assert!(st.sigma_voxels().unwrap() < 0.3);
    assert_eq!(st.fit_noise_voxels(), st.pair_sigma_voxels());
    // Precise samples keep the spread within voxels (the fit's reach asks for it).
    let (pos, nrm) = relief(40_000, 1.5, 8.0, 0.0, h);
    let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
    assert!(st.sigma_voxels().unwrap() < PRECISE_WITHIN_VOXELS);
    assert_eq!(st.fit_noise_voxels(), st.sigma_voxels());
}

#[test]
fn past_ten_million_points_a_share_of_the_cells_reads_the_same_noise() {
    assert_eq!(noise_cell_stride(0), 1);
    assert_eq!(noise_cell_stride(NOISE_FULL_RATE_POINTS), 1);
    assert_eq!(noise_cell_stride(NOISE_FULL_RATE_POINTS + 1), 2);
    assert_eq!(noise_cell_stride(100_000_000), 10);
    // 250K samples on 62,500 voxels of a plane (4 a voxel), noise of one voxel, in 50
    // stripes of 5,000 (store cells): every tenth stripe reads the spread of them all.
    let h = 0.002;
    let (mut pos, nrm) = noisy_plane(250_000, 1.0, h, 5);
    // Stripes along x, as a store's cells are boxes.
    pos.sort_by(|a, b| a[0].total_cmp(&b[0]));
    let mut full = NoiseStats::default();
    let mut thin = NoiseStats::default();
    for (j, (p, n)) in pos.chunks(5_000).zip(nrm.chunks(5_000)).enumerate() {
        let st = NoiseStats::of(p, n, [0.0; 3], h);
        if j % noise_cell_stride(100_000_000) == 0 {
            thin.add(st);
        }
        full.add(st);
    }
    let (a, b) = (full.jets[0].fits, thin.jets[0].fits);
    assert!(a >= 9 * b && b >= JET_MIN_FITS, "{a} {b}");
    for st in [&full, &thin] {
        let jet = st.jet_sigma_voxels().unwrap();
        assert!((jet - 1.0).abs() <= 0.1, "{jet}: {st:?}");
        let within = st.sigma_voxels().unwrap();
        assert!((0.25..0.3).contains(&within), "{within}: {st:?}");
    }
}

#[test]
fn jets_follow_curvature() {
    // A noise-free sphere of radius 20 voxels, 8 samples a voxel of its area: the
    // quadrics leave almost nothing; a plane's fit would leave r²/(2R) ≈ 0.06 voxel.
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;
    let (h, r) = (0.01, 0.2);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(9);
    let mut pos = Vec::new();
    let mut nrm = Vec::new();
    for _ in 0..40_000 {
        let d: [f64; 3] = [0; 3].map(|_| rng.sample(StandardNormal));
        let l = dot(d, d).sqrt();
        let n = d.map(|x| x / l);
        pos.push([0, 1, 2].map(|a| 0.5 + r * n[a]));
        nrm.push(n.map(|x| x as f32));
    }
    let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
    assert!(st.jet_sigma_voxels().unwrap() < 0.01, "{st:?}");
}

#[test]
fn noise_stats_need_two_samples_in_a_voxel() {
    let pos = [[0.05, 0.05, 0.05], [0.15, 0.05, 0.05]];
    let st = NoiseStats::of(&pos, &[[0.0, 0.0, 1.0]; 2], [0.0; 3], 0.1);
    assert_eq!(st.sigma_voxels(), None);
    // Opposite normals in one voxel: a thin sheet, not noise.
    let pos = [[0.05, 0.05, 0.04], [0.05, 0.05, 0.06]];
    let st = NoiseStats::of(&pos, &[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], [0.0; 3], 0.1);
    assert_eq!(st.sigma_voxels(), None);
}
