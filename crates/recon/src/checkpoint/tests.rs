use super::*;
use crate::noise::{PAIR_BINS, PAIR_X_BINS};
use crate::pou::quantise_detail;

#[test]
fn coarse_checkpoints_round_trip_and_bad_ones_are_named() {
    let d = tempfile::tempdir().unwrap();
    let path = coarse_path(d.path());
    assert_eq!(read_coarse(&path).unwrap(), None);
    let c = CoarseCheckpoint {
        iterations: 7,
        point_weight: 1.25,
        noise: NoiseStats {
            sum_sq: 3.5,
            dof: 12,
            jets: [
                JetStats {
                    sum_sq: 0.5,
                    dof: 40,
                    fits: 3,
                },
                JetStats {
                    sum_sq: 0.75,
                    dof: 90,
                    fits: 2,
                },
            ],
            pairs: PairStats {
                bins: std::array::from_fn(|j| {
                    std::array::from_fn(|i| [i as f64, 0.5, 0.25 * i as f64, 7.0, -1.5 * j as f64])
                }),
            },
        },
        field: Cow::Borrowed(&[1.0, -2.5, f32::MIN_POSITIVE]),
        density: Cow::Borrowed(&[0, 256, 77]),
        support: Cow::Borrowed(&[u64::MAX, 5]),
        occupied: vec![CellKey::new(3, [1, 2, 3]), CellKey::new(3, [4, 0, 7])],
    };
    write_coarse(&path, &c).unwrap();
    assert_eq!(read_coarse(&path).unwrap(), Some(c.clone()));
    // Cut short, a flipped bit in the density counts, and a foreign file: errors naming
    // the file.
    let z = std::fs::read(&path).unwrap();
    let raw = zstd::stream::decode_all(&z[..]).unwrap();
    let mut flipped = raw.clone();
    flipped[8 + 4 + 8 + 16 + 48 + 40 * PAIR_BINS * PAIR_X_BINS + 8 + 12 + 8] ^= 1;
    for cut in [&raw[..raw.len() - 3], &flipped[..], &b"SFLEAF03xxxx"[..]] {
        std::fs::write(&path, zstd::bulk::compress(cut, 1).unwrap()).unwrap();
        let e = read_coarse(&path).unwrap_err().to_string();
        assert!(
            e.contains("coarse.zst") && e.contains("corrupt coarse checkpoint"),
            "{e}"
        );
    }
}

#[test]
fn coarse_parts_round_trip_and_bad_ones_are_named() {
    let d = tempfile::tempdir().unwrap();
    let dens = vec![
        DensityBox {
            lo: [1, 2, 3],
            dims: [2, 1, 2],
            counts: vec![0, 256, 7, u32::MAX],
        },
        DensityBox::default(),
    ];
    let splat = vec![CellSplat {
        splat: SplatBox {
            lo: [-1, 0, 5],
            dims: [1, 2, 1],
            values: vec![[1.0, -0.5, 2.0], [f32::MIN_POSITIVE, 0.0, -3.0]],
        },
        screen: vec![(4, ([0.5, 0.25, 1.5], 3)), (70, ([0.0; 3], 1))],
        noise: NoiseStats {
            sum_sq: 2.5,
            dof: 4,
            jets: [JetStats {
                sum_sq: 0.5,
                dof: 6,
                fits: 1,
            }; 2],
            pairs: PairStats {
                bins: std::array::from_fn(|j| {
                    std::array::from_fn(|i| [2.0, 0.5, 0.125, j as f64, 0.25 * i as f64])
                }),
            },
        },
        moments: std::array::from_fn(|i| i as f64 * 0.5 - 1.0),
        marks: vec![3, 8, 1 << 40],
        leaves: vec![CellKey::new(4, [1, 2, 3])],
    }];
    let (dp, sp) = (
        coarse_part_path(d.path(), CoarsePartKind::Density, 3),
        coarse_part_path(d.path(), CoarsePartKind::Splat, 3),
    );
    assert_ne!(dp, sp);
    write_density_parts(&dp, &dens).unwrap();
    write_splat_parts(&sp, &splat).unwrap();
    assert_eq!(read_density_parts(&dp).unwrap(), dens);
    assert_eq!(read_splat_parts(&sp).unwrap(), splat);
    // Cut short, a flipped bit, the other kind, and none: errors naming the file.
    let raw = zstd::stream::decode_all(&std::fs::read(&sp).unwrap()[..]).unwrap();
    let mut flipped = raw.clone();
    flipped[30] ^= 1;
    let dens_raw = std::fs::read(&dp).unwrap();
    for bad in [
        zstd::bulk::compress(&raw[..raw.len() - 3], 1).unwrap(),
        zstd::bulk::compress(&flipped, 1).unwrap(),
        dens_raw,
    ] {
        std::fs::write(&sp, bad).unwrap();
        let e = read_splat_parts(&sp).unwrap_err().to_string();
        assert!(
            e.contains("coarse-splat-000003.zst") && e.contains("corrupt coarse pass part"),
            "{e}"
        );
    }
    std::fs::remove_file(&dp).unwrap();
    let e = read_density_parts(&dp).unwrap_err().to_string();
    assert!(e.contains("coarse-density-000003.zst"), "{e}");
}

