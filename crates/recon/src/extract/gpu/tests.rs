//! GPU tests: every mesh against the CPU kernel's (keys, positions bit for bit, triangles),
//! on any adapter, Mesa lavapipe included; without one they print why and skip.

use rand::{Rng, SeedableRng};

use super::adapter::describe;
use super::passes::{CASE_INFO, USED_START, iso_key, table_words};
use super::plan::{SubBlock, block_bytes, plan};
use super::*;
use crate::extract::tables;

/// Why GPU tests skip, given the adapters wgpu lists: only when there is none at all.
fn skip_reason(adapters: &[String]) -> Option<String> {
    adapters.is_empty().then(|| {
        "skipping GPU test: wgpu finds no adapter (no Vulkan driver; \
         `apt-get install mesa-vulkan-drivers` gives Mesa's lavapipe)"
            .to_string()
    })
}

/// The GPU path on any adapter (lavapipe included), or `None` with the reason printed
/// when there is no adapter at all. Any other failure to open one fails the test.
fn gpu() -> Option<GpuExtractor> {
    if let Some(why) = skip_reason(&adapter_names()) {
        eprintln!("{why}");
        return None;
    }
    let g = GpuExtractor::new(GpuMode::On)
        .expect("an adapter exists, so --gpu on must open one")
        .expect("--gpu on gives an extractor");
    eprintln!(
        "GPU tests on {}, buffers up to {} bytes",
        describe(&g.info),
        g.max_buffer_bytes()
    );
    Some(g)
}

fn idx(dims: [usize; 3], x: usize, y: usize, z: usize) -> usize {
    (z * dims[1] + y) * dims[0] + x
}

fn random_field(seed: u64, dims: [usize; 3]) -> Vec<f32> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    (0..dims[0] * dims[1] * dims[2])
        .map(|_| rng.random_range(-1.0f32..1.0))
        .collect()
}

fn field(dims: [usize; 3], mut f: impl FnMut(usize, usize, usize) -> f32) -> Vec<f32> {
    let mut v = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                v.push(f(x, y, z));
            }
        }
    }
    v
}

/// The GPU mesh is the CPU mesh: same keys, bitwise the same positions, same triangles.
fn assert_same(
    g: &mut GpuExtractor,
    values: &[f32],
    dims: [usize; 3],
    origin: [u64; 3],
    iso: f32,
    geom: &GridGeom,
) -> GpuStats {
    let mut want = TileMesh::default();
    let cs = McWorkspace::new()
        .extract(values, dims, origin, iso, geom, &mut want)
        .unwrap();
    let mut got = TileMesh {
        keys: vec![crate::types::EdgeKey(7)],
        ..TileMesh::default()
    };
    let gs = g
        .extract(values, dims, origin, iso, geom, &mut got)
        .unwrap();
    assert!(!gs.fell_back, "{dims:?}: fell back to the CPU");
    assert_eq!((gs.cells, gs.active_cells), (cs.cells, cs.active_cells));
    assert_eq!(got.keys, want.keys, "{dims:?} iso {iso}: keys");
    let bits = |m: &TileMesh| -> Vec<[u64; 3]> {
        m.positions.iter().map(|p| p.map(f64::to_bits)).collect()
    };
    assert!(bits(&got) == bits(&want), "{dims:?} iso {iso}: positions");
    assert_eq!(
        got.triangles, want.triangles,
        "{dims:?} iso {iso}: triangles"
    );
    gs
}

/// The GPU mesh of a blended tile is the CPU mesh of its field, [`Blend::eval`].
fn assert_same_blend(g: &mut GpuExtractor, b: &Blend, iso: f32, geom: &GridGeom) -> GpuStats {
    let values = b.eval();
    let origin = b.lo.map(|v| v as u64);
    let mut want = TileMesh::default();
    McWorkspace::new()
        .extract(&values, b.dims, origin, iso, geom, &mut want)
        .unwrap();
    let mut got = TileMesh::default();
    let gs = g.extract_blend(b, iso, geom, &mut got).unwrap();
    assert!(!gs.fell_back, "{:?}: fell back to the CPU", b.dims);
    assert!(!want.triangles.is_empty(), "a test tile without surface");
    assert_eq!(got.keys, want.keys, "{:?} at {:?}: keys", b.dims, b.lo);
    let bits = |m: &TileMesh| -> Vec<[u64; 3]> {
        m.positions.iter().map(|p| p.map(f64::to_bits)).collect()
    };
    assert!(bits(&got) == bits(&want), "{:?}: positions", b.dims);
    assert_eq!(got.triangles, want.triangles, "{:?}: triangles", b.dims);
    gs
}

