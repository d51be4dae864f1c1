use super::*;

/// One hexahedron as gmsh 4.15 writes it (VTK 2.0 ASCII): `POINTS` on line 5, the points
/// on lines 6 to 13, `CELLS` on 15, the cell on 16, `CELL_TYPES` on 18, its value on 19.
pub(in crate::volume) const GMSH_HEX: &str = "# vtk DataFile Version 2.0\nb, Created by Gmsh 4.15.2 \nASCII\n\
                        DATASET UNSTRUCTURED_GRID\nPOINTS 8 double\n0 0 1\n0 0 0\n0 1 1\n\
                        0 1 0\n2 0 1\n2 0 0\n2 1 1\n2 1 0\n\nCELLS 1 9\n8 2 0 1 3 6 4 5 7\n\n\
                        CELL_TYPES 1\n12\n\nCELL_DATA 1\nSCALARS CellEntityIds int 1\n\
                        LOOKUP_TABLE default\n7\n";

/// The hexahedron's vertices in the file's order.
const GMSH_HEX_CELL: [u32; 8] = [2, 0, 1, 3, 6, 4, 5, 7];

/// Five tetrahedra of the unit cube as meshio 5.3 writes them (VTK 5.1 ASCII).
pub(in crate::volume) const MESHIO_TETS: &str = "# vtk DataFile Version 5.1\nwritten by meshio v5.3.5\nASCII\n\
    DATASET UNSTRUCTURED_GRID\nPOINTS 8 double\n0.0 0.0 0.0 1.0 0.0 0.0 1.0 1.0 0.0 0.0 1.0 \
    0.0 0.0 0.0 1.0 1.0 0.0 1.0 1.0 1.0 1.0 0.0 1.0 1.0\nCELLS 6 20\nOFFSETS vtktypeint64\n\
    0\n4\n8\n12\n16\n20\nCONNECTIVITY vtktypeint64\n0\n1\n3\n4\n1\n2\n3\n6\n1\n6\n4\n5\n3\n4\n\
    6\n7\n1\n3\n4\n6\nCELL_TYPES 5\n10\n10\n10\n10\n10\n";

fn read_bytes(data: &[u8]) -> Result<VolumeMesh> {
    read(Path::new("dir/bad.vtk"), data)
}

/// The error for `data`, which must name the file and contain every one of `want`.
fn err(data: impl AsRef<[u8]>, want: &[&str]) {
    let e = read_bytes(data.as_ref()).unwrap_err().to_string();
    assert!(e.starts_with("dir/bad.vtk: "), "{e}");
    for w in want {
        assert!(e.contains(w), "{e:?} lacks {w:?}");
    }
}

/// A binary file: one hexahedron (the unit cube), one triangle and one line, points as
/// `float` or `double`, cells in the layout of version 4.2 or 5.1, with a `FIELD` block
/// before the points and `METADATA` after them. Also the bytes where the points and the
/// cell ids start.
pub(in crate::volume) fn binary(v5: bool, double: bool) -> (Vec<u8>, usize, usize) {
    let mut b = Vec::new();
    let version = if v5 { "5.1" } else { "4.2" };
    b.extend_from_slice(
        format!(
            "# vtk DataFile Version {version}\ntest\nBINARY\nDATASET UNSTRUCTURED_GRID\n\
             FIELD FieldData 1\nTIME 1 1 double\n"
        )
        .as_bytes(),
    );
    b.extend_from_slice(&0.5f64.to_be_bytes());
    let ty = if double { "double" } else { "float" };
    b.extend_from_slice(format!("\nPOINTS 8 {ty}\n").as_bytes());
    let points_at = b.len();
    for i in 0..8u32 {
        let p = [(i & 1) ^ ((i >> 1) & 1), (i >> 1) & 1, i >> 2]; // VTK order
        for c in p {
            if double {
                b.extend_from_slice(&(c as f64).to_be_bytes());
            } else {
                b.extend_from_slice(&(c as f32).to_be_bytes());
            }
        }
    }
    b.extend_from_slice(b"\nMETADATA\nINFORMATION 0\n\n");
    let cells: [&[i64]; 3] = [&[0, 1, 2, 3, 4, 5, 6, 7], &[0, 1, 2], &[6, 7]];
    let ids_at;
    if v5 {
        b.extend_from_slice(b"CELLS 4 13\nOFFSETS vtktypeint64\n");
        for o in [0i64, 8, 11, 13] {
            b.extend_from_slice(&o.to_be_bytes());
        }
        b.extend_from_slice(b"\nCONNECTIVITY vtktypeint64\n");
        ids_at = b.len();
        for c in cells {
            for &v in c {
                b.extend_from_slice(&v.to_be_bytes());
            }
        }
    } else {
        b.extend_from_slice(b"CELLS 3 16\n");
        ids_at = b.len();
        for c in cells {
            b.extend_from_slice(&(c.len() as i32).to_be_bytes());
            for &v in c {
                b.extend_from_slice(&(v as i32).to_be_bytes());
            }
        }
    }
    b.extend_from_slice(b"\nCELL_TYPES 3\n");
    for t in [12i32, 5, 3] {
        b.extend_from_slice(&t.to_be_bytes());
    }
    b.extend_from_slice(b"\nCELL_DATA 3\nSCALARS q double 1\nLOOKUP_TABLE default\n");
    (b, points_at, ids_at)
}

