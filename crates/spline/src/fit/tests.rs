use super::*;

/// Scattered points on `z = f(x, y)` over `[0, 1]²` (a low-discrepancy sequence, so the test
/// needs no generator).
fn height_field(n: usize, f: impl Fn(f64, f64) -> f64) -> (Vec<[f64; 3]>, Vec<[f64; 2]>) {
    let mut pts = Vec::with_capacity(n);
    let mut uv = Vec::with_capacity(n);
    for k in 0..n {
        let x = (k as f64 * 0.754_877_666_246_692_7 + 0.1).fract();
        let y = (k as f64 * 0.569_840_290_998_053_3 + 0.3).fract();
        pts.push([x, y, f(x, y)]);
        uv.push([x, y]);
    }
    (pts, uv)
}

fn bump(x: f64, y: f64) -> f64 {
    0.1 * (2.0 * x).sin() * (1.5 * y).cos()
        + 0.05 * (-((x - 0.7).powi(2) + (y - 0.3).powi(2)) / 0.004).exp()
}

#[test]
fn approximation_meets_the_tolerance_and_the_truth() {
    let (pts, uv) = height_field(4000, bump);
    let params = FitParams {
        tolerance: 1e-3,
        ..FitParams::default()
    };
    let fit = fit(&pts, &uv, [1.0, 1.0], &params).unwrap();
    let r = &fit.report;
    assert!(r.met, "{r:?}");
    assert!(r.max_deviation <= 1e-3);
    assert!(r.missed.is_empty());
    // The surface between the points follows the truth.
    let mut worst: f64 = 0.0;
    for k in 0..400 {
        let (x, y) = (
            0.05 + 0.9 * (k as f64 * 0.618).fract(),
            0.05 + 0.9 * (k as f64 * 0.382).fract(),
        );
        let q = [x, y, bump(x, y)];
        let (_, d) = tensor::project(&fit.surface, q, [x + 0.02 * 1.04, y + 0.02 * 1.04]);
        worst = worst.max(d);
    }
    assert!(worst < 3e-3, "{worst}");
}

#[test]
fn local_refinement_needs_fewer_control_points_than_global() {
    let (pts, uv) = height_field(6000, bump);
    let base = FitParams {
        tolerance: 2e-4,
        ..FitParams::default()
    };
    let local = fit(&pts, &uv, [1.0, 1.0], &base).unwrap().report;
    let global = fit(
        &pts,
        &uv,
        [1.0, 1.0],
        &FitParams {
            refine: Refine::Global,
            ..base.clone()
        },
    )
    .unwrap()
    .report;
    assert!(local.met && global.met, "{local:?} {global:?}");
    assert!(
        local.control_points < global.control_points,
        "local {} global {}",
        local.control_points,
        global.control_points
    );
}

#[test]
fn interpolation_hits_every_point() {
    let (pts, uv) = height_field(300, bump);
    let params = FitParams {
        tolerance: 1e-9,
        interpolate: true,
        ..FitParams::default()
    };
    let fit = fit(&pts, &uv, [1.0, 1.0], &params).unwrap();
    assert!(
        fit.report.max_residual < 1e-9 * 2f64.sqrt(),
        "{:?}",
        fit.report
    );
    assert!(fit.report.max_deviation <= fit.report.max_residual + 1e-15);
}

#[test]
fn data_dependent_fairness_meets_the_tolerance() {
    let (pts, uv) = height_field(3000, bump);
    let params = FitParams {
        tolerance: 1e-3,
        fairness: Fairness::Data,
        ..FitParams::default()
    };
    let fit = fit(&pts, &uv, [1.0, 1.0], &params).unwrap();
    assert!(fit.report.met, "{:?}", fit.report);
    assert!(fit.report.fairness_energy > 0.0);
}

#[test]
fn an_unreachable_tolerance_reports_the_regions_that_miss_it() {
    let (pts, uv) = height_field(3000, bump);
    let params = FitParams {
        tolerance: 1e-6,
        max_level: 1,
        ..FitParams::default()
    };
    let fit = fit(&pts, &uv, [1.0, 1.0], &params).unwrap();
    assert!(!fit.report.met);
    assert!(!fit.report.missed.is_empty());
    let counted: usize = fit.report.missed.iter().map(|m| m.points).sum();
    let beyond = fit.distance.iter().filter(|&&d| d > 1e-6).count();
    assert_eq!(counted, beyond);
}

#[test]
fn too_few_points_is_an_error() {
    let e = fit(
        &[[0.0; 3]; 2],
        &[[0.0; 2]; 2],
        [1.0, 1.0],
        &FitParams::default(),
    );
    assert_eq!(e.err(), Some(FitError::TooFewPoints(2)));
}