#[test]
fn blended_fields_match_the_cpu() {
    use crate::extract::field::tests::RandomBlend;
    let Some(mut g) = gpu() else { return };
    let geom = GridGeom::new([0.0, 0.0, 0.0], 0.01, 1024).unwrap();
    for (seed, lo, dims, e, fill) in [
        (1, [0, 0, 0], [33, 33, 33], 32, 0.7),
        (2, [64, 32, 96], [65, 17, 40], 32, 0.5),
        (3, [40, 8, 0], [20, 30, 50], 16, 1.0),
        (4, [8, 16, 24], [9, 9, 9], 8, 0.3),
    ] {
        let rb = RandomBlend::new(seed, lo, dims, e, fill);
        // Each random blend names its leaves 0, 1, ...
        g.forget_leaves();
        for iso in [0.0, 0.3] {
            let s = assert_same_blend(&mut g, &rb.blend(), iso, &geom);
            assert!(s.field_on_gpu, "seed {seed}: blended on the host");
        }
    }
}

#[test]
fn gpu_errors_on_blended_tiles_fall_back_to_the_cpu() {
    use crate::extract::field::tests::RandomBlend;
    let Some(mut g) = gpu() else { return };
    let geom = GridGeom::new([0.0, 0.0, 0.0], 0.01, 1024).unwrap();
    let rb = RandomBlend::new(21, [32, 0, 64], [33, 20, 25], 32, 0.8);
    let b = rb.blend();
    let mut want = TileMesh::default();
    McWorkspace::new()
        .extract(&b.eval(), b.dims, [32, 0, 64], 0.1, &geom, &mut want)
        .unwrap();
    // A validation error on the device: this tile on the CPU, the next on the GPU.
    g.fail_next = true;
    let mut got = TileMesh::default();
    let s = g.extract_blend(&b, 0.1, &geom, &mut got).unwrap();
    assert!(s.fell_back);
    assert_eq!(got, want);
    let s = assert_same_blend(&mut g, &b, 0.1, &geom);
    assert!(s.field_on_gpu);
    // Inconsistent tables are the caller's error, not a fallback.
    let mut bad = rb.blend();
    bad.axes[0].w0.pop();
    let e = g.extract_blend(&bad, 0.1, &geom, &mut got).unwrap_err();
    assert!(e.to_string().contains("axis 0"), "{e}");
}

#[test]
fn resident_leaves_are_not_sent_again() {
    use crate::extract::field::tests::RandomBlend;
    let Some(mut g) = gpu() else { return };
    let geom = GridGeom::new([0.0, 0.0, 0.0], 0.01, 1024).unwrap();
    let rb = RandomBlend::new(9, [32, 32, 32], [33, 33, 33], 32, 1.0);
    let b = rb.blend();
    let first = assert_same_blend(&mut g, &b, 0.0, &geom);
    let again = assert_same_blend(&mut g, &b, 0.1, &geom);
    let slot = 4 * (b.dm() as u64).pow(3);
    assert!(
        first.upload_bytes >= 8 * slot,
        "{} bytes",
        first.upload_bytes
    );
    assert!(
        again.upload_bytes < slot,
        "{} bytes sent again",
        again.upload_bytes
    );
    // Other data under the same ids needs forget_leaves.
    g.forget_leaves();
    let other = RandomBlend::new(10, [32, 32, 32], [33, 33, 33], 32, 1.0);
    assert_same_blend(&mut g, &other.blend(), 0.0, &geom);
}

#[test]
fn blended_sub_blocks_and_host_blending_give_the_same_mesh() {
    use crate::extract::field::tests::RandomBlend;
    let Some(mut g) = gpu() else { return };
    let geom = GridGeom::new([0.0, 0.0, 0.0], 0.01, 1024).unwrap();
    let rb = RandomBlend::new(12, [16, 8, 0], [33, 17, 41], 8, 0.1);
    let b = rb.blend();
    // Several slabs, the leaves on the device.
    g.set_max_buffer_bytes(200_000);
    let s = assert_same_blend(&mut g, &b, 0.0, &geom);
    assert!(s.sub_blocks > 1 && s.field_on_gpu, "{s:?}");
    // Too small a pool for the tile's leaves: blended on the host, same mesh.
    g.set_max_buffer_bytes(4 * 13 * 13 * 13);
    let s = assert_same_blend(&mut g, &b, 0.0, &geom);
    assert!(!s.field_on_gpu, "{s:?}");
}

