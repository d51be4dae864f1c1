use super::*;

/// Two unit hexahedra side by side along x, sharing a face, with coordinates that test
/// the round trip of decimal formatting.
pub(super) fn two_hexes() -> HexMesh {
    let mut verts = Vec::new();
    for z in [0.0, 1.0 / 3.0] {
        for (x, y) in [
            (0.0, 0.0),
            (0.1, 0.0),
            (0.2, 0.0),
            (0.2, 1e-7),
            (0.1, 1e-7),
            (0.0, 1e-7),
        ] {
            verts.push([x - 12345.678901234567, y, z + 1e-300]);
        }
    }
    HexMesh {
        verts,
        hexes: vec![[0, 1, 4, 5, 6, 7, 10, 11], [1, 2, 3, 4, 7, 8, 9, 10]],
    }
}

/// The unit cube cut into 5 positively oriented tetrahedra.
pub(super) fn five_tet_cube() -> TetMesh {
    let verts = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [1.0, 1.0, 1.0],
        [0.0, 1.0, 1.0],
    ];
    let tets = vec![
        [0, 1, 3, 4],
        [1, 2, 3, 6],
        [1, 6, 4, 5],
        [3, 4, 6, 7],
        [1, 3, 4, 6],
    ];
    let m = TetMesh { verts, tets };
    for t in 0..5 {
        assert!(m.volume(t) > 0.0, "tet {t}");
    }
    m
}

#[test]
fn hexes_round_trip_through_every_format() {
    let d = tempfile::tempdir().unwrap();
    let m = two_hexes();
    let quality = [0.5, -0.25];
    for name in ["h.vtk", "h.mesh", "h.msh", "H.VTK", "h.Msh"] {
        let p = d.path().join(name);
        write_hex(&p, &m, &[("quality", &quality), ("other", &[1.0, 2.0])]).unwrap();
        let v = read(&p).unwrap();
        assert!(v.tets.is_empty() && v.triangles.is_empty(), "{name}");
        assert!(v.skipped.is_empty(), "{name}: {:?}", v.skipped);
        let back = v.into_hex_mesh(&p).unwrap();
        assert_eq!(back, m, "{name}");
        let e = read(&p).unwrap().into_tet_mesh(&p).unwrap_err().to_string();
        assert!(
            e.contains(name) && e.contains("no tetrahedra") && e.contains("2 hexahedra"),
            "{e}"
        );
    }
    let names: Vec<_> = std::fs::read_dir(d.path()).unwrap().flatten().collect();
    assert_eq!(names.len(), 5, "no temporary file is left");
}

#[test]
fn tets_round_trip_through_every_format() {
    let d = tempfile::tempdir().unwrap();
    let m = five_tet_cube();
    let vol: Vec<f64> = (0..5).map(|t| m.volume(t)).collect();
    for name in ["t.vtk", "t.mesh", "t.msh"] {
        let p = d.path().join(name);
        write_tet(&p, &m, &[("volume", &vol)]).unwrap();
        let back = read(&p).unwrap().into_tet_mesh(&p).unwrap();
        assert_eq!(back, m, "{name}");
        let e = read(&p).unwrap().into_hex_mesh(&p).unwrap_err().to_string();
        assert!(e.contains(name) && e.contains("no hexahedra"), "{e}");
    }
}

#[test]
fn empty_meshes_round_trip() {
    let d = tempfile::tempdir().unwrap();
    for name in ["e.vtk", "e.mesh", "e.msh"] {
        let p = d.path().join(name);
        write_hex(&p, &HexMesh::default(), &[]).unwrap();
        let v = read(&p).unwrap();
        assert_eq!(v, VolumeMesh::default(), "{name}");
    }
}

