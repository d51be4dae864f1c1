//! `hexmesh` and `hexcheck` end to end: a box meshed by CubeCover and read back by an
//! independent checker (meshio and gmsh through `scripts/hex_check.py`), the frame field's
//! failures reported on a real mesh, and bad input named.

use std::path::Path;
use std::process::Command;

use scanflow::hex::mesh::{HexMesh, TetMesh};

use super::common::*;

/// `scripts/hex_check.py MESH [--reference REF]`, parsed; `None` (with the reason printed)
/// when meshio is not installed.
fn hex_check(mesh: &Path, reference: Option<&Path>) -> Option<serde_json::Value> {
    let mut cmd = Command::new("python3");
    cmd.arg(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../scripts/hex_check.py"
    ))
    .arg(mesh);
    if let Some(r) = reference {
        cmd.arg("--reference").arg(r);
    }
    let o = cmd.output().ok()?;
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "hex_check.py: {e}\n{}\n{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        )
    });
    if let Some(r) = v.get("skipped") {
        eprintln!("skipped (hex_check.py): {r}");
        return None;
    }
    assert!(o.status.success(), "{v}");
    Some(v)
}

/// A 4.4 × 2.7 × 2.6 box of 144 tetrahedra.
fn write_box(path: &Path) {
    let mut m = TetMesh::grid_box([4, 3, 2], 1.0);
    for p in &mut m.verts {
        *p = [p[0] * 1.1, p[1] * 0.9, p[2] * 1.3];
    }
    scanflow::hex::volume::write_tet(path, &m, &[]).unwrap();
}

#[test]
fn a_box_becomes_cubes_and_independent_readers_agree() {
    let d = tempfile::tempdir().unwrap();
    let input = d.path().join("box.mesh");
    write_box(&input);
    for (frames, ext) in [("smooth", "vtk"), ("constant", "msh"), ("smooth", "mesh")] {
        let out = d.path().join(format!("box_{frames}.{ext}"));
        let rep = d.path().join(format!("box_{frames}_{ext}.json"));
        let text = ok(&[
            "hexmesh",
            s(&input),
            "-o",
            s(&out),
            "--frames",
            frames,
            "--scale",
            "0.5",
            "--report",
            s(&rep),
            "--progress",
            "none",
        ]);
        assert!(text.contains("scaled Jacobian"), "{text}");
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
        // A box needs no singular edge: the smooth field's singular graph is empty.
        assert_eq!(
            r["singular_by_valence"],
            serde_json::json!([0, 0, 0]),
            "{r}"
        );
        assert_eq!(r["param"]["flipped_final"].as_u64(), Some(0), "{r}");
        // 4.4 / 0.5 → 9, 2.7 / 0.5 → 5, 2.6 / 0.5 → 5 cells; the hexes fill the box exactly.
        assert_eq!(r["quality"]["hexes"].as_u64(), Some(225), "{r}");
        assert_eq!(r["quality"]["inverted"].as_u64(), Some(0), "{r}");
        let vol = r["quality"]["total_volume"].as_f64().unwrap();
        assert!((vol - 4.4 * 2.7 * 2.6).abs() < 1e-9, "{vol}");
        assert!(r["quality"]["min_sj"].as_f64().unwrap() > 0.99, "{r}");
        // hexcheck reads it back.
        let q = ok(&["hexcheck", s(&out), "--json"]);
        let q: serde_json::Value = serde_json::from_str(&q).unwrap();
        assert_eq!(q["hexes"].as_u64(), Some(225), "{q}");
        let Some(c) = hex_check(&out, Some(&input)) else {
            continue;
        };
        assert_eq!(c["hexes"].as_u64(), Some(225), "{c}");
        assert!(c["scaled_jacobian"]["min"].as_f64().unwrap() > 0.99, "{c}");
        assert_eq!(c["scaled_jacobian"]["count_le_0"].as_u64(), Some(0), "{c}");
        assert_eq!(c["boundary"]["closed"].as_bool(), Some(true), "{c}");
        // The hex boundary lies on the box's.
        assert!(c["reference"]["max"].as_f64().unwrap() < 1e-9, "{c}");
        if ext == "msh"
            && let Some(g) = c["gmsh"]["min_sj_hex"].as_f64()
        {
            assert!(g > 0.99, "{c}");
        }
    }
}