#[test]
fn reads_gmsh_and_meshio_output() {
    let m = read_bytes(GMSH_HEX.as_bytes()).unwrap();
    assert_eq!(m.verts[0], [0.0, 0.0, 1.0]);
    assert_eq!(m.hexes, vec![GMSH_HEX_CELL]);
    let m = read_bytes(MESHIO_TETS.as_bytes()).unwrap();
    assert_eq!(m.verts[6], [1.0, 1.0, 1.0]);
    assert_eq!(m.tets.len(), 5);
    assert_eq!(m.tets[4], [1, 3, 4, 6]);
}

#[test]
fn reads_binary_in_both_layouts() {
    for v5 in [false, true] {
        for double in [false, true] {
            let (data, _, _) = binary(v5, double);
            let m = read_bytes(&data).unwrap();
            assert_eq!(m.verts[2], [1.0, 1.0, 0.0]);
            assert_eq!(m.verts[7], [0.0, 1.0, 1.0]);
            assert_eq!(m.hexes, vec![[0, 1, 2, 3, 4, 5, 6, 7]]);
            assert_eq!(m.triangles, vec![[0, 1, 2]]);
            assert_eq!(m.skipped, vec![("VTK_LINE".to_string(), 1)]);
        }
    }
}

#[test]
fn voxels_become_hexahedra() {
    let text = GMSH_HEX.replace("CELL_TYPES 1\n12", "CELL_TYPES 1\n11");
    let m = read_bytes(text.as_bytes()).unwrap();
    let c = GMSH_HEX_CELL;
    assert_eq!(
        m.hexes,
        vec![[c[0], c[1], c[3], c[2], c[4], c[5], c[7], c[6]]]
    );
}

#[test]
fn truncated_files() {
    let at = |n: usize| GMSH_HEX.lines().take(n).collect::<Vec<_>>().join("\n") + "\n";
    err(
        at(8),
        &[
            "line 9: ",
            "file ends in POINTS (8 points, 24 numbers) after 9 of 24 values",
        ],
    );
    err(at(4), &["line 5: ", "no POINTS"]);
    err(
        at(15),
        &["line 16: ", "file ends in CELLS after 0 of 9 values"],
    );
    err(at(16), &["line 15: ", "CELLS without CELL_TYPES"]);
    err(
        at(18),
        &["line 19: ", "file ends in CELL_TYPES after 0 of 1 values"],
    );
    // The cell type 12 cut to 1: still a number, but the file ends inside it.
    err(
        &at(19)[..at(19).len() - 2],
        &["line 19: ", "ends inside \"1\"", "truncated"],
    );
    err(&GMSH_HEX[..10], &["line 1: ", "not a VTK legacy file"]);
    for v5 in [false, true] {
        let (data, points, ids) = binary(v5, true);
        err(
            &data[..points + 100],
            &[
                &format!("byte {}: ", points + 100),
                &format!(
                    "file ends in POINTS (8 points, 24 numbers): expected 24 values of 8 bytes from byte {points}, found 100 bytes"
                ),
            ],
        );
        let (what, n) = if v5 {
            ("CONNECTIVITY", 13)
        } else {
            ("CELLS", 16)
        };
        err(
            &data[..ids + 7],
            &[
                &format!("file ends in {what}: expected {n} values"),
                &format!("from byte {ids}"),
            ],
        );
    }
}

#[test]
fn missing_sections_and_unknown_keywords() {
    err(
        GMSH_HEX.replace("POINTS 8 double", "POINTZ 8 double"),
        &[
            "line 5: ",
            "expected POINTS, CELLS, CELL_TYPES, FIELD, POINT_DATA or CELL_DATA, found \"POINTZ\"",
        ],
    );
    let no_points = "# vtk DataFile Version 2.0\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n\
                     CELLS 1 9\n8 0 1 2 3 4 5 6 7\nCELL_TYPES 1\n12\n";
    err(
        no_points,
        &["line 5: ", "CELLS before POINTS: expected POINTS first"],
    );
    err(
        GMSH_HEX.replace("UNSTRUCTURED_GRID", "POLYDATA"),
        &[
            "line 4: ",
            "DATASET \"POLYDATA\": only UNSTRUCTURED_GRID is supported",
        ],
    );
    err(
        GMSH_HEX.replace("ASCII", "TEXT"),
        &["line 3: ", "expected ASCII or BINARY, found \"TEXT\""],
    );
    err(
        GMSH_HEX.replace("CELL_TYPES 1\n12\n", ""),
        &["line 15: ", "CELLS without CELL_TYPES"],
    );
    err(
        GMSH_HEX.replace("POINTS 8 double", "POINTS 8 quad"),
        &["line 5: ", "POINTS: unsupported data type \"quad\""],
    );
}