#[test]
fn gpu_mode_parses_and_names_the_options() {
    assert_eq!("auto".parse::<GpuMode>().unwrap(), GpuMode::Auto);
    assert_eq!("on".parse::<GpuMode>().unwrap(), GpuMode::On);
    assert_eq!("off".parse::<GpuMode>().unwrap(), GpuMode::Off);
    let e = "yes".parse::<GpuMode>().unwrap_err().to_string();
    assert!(e.contains("\"yes\"") && e.contains("auto, on, off"), "{e}");
    for m in [GpuMode::Auto, GpuMode::On, GpuMode::Off] {
        assert_eq!(m.to_string().parse::<GpuMode>().unwrap(), m);
    }
    assert!(GpuExtractor::new(GpuMode::Off).unwrap().is_none());
}

#[test]
fn no_adapter_is_a_skip_with_a_reason() {
    let why = skip_reason(&[]).unwrap();
    assert!(why.contains("no adapter") && why.contains("mesa-vulkan-drivers"));
    assert_eq!(skip_reason(&["llvmpipe".to_string()]), None);
}

/// The tables buffer holds exactly the case tables the CPU kernel uses.
#[test]
fn table_words_match_the_case_tables() {
    let w = table_words();
    for case in 0..=255u8 {
        let c = case as usize;
        let tris = &w[w[c] as usize..w[c + 1] as usize];
        let want: Vec<u32> = tables::case_triangles(case)
            .iter()
            .flatten()
            .map(|&e| e as u32)
            .collect();
        assert_eq!(tris, &want[..], "case {case}");
        let used = &w[w[USED_START + c] as usize..w[USED_START + c + 1] as usize];
        let want: Vec<u32> = tables::case_edges(case).iter().map(|&e| e as u32).collect();
        assert_eq!(used, &want[..], "case {case}");
        let info = w[CASE_INFO + c];
        assert_eq!(info & 15, tables::case_triangles(case).len() as u32);
        assert_eq!(info >> 4, tables::crossing_edges(case) as u32);
    }
}

#[test]
fn extractor_is_send() {
    fn send<T: Send>() {}
    send::<GpuExtractor>();
}

#[test]
fn iso_keys_order_like_floats() {
    let vals = [
        f32::NEG_INFINITY,
        -1e30,
        -1.0,
        -f32::MIN_POSITIVE,
        -1e-45,
        -0.0,
        0.0,
        1e-45,
        f32::MIN_POSITIVE,
        0.5,
        1.0,
        f32::INFINITY,
    ];
    for &a in &vals {
        for &b in &vals {
            assert_eq!(iso_key(a) < iso_key(b), a < b, "{a} < {b}");
        }
    }
    assert_eq!(iso_key(f32::NAN), 0);
}

/// The cells of `blocks` (tile cell indices), in block order, each block in cell order.
fn cell_order(blocks: &[SubBlock], dims: [usize; 3]) -> Vec<usize> {
    let mut order = Vec::new();
    for b in blocks {
        assert!(b.dims.iter().all(|&d| d >= 2));
        for z in 0..b.dims[2] - 1 {
            for y in 0..b.dims[1] - 1 {
                for x in 0..b.dims[0] - 1 {
                    order.push(idx(dims, b.at[0] + x, b.at[1] + y, b.at[2] + z));
                }
            }
        }
    }
    order
}

