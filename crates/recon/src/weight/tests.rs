use super::*;

/// Pairs of close samples whose nugget is `sigma²` (squared voxels), on a line of slope
/// 0.5 in the squared distance: one height difference at each distance, scaled by the
/// share of a normal variance the trimmed estimate keeps, so that it reads `sigma`
/// exactly (for `sigma` of 0.3 voxel or more, whose pairs all lie within its cut).
fn pairs_reading(sigma: f64) -> PairStats {
    let share = trimmed_variance_share(PAIR_TRIM_SIGMAS);
    let mut p = PairStats::default();
    for i in 0..PAIR_MIN_COUNT as usize {
        let x = (i % 10) as f64 * 0.05;
        p.add_pair(x, (2.0 * share * (sigma * sigma + 0.5 * x)).sqrt());
    }
    p
}

/// Statistics reading `within` fine voxels, `jet` about quadrics (narrow and wide fits
/// alike) and `pairs` between close samples.
fn reading(within: f64, jet: f64, pairs: PairStats) -> NoiseStats {
    NoiseStats {
        sum_sq: within * within,
        dof: 1,
        jets: [JetStats {
            sum_sq: jet * jet,
            dof: 1,
            fits: JET_MIN_FITS,
        }; 2],
        pairs,
    }
}

#[test]
fn the_weight_falls_with_noise_beyond_the_limit() {
    let noise = |sigma: f64, jet: f64| reading(sigma, jet, PairStats::default());
    let unmeasured = NoiseStats::default();
    assert_eq!(PointWeight::Standard.alpha(&unmeasured), BASE_POINT_WEIGHT);
    assert_eq!(PointWeight::Auto.alpha(&unmeasured), BASE_POINT_WEIGHT);
    // Up to the limit the default is 4 whatever the noise within voxels, beyond the
    // precise.
    assert_eq!(PointWeight::Standard.alpha(&noise(0.05, 0.8)), 4.0);
    assert_eq!(
        PointWeight::Standard.alpha(&noise(0.28, NOISE_LIMIT_VOXELS)),
        4.0
    );
    // Beyond it, 1/σ²: twice the limit, a quarter of the weight.
    let twice = noise(0.28, 2.0 * NOISE_LIMIT_VOXELS);
    assert!((PointWeight::Standard.alpha(&twice) - 1.0).abs() < 1e-12);
    // `auto` raises for precision within voxels and lowers for noise beyond them.
    assert!((PointWeight::Auto.alpha(&noise(0.1, 0.5)) - 16.0).abs() < 1e-12);
    assert!((PointWeight::Auto.alpha(&noise(0.1, 1.7)) - 4.0).abs() < 1e-12);
    // Precise within voxels, the quadrics' residual is relief they miss, not noise, and
    // the default doubles the weight.
    assert_eq!(
        PointWeight::Standard.alpha(&noise(0.02, 1.7)),
        PRECISE_POINT_WEIGHT
    );
    assert_eq!(PointWeight::Auto.alpha(&noise(0.02, 1.7)), 32.0);
    // Where pairs of close samples read the noise, they decide: a relief the quadrics
    // misread (1.7) under noise of 0.8 is not lowered as noise beyond the limit, only
    // to the relief's share of their residual ([`relief_weight`]); noise of twice the
    // limit, read by both, is all the residual, and is solved unscreened.
    let relief = NoiseStats {
        pairs: pairs_reading(0.8),
        ..noise(0.28, 1.7)
    };
    assert!((relief.noise_voxels().unwrap() - 0.8).abs() < 1e-9);
    let share = 0.8f64.powi(2) / 1.7f64.powi(2);
    assert!((PointWeight::Standard.alpha(&relief) - 4.0 * (1.0 - share)).abs() < 1e-9);
    let noisy = NoiseStats {
        pairs: pairs_reading(2.0 * NOISE_LIMIT_VOXELS),
        ..noise(0.28, 1.7)
    };
    assert!(PointWeight::Standard.alpha(&noisy).abs() < 1e-9);
    // A given weight is the weight.
    assert_eq!(PointWeight::Fixed(4.0).alpha(&twice), 4.0);
    assert_eq!(PointWeight::Fixed(0.0).alpha(&twice), 0.0);
}