#[test]
fn extensions_are_checked() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("m.obj");
    std::fs::write(&p, "v 0 0 0\n").unwrap();
    let e = read(&p).unwrap_err().to_string();
    assert!(
        e.contains("m.obj") && e.contains(".mesh") && e.contains(".msh") && e.contains(".vtk"),
        "{e}"
    );
    let e = write_hex(&d.path().join("out.ply"), &two_hexes(), &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("out.ply") && e.contains(".vtk"), "{e}");
    let p = d.path().join("m.meshb");
    std::fs::write(&p, [1u8, 0, 0, 0]).unwrap();
    let e = read(&p).unwrap_err().to_string();
    assert!(e.contains("m.meshb") && e.contains("binary MEDIT"), "{e}");
    let p = d.path().join("empty.msh");
    std::fs::write(&p, "").unwrap();
    let e = read(&p).unwrap_err().to_string();
    assert!(e.contains("empty.msh") && e.contains("empty"), "{e}");
    let e = read(d.path()).unwrap_err().to_string();
    assert!(e.contains("unknown volume mesh format"), "{e}");
    let dir = d.path().join("dir.vtk");
    std::fs::create_dir(&dir).unwrap();
    let e = read(&dir).unwrap_err().to_string();
    assert!(e.contains("is a directory"), "{e}");
}

#[test]
fn writers_refuse_bad_meshes_and_leave_nothing() {
    let d = tempfile::tempdir().unwrap();
    for name in ["bad.vtk", "bad.mesh", "bad.msh"] {
        let p = d.path().join(name);
        let mut m = two_hexes();
        m.hexes[1][3] = 12;
        let e = write_hex(&p, &m, &[]).unwrap_err().to_string();
        assert!(
            e.contains(name) && e.contains("vertex 12 is beyond the 12"),
            "{e}"
        );
        let mut m = two_hexes();
        m.verts[4][1] = f64::NAN;
        let e = write_hex(&p, &m, &[]).unwrap_err().to_string();
        assert!(e.contains("vertex 4") && e.contains("finite"), "{e}");
        let e = write_hex(&p, &two_hexes(), &[("q", &[1.0])])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("\"q\" has 1 values") && e.contains("2 hexahedra"),
            "{e}"
        );
        let e = write_hex(&p, &two_hexes(), &[("a b", &[1.0, 2.0])])
            .unwrap_err()
            .to_string();
        assert!(e.contains("\"a b\""), "{e}");
    }
    assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 0);
}

#[test]
fn mixed_meshes_do_not_convert() {
    let p = Path::new("mixed.vtk");
    let mut v = VolumeMesh {
        verts: five_tet_cube().verts,
        tets: five_tet_cube().tets,
        hexes: vec![[0, 1, 2, 3, 4, 5, 6, 7]],
        ..Default::default()
    };
    v.skip("edge", 3);
    v.skip("edge", 2);
    assert_eq!(v.skipped, vec![("edge".to_string(), 5)]);
    let e = v.clone().into_tet_mesh(p).unwrap_err().to_string();
    assert!(
        e.contains("mixed.vtk") && e.contains("hexahedra besides"),
        "{e}"
    );
    assert!(e.contains("5 edge (skipped)"), "{e}");
    let e = v.into_hex_mesh(p).unwrap_err().to_string();
    assert!(e.contains("tetrahedra besides"), "{e}");
}

#[test]
fn decimal_formatting_round_trips() {
    for x in [
        0.0,
        -0.0,
        0.1,
        1.0 / 3.0,
        1e-5,
        9.99999e-6,
        1e16,
        -1e300,
        5e-324,
        f64::MAX,
        123456.789,
    ] {
        let s = fmt_f64(x);
        assert_eq!(s.parse::<f64>().unwrap().to_bits(), x.to_bits(), "{s}");
        assert!(s.len() < 26, "{s}");
    }
}

/// `../shared/data/REL` beside the repository, or `None` with the reason printed.
fn shared(rel: &str) -> Option<std::path::PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(rel);
    if p.is_file() {
        Some(p)
    } else {
        eprintln!("skipped: {} is not present", p.display());
        None
    }
}

/// Read a real tetrahedral mesh, check its counts, first entries and orientation, and
/// that it survives a write and read through every format unchanged.
fn real_tet_mesh(
    rel: &str,
    counts: (usize, usize, usize),
    first_vertex: [f64; 3],
    first_tet: [u32; 4],
) {
    let Some(p) = shared(rel) else { return };
    let v = read(&p).unwrap();
    assert_eq!(
        (v.verts.len(), v.tets.len(), v.triangles.len()),
        counts,
        "{}",
        v.describe()
    );
    assert!(
        v.hexes.is_empty() && v.skipped.is_empty(),
        "{}",
        v.describe()
    );
    assert_eq!(v.verts[0], first_vertex);
    assert_eq!(v.tets[0], first_tet);
    let m = v.into_tet_mesh(&p).unwrap();
    let negative = (0..m.tets.len()).filter(|&t| m.volume(t) <= 0.0).count();
    assert_eq!(negative, 0, "every tetrahedron is positively oriented");
    let d = tempfile::tempdir().unwrap();
    for name in ["t.vtk", "t.mesh", "t.msh"] {
        let out = d.path().join(name);
        write_tet(&out, &m, &[]).unwrap();
        assert_eq!(
            read(&out).unwrap().into_tet_mesh(&out).unwrap(),
            m,
            "{name}"
        );
    }
}