/// Sub-blocks, planned or halved down to single cells, cover every cell once, share
/// faces, fit the limit, and list cells in the tile's cell order.
#[test]
fn sub_blocks_keep_the_tile_cell_order() {
    let dims = [7, 6, 5];
    let want: Vec<usize> = (0..6 * 5 * 4)
        .map(|i| idx(dims, i % 6, (i / 6) % 5, i / 30))
        .collect();
    for limit in [128u64, 300, 500, 1500, 2100, 1 << 40] {
        let mut blocks = plan(dims, limit).unwrap();
        for b in &blocks {
            assert!(block_bytes(b.dims.map(|d| d - 1)).1 <= limit);
        }
        assert_eq!(cell_order(&blocks, dims), want, "limit {limit}");
        // Halve the first halvable block until all are single cells.
        while let Some(i) = blocks.iter().position(|b| b.halve().is_some()) {
            let (lo, hi) = blocks[i].halve().unwrap();
            blocks.splice(i..=i, [lo, hi]);
            assert_eq!(cell_order(&blocks, dims), want, "limit {limit}");
        }
        assert_eq!(blocks.len(), want.len());
    }
    assert_eq!(plan(dims, 1 << 40).unwrap().len(), 1);
    assert_eq!(plan(dims, 1 << 40).unwrap()[0].seam_mask(dims), 0);
    assert_eq!(plan(dims, 128).unwrap().len(), 6 * 5 * 4);
    assert!(plan(dims, 127).is_err());
    let b = SubBlock {
        at: [0, 2, 1],
        dims: [7, 2, 4],
    };
    assert_eq!(b.seam_mask(dims), 0b01_1100);
}

#[test]
fn random_fields_match_the_cpu() {
    let Some(mut g) = gpu() else { return };
    let geom = GridGeom::new([0.5, -2.0, 7.0], 0.25, 200).unwrap();
    for (seed, dims) in [
        [2, 2, 2],
        [3, 2, 2],
        [4, 5, 6],
        [17, 9, 33],
        [33, 17, 9],
        [70, 70, 70],
    ]
    .into_iter()
    .enumerate()
    {
        let v = random_field(seed as u64, dims);
        for iso in [0.0, 0.37, -0.9] {
            assert_same(&mut g, &v, dims, [3, 1, 4], iso, &geom);
        }
    }
}

/// More than 1024² nodes: three levels of block sums.
#[test]
fn three_scan_levels_match_the_cpu() {
    let Some(mut g) = gpu() else { return };
    let dims = [130, 101, 81];
    let geom = GridGeom::new([0.0; 3], 1.0, 300).unwrap();
    let v = random_field(77, dims);
    let s = assert_same(&mut g, &v, dims, [0; 3], 0.1, &geom);
    assert_eq!(s.sub_blocks, 1);
}

#[test]
fn checkerboards_of_ambiguous_cases_match_the_cpu() {
    let Some(mut g) = gpu() else { return };
    let geom = GridGeom::new([-1.0, 0.0, 1.0], 0.5, 100).unwrap();
    for parity in 0..2 {
        for dims in [[9, 8, 7], [40, 33, 20]] {
            let v = field(
                dims,
                |x, y, z| {
                    if (x + y + z) % 2 == parity { -1.0 } else { 1.0 }
                },
            );
            let s = assert_same(&mut g, &v, dims, [1, 2, 3], 0.0, &geom);
            assert_eq!(s.active_cells, s.cells);
        }
    }
    // Checkerboards of planes and lines: other ambiguous faces.
    let dims = [21, 22, 23];
    let v = field(dims, |x, y, _| if (x + y) % 2 == 0 { -1.0 } else { 1.0 });
    assert_same(&mut g, &v, dims, [0; 3], 0.0, &geom);
    let v = field(
        dims,
        |x, _, z| if (x / 2 + z) % 2 == 0 { -1.0 } else { 1.0 },
    );
    assert_same(&mut g, &v, dims, [0; 3], 0.0, &geom);
}

#[test]
fn sphere_matches_the_cpu() {
    let Some(mut g) = gpu() else { return };
    let dims = [48, 41, 45];
    let geom = GridGeom::new([-3.0, 1.0, 2.5], 0.3, 100).unwrap();
    let origin = [2, 3, 4];
    let c = geom.node_position([26, 23, 27]);
    let v = field(dims, |x, y, z| {
        let p = geom.node_position([x as u64 + 2, y as u64 + 3, z as u64 + 4]);
        let d = ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt();
        (d - 5.3) as f32
    });
    let s = assert_same(&mut g, &v, dims, origin, 0.0, &geom);
    assert!(s.active_cells > 1000 && s.active_cells < s.cells / 4);
    // A sphere cut by the block's border, and one that misses it.
    assert_same(&mut g, &v, dims, origin, 4.0, &geom);
    let s = assert_same(&mut g, &v, dims, origin, -100.0, &geom);
    assert_eq!(s.active_cells, 0);
}