#[test]
fn hexcheck_exits_non_zero_on_an_inverted_hex() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("bad.vtk");
    let mut verts: Vec<[f64; 3]> = vec![
        [0., 0., 0.],
        [1., 0., 0.],
        [1., 1., 0.],
        [0., 1., 0.],
        [0., 0., 1.],
        [1., 0., 1.],
        [1., 1., 1.],
        [0., 1., 1.],
    ];
    // Push one top corner through the bottom face.
    verts[6] = [1.0, 1.0, -0.5];
    let m = HexMesh {
        verts,
        hexes: vec![[0, 1, 2, 3, 4, 5, 6, 7]],
    };
    scanflow::hex::volume::write_hex(&path, &m, &[]).unwrap();
    let e = fails(&["hexcheck", s(&path)]);
    assert!(e.contains("bad.vtk") && e.contains("inverted"), "{e}");
}

#[test]
fn bad_tetrahedra_and_options_are_named() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("o.vtk");
    // An inverted tetrahedron: two corners swapped.
    let mut m = TetMesh::grid_box([1, 1, 1], 1.0);
    m.tets[3].swap(0, 1);
    let inv = d.path().join("inverted.mesh");
    scanflow::hex::volume::write_tet(&inv, &m, &[]).unwrap();
    let e = fails(&["hexmesh", s(&inv), "-o", s(&out), "--progress", "none"]);
    assert!(
        e.contains("inverted.mesh") && e.contains("tetrahedron 3"),
        "{e}"
    );
    // An open boundary is impossible for tets; a non-manifold face is not: three tets on
    // one face.
    let nm = TetMesh {
        verts: vec![
            [0., 0., 0.],
            [1., 0., 0.],
            [0., 1., 0.],
            [0., 0., 1.],
            [0.2, 0.2, 1.0],
            [0.3, 0.1, 0.9],
        ],
        tets: vec![[0, 1, 2, 3], [0, 1, 2, 4], [0, 1, 2, 5]],
    };
    let nmp = d.path().join("nonmanifold.mesh");
    scanflow::hex::volume::write_tet(&nmp, &nm, &[]).unwrap_or(());
    if nmp.exists() {
        let e = fails(&["hexmesh", s(&nmp), "-o", s(&out), "--progress", "none"]);
        assert!(e.contains("nonmanifold.mesh"), "{e}");
    }
    // A .mesh without its Tetrahedra section.
    let missing = d.path().join("missing.mesh");
    std::fs::write(
        &missing,
        "MeshVersionFormatted 2\nDimension 3\nVertices\n1\n0 0 0 0\nEnd\n",
    )
    .unwrap();
    let e = fails(&["hexmesh", s(&missing), "-o", s(&out), "--progress", "none"]);
    assert!(e.contains("missing.mesh"), "{e}");
    assert!(!out.exists());
    // Options checked before any work.
    let e = usage(&["hexmesh", s(&missing), "-o", s(&out), "--scale", "-1"]);
    assert!(e.contains("--scale"), "{e}");
    let e = usage(&["hexmesh", s(&missing), "-o", s(&out), "--tet-size", "0"]);
    assert!(e.contains("--tet-size"), "{e}");
    let e = usage(&["hexmesh", s(&missing), "-o", s(&out), "--frames", "wavy"]);
    assert!(e.contains("--frames"), "{e}");
    let e = usage(&["hexmesh", s(&missing), "-o", s(&d.path().join("o.ply"))]);
    assert!(e.contains("o.ply"), "{e}");
}