#[test]
fn reads_octopus_low() {
    real_tet_mesh(
        "tetmesh/octopus-low.mesh",
        (452, 1140, 898),
        [-0.066882, 0.13753, -0.071187],
        [235, 406, 254, 403],
    );
}

#[test]
fn reads_fandisk() {
    real_tet_mesh(
        "tetmesh/fandisk.mesh",
        (11707, 59095, 6420),
        [-13.8084653, -4.38087523, -6.9209075],
        [1060, 974, 10156, 5622],
    );
}

/// A 2×2×2 grid of unit cubes with its centre vertex moved off-centre (so the eight
/// scaled Jacobians differ), and beside it one cube sheared by `atan(1/2)` along x.
fn grid_and_sheared() -> HexMesh {
    let mut verts = Vec::new();
    for k in 0..3 {
        for j in 0..3 {
            for i in 0..3 {
                verts.push([i as f64, j as f64, k as f64]);
            }
        }
    }
    verts[13] = [1.2, 0.9, 1.1];
    let id = |i: u32, j: u32, k: u32| i + 3 * j + 9 * k;
    let mut hexes = Vec::new();
    for c in 0..2 {
        for b in 0..2 {
            for a in 0..2 {
                let q = |k| {
                    [
                        id(a, b, k),
                        id(a + 1, b, k),
                        id(a + 1, b + 1, k),
                        id(a, b + 1, k),
                    ]
                };
                let (lo, hi) = (q(c), q(c + 1));
                hexes.push([lo[0], lo[1], lo[2], lo[3], hi[0], hi[1], hi[2], hi[3]]);
            }
        }
    }
    let n = verts.len() as u32;
    for (z, dx) in [(0.0, 0.0), (1.0, 0.5)] {
        for (x, y) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            verts.push([5.0 + x + dx, y, z]);
        }
    }
    hexes.push(std::array::from_fn(|i| n + i as u32));
    HexMesh { verts, hexes }
}

/// Rust's scaled Jacobian of every hexahedron of `m`.
fn scaled_jacobians(m: &HexMesh) -> Vec<f64> {
    m.hexes
        .iter()
        .map(|h| crate::quality::hex_scaled_jacobian(&h.map(|v| m.verts[v as usize])))
        .collect()
}

#[test]
fn grid_and_sheared_jacobians() {
    let sj = scaled_jacobians(&grid_and_sheared());
    assert!((sj[8] - 1.0 / 1.25f64.sqrt()).abs() < 1e-12, "{}", sj[8]);
    assert!(sj[..8].iter().all(|&q| q > 0.5 && q < 1.0), "{sj:?}");
}

/// `python3 scripts/hex_check.py PATH ARGS...`, started.
fn spawn_hex_check(path: &Path, args: &[&str]) -> std::io::Result<std::process::Child> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/hex_check.py");
    std::process::Command::new("python3")
        .arg(script)
        .arg(path)
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
}

/// The JSON a started checker prints, or `None` (reason printed) when python3, numpy or
/// meshio is missing. Panics when the checker fails.
fn hex_check_json(child: std::io::Result<std::process::Child>) -> Option<serde_json::Value> {
    let child = match child {
        Ok(c) => c,
        Err(e) => {
            eprintln!("skipped: python3 cannot be run: {e}");
            return None;
        }
    };
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "hex_check failed: {stdout}{stderr}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("hex_check printed no JSON ({e}): {stdout}{stderr}"));
    if let Some(why) = v.get("skipped") {
        eprintln!("skipped: hex_check: {why}");
        return None;
    }
    Some(v)
}

