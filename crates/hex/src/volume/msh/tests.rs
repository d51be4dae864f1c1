use super::*;

/// A tetrahedron in MSH 4.1 ASCII: `$Nodes` on line 4, coordinates on lines 11 to 14,
/// the element block header on 18 and the element on 19.
const TET41: &str = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 4 1 4\n3 1 0 4\n\
                     1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n$Elements\n\
                     1 1 1 1\n3 1 4 1\n1 1 2 3 4\n$EndElements\n";

/// One hexahedron as gmsh 4.15 writes it in MSH 2.2 ASCII.
const GMSH22: &str = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n8\n1 0 0 1\n\
                      2 0 0 0\n3 0 1 1\n4 0 1 0\n5 2 0 1\n6 2 0 0\n7 2 1 1\n8 2 1 0\n\
                      $EndNodes\n$Elements\n1\n1 5 2 7 1 3 1 2 4 7 5 6 8\n$EndElements\n";

/// The same hexahedron as gmsh 4.15 writes it in MSH 2.2 binary (little-endian).
pub(in crate::volume) const GMSH22_BINARY: &str = "\
    244d657368466f726d61740a322e32203120380a010000000a24456e644d657368466f726d61740a244e6f6465730a38\
    0a0100000000000000000000000000000000000000000000000000f03f02000000000000000000000000000000000000\
    000000000000000000030000000000000000000000000000000000f03f000000000000f03f0400000000000000000000\
    00000000000000f03f00000000000000000500000000000000000000400000000000000000000000000000f03f060000\
    00000000000000004000000000000000000000000000000000070000000000000000000040000000000000f03f000000\
    000000f03f080000000000000000000040000000000000f03f00000000000000000a24456e644e6f6465730a24456c65\
    6d656e74730a310a05000000010000000200000001000000070000000100000003000000010000000200000004000000\
    070000000500000006000000080000000a24456e64456c656d656e74730a";

pub(in crate::volume) fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

fn read_bytes(data: &[u8]) -> Result<VolumeMesh> {
    read(Path::new("dir/bad.msh"), data)
}

/// The error for `data`, which must name the file and contain every one of `want`.
fn err(data: impl AsRef<[u8]>, want: &[&str]) {
    let e = read_bytes(data.as_ref()).unwrap_err().to_string();
    assert!(e.starts_with("dir/bad.msh: "), "{e}");
    for w in want {
        assert!(e.contains(w), "{e:?} lacks {w:?}");
    }
}

/// Binary MSH 4.1 in either byte order.
struct Bin {
    b: Vec<u8>,
    le: bool,
}

impl Bin {
    fn text(&mut self, s: &str) {
        self.b.extend_from_slice(s.as_bytes());
    }
    fn int(&mut self, v: i32) {
        let x = if self.le {
            v.to_le_bytes()
        } else {
            v.to_be_bytes()
        };
        self.b.extend_from_slice(&x);
    }
    fn size(&mut self, v: u64) {
        let x = if self.le {
            v.to_le_bytes()
        } else {
            v.to_be_bytes()
        };
        self.b.extend_from_slice(&x);
    }
    fn f64(&mut self, v: f64) {
        let x = if self.le {
            v.to_le_bytes()
        } else {
            v.to_be_bytes()
        };
        self.b.extend_from_slice(&x);
    }
}

