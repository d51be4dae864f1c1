use super::deform::{STRETCH, clamp_stretch, sym_eigen_range};
use super::labels::{remove_turns, triangle_graph};
use super::*;
use crate::frames::{matchings, singularities};
use crate::param::{Field, ParamParams, param_volume, parameterise_with};
use crate::rotation::Rot;
use crate::topology::check_tets;
use nalgebra::Rotation3;

/// The grid box rotated by `r` about the origin.
fn turned_box(r: &Matrix3<f64>) -> TetMesh {
    let mut m = TetMesh::grid_box([4, 3, 2], 0.5);
    for p in &mut m.verts {
        let q = r * Vector3::from(*p);
        *p = [q[0], q[1], q[2]];
    }
    m
}

#[test]
fn a_tongue_between_two_levels_of_a_plane_is_relabelled() {
    // A strip of columns x = i: a +y wall (y = 0, z 0..1), a −z step (z = 1, y 0..h),
    // and a +y wall above (y = h, z 1..2). The step's height h fades from 1 to 0 over
    // x 4..8, so past x = 8 the two +y walls are one plane; left of x = 0 the upper
    // wall is −z too, joining the step into a larger −z chart. The step between x = 0 and
    // x = 8 is a tongue: its border with the +y chart is concave below and convex above.
    let h = |i: i32| (1.0 - (f64::from(i) - 4.0).max(0.0) / 4.0).max(0.0);
    let (cols, rows) = (-6..=12, 7u32);
    let mut y = Vec::new();
    for i in cols.clone() {
        for j in 0..rows {
            let x = f64::from(i);
            let jf = f64::from(j);
            y.push(match j {
                0..=2 => [x, 0.0, 0.5 * jf],
                3 | 4 => [x, h(i) * (jf - 2.0) / 2.0, 1.0],
                _ => [x, h(i), 1.0 + 0.5 * (jf - 4.0)],
            });
        }
    }
    let v = |i: i32, j: u32| ((i + 6) as u32) * rows + j;
    let (mut tris, mut lab) = (Vec::new(), Vec::new());
    for i in -6..12 {
        for j in 0..rows - 1 {
            let l = match j {
                0 | 1 => 2,
                2 | 3 if i < 8 => 5,
                2 | 3 => 2,
                _ if i < 0 => 5,
                _ => 2,
            };
            tris.push([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
            tris.push([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
            lab.extend([l, l]);
        }
    }
    let (adj, shared) = triangle_graph(&tris);
    let before = lab.clone();
    assert!(remove_turns(&tris, &adj, &shared, &mut lab, &y));
    for (k, t) in tris.iter().enumerate() {
        let x = t.iter().map(|&p| y[p as usize][0]).sum::<f64>() / 3.0;
        let step = before[k] == 5 && (2..4).contains(&(t[0] % rows));
        // The tongue is +y now; the rest of the −z chart, and everything else, is kept.
        let want = if step && x > 0.0 { 2 } else { before[k] };
        assert_eq!(lab[k], want, "triangle {k} at x {x}");
    }
    // No border turns any more.
    assert!(!remove_turns(&tris, &adj, &shared, &mut lab, &y));
}

#[test]
fn the_closed_form_stretch_range_matches_the_singular_values() {
    // Deterministic pseudo-random gradients, some stretched past the bounds, and the
    // diagonal and repeated-eigenvalue cases the closed form treats apart.
    let mut seed = 7u64;
    let mut next = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut cases: Vec<Matrix3<f64>> = (0..200)
        .map(|k| Matrix3::from_fn(|_, _| next()) * (0.3 + k as f64 / 40.0))
        .collect();
    cases.push(Matrix3::from_diagonal(&Vector3::new(0.4, 1.0, 3.0)));
    cases.push(Matrix3::identity() * 2.0);
    cases.push(Rotation3::new(Vector3::new(0.3, 0.1, -0.2)).into_inner());
    for m in cases {
        let sv = m.singular_values();
        let (lo, hi) = sym_eigen_range(&(m.transpose() * m));
        let (smin, smax) = (sv.min(), sv.max());
        assert!(
            (lo - smin * smin).abs() < 1e-9 * (1.0 + smax * smax),
            "{m} {lo} {smin}"
        );
        assert!(
            (hi - smax * smax).abs() < 1e-9 * (1.0 + smax * smax),
            "{m} {hi} {smax}"
        );
        // Within the bounds the clamp returns the gradient itself.
        let c = clamp_stretch(&m, STRETCH);
        if smin >= STRETCH && smax <= 1.0 / STRETCH {
            assert_eq!(c, m);
        } else {
            let cs = c.singular_values();
            assert!(cs.min() >= STRETCH - 1e-12 && cs.max() <= 1.0 / STRETCH + 1e-12);
        }
    }
}

#[test]
fn an_axis_aligned_box_is_already_a_polycube() {
    let m = TetMesh::grid_box([3, 3, 2], 1.0);
    let topo = check_tets(&m).unwrap();
    let Polycube {
        frames,
        deformed: y,
        report: rep,
        ..
    } = polycube_frames(&m, &topo, &PolycubeParams::default()).unwrap();
    assert_eq!(rep.iterations, 0);
    assert_eq!(rep.flipped, 0);
    assert!(rep.mean_deviation < 1e-9);
    assert_eq!(y, m.verts);
    for f in frames {
        for (a, b) in f
            .iter()
            .flatten()
            .zip(super::super::frames::IDENTITY.iter().flatten())
        {
            assert!((a - b).abs() < 1e-12);
        }
    }
}

#[test]
fn a_turned_box_is_turned_back_and_its_frames_follow_its_edges() {
    let r = Rotation3::new(Vector3::new(0.2, -0.3, 0.25)).into_inner();
    let m = turned_box(&r);
    let topo = check_tets(&m).unwrap();
    let Polycube {
        frames,
        report: rep,
        ..
    } = polycube_frames(&m, &topo, &PolycubeParams::default()).unwrap();
    assert!(rep.mean_deviation_start > 10.0, "{rep:?}");
    assert!(rep.mean_deviation < 1.0, "{rep:?}");
    assert_eq!(rep.flipped, 0);
    // Each frame axis is within 8° of one of the box's turned edges (the iteration stops
    // at a mean boundary deviation of 1°).
    for f in &frames {
        for axis in f {
            let a = Vector3::from(*axis);
            let best = (0..3)
                .map(|c| a.dot(&r.column(c)).abs())
                .fold(0.0, f64::max);
            assert!(best > 0.99, "{axis:?}");
        }
    }
    let m2 = matchings(&frames, &topo);
    assert!(m2.iter().flatten().all(|&x| x == Rot::ID));
    assert!(singularities(&m, &topo, &frames, &m2).edges.is_empty());
}

#[test]
fn a_rounded_solid_gets_charts_and_no_interior_singularity() {
    // A cylinder of radius 1 and height 1 along z, stuffed with tetrahedra: the
    // deformation squares its cross-section.
    let f = |p: [f64; 3]| (p[0].hypot(p[1]) - 1.0).max(p[2].abs() - 0.5);
    let (m, _) = crate::stuffing::stuff(
        &f,
        [-1.2, -1.2, -0.7],
        [1.2, 1.2, 0.7],
        &crate::stuffing::StuffingParams::new(0.2),
    )
    .unwrap();
    let topo = check_tets(&m).unwrap();
    let Polycube {
        frames,
        gradients,
        axes,
        report: rep,
        ..
    } = polycube_frames(&m, &topo, &PolycubeParams::default()).unwrap();
    assert!(
        rep.mean_deviation < rep.mean_deviation_start / 3.0,
        "{rep:?}"
    );
    assert_eq!(rep.flipped, 0, "{rep:?}");
    assert!(rep.labels.iter().all(|&n| n > 0), "{rep:?}");
    // No interior singularity, and the polycube map flips nothing at three scales,
    // drawn towards the frames or towards the deformation.
    let ident = vec![[Rot::ID; 4]; m.tets.len()];
    let sing = singularities(&m, &topo, &frames, &ident);
    assert!(sing.edges.is_empty() && sing.invalid.is_empty());
    for targets in [&frames, &gradients] {
        for scale in [0.5, 0.35, 0.25] {
            let (map, rep) = parameterise_with(
                &m,
                &topo,
                &Field {
                    frames: &frames,
                    targets,
                    axes: Some(&axes),
                    matchings: &ident,
                    singular: &[],
                },
                &ParamParams {
                    scale,
                    ..Default::default()
                },
            )
            .unwrap();
            assert_eq!(rep.flipped_final, 0, "{scale}: {rep:?}");
            assert!(map.uvw.iter().all(|u| param_volume(u) > 0.0));
            assert!(rep.integer_unknowns > 0);
        }
    }
}