/// Write the grid and the five-tetrahedra cube as `ext` and check both with hex_check:
/// counts, every scaled Jacobian, boundaries, cell data and, for `.msh`, gmsh's view.
fn hex_check_agrees(ext: &str) {
    let d = tempfile::tempdir().unwrap();
    let hex = grid_and_sheared();
    let sj = scaled_jacobians(&hex);
    let hp = d.path().join(format!("grid.{ext}"));
    write_hex(&hp, &hex, &[("sj", &sj)]).unwrap();
    let tet = five_tet_cube();
    let vol: Vec<f64> = (0..5).map(|t| tet.volume(t)).collect();
    let tp = d.path().join(format!("cube.{ext}"));
    write_tet(&tp, &tet, &[("volume", &vol)]).unwrap();
    // Both checkers run at once.
    let (h, t) = (
        spawn_hex_check(&hp, &["--per-hex"]),
        spawn_hex_check(&tp, &[]),
    );
    let (Some(h), Some(t)) = (hex_check_json(h), hex_check_json(t)) else {
        return;
    };
    eprintln!("{ext}: {h}\n{ext}: {t}");
    let n = |v: &serde_json::Value, k: &str| v[k].as_u64().unwrap_or_else(|| panic!("{k}: {v}"));
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"));
    assert!(h["reader"].as_str().unwrap().starts_with("meshio"), "{h}");
    assert_eq!((n(&h, "points"), n(&h, "hexes"), n(&h, "tets")), (35, 9, 0));
    let per_hex = h["scaled_jacobian"]["per_hex"].as_array().unwrap();
    assert_eq!(per_hex.len(), 9);
    for (i, (theirs, ours)) in per_hex.iter().zip(&sj).enumerate() {
        assert!(
            (f(theirs) - ours).abs() < 1e-12,
            "hex {i}: {theirs} vs {ours}"
        );
    }
    let min = sj.iter().copied().fold(f64::INFINITY, f64::min);
    assert!((f(&h["scaled_jacobian"]["min"]) - min).abs() < 1e-12);
    assert_eq!(n(&h["scaled_jacobian"], "count_le_0"), 0);
    assert_eq!(n(&h["boundary"], "quads"), 24 + 6);
    assert_eq!(h["boundary"]["closed"], true);
    assert_eq!((n(&t, "points"), n(&t, "hexes"), n(&t, "tets")), (8, 0, 5));
    assert_eq!(n(&t["tet_volume"], "count_le_0"), 0);
    assert!((f(&t["tet_volume"]["min"]) - 1.0 / 6.0).abs() < 1e-12);
    assert_eq!(n(&t["boundary"], "triangles"), 12);
    assert_eq!(t["boundary"]["closed"], true);
    if ext != "mesh" {
        // The cell data each writer adds, under its name.
        let q = &h["cell_data"]["sj"];
        assert_eq!(n(q, "count"), 9, "{h}");
        assert!((f(&q["min"]) - min).abs() < 1e-12);
        assert!(
            (f(&t["cell_data"]["volume"]["max"]) - 1.0 / 3.0).abs() < 1e-12,
            "{t}"
        );
    }
    if ext == "msh" {
        for (v, hexes, tets) in [(&h, 9, 0), (&t, 0, 5)] {
            let g = &v["gmsh"];
            if g.get("skipped").is_some() {
                eprintln!("skipped: gmsh: {}", g["skipped"]);
                continue;
            }
            assert!(g.get("error").is_none(), "gmsh could not read it: {g}");
            assert_eq!((n(g, "hexes"), n(g, "tets")), (hexes, tets), "{g}");
            assert_eq!(n(g, "nodes"), n(v, "points"));
        }
        // gmsh's own minSJ: positive for valid hexahedra in the order gmsh expects, 1
        // for a parallelepiped such as the sheared cube.
        if let Some(g) = h["gmsh"]["min_sj_per_hex"].as_array() {
            assert_eq!(g.len(), 9);
            assert!(g.iter().all(|q| f(q) > 0.0 && f(q) <= 1.0 + 1e-9), "{g:?}");
            assert!((f(&g[8]) - 1.0).abs() < 1e-9, "{g:?}");
        }
    }
}

#[test]
fn hex_check_agrees_on_vtk() {
    hex_check_agrees("vtk");
}

#[test]
fn hex_check_agrees_on_medit() {
    hex_check_agrees("mesh");
}

#[test]
fn hex_check_agrees_on_msh() {
    hex_check_agrees("msh");
}