#[test]
fn the_octopus_becomes_the_grid_of_the_axes_when_no_polycube_map_fits() {
    // The coarse octopus (1140 tetrahedra, its eight arms curled, tapering to points): no
    // polycube map of it is found, so the aligned parameterisation flips tetrahedra before
    // any rounding. The run says so, then meshes the grid of the axes, its staircase made
    // pillowable, pillowed and relaxed: all hexahedra positive by meshio's independent
    // computation, the boundary closed and on the octopus's (the arms' tips, thinner than a
    // cube, are lost: stated below). The report keeps the deformation's and the aligned
    // map's figures.
    let Some(oct) = shared("tetmesh/octopus-low.mesh") else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("o.vtk");
    let rep = d.path().join("o.json");
    let err = ok_log(&[
        "hexmesh",
        s(&oct),
        "-o",
        s(&out),
        "--report",
        s(&rep),
        "--progress",
        "none",
    ]);
    assert!(
        err.contains("octopus-low.mesh")
            && err.contains("before any rounding")
            && err.contains("grid of the axes"),
        "{err}"
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    assert_eq!(r["targets"].as_str(), Some("grid"), "{r}");
    assert!(
        r["grid_fallback"].as_str().unwrap().contains("flips"),
        "{r}"
    );
    let p = &r["polycube"];
    assert!(p["stiffened"].as_u64().unwrap() >= 1, "{p}");
    let (start, end) = (
        p["mean_deviation_start"].as_f64().unwrap(),
        p["mean_deviation"].as_f64().unwrap(),
    );
    assert!(end < start - 10.0, "{p}");
    assert!(
        r["param"]["flipped_continuous"].as_u64().unwrap() > 0,
        "{r}"
    );
    // The edge: the octopus's volume over its boundary's area (0.0167), finer than a
    // twentieth of its diagonal (0.067), which holds two whole cubes.
    let scale = r["scale"].as_f64().unwrap();
    assert!((scale - 0.01672).abs() < 2e-4, "{r}");
    assert!(r["pillow"]["removed"].as_u64().unwrap() > 0, "{r}");
    assert_eq!(r["quality"]["inverted"].as_u64(), Some(0), "{r}");
    assert!(r["quality"]["hexes"].as_u64().unwrap() > 1000, "{r}");
    assert!(r["quality"]["min_sj"].as_f64().unwrap() > 0.2, "{r}");
    let Some(c) = hex_check(&out, Some(&oct)) else {
        return;
    };
    assert_eq!(c["scaled_jacobian"]["count_le_0"].as_u64(), Some(0), "{c}");
    assert!(c["scaled_jacobian"]["min"].as_f64().unwrap() > 0.2, "{c}");
    assert_eq!(c["boundary"]["closed"].as_bool(), Some(true), "{c}");
    // Measured: hexes → octopus mean 0.0072, max 0.028 (under two edges); octopus → hexes
    // mean 0.044, max 0.32 (the arms' tips: the diagonal is 1.35).
    let rf = &c["reference"];
    assert!(
        rf["mesh_to_reference"]["mean"].as_f64().unwrap() < scale,
        "{c}"
    );
    assert!(
        rf["mesh_to_reference"]["max"].as_f64().unwrap() < 2.5 * scale,
        "{c}"
    );
    assert!(
        rf["reference_to_mesh"]["mean"].as_f64().unwrap() < 0.06,
        "{c}"
    );

    // A field the user chose is not replaced: the smooth field's invalid singular edges are
    // named, and nothing is written.
    let out2 = d.path().join("o2.vtk");
    let e = fails(&[
        "hexmesh",
        s(&oct),
        "-o",
        s(&out2),
        "--frames",
        "smooth",
        "--progress",
        "none",
    ]);
    assert!(
        e.contains("octopus-low.mesh") && e.contains("configuration"),
        "{e}"
    );
    assert!(!out2.exists());
}

#[test]
fn the_fandisk_becomes_hexes_with_none_inverted() {
    // The fandisk (59K tetrahedra, sharp edges and a curved fan), at the default edge: its
    // rounded polycube map inverts a few dozen tetrahedra, which the untangling turns back without moving an
    // integer; the pillowed and relaxed hexahedra that still fold are untangled too. All
    // hexahedra come out positive, read back by meshio, and the boundary lies on the input's.
    let Some(fan) = shared("tetmesh/fandisk.mesh") else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("fan.vtk");
    let out2 = d.path().join("fan2.vtk");
    let rep = d.path().join("fan.json");
    ok(&[
        "hexmesh",
        s(&fan),
        "-o",
        s(&out),
        "--frames",
        "polycube",
        "--report",
        s(&rep),
        "--progress",
        "none",
    ]);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    // The default edge (a twentieth of the diagonal, 2.18) folds two hexahedra at a corner;
    // the next, 0.85 of it, does not.
    let tries = r["tries"].as_array().unwrap();
    assert_eq!(tries.len(), 1, "{r}");
    assert!(
        (tries[0]["scale"].as_f64().unwrap() - 43.563 / 20.0).abs() < 1e-2,
        "{r}"
    );
    assert!(
        tries[0]["error"].as_str().unwrap().contains("folded"),
        "{r}"
    );
    let scale = r["scale"].as_f64().unwrap();
    assert!(
        (scale - 0.85 * tries[0]["scale"].as_f64().unwrap()).abs() < 1e-9,
        "{r}"
    );
    let u = &r["param"]["untangle"];
    assert!(u["inverted_before"].as_u64().unwrap() > 0, "{r}");
    assert_eq!(u["inverted_after"].as_u64(), Some(0), "{r}");
    assert_eq!(r["param"]["flipped_final"].as_u64(), Some(0), "{r}");
    assert_eq!(r["quality"]["inverted"].as_u64(), Some(0), "{r}");
    assert!(r["quality"]["min_sj"].as_f64().unwrap() > 0.05, "{r}");
    let Some(c) = hex_check(&out, Some(&fan)) else {
        return;
    };
    assert_eq!(c["scaled_jacobian"]["count_le_0"].as_u64(), Some(0), "{c}");
    assert_eq!(c["boundary"]["closed"].as_bool(), Some(true), "{c}");
    // The fandisk's diagonal is 43.6: on average within 0.6% of it (0.21 measured), at most
    // 3 hex edges (4.8, 2.6 edges, measured: where the hexes' faces cut its sharp edges).
    assert!(c["reference"]["mean"].as_f64().unwrap() < 0.25, "{c}");
    assert!(c["reference"]["max"].as_f64().unwrap() < 3.0 * scale, "{c}");

    // An explicit edge is tried alone: at 2.0 the same corner folds, and the run says so.
    let e = fails(&[
        "hexmesh",
        s(&fan),
        "-o",
        s(&out2),
        "--scale",
        "2.0",
        "--report",
        s(&rep),
        "--progress",
        "none",
    ]);
    assert!(e.contains("fandisk.mesh") && e.contains("folded"), "{e}");
    assert!(!e.contains("failed too"), "{e}");
    assert!(!out2.exists());
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    assert_eq!(r["tries"].as_array().map(Vec::len), Some(0), "{r}");
    assert_eq!(r["scale"].as_f64(), Some(2.0), "{r}");
}

/// Axis-aligned boxes (min, max corners) as one ASCII PLY of 12 outward triangles each.
fn boxes_ply(boxes: &[([f64; 3], [f64; 3])]) -> String {
    const FACES: [[usize; 3]; 12] = [
        [0, 2, 1],
        [0, 3, 2],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 0, 4],
        [3, 4, 7],
    ];
    let mut text = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        8 * boxes.len(),
        12 * boxes.len()
    );
    for (lo, hi) in boxes {
        for k in 0..8 {
            let x = if (k + 1) % 4 >= 2 { hi[0] } else { lo[0] };
            let y = if k % 4 >= 2 { hi[1] } else { lo[1] };
            let z = if k >= 4 { hi[2] } else { lo[2] };
            text += &format!("{x} {y} {z}\n");
        }
    }
    for b in 0..boxes.len() {
        for t in FACES {
            text += &format!("3 {} {} {}\n", 8 * b + t[0], 8 * b + t[1], 8 * b + t[2]);
        }
    }
    text
}