#[test]
fn leaf_checkpoints_round_trip_and_bad_ones_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let m = 5;
    let key = CellKey::new(3, [1, 2, 3]);
    let raw: Vec<f32> = (0..m * m * m).map(|i| (i as f32 - 60.0) * 0.37).collect();
    let refined = LeafDetail {
        detail: Some(quantise_detail(&raw, 1.0 / 64.0)),
        iso_sum: -12.5,
        iso_count: 7,
        iterations: 0,
    };
    write_leaf(dir.path(), key, &refined).unwrap();
    let back = read_leaf(dir.path(), key, m).unwrap();
    assert_eq!(back.detail, refined.detail);
    assert_eq!((back.iso_sum, back.iso_count), (-12.5, 7));
    assert_eq!(
        leaf_detail(dir.path(), key, m).unwrap(),
        refined.detail.unwrap()
    );
    // A leaf left to the coarse solution: no detail, which the tile stage must not read.
    let plain = CellKey::new(3, [0, 0, 0]);
    let coarse = LeafDetail {
        detail: None,
        iso_sum: 1.0,
        iso_count: 2,
        iterations: 0,
    };
    write_leaf(dir.path(), plain, &coarse).unwrap();
    assert!(read_leaf(dir.path(), plain, m).unwrap().detail.is_none());
    // The header alone gives what the leaf pass sums (shards read others' leaves so).
    let s = read_leaf_summary(dir.path(), key).unwrap();
    assert_eq!((s.iso_sum, s.iso_count, s.has_detail), (-12.5, 7, true));
    let s = read_leaf_summary(dir.path(), plain).unwrap();
    assert_eq!((s.iso_sum, s.iso_count, s.has_detail), (1.0, 2, false));
    let e = read_leaf_summary(dir.path(), CellKey::new(3, [5, 5, 5]));
    assert!(e.unwrap_err().to_string().contains(".zst"));
    let e = leaf_detail(dir.path(), plain, m).unwrap_err().to_string();
    assert!(e.contains("without a detail") && e.contains(".zst"), "{e}");
    // Bad files: another grid size, another cell, an older format, garbage.
    let e = read_leaf(dir.path(), key, m + 1).unwrap_err().to_string();
    assert!(
        e.contains("corrupt leaf checkpoint") && e.contains("expected"),
        "{e}"
    );
    std::fs::copy(leaf_path(dir.path(), key), leaf_path(dir.path(), plain)).unwrap();
    let e = read_leaf(dir.path(), plain, m).unwrap_err().to_string();
    assert!(e.contains("another cell"), "{e}");
    let mut old = b"SFLEAF01".to_vec();
    old.extend_from_slice(&[0; 24]);
    std::fs::write(
        leaf_path(dir.path(), key),
        zstd::bulk::compress(&old, 1).unwrap(),
    )
    .unwrap();
    let e = read_leaf(dir.path(), key, m).unwrap_err().to_string();
    assert!(
        e.contains("another version of scanflow") && e.contains("SFLEAF01"),
        "{e}"
    );
    std::fs::write(leaf_path(dir.path(), key), b"not zstd").unwrap();
    let e = read_leaf(dir.path(), key, m).unwrap_err().to_string();
    assert!(e.contains("corrupt leaf checkpoint"), "{e}");
}

#[test]
fn tile_checkpoints_round_trip_with_every_attribute() {
    let dir = tempfile::tempdir().unwrap();
    let path = tile_path(dir.path(), 5);
    let mut m = TileMesh {
        keys: vec![EdgeKey(3), EdgeKey(9), EdgeKey(12)],
        positions: vec![[0.5, 1.0, 2.0], [1.5, -1.0, 0.25], [3.0, 2.0, 1.0]],
        triangles: vec![[0, 1, 2]],
        ..TileMesh::default()
    };
    write_tile(&path, &m).unwrap();
    assert_eq!(read_tile(&path).unwrap(), m);
    m.colors = vec![[1, 2, 3], [4, 5, 6], [7, 8, 9]];
    m.density = vec![10.5, 20.0, 4.25];
    write_tile(&path, &m).unwrap();
    assert_eq!(read_tile(&path).unwrap(), m);
    m.intensity = vec![0.5, 0.25, 1.0];
    write_tile(&path, &m).unwrap();
    assert_eq!(read_tile(&path).unwrap(), m);
    // A density per vertex or none: anything else is corrupt.
    let raw = zstd::stream::decode_all(&std::fs::read(&path).unwrap()[..]).unwrap();
    let mut bad = raw.clone();
    bad[40] = 2;
    std::fs::write(&path, zstd::bulk::compress(&bad, 1).unwrap()).unwrap();
    let e = read_tile(&path).unwrap_err().to_string();
    assert!(e.contains("corrupt tile checkpoint"), "{e}");
}