#[test]
fn hex_check_measures_distance_to_a_reference() {
    let d = tempfile::tempdir().unwrap();
    // The unit cube as 2×2×2 hexahedra, against the five-tetrahedra cube (the same
    // boundary) and against a box 0.1 taller given as an OBJ surface.
    let mut verts = Vec::new();
    for k in 0..3 {
        for j in 0..3 {
            for i in 0..3 {
                verts.push([i as f64 / 2.0, j as f64 / 2.0, k as f64 / 2.0]);
            }
        }
    }
    let hexes = grid_and_sheared().hexes[..8].to_vec();
    let hp = d.path().join("half.vtk");
    write_hex(&hp, &HexMesh { verts, hexes }, &[]).unwrap();
    let tp = d.path().join("cube.mesh");
    write_tet(&tp, &five_tet_cube(), &[]).unwrap();
    let op = d.path().join("box.obj");
    let mut obj = String::new();
    for v in five_tet_cube().verts {
        obj += &format!("v {} {} {}\n", v[0], v[1], v[2] * 1.1);
    }
    for f in [
        [1, 3, 2],
        [1, 4, 3],
        [5, 6, 7],
        [5, 7, 8],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 4, 8],
        [3, 8, 7],
        [4, 1, 5],
        [4, 5, 8],
    ] {
        obj += &format!("f {} {} {}\n", f[0], f[1], f[2]);
    }
    std::fs::write(&op, obj).unwrap();
    let (a, b) = (
        spawn_hex_check(
            &hp,
            &["--samples", "5000", "--reference", tp.to_str().unwrap()],
        ),
        spawn_hex_check(
            &hp,
            &["--samples", "5000", "--reference", op.to_str().unwrap()],
        ),
    );
    let (Some(a), Some(b)) = (hex_check_json(a), hex_check_json(b)) else {
        return;
    };
    eprintln!("{a}\n{b}");
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"));
    let r = &a["reference"];
    assert_eq!(
        (r["kind"].as_str(), r["triangles"].as_u64()),
        (Some("tetmesh"), Some(12))
    );
    assert!(f(&r["max"]) < 1e-12, "{r}");
    let r = &b["reference"];
    assert_eq!(
        (r["kind"].as_str(), r["triangles"].as_u64()),
        (Some("surface"), Some(12))
    );
    for side in ["mesh_to_reference", "reference_to_mesh"] {
        assert!((f(&r[side]["max"]) - 0.1).abs() < 1e-9, "{r}");
    }
    // The cube's top face (1/6 of its area) lies 0.1 below the box's top, nearer to the
    // box's sides within 0.1 of its edges: its mean distance is
    // ∫₀^0.1 t·4(1−2t) dt + 0.1·∫_0.1^0.5 4(1−2t) dt = 0.0813…; the rest is at 0. The
    // box's top (area 1) is 0.1 above the cube, the strips above the cube (area 0.4) a
    // mean 0.05, the rest (area 5) at 0.
    let top = 4.0 * (0.005 - 0.002 / 3.0) + 0.4 * (0.25 - 0.09);
    assert!(
        (f(&r["mesh_to_reference"]["mean"]) - top / 6.0).abs() < 2e-3,
        "{r}"
    );
    assert!(
        (f(&r["reference_to_mesh"]["mean"]) - 0.12 / 6.4).abs() < 2e-3,
        "{r}"
    );
}

/// Files of every reader: what the writers write, and the other tools' files the
/// submodules' tests hold.
fn fuzz_samples() -> Vec<(String, Vec<u8>)> {
    let d = tempfile::tempdir().unwrap();
    let mut out = Vec::new();
    for ext in ["vtk", "mesh", "msh"] {
        let p = d.path().join(format!("h.{ext}"));
        write_hex(&p, &two_hexes(), &[("q", &[1.0, 2.0])]).unwrap();
        out.push((format!("h.{ext}"), std::fs::read(&p).unwrap()));
        let p = d.path().join(format!("t.{ext}"));
        write_tet(&p, &five_tet_cube(), &[]).unwrap();
        out.push((format!("t.{ext}"), std::fs::read(&p).unwrap()));
    }
    for le in [true, false] {
        out.push(("b41.msh".into(), msh::tests::tet41_binary(le).0));
    }
    out.push((
        "b22.msh".into(),
        msh::tests::unhex(msh::tests::GMSH22_BINARY),
    ));
    for v5 in [false, true] {
        out.push(("b.vtk".into(), vtk::tests::binary(v5, v5).0));
    }
    out.push(("g.vtk".into(), vtk::tests::GMSH_HEX.as_bytes().to_vec()));
    out.push(("m.vtk".into(), vtk::tests::MESHIO_TETS.as_bytes().to_vec()));
    out
}