#[test]
fn a_closed_surface_is_stuffed_then_meshed_or_the_failure_named() {
    // A 2 × 1.5 × 1 box as 12 outward triangles: stuffed with tetrahedra (winding number),
    // then CubeCover. Stuffing bevels the corners, and snapping the planes there can flip
    // tetrahedra: then the run must say so, name the rounding and write nothing.
    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("boxs.ply");
    let text = boxes_ply(&[([-1.0, -0.75, -0.5], [1.0, 0.75, 0.5])]);
    std::fs::write(&ply, text).unwrap();
    let out = d.path().join("boxs.vtk");
    let rep = d.path().join("boxs.json");
    let o = run(&[
        "hexmesh",
        s(&ply),
        "-o",
        s(&out),
        "--frames",
        "constant",
        "--scale",
        "0.5",
        "--tet-size",
        "0.2",
        "--report",
        s(&rep),
        "--progress",
        "none",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("panicked"), "{err}");
    if o.status.success() {
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
        assert!(r["stuffing"]["tets"].as_u64().unwrap() > 0, "{r}");
        assert_eq!(r["quality"]["inverted"].as_u64(), Some(0), "{r}");
    } else {
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.contains("boxs.ply") && err.contains("flips") && err.contains("rounding"),
            "{err}"
        );
        assert!(!out.exists());
    }
}