/// Values at iso (both zeros), NaN, infinities and subnormals classify as on the CPU.
#[test]
fn special_values_match_the_cpu() {
    let Some(mut g) = gpu() else { return };
    let specials = [
        0.0,
        -0.0,
        f32::NAN,
        -f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        1e-45,
        -1e-45,
        f32::MIN_POSITIVE,
        -1.0,
        1.0,
    ];
    let dims = [15, 14, 13];
    let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
    let v = field(dims, |_, _, _| {
        specials[rng.random_range(0..specials.len())]
    });
    let geom = GridGeom::new([0.0; 3], 1.0, 50).unwrap();
    for iso in [0.0, -0.0, 1e-45, -1e-45, 1.0, f32::INFINITY, f32::NAN] {
        assert_same(&mut g, &v, dims, [0; 3], iso, &geom);
    }
}

/// A tiny buffer limit cuts the tile into slabs, bands or runs; the mesh is the same.
#[test]
fn sub_blocks_give_the_same_mesh() {
    let Some(mut g) = gpu() else { return };
    let geom = GridGeom::new([0.0, 1.0, 2.0], 0.5, 100).unwrap();
    let dims = [17, 9, 33];
    let rand = random_field(11, dims);
    let checker = field(
        dims,
        |x, y, z| if (x + y + z) % 2 == 0 { -1.0 } else { 1.0 },
    );
    let sphere = field(dims, |x, y, z| {
        let d = [x as f32 - 8.3, y as f32 - 4.1, z as f32 - 15.2];
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - 6.0
    });
    // Whole, slabs of several layers, one layer, bands of rows, single rows, runs.
    for limit in [u64::MAX, 40_000, 8_000, 4_000, 1_500, 600, 200] {
        g.set_max_buffer_bytes(limit);
        let planned = plan(dims, g.max_buffer_bytes()).unwrap().len() as u64;
        for v in [&rand, &checker, &sphere] {
            let s = assert_same(&mut g, v, dims, [5, 6, 7], 0.0, &geom);
            // Sub-blocks whose triangles overflow are halved: more than planned.
            assert!(s.sub_blocks >= planned, "limit {limit}");
        }
        let want = planned;
        if limit < 40_000 {
            assert!(want > 1, "limit {limit}");
        }
    }
}

/// A GPU error on a tile sends it to the CPU: same mesh, `fell_back` set, and the next
/// tile runs on the GPU again; after a panic, all later tiles run on the CPU.
#[test]
fn gpu_errors_fall_back_to_the_cpu() {
    let Some(mut g) = gpu() else { return };
    let dims = [12, 11, 10];
    let v = random_field(3, dims);
    let geom = GridGeom::new([0.0; 3], 1.0, 20).unwrap();
    let mut want = TileMesh::default();
    McWorkspace::new()
        .extract(&v, dims, [0; 3], 0.0, &geom, &mut want)
        .unwrap();
    g.fail_next = true;
    let mut got = TileMesh::default();
    let s = g.extract(&v, dims, [0; 3], 0.0, &geom, &mut got).unwrap();
    assert!(s.fell_back);
    assert_eq!(got, want);
    assert_same(&mut g, &v, dims, [0; 3], 0.0, &geom);
    // A panic inside the GPU path: this and later tiles go to the CPU, same mesh.
    g.panic_next = true;
    for _ in 0..2 {
        let s = g.extract(&v, dims, [0; 3], 0.0, &geom, &mut got).unwrap();
        assert!(s.fell_back);
        assert_eq!(got, want);
    }
    assert!(g.broken.is_some());
}

/// Bad shapes are the CPU kernel's errors; blocks without cells are empty.
#[test]
fn bad_shapes_are_the_cpu_errors() {
    let Some(mut g) = gpu() else { return };
    let geom = GridGeom::new([0.0; 3], 1.0, 4).unwrap();
    let mut m = TileMesh::default();
    let e = g.extract(&[0.0; 7], [2, 2, 2], [0; 3], 0.0, &geom, &mut m);
    assert!(matches!(e, Err(Error::Internal(_))));
    let e = g.extract(&[0.0; 8], [2, 2, 2], [4, 0, 0], 0.0, &geom, &mut m);
    assert!(matches!(e, Err(Error::Internal(_))));
    let s = g
        .extract(&[-1.0; 4], [2, 2, 1], [0; 3], 0.0, &geom, &mut m)
        .unwrap();
    assert_eq!((s.cells, s.fell_back), (0, false));
    assert!(m.triangles.is_empty());
}