/// A tetrahedron and a point element in binary MSH 4.1 with an `$Entities` and a
/// `$PhysicalNames` section; node tags 10, 20, 30, 40 in two blocks, the second
/// parametric (u, v after each node). Also the byte where the second block's
/// coordinates start.
pub(in crate::volume) fn tet41_binary(le: bool) -> (Vec<u8>, usize) {
    let mut w = Bin { b: Vec::new(), le };
    w.text("$MeshFormat\n4.1 1 8\n");
    w.int(1);
    w.text("\n$EndMeshFormat\n$PhysicalNames\n1\n3 7 \"$Nodes\"\n$EndPhysicalNames\n");
    w.text("$Entities\n");
    for n in [1, 0, 0, 1] {
        w.size(n);
    }
    w.int(1); // a point entity: tag, x y z, no physical tag
    for _ in 0..3 {
        w.f64(0.0);
    }
    w.size(0);
    w.int(1); // a volume entity: tag, box, physical tag 7, no bounding surface
    for v in [0.0, 0.0, 0.0, 1.0, 1.0, 1.0] {
        w.f64(v);
    }
    w.size(1);
    w.int(7);
    w.size(0);
    w.text("\n$EndEntities\n$Nodes\n");
    for n in [2, 4, 10, 40] {
        w.size(n);
    }
    for v in [0, 1, 0] {
        w.int(v);
    }
    w.size(1);
    w.size(10);
    for _ in 0..3 {
        w.f64(0.0);
    }
    for v in [2, 1, 1] {
        w.int(v);
    }
    w.size(3);
    for t in [20, 30, 40] {
        w.size(t);
    }
    let coords_at = w.b.len();
    for p in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
        for c in p {
            w.f64(c);
        }
        w.f64(0.25); // u
        w.f64(0.5); // v
    }
    w.text("\n$EndNodes\n$Elements\n");
    for n in [2, 2, 1, 2] {
        w.size(n);
    }
    for v in [0, 1, 15] {
        w.int(v);
    }
    w.size(1);
    w.size(1);
    w.size(10);
    for v in [3, 1, 4] {
        w.int(v);
    }
    w.size(1);
    for t in [2, 10, 20, 30, 40] {
        w.size(t);
    }
    w.text("\n$EndElements\n");
    (w.b, coords_at)
}