#[test]
fn a_stuffing_that_cannot_resolve_the_solid_says_where() {
    // Two cubes touching along an edge: the stuffed tetrahedra meet there in a boundary edge
    // of four triangles. The indices of the stuffed mesh mean nothing to the user, so the
    // error gives the place and the --tet-size, and writes nothing.
    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("touching.ply");
    std::fs::write(
        &ply,
        boxes_ply(&[
            ([-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]),
            ([0.5, 0.5, -0.5], [1.5, 1.5, 0.5]),
        ]),
    )
    .unwrap();
    let out = d.path().join("touching.vtk");
    let e = fails(&[
        "hexmesh",
        s(&ply),
        "-o",
        s(&out),
        "--tet-size",
        "0.2",
        "--progress",
        "none",
    ]);
    assert!(
        e.contains("touching.ply") && e.contains("--tet-size 0.2") && e.contains("near (0.5"),
        "{e}"
    );
    assert!(!out.exists());
}

/// A closed cylinder of radius 1 and height 2 along z, `n` sides, outward triangles, as ASCII
/// PLY.
fn write_cylinder(path: &Path, n: usize) {
    let mut v: Vec<[f64; 3]> = Vec::new();
    for z in [-1.0, 1.0] {
        for i in 0..n {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            v.push([a.cos(), a.sin(), z]);
        }
    }
    v.push([0.0, 0.0, -1.0]);
    v.push([0.0, 0.0, 1.0]);
    let (cb, ct) = (2 * n, 2 * n + 1);
    let mut f: Vec<[usize; 3]> = Vec::new();
    for i in 0..n {
        let j = (i + 1) % n;
        f.extend([
            [i, j, n + j],
            [i, n + j, n + i],
            [cb, j, i],
            [ct, n + i, n + j],
        ]);
    }
    let mut text = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        v.len(),
        f.len()
    );
    for p in v {
        text += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    for t in f {
        text += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
    }
    std::fs::write(path, text).unwrap();
}

