use super::*;

fn grid() -> LocalGrid {
    LocalGrid {
        n: 8,
        h: 0.5,
        origin: [-2.0; 3],
        unit: 4.0,
    }
}

#[test]
fn samples_of_one_voxel_become_one_aggregate_at_their_mean() {
    let g = grid();
    // Two samples in voxel (4, 4, 4) and one in voxel (1, 4, 4).
    let pos = [[0.1, 0.1, 0.1], [0.3, 0.2, 0.4], [-1.4, 0.2, 0.2]];
    let s = Screen::from_points(&g, &pos, 2.0);
    assert_eq!(s.len(), 2);
    // A linear function is interpolated exactly at the aggregates' mean positions.
    let f = |i: usize| {
        let (x, y, z) = (i % 8, (i / 8) % 8, i / 64);
        (x + 2 * y + 3 * z) as f32
    };
    let v: Vec<f32> = (0..512).map(f).collect();
    let at = s.gather(&v);
    let u = |p: [f64; 3]| (p[0] + 2.0) / 0.5 + 2.0 * (p[1] + 2.0) / 0.5 + 3.0 * (p[2] + 2.0) / 0.5;
    let mean = [0.2, 0.15, 0.25];
    assert!((at[0] - u([-1.4, 0.2, 0.2])).abs() < 1e-5, "{at:?}");
    assert!((at[1] - u(mean)).abs() < 1e-5, "{at:?}");
    // Weights: α/h² (cube units) per sample over the mean count, so the sum is
    // α/h² per occupied voxel.
    let h_u = 0.5 / 4.0;
    assert!((s.gamma_sum() - 2.0 * 2.0 / (h_u * h_u)).abs() < 1e-9);
    assert!((s.gamma()[1] / s.gamma()[0] - 2.0).abs() < 1e-12);
}

#[test]
fn the_dense_index_gathers_what_the_maps_gather() {
    let g = grid();
    // Points inside the grid and beyond it (wrapped), some sharing voxels; then voxel
    // sums on the grid's own lattice, one in a voxel the points hold.
    let pos: Vec<[f64; 3]> = (0..300)
        .map(|i| {
            let t = i as f64 * 0.618_033_988_7;
            [
                -3.0 + 6.0 * t.fract(),
                -2.0 + (t * 3.1).fract() * 3.0,
                (t * 7.3).fract(),
            ]
        })
        .collect();
    let sums: Vec<VoxelSum> = [[1i64, 2, 3], [5, 5, 2], [1, 2, 3]]
        .iter()
        .enumerate()
        .map(|(i, &at)| VoxelSum {
            at,
            corner: [[0.0; 3]; 8],
            offset: [0.3 * i as f64, 0.5, 0.25],
            mean: [0.0; 3],
            count: 2 + i as u32,
        })
        .collect();
    let on = OnLattice {
        origin: [0; 3],
        step: 1,
    };
    let build = |mut b: ScreenBuilder| {
        b.add(&pos[..200]);
        b.add_voxels(on, &sums);
        b.add_parts(&[
            &ScreenBuilder::part(&g, &pos[200..250]),
            &ScreenBuilder::part(&g, &pos[250..]),
        ]);
        b.finish(2.0)
    };
    let (maps, dense) = (
        build(ScreenBuilder::new(&g)),
        build(ScreenBuilder::dense(&g)),
    );
    assert!(maps.len() > 50);
    assert_eq!(maps.nodes(), dense.nodes());
    assert_eq!(maps.weights(), dense.weights());
    assert_eq!(maps.gamma(), dense.gamma());
}

#[test]
fn scatter_is_the_transpose_of_gather() {
    let g = grid();
    let pos: Vec<[f64; 3]> = (0..40)
        .map(|i| {
            let t = i as f64 * 0.37;
            [t.sin() * 1.7, (1.3 * t).cos() * 1.7, (0.7 * t).sin() * 1.9]
        })
        .collect();
    let s = Screen::from_points(&g, &pos, 1.0);
    let u: Vec<f32> = (0..512).map(|i| ((i * 37) % 19) as f32 - 9.0).collect();
    let c: Vec<f64> = (0..s.len()).map(|a| (a as f64 * 0.61).sin()).collect();
    // ⟨S u, c⟩ = ⟨u, Sᵀ c⟩.
    let lhs: f64 = s.gather(&u).iter().zip(&c).map(|(a, b)| a * b).sum();
    let mut st = vec![0f32; 512];
    s.scatter_add(&c, &mut st);
    let rhs: f64 = u.iter().zip(&st).map(|(a, b)| *a as f64 * *b as f64).sum();
    assert!((lhs - rhs).abs() < 1e-4 * lhs.abs().max(1.0), "{lhs} {rhs}");
}

#[test]
fn a_zero_weight_screens_nothing() {
    assert!(Screen::from_points(&grid(), &[[0.0; 3]], 0.0).is_empty());
}