#[test]
fn indices_out_of_range() {
    err(
        GMSH_HEX.replace("8 2 0 1 3 6 4 5 7", "8 2 0 1 3 6 4 5 8"),
        &[
            "line 16: ",
            "cell 0 (VTK_HEXAHEDRON): point 8 is beyond the 8 points",
        ],
    );
    err(
        GMSH_HEX.replace("8 2 0 1 3 6 4 5 7", "8 2 0 1 3 -6 4 5 7"),
        &["line 16: ", "point -6 is beyond the 8 points"],
    );
    for v5 in [false, true] {
        let (mut data, _, ids) = binary(v5, false);
        let (size, skip) = if v5 { (8, 0) } else { (4, 4) };
        let at = ids + skip + 2 * size; // the third id of the hexahedron
        data[at + size - 1] = 9;
        err(
            &data,
            &[
                &format!("byte {at}: "),
                "cell 0 (VTK_HEXAHEDRON): point 9 is beyond the 8 points",
            ],
        );
    }
}

#[test]
fn non_finite_coordinates() {
    err(
        GMSH_HEX.replace("0 0 0\n", "nan 0 0\n"),
        &[
            "line 7: ",
            "POINTS: point 1: x is NaN, expected a finite coordinate",
        ],
    );
    let (mut data, points, _) = binary(false, true);
    let at = points + 8 * 5; // point 1, y
    data[at..at + 8].copy_from_slice(&f64::NEG_INFINITY.to_be_bytes());
    err(&data, &[&format!("byte {at}: "), "point 1: z is -inf"]);
    let (mut data, points, _) = binary(true, false);
    let at = points + 4 * 3;
    data[at..at + 4].copy_from_slice(&f32::NAN.to_be_bytes());
    err(&data, &[&format!("byte {at}: "), "point 1: x is NaN"]);
}

#[test]
fn malformed_cells() {
    err(
        GMSH_HEX
            .replace("CELLS 1 9", "CELLS 1 10")
            .replace("4 5 7\n", "4 5 7 0\n"),
        &[
            "line 15: ",
            "the 1 cells take 9 numbers, not the 10 announced",
        ],
    );
    err(
        GMSH_HEX.replace("8 2 0 1 3 6 4 5 7", "9 2 0 1 3 6 4 5 7"),
        &[
            "line 16: ",
            "cell 0: point count 9: expected 0 to the 8 numbers left",
        ],
    );
    err(
        GMSH_HEX.replace("CELLS 1 9\n8 2 0 1 3 6 4 5 7", "CELLS 1 5\n4 2 0 1 3"),
        &[
            "line 19: ",
            "cell 0: VTK_HEXAHEDRON (12) with 4 points, expected 8",
        ],
    );
    err(
        GMSH_HEX.replace("CELL_TYPES 1\n12", "CELL_TYPES 2\n12 12"),
        &[
            "line 18: ",
            "CELL_TYPES 2: expected 1, one type per cell of CELLS",
        ],
    );
    err(
        MESHIO_TETS.replace("OFFSETS vtktypeint64\n0\n", "OFFSETS vtktypeint64\n1\n"),
        &[
            "line 9: ",
            "OFFSETS: offset 0 is 1: expected offsets from 0",
        ],
    );
    err(
        MESHIO_TETS.replace("\n16\n20\nCONN", "\n16\n19\nCONN"),
        &[
            "line 14: ",
            "offset 5 is 19",
            "the last equal to the 20 connectivity entries",
        ],
    );
    err(
        MESHIO_TETS.replace("OFFSETS vtktypeint64", "OFFSETS string"),
        &["line 8: ", "OFFSETS: unsupported data type \"string\""],
    );
    err(
        MESHIO_TETS.replace("OFFSETS vtktypeint64", "CELL_TYPES 5"),
        &[
            "line 8: ",
            "expected OFFSETS and CONNECTIVITY, found \"CELL_TYPES\"",
        ],
    );
}

#[test]
fn higher_order_cells() {
    for (t, name) in [
        (25, "VTK_QUADRATIC_HEXAHEDRON"),
        (29, "VTK_TRIQUADRATIC_HEXAHEDRON"),
        (24, "VTK_QUADRATIC_TETRA"),
        (72, "VTK_LAGRANGE_HEXAHEDRON"),
    ] {
        err(
            GMSH_HEX.replace("CELL_TYPES 1\n12", &format!("CELL_TYPES 1\n{t}")),
            &[
                "line 19: ",
                &format!("cell 0: {name} ({t}): only linear cells are supported"),
            ],
        );
    }
    let (mut data, _, _) = binary(true, true);
    let types = memchr::memmem::find(&data, b"CELL_TYPES 3\n").unwrap() + 13;
    data[types + 3] = 25;
    err(
        &data,
        &[&format!("byte {types}: "), "VTK_QUADRATIC_HEXAHEDRON (25)"],
    );
}