/// Read `data` as file `name` with the reader of its extension.
fn read_as(name: &str, data: &[u8]) -> Result<VolumeMesh> {
    let p = Path::new(name);
    match format_of(p, true).unwrap() {
        Format::Medit => medit::read(p, data),
        Format::Msh => msh::read(p, data),
        Format::Vtk => vtk::read(p, data),
    }
}

/// An error must name the file and a line or a byte.
fn assert_located(name: &str, e: &Error) {
    let s = e.to_string();
    assert!(
        s.starts_with(&format!("{name}: line ")) || s.starts_with(&format!("{name}: byte ")),
        "{s}"
    );
}

#[test]
fn every_truncation_fails_cleanly() {
    for (name, data) in fuzz_samples() {
        let full = read_as(&name, &data).unwrap();
        assert!(!full.verts.is_empty(), "{name}");
        let mut errors = 0;
        for len in 0..data.len() {
            match read_as(&name, &data[..len]) {
                Err(e) => {
                    assert_located(&name, &e);
                    errors += 1;
                }
                // A file cut between two sections reads as the sections before the cut
                // (the caller then finds no cells); never as partial sections.
                Ok(m) => {
                    assert!(
                        m.verts.is_empty() || m.verts == full.verts,
                        "{name} cut at {len}"
                    );
                    assert!(
                        m.tets.is_empty() || m.tets == full.tets,
                        "{name} cut at {len}"
                    );
                    assert!(
                        m.hexes.is_empty() || m.hexes == full.hexes,
                        "{name} cut at {len}"
                    );
                }
            }
        }
        assert!(
            errors > data.len() / 2,
            "{name}: {errors} of {}",
            data.len()
        );
    }
}

#[test]
fn corrupted_files_never_panic() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_pcg::Pcg64::seed_from_u64(20240611);
    const BYTES: &[u8] = b"0123456789 \n\r\t-+.eE$#\x00\x01\x7f\xff";
    for (name, data) in fuzz_samples() {
        for _ in 0..1500 {
            let mut d = data.clone();
            for _ in 0..rng.random_range(1..5) {
                let i = rng.random_range(0..d.len());
                d[i] = if rng.random_bool(0.5) {
                    BYTES[rng.random_range(0..BYTES.len())]
                } else {
                    rng.random()
                };
            }
            if let Err(e) = read_as(&name, &d) {
                assert_located(&name, &e);
            }
        }
    }
    // Random bytes, and random text made of the formats' own words.
    const WORDS: &[&str] = &[
        "$MeshFormat\n",
        "4.1 0 8\n",
        "2.2 1 8\n",
        "$Nodes\n",
        "$Elements\n",
        "$EndNodes\n",
        "$EndElements\n",
        "$EndMeshFormat\n",
        "Vertices ",
        "Tetrahedra ",
        "Hexahedra ",
        "Dimension 3 ",
        "End ",
        "# vtk DataFile Version 5.1\nt\nASCII\n",
        "DATASET UNSTRUCTURED_GRID\n",
        "POINTS ",
        "CELLS ",
        "CELL_TYPES ",
        "OFFSETS ",
        "CONNECTIVITY ",
        "vtktypeint64\n",
        "double\n",
        "1 ",
        "0 ",
        "8 ",
        "12 ",
        "-1 ",
        "99999999999999999999 ",
        "4294967295 ",
        "nan ",
        "1e308 ",
        "\n",
    ];
    for ext in ["mesh", "msh", "vtk"] {
        let name = format!("r.{ext}");
        for _ in 0..1500 {
            let n = rng.random_range(0..200);
            let d: Vec<u8> = if rng.random_bool(0.3) {
                (0..n).map(|_| rng.random()).collect()
            } else {
                (0..n / 4)
                    .flat_map(|_| WORDS[rng.random_range(0..WORDS.len())].bytes())
                    .collect()
            };
            if let Err(e) = read_as(&name, &d) {
                assert_located(&name, &e);
            }
        }
    }
}