#[test]
fn reads_msh41_ascii() {
    let m = read_bytes(TET41.as_bytes()).unwrap();
    assert_eq!(m.verts[1], [1.0, 0.0, 0.0]);
    assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
    // Sparse tags, a parametric block (x y z u v on surface 1), an empty block, points
    // and lines skipped, an unknown element type skipped in ASCII, other sections skipped.
    let text = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Comments\n$Nodes inside\n\
                $EndComments\n$Nodes\n3 4 5 40\n0 1 0 1\n5\n0 0 0\n2 1 1 3\n10\n20\n40\n\
                1 0 0 0.5 0.5\n0 1 0 0 1\n0 0 1 1 0\n3 1 0 0\n$EndNodes\n$Elements\n\
                4 4 1 4\n0 1 15 1\n1 5\n1 1 1 1\n2 5 10\n3 1 4 1\n3 5 10 20 40\n\
                2 1 99 1\n4 1 2 3 4 5 6 7 8\n$EndElements\n$NodeData\n1\n\"t\"\n\
                $EndNodeData\n";
    let m = read_bytes(text.as_bytes()).unwrap();
    assert_eq!(
        m.verts,
        [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    );
    assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
    let skipped: Vec<(&str, usize)> = m.skipped.iter().map(|(k, n)| (k.as_str(), *n)).collect();
    assert_eq!(
        skipped,
        [("point", 1), ("2-node line", 1), ("element type 99", 1)]
    );
}

#[test]
fn reads_msh41_binary_in_both_byte_orders() {
    for le in [true, false] {
        let (data, _) = tet41_binary(le);
        let m = read_bytes(&data).unwrap();
        assert_eq!(
            m.verts,
            [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            "le {le}"
        );
        assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
        assert_eq!(m.skipped, vec![("point".to_string(), 1)]);
    }
}

#[test]
fn reads_msh22_as_gmsh_writes_it() {
    let want = [2, 0, 1, 3, 6, 4, 5, 7];
    for data in [GMSH22.as_bytes().to_vec(), unhex(GMSH22_BINARY)] {
        let m = read_bytes(&data).unwrap();
        assert_eq!(m.verts.len(), 8);
        assert_eq!(m.verts[4], [2.0, 0.0, 1.0]);
        assert_eq!(m.hexes, vec![want]);
    }
    // Sparse tags, several tags per element, lines and unknown types skipped.
    let text = "$MeshFormat\n2.0 0 8\n$EndMeshFormat\n$Nodes\n4\n10 0 0 0\n20 1 0 0\n\
                30 0 1 0\n40 0 0 1\n$EndNodes\n$Elements\n4\n1 1 2 0 1 10 20\n\
                2 4 3 1 2 3 10 20 30 40\n3 99 0 1 2\n4 2 0 10 20 30\n$EndElements\n";
    let m = read_bytes(text.as_bytes()).unwrap();
    assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
    assert_eq!(m.triangles, vec![[0, 1, 2]]);
    assert_eq!(m.skipped.len(), 2);
}

#[test]
fn truncated_files() {
    let at = |n: usize| TET41.lines().take(n).collect::<Vec<_>>().join("\n") + "\n";
    err(
        at(12),
        &[
            "line 13: ",
            "file ends in $Nodes: expected node coordinates",
        ],
    );
    err(
        at(2),
        &[
            "line 3: ",
            "file ends in $MeshFormat: expected $EndMeshFormat",
        ],
    );
    err(
        at(19),
        &["line 20: ", "file ends in $Elements: expected $EndElements"],
    );
    err(
        TET41.strip_suffix("$EndElements\n").unwrap().to_string() + "$EndElem",
        &["line 20: ", "expected $EndElements, found \"$EndElem\""],
    );
    err(
        TET41.to_string() + "$NodeData\n1\n",
        &["line 21: ", "section $NodeData has no $EndNodeData"],
    );
    // Binary data cut inside an array, in either byte order.
    for le in [true, false] {
        let (data, coords) = tet41_binary(le);
        err(
            &data[..coords + 30],
            &[
                &format!("byte {coords}: "),
                "file ends in $Nodes coordinates: expected 3 records of 40 bytes, found 30",
            ],
        );
    }
    let b = unhex(GMSH22_BINARY);
    err(
        &b[..100],
        &[
            "byte 49: ",
            "file ends in $Nodes: expected 8 records of 28 bytes, found 51",
        ],
    );
    err(
        &b[..320],
        &[
            "byte 308: ",
            "file ends in $Elements: expected 1 records of 44 bytes, found 12",
        ],
    );
}

#[test]
fn missing_sections() {
    let no_nodes = TET41.replace(
        "$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n",
        "",
    );
    err(no_nodes, &["line 4: ", "$Elements before $Nodes"]);
    err(
        "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n",
        &[
            "line 4: ",
            "no $Nodes section: expected $Nodes and $Elements",
        ],
    );
    err(
        "",
        &["line 1: ", "not a gmsh MSH file: expected $MeshFormat"],
    );
    err(
        "$Nodes\n",
        &["line 1: ", "expected $MeshFormat, found \"$Nodes\""],
    );
    err("$NOD\n1\n", &["MSH version 1 ($NOD) is not supported"]);
    err(
        TET41.replace("$EndNodes\n$Elements", "$EndNodes\n$EndElements\n$Elements"),
        &["line 16: ", "\"$EndElements\" without its section"],
    );
}

#[test]
fn indices_out_of_range() {
    err(
        TET41.replace("1 1 2 3 4\n", "1 1 2 3 9\n"),
        &[
            "line 19: ",
            "element 1: node 9 is not among the 4 nodes of $Nodes",
        ],
    );
    err(
        GMSH22.replace("1 2 4 7 5 6 8", "1 2 4 7 5 6 0"),
        &["line 17: ", "element 1: node 0 is not among the 8 nodes"],
    );
    let mut b = unhex(GMSH22_BINARY);
    let last = b.len() - 18; // the last node tag of the element, little-endian
    b[last] = 9;
    err(
        &b,
        &["byte 308: ", "element 1: node 9 is not among the 8 nodes"],
    );
    for le in [true, false] {
        let (mut data, _) = tet41_binary(le);
        let n = data.len();
        let last = if le { n - 22 } else { n - 15 }; // the low byte of node tag 40
        assert_eq!(data[last], 40);
        data[last] = 41;
        err(&data, &["element 2: node 41 is not among the 4 nodes"]);
    }
    err(
        TET41.replace("3\n4\n0 0 0", "3\n3\n0 0 0"),
        &["line 14: ", "node tag 3 appears twice"],
    );
}

#[test]
fn non_finite_coordinates() {
    err(
        TET41.replace("1 0 0\n", "1 nan 0\n"),
        &[
            "line 12: ",
            "node 2: y is NaN, expected a finite coordinate",
        ],
    );
    err(
        GMSH22.replace("5 2 0 1", "5 2 0 -inf"),
        &[
            "line 10: ",
            "node 5: z is -inf, expected a finite coordinate",
        ],
    );
    let (mut data, coords) = tet41_binary(true);
    data[coords + 8..coords + 16].copy_from_slice(&f64::INFINITY.to_le_bytes());
    err(
        &data,
        &[
            &format!("byte {coords}: "),
            "node 20: y is inf, expected a finite",
        ],
    );
}

#[test]
fn unknown_and_malformed_content() {
    err(
        TET41.replace("$Elements", "Elements"),
        &[
            "line 16: ",
            "expected a section such as $Nodes or $Elements, found \"Elements\"",
        ],
    );
    err(
        TET41.replace("4.1 0 8", "4 0 8"),
        &["line 2: ", "MSH version \"4\": expected 4.1"],
    );
    err(
        TET41.replace("4.1 0 8", "3.0 0 8"),
        &["MSH version \"3.0\""],
    );
    err(TET41.replace("4.1 0 8", "4.1 2 8"), &["file type 2"]);
    err(TET41.replace("4.1 0 8", "4.1 1 4"), &["data size 4"]);
    err(
        TET41.replace("4.1 0 8", "4.1 0"),
        &["line 2: ", "expected `version file-type data-size`"],
    );
    err(
        TET41.replace("1 1 2 3 4\n", "1 1 2 3\n"),
        &["line 19: ", "expected 5 numbers for an element of type 4"],
    );
    err(
        TET41.replace("1 4 1 4\n", "1 5 1 5\n"),
        &["the header announces 5 nodes, the blocks hold 4"],
    );
    err(
        TET41.replace("3 1 0 4\n", "3 1 0 -4\n"),
        &["line 6: ", "expected a node count >= 0, found -4"],
    );
    err(
        TET41.replace("1 0 0\n", "1 0\n"),
        &[
            "line 12: ",
            "node 2: expected 3 numbers (x y z), found \"1 0\"",
        ],
    );
    err(
        GMSH22.replace("1 5 2 7 1", "1 5 7 7 1"),
        &[
            "line 17: ",
            "expected 18 numbers for an element of type 5 with 7 tags",
        ],
    );
    let mut b = unhex(GMSH22_BINARY);
    b[0x14] = 2; // the byte-order integer
    err(&b, &["byte 20: ", "expected the integer 1"]);
}

#[test]
fn higher_order_elements() {
    err(
        TET41.replace("3 1 4 1\n1 1 2 3 4\n", "3 1 11 1\n1 1 2 3 4 1 2 3 4 1 2\n"),
        &[
            "line 18: ",
            "element type 11 (10-node tetrahedron): only linear elements",
        ],
    );
    err(
        GMSH22.replace("1 5 2 7 1", "1 12 2 7 1"),
        &["line 17: ", "element type 12 (27-node hexahedron)"],
    );
    let mut b = unhex(GMSH22_BINARY);
    let at = b.len() - 70; // the element type of the binary block
    assert_eq!(b[at], 5);
    b[at] = 17;
    err(
        &b,
        &[
            &format!("byte {at}: "),
            "element type 17 (20-node hexahedron)",
        ],
    );
    let (mut data, _) = tet41_binary(true);
    let n = data.len();
    let at = n - 14 - 40 - 20; // the second block: its header, one record, $EndElements
    assert_eq!(data[at + 8], 4);
    data[at + 8] = 29;
    err(
        &data,
        &[
            &format!("byte {at}: "),
            "element type 29 (20-node tetrahedron)",
        ],
    );
}