#[test]
fn noise_that_outweighs_the_relief_takes_the_weight_down_to_the_reliefs_share() {
    // Noise `pair` between close samples, `jet` about quadrics, 0.28 within voxels.
    let read = |pair: f64, jet: f64| reading(0.28, jet, pairs_reading(pair));
    let limit = crate::noise::FIT_NOISE_LIMIT_VOXELS;
    // Up to the vertex fit's limit, the weight stays whatever the share.
    assert_eq!(relief_weight(&read(0.9 * limit, 0.9 * limit)), 1.0);
    assert!((PointWeight::Standard.alpha(&read(limit, limit)) - 4.0).abs() < 1e-9);
    // From the dominant noise on, all of the noise's share comes off: a plain noisy
    // surface (the pairs read the quadrics' residual) is solved unscreened, a relief
    // the quadrics miss keeps its part.
    let d = NOISE_DOMINANT_VOXELS;
    assert!(relief_weight(&read(d, d)).abs() < 1e-9);
    assert!((relief_weight(&read(d, 2.0 * d)) - 0.75).abs() < 1e-9);
    // In between, a linear share of it: halfway, half.
    let mid = 0.5 * (limit + d);
    assert!((relief_weight(&read(mid, mid)) - 0.5).abs() < 1e-9);
    assert!((PointWeight::Auto.alpha(&read(mid, mid)) - 2.0).abs() < 1e-9);
    // More relief, more weight: the weight grows as the quadrics read more.
    let w: Vec<f64> = [0.8, 1.0, 1.5, 3.0]
        .iter()
        .map(|&j| PointWeight::Standard.alpha(&read(0.8, j)))
        .collect();
    assert!(w.windows(2).all(|p| p[0] < p[1]), "{w:?}");
    // Unmeasured pairs or quadrics leave it; precise samples and a given weight ignore it.
    let no_pairs = NoiseStats {
        pairs: PairStats::default(),
        ..read(d, d)
    };
    assert_eq!(relief_weight(&no_pairs), 1.0);
    let precise = NoiseStats {
        sum_sq: 0.01 * 0.01,
        ..read(d, d)
    };
    assert_eq!(PointWeight::Standard.alpha(&precise), PRECISE_POINT_WEIGHT);
    assert_eq!(PointWeight::Fixed(4.0).alpha(&read(d, d)), 4.0);
}

#[test]
fn the_smoothing_follows_the_precision() {
    let within = |sigma: f64| NoiseStats {
        sum_sq: sigma * sigma,
        dof: 1,
        ..NoiseStats::default()
    };
    // Unmeasured: Kazhdan's voxel.
    assert_eq!(
        Smoothing::Measured.voxels(&NoiseStats::default(), None),
        1.0
    );
    // Precise samples take the narrowest, noise at the reference and beyond one voxel,
    // in between the spread over the reference.
    assert_eq!(
        Smoothing::Measured.voxels(&within(0.0), None),
        SMOOTH_PRECISE_VOXELS
    );
    assert_eq!(
        Smoothing::Measured.voxels(&within(0.02), None),
        SMOOTH_PRECISE_VOXELS
    );
    assert!((Smoothing::Measured.voxels(&within(0.14), None) - 0.7).abs() < 1e-12);
    assert_eq!(Smoothing::Measured.voxels(&within(0.2), None), 1.0);
    assert_eq!(Smoothing::Measured.voxels(&within(0.29), None), 1.0);
    // Noise beyond the limit about quadrics keeps one voxel, unless precise within.
    let rough = |sigma: f64| NoiseStats {
        jets: [JetStats {
            sum_sq: 4.0,
            dof: 1,
            fits: JET_MIN_FITS,
        }; 2],
        ..within(sigma)
    };
    assert_eq!(Smoothing::Measured.voxels(&rough(0.099), None), 1.0);
    // Under the limit, the width narrows by the share of the quadrics' residual that
    // pairs of close samples read as noise: 0.8 of 1.0 (0.64), 0.8 of 2.0 (0.16, so
    // the narrowest); all of it where the pairs read as much as the quadrics.
    let relief = |pairs: f64| NoiseStats {
        pairs: pairs_reading(pairs),
        ..rough(0.28)
    };
    let share = |jet: f64| NoiseStats {
        jets: [JetStats {
            sum_sq: jet * jet,
            dof: 1,
            fits: JET_MIN_FITS,
        }; 2],
        ..relief(0.8)
    };
    assert!((Smoothing::Measured.voxels(&share(1.0), None) - 0.64).abs() < 1e-9);
    assert_eq!(
        Smoothing::Measured.voxels(&share(2.0), None),
        SMOOTH_PRECISE_VOXELS
    );
    assert!((Smoothing::Measured.voxels(&share(0.7), None) - 1.0).abs() < 1e-9);
    // Pairs reading noise beyond the limit: one voxel.
    assert_eq!(Smoothing::Measured.voxels(&relief(1.9), None), 1.0);
    assert_eq!(
        Smoothing::Measured.voxels(&rough(0.02), None),
        SMOOTH_PRECISE_VOXELS
    );
    // A given width is the width.
    assert_eq!(Smoothing::Fixed(2.5).voxels(&within(0.0), None), 2.5);
    // Sparse samples widen the measured width to 0.4 of their spacing, up to 4 voxels;
    // dense ones keep it; a given width stays.
    assert_eq!(
        Smoothing::Measured.voxels(&within(0.0), Some(0.5)),
        SMOOTH_PRECISE_VOXELS
    );
    assert_eq!(Smoothing::Measured.voxels(&within(0.2), Some(2.0)), 1.0);
    assert!((Smoothing::Measured.voxels(&within(0.0), Some(7.5)) - 3.0).abs() < 1e-12);
    assert!((Smoothing::Measured.voxels(&within(0.2), Some(5.0)) - 2.0).abs() < 1e-12);
    assert_eq!(
        Smoothing::Measured.voxels(&within(0.0), Some(40.0)),
        SPARSE_MAX_VOXELS
    );
    assert_eq!(Smoothing::Fixed(0.5).voxels(&within(0.0), Some(7.5)), 0.5);
    assert_eq!(Smoothing::Measured.to_string(), "measured");
}