#[test]
fn a_cylinder_becomes_hexes_by_a_polycube_map_with_none_inverted() {
    // Stuffed with tetrahedra, deformed into a polycube (a square prism), mapped, extracted,
    // pillowed and relaxed: no interior singular edge, no inverted hexahedron, the boundary
    // on the cylinder.
    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("cyl.ply");
    write_cylinder(&ply, 48);
    let out = d.path().join("cyl.vtk");
    let rep = d.path().join("cyl.json");
    let text = ok(&[
        "hexmesh",
        s(&ply),
        "-o",
        s(&out),
        "--scale",
        "0.4",
        "--tet-size",
        "0.15",
        "--report",
        s(&rep),
        "--progress",
        "none",
    ]);
    assert!(text.contains("scaled Jacobian"), "{text}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    assert_eq!(
        r["singular_by_valence"],
        serde_json::json!([0, 0, 0]),
        "{r}"
    );
    let pc = &r["polycube"];
    assert!(
        pc["mean_deviation"].as_f64().unwrap() < pc["mean_deviation_start"].as_f64().unwrap() / 5.0,
        "{pc}"
    );
    // Six charts' labels: ±x, ±y on the side, ±z on the caps.
    assert!(
        pc["labels"]
            .as_array()
            .unwrap()
            .iter()
            .all(|n| n.as_u64().unwrap() > 0),
        "{pc}"
    );
    assert_eq!(r["param"]["flipped_final"].as_u64(), Some(0), "{r}");
    assert!(r["pillow"]["multi_face_hexes"].as_u64().unwrap() > 0, "{r}");
    assert_eq!(r["quality"]["inverted"].as_u64(), Some(0), "{r}");
    assert!(r["quality"]["min_sj"].as_f64().unwrap() > 0.3, "{r}");
    let vol = r["quality"]["total_volume"].as_f64().unwrap();
    let exact = std::f64::consts::PI * 2.0;
    assert!((vol - exact).abs() < 0.1 * exact, "{vol}");
    let Some(c) = hex_check(&out, Some(&ply)) else {
        return;
    };
    assert_eq!(c["scaled_jacobian"]["count_le_0"].as_u64(), Some(0), "{c}");
    assert!(c["scaled_jacobian"]["min"].as_f64().unwrap() > 0.3, "{c}");
    assert_eq!(c["boundary"]["closed"].as_bool(), Some(true), "{c}");
    // On average within an eighth of the hex edge (0.4) of the cylinder; the largest gaps
    // (under 0.6 edges) are at the rims, which the stuffing bevels and the hexes' faces cut.
    assert!(c["reference"]["mean"].as_f64().unwrap() < 0.05, "{c}");
    assert!(c["reference"]["max"].as_f64().unwrap() < 0.25, "{c}");
}

#[test]
fn a_scanned_torus_is_reconstructed_then_meshed_with_hexes() {
    // Points of a torus → reconstruct → the surface stuffed, polycube map, hexahedra: one
    // command. Bad --hex options are refused before any work.
    let d = tempfile::tempdir().unwrap();
    let pts = d.path().join("torus.ply");
    ok(&[
        "synth",
        "torus",
        "--points",
        "30000",
        "-o",
        s(&pts),
        "--progress",
        "none",
    ]);
    let mesh = d.path().join("torus_mesh.ply");
    let hex = d.path().join("torus_hex.msh");
    for (bad, what) in [
        (vec!["--hex", "x.ply"], "--hex"),
        (vec!["--hex", "h.vtk", "--hex-scale", "0"], "--hex-scale"),
    ] {
        let mut args = vec!["reconstruct", s(&pts), "-o", s(&mesh), "--depth", "6"];
        args.extend(bad);
        let o = run(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(err.contains(what), "{err}");
        assert!(!mesh.exists());
    }
    let text = ok(&[
        "reconstruct",
        s(&pts),
        "-o",
        s(&mesh),
        "--depth",
        "6",
        "--hex",
        s(&hex),
        "--hex-scale",
        HEX_TORUS_SCALE,
        "--progress",
        "none",
    ]);
    assert!(text.contains("polycube deformation"), "{text}");
    assert!(text.contains("scaled Jacobian"), "{text}");
    let q = ok(&["hexcheck", s(&hex), "--json"]);
    let q: serde_json::Value = serde_json::from_str(&q).unwrap();
    assert_eq!(q["inverted"].as_u64(), Some(0), "{q}");
    assert!(q["hexes"].as_u64().unwrap() > 100, "{q}");
    let Some(c) = hex_check(&hex, Some(&mesh)) else {
        return;
    };
    assert_eq!(c["scaled_jacobian"]["count_le_0"].as_u64(), Some(0), "{c}");
    assert_eq!(c["boundary"]["closed"].as_bool(), Some(true), "{c}");
    assert!(c["reference"]["mean"].as_f64().unwrap() < 0.05, "{c}");
}

/// The hex edge of the reconstructed-torus test.
const HEX_TORUS_SCALE: &str = "0.2";
