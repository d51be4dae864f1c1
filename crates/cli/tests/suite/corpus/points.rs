//! The corpus's point files: broken PLY headers, data, binary bodies and normals, XYZ,
//! LAS/LAZ, `.conf` files, FIFOs and devices.

use super::*;

/// PLY headers.
pub(super) fn ply_header_cases(c: &mut Corpus) {
    use Cmd::*;
    let good3 = "0 0 0\n1 0 0\n0 1 0\n";
    c.file("ply_empty", "empty.ply", b"", Ingest, NONE);
    c.file("ply_magic_only", "magic.ply", b"ply\n", Ingest, ANY_LOC);
    c.file("ply_not_ply", "notply.ply", b"hello\n1 2 3\n", Ingest, BYTE);
    let no_end = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
    c.file(
        "ply_no_end_header",
        "noend.ply",
        no_end.as_bytes(),
        Ingest,
        ANY_LOC,
    );
    let no_fmt = "ply\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n";
    c.file(
        "ply_no_format",
        "nofmt.ply",
        no_fmt.as_bytes(),
        Ingest,
        ANY_LOC,
    );
    let bad_fmt =
        "ply\nformat binary_middle_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n";
    c.file(
        "ply_bad_format",
        "badfmt.ply",
        bad_fmt.as_bytes(),
        Ingest,
        LINE,
    );
    let bad_ver = "ply\nformat ascii\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n";
    c.file(
        "ply_bad_version",
        "badver.ply",
        bad_ver.as_bytes(),
        Ingest,
        LINE,
    );
    let no_vertex = "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n3 0 1 2\n";
    c.file(
        "ply_no_vertex",
        "novertex.ply",
        no_vertex.as_bytes(),
        Ingest,
        LINE,
    );
    let t = ascii_head("3", &["y", "z"]) + "0 0\n1 0\n0 1\n";
    c.file("ply_missing_x", "nox.ply", t.as_bytes(), Ingest, LINE);
    let t = ascii_head("3", &["x", "y"]) + "0 0\n1 0\n0 1\n";
    c.file("ply_missing_z", "noz.ply", t.as_bytes(), Ingest, LINE);
    let t = "ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nproperty float y\nproperty float z\nend_header\n0 0 0\n";
    c.file("ply_bad_type", "badtype.ply", t.as_bytes(), Ingest, LINE);
    let t = "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\nproperty float y\nproperty float z\nend_header\n1 0 0 0\n";
    c.file("ply_list_as_x", "listx.ply", t.as_bytes(), Ingest, LINE);
    let t = ascii_head("abc", &XYZ) + good3;
    c.file(
        "ply_count_not_number",
        "countnan.ply",
        t.as_bytes(),
        Ingest,
        LINE,
    );
    let t = ascii_head("-5", &XYZ) + good3;
    c.file(
        "ply_negative_count",
        "negcount.ply",
        t.as_bytes(),
        Ingest,
        LINE,
    );
    let t = ascii_head("18446744073709551615", &XYZ) + good3;
    c.file(
        "ply_huge_count_ascii",
        "hugeascii.ply",
        t.as_bytes(),
        Ingest,
        ANY_LOC,
    );
}

/// PLY data: counts, values and records.
pub(super) fn ply_data_cases(c: &mut Corpus) {
    use Cmd::*;
    let good3 = "0 0 0\n1 0 0\n0 1 0\n";
    let b = binary_ply(4_000_000_000, &XYZ, &[0.0; 9], true);
    c.file("ply_huge_count_binary", "hugebin.ply", &b, Ingest, ANY_LOC);
    let b = binary_ply(u64::MAX / 4, &XYZ, &[0.0; 9], true);
    c.file(
        "ply_overflow_count_binary",
        "overflow.ply",
        &b,
        Ingest,
        ANY_LOC,
    );
    let t = ascii_head("5", &XYZ) + good3;
    c.file(
        "ply_fewer_lines",
        "fewer.ply",
        t.as_bytes(),
        Ingest,
        ANY_LOC,
    );
    let t = ascii_head("3", &XYZ) + "0 0 0\n1 abc 0\n0 1 0\n";
    c.file(
        "ply_non_number",
        "nonnum.ply",
        t.as_bytes(),
        Ingest,
        ELEMENT,
    );
    let t = ascii_head("3", &XYZ) + "0 0 0\n1 0\n0 1 0\n";
    c.file(
        "ply_too_few_values",
        "fewvals.ply",
        t.as_bytes(),
        Ingest,
        ANY_LOC,
    );
    let t = ascii_head("3", &XYZ) + "0 0 0\nnan 0 0\n0 1 0\n";
    c.file(
        "ply_nan_coordinate",
        "nanx.ply",
        t.as_bytes(),
        Ingest,
        ELEMENT,
    );
    let t = ascii_head("3", &XYZ) + "0 0 0\n1 0 0\n0 inf 0\n";
    c.file(
        "ply_inf_coordinate",
        "infy.ply",
        t.as_bytes(),
        Ingest,
        ELEMENT,
    );
    let t = ascii_head("3", &XYZ) + "0 0 0\n1 0 0\n0 1 1e999\n";
    c.file(
        "ply_overflowing_coordinate",
        "bigz.ply",
        t.as_bytes(),
        Ingest,
        ELEMENT,
    );
}

/// Binary PLY records, odd headers and the other commands.
pub(super) fn ply_binary_cases(c: &mut Corpus) {
    use Cmd::*;
    let b = binary_ply(
        3,
        &XYZ,
        &[0.0, 0.0, 0.0, 1.0, f32::NAN, 0.0, 0.0, 1.0, 0.0],
        true,
    );
    c.file("ply_binary_nan", "binnan.ply", &b, Ingest, ELEMENT);
    let b = binary_ply(3, &XYZ, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], true);
    c.file(
        "ply_binary_truncated_mid_record",
        "midrec.ply",
        &b,
        Ingest,
        ANY_LOC,
    );
    let b = binary_ply(100, &XYZ, &[1.0; 30], true);
    c.file(
        "ply_binary_truncated_records",
        "fewrec.ply",
        &b,
        Ingest,
        ANY_LOC,
    );
    let mut b = binary_ply(50, &XYZ, &[], false);
    b.extend(std::iter::repeat_n(0xffu8, 50 * 12));
    c.file(
        "ply_big_endian_garbage",
        "begarbage.ply",
        &b,
        Ingest,
        ELEMENT,
    );
    let t = ascii_head("0", &XYZ);
    c.file(
        "ply_header_only",
        "headeronly.ply",
        t.as_bytes(),
        Ingest,
        NONE,
    );
    let t = (ascii_head("3", &XYZ) + "0 0 0\n1 x 0\n0 1 0\n").replace('\n', "\r\n");
    c.file(
        "ply_crlf_non_number",
        "crlf.ply",
        t.as_bytes(),
        Ingest,
        ELEMENT,
    );
    let mut b = b"ply\n".to_vec();
    b.extend(junk(4096, 7));
    c.file(
        "ply_binary_junk_header",
        "junkhead.ply",
        &b,
        Ingest,
        ANY_LOC,
    );
    let mut t = "ply\nformat ascii 1.0\n".to_string();
    while t.len() < (1 << 20) + 100 {
        t += "comment a very long header that never ends\n";
    }
    c.file(
        "ply_endless_header",
        "endless.ply",
        t.as_bytes(),
        Ingest,
        ANY_LOC,
    );
    let t = ascii_head("3", &["x", "y", "z", "x"]) + "0 0 0 0\n1 0 0 1\n0 1 0 0\n";
    c.file(
        "ply_duplicate_property",
        "dupx.ply",
        t.as_bytes(),
        Ingest,
        LINE,
    );
    let t = "ply\nformat ascii 1.0\nelephant vertex 3\nend_header\n";
    c.file(
        "ply_unknown_keyword",
        "keyword.ply",
        t.as_bytes(),
        Ingest,
        LINE,
    );
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement face 2\nproperty list uchar int vertex_indices\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    b.push(3);
    b.extend_from_slice(&1i32.to_le_bytes());
    c.file(
        "ply_face_list_truncated",
        "facelist.ply",
        &b,
        Ingest,
        ANY_LOC,
    );
    let t = ascii_head("3", &XYZ) + "0 0 0\n1 0 0\n0 1 zz\n";
    c.file(
        "ply_reconstruct_non_number",
        "recon.ply",
        t.as_bytes(),
        Reconstruct,
        ELEMENT,
    );
    let t = ascii_head("3", &XYZ) + "0 0 0\n1 0 0\n0 1 zz\n";
    c.file(
        "ply_info_non_number",
        "info.ply",
        t.as_bytes(),
        Info,
        ELEMENT,
    );
}

/// NaN, infinite and zero normals (another change makes these ingest errors).
pub(super) fn ply_normal_cases(c: &mut Corpus) {
    use Cmd::*;
    for (name, n) in [
        ("ply_nan_normals", "nan 0 1"),
        ("ply_inf_normals", "0 inf 1"),
        ("ply_zero_normals", "0 0 0"),
    ] {
        let mut t = ascii_head("4", &XYZN);
        for p in ["0 0 0", "1 0 0", "0 1 0", "0 0 1"] {
            t += &format!("{p} {n}\n");
        }
        let p = c.write(name, &format!("{name}.ply"), t.as_bytes());
        c.add_named(name, Ingest, &p, &p, ELEMENT, PENDING_NORMALS);
    }
    let mut v = Vec::new();
    for i in 0..64 {
        v.extend_from_slice(&[
            i as f32,
            (i * 7 % 5) as f32,
            (i % 3) as f32,
            f32::NAN,
            0.0,
            1.0,
        ]);
    }
    let p = c.write(
        "ply_binary_nan_normals",
        "binnannormal.ply",
        &binary_ply(64, &XYZN, &v, true),
    );
    c.add_named(
        "ply_binary_nan_normals",
        Ingest,
        &p,
        &p,
        ELEMENT,
        PENDING_NORMALS,
    );
}

pub(super) fn xyz_cases(c: &mut Corpus) {
    use Cmd::*;
    c.file("xyz_empty", "empty.xyz", b"", Ingest, NONE);
    c.file("xyz_blank_lines", "blank.xyz", b"\n\n   \n", Ingest, NONE);
    c.file(
        "xyz_non_number",
        "nonnum.xyz",
        b"0 0 0\n1 2 x\n",
        Ingest,
        LINE,
    );
    c.file("xyz_two_columns", "twocol.xyz", b"0 0\n1 2\n", Ingest, LINE);
    c.file(
        "xyz_column_count_changes",
        "colchange.xyz",
        b"0 0 0\n1 2 3\n1 2 3 4 5\n",
        Ingest,
        LINE,
    );
    c.file("xyz_binary_junk", "junk.xyz", &junk(8192, 11), Ingest, LINE);
    c.file("xyz_nan", "nan.xyz", b"0 0 0\nnan 1 2\n", Ingest, LINE);
    c.file("xyz_inf", "inf.xyz", b"0 0 0\n1 -inf 2\n", Ingest, LINE);
    c.file(
        "xyz_overflow",
        "overflow.xyz",
        b"0 0 0\n1 2 1e400\n",
        Ingest,
        LINE,
    );
    c.file(
        "pts_count_mismatch",
        "count.pts",
        b"5\n1 2 3\n4 5 6\n",
        Ingest,
        LINE,
    );
    c.file(
        "txt_not_utf8",
        "latin.txt",
        b"0 0 0\n1 \xe9 2\n",
        Ingest,
        LINE,
    );
    c.file(
        "xyz_reconstruct_non_number",
        "recon.xyz",
        b"0 0 0\n1 0 0\n0 q 1\n",
        Reconstruct,
        LINE,
    );
    c.file(
        "xyz_info_two_columns",
        "info.xyz",
        b"0 0 0\n1 2\n",
        Info,
        LINE,
    );
    c.file("csv_unknown_format", "points.csv", b"0,0,0\n", Ingest, NONE);
    for (name, n) in [
        ("xyz_nan_normals", "nan 0 1"),
        ("xyz_zero_normals", "0 0 0"),
    ] {
        let t: String = ["0 0 0", "1 0 0", "0 1 0", "0 0 1"]
            .iter()
            .map(|p| format!("{p} {n}\n"))
            .collect();
        let p = c.write(name, &format!("{name}.xyz"), t.as_bytes());
        c.add_named(name, Ingest, &p, &p, LINE, PENDING_NORMALS);
    }
}

/// A valid LAS 1.2 (or LAZ, by extension) of `n` points of format 0.
pub(super) fn las_bytes(dir: &Path, file: &str, n: usize) -> Vec<u8> {
    let p = dir.join(format!("src-{file}"));
    let mut b = las::Builder::default();
    b.version = las::Version::new(1, 2);
    b.point_format = las::point::Format::new(0).unwrap();
    let mut w = las::Writer::from_path(&p, b.into_header().unwrap()).unwrap();
    for i in 0..n {
        let f = i as f64;
        w.write_point(las::Point {
            x: f,
            y: (f * 0.7).sin(),
            z: (f * 0.3).cos(),
            ..Default::default()
        })
        .unwrap();
    }
    w.close().unwrap();
    let bytes = std::fs::read(&p).unwrap();
    std::fs::remove_file(&p).unwrap();
    bytes
}

pub(super) fn las_cases(c: &mut Corpus) {
    use Cmd::*;
    let src = c.dir("las_sources");
    let las = las_bytes(&src, "a.las", 200);
    let laz = las_bytes(&src, "a.laz", 200);
    let patch = |b: &[u8], at: usize, v: &[u8]| {
        let mut b = b.to_vec();
        b[at..at + v.len()].copy_from_slice(v);
        b
    };
    c.file(
        "las_bad_signature",
        "sig.las",
        &patch(&las, 0, b"LASX"),
        Ingest,
        BYTE,
    );
    c.file(
        "laz_bad_signature",
        "sig.laz",
        &patch(&laz, 0, b"XASF"),
        Ingest,
        BYTE,
    );
    c.file("las_not_las", "hello.las", b"hello world", Ingest, BYTE);
    c.file(
        "las_truncated_header",
        "head.las",
        &las[..100],
        Ingest,
        BYTE,
    );
    c.file("las_signature_only", "sigonly.las", b"LASF", Ingest, BYTE);
    let more = patch(&las, 107, &100_000u32.to_le_bytes());
    c.file("las_count_beyond_file", "count.las", &more, Ingest, ANY_LOC);
    c.file(
        "las_bad_point_format",
        "pfmt.las",
        &patch(&las, 104, &[77]),
        Ingest,
        ANY_LOC,
    );
    let off = patch(&las, 96, &1_000_000_000u32.to_le_bytes());
    c.file("las_offset_beyond_file", "offset.las", &off, Ingest, BYTE);
    c.file(
        "las_bad_record_length",
        "reclen.las",
        &patch(&las, 105, &5u16.to_le_bytes()),
        Ingest,
        ANY_LOC,
    );
    c.file(
        "las_bad_header_size",
        "hsize.las",
        &patch(&las, 94, &10u16.to_le_bytes()),
        Ingest,
        ANY_LOC,
    );
    c.file(
        "las_bad_version",
        "version.las",
        &patch(&las, 24, &[9, 9]),
        Ingest,
        BYTE,
    );
    c.file(
        "las_truncated_points",
        "cut.las",
        &las[..las.len() - 13],
        Ingest,
        ANY_LOC,
    );
    c.file(
        "las_zero_points",
        "zero.las",
        &patch(&las, 107, &0u32.to_le_bytes()),
        Ingest,
        NONE,
    );
    let more = patch(&laz, 107, &100_000u32.to_le_bytes());
    c.file("laz_count_beyond_file", "count.laz", &more, Ingest, ANY_LOC);
    c.file(
        "laz_truncated",
        "cut.laz",
        &laz[..laz.len() / 2],
        Ingest,
        ANY_LOC,
    );
    let mut g = laz.clone();
    let start = u32::from_le_bytes(laz[96..100].try_into().unwrap()) as usize;
    let n = g.len() - start;
    g[start..].copy_from_slice(&junk(n, 5));
    c.file("laz_garbage_points", "garbage.laz", &g, Ingest, ANY_LOC);
    c.file(
        "las_reconstruct_truncated",
        "rcut.las",
        &las[..las.len() - 13],
        Reconstruct,
        ANY_LOC,
    );
    c.file(
        "las_info_truncated_header",
        "ihead.las",
        &las[..50],
        Info,
        BYTE,
    );
}

pub(super) fn conf_cases(c: &mut Corpus) {
    let scan = ascii_head("3", &XYZ) + "0 0 0\n1 0 0\n0 1 0\n";
    let conf = |c: &mut Corpus, name: &str, text: &str, loc: &'static [&'static str]| {
        let d = c.dir(name);
        std::fs::write(d.join("scan.ply"), &scan).unwrap();
        let p = d.join(format!("{name}.conf"));
        std::fs::write(&p, text).unwrap();
        let out = d.join("out.store");
        c.cases.push(Case {
            name: name.into(),
            args: [
                "ingest",
                "--conf",
                s(&p),
                "-o",
                s(&out),
                "--progress",
                "none",
            ]
            .map(String::from)
            .to_vec(),
            file: format!("{name}.conf"),
            loc,
            out: Some(out),
            pending: None,
            dir: d.clone(),
            code: 1,
        });
    };
    conf(
        c,
        "conf_missing_scan",
        "bmesh nothere.ply 0 0 0 0 0 0 1\n",
        LINE,
    );
    conf(c, "conf_bad_number", "bmesh scan.ply 0 0 x 0 0 0 1\n", LINE);
    conf(c, "conf_nan", "bmesh scan.ply 0 0 0 nan 0 0 1\n", LINE);
    conf(
        c,
        "conf_quaternion_zero",
        "camera 0 0 0 0 0 0 1\nbmesh scan.ply 0 0 0 0 0 0 0\n",
        LINE,
    );
    conf(c, "conf_wrong_fields", "bmesh scan.ply 0 0\n", LINE);
    conf(
        c,
        "conf_unknown_keyword",
        "scan scan.ply 0 0 0 0 0 0 1\n",
        LINE,
    );
    conf(c, "conf_no_bmesh", "camera 0 0 0 0 0 0 1\n", NONE);
    conf(c, "conf_empty", "", NONE);
    let d = c.dir("conf_directory_scan");
    std::fs::create_dir_all(d.join("scans")).unwrap();
    conf(
        c,
        "conf_directory_scan",
        "bmesh scans 0 0 0 0 0 0 1\n",
        LINE,
    );
    // The .conf itself missing, or a directory.
    let d = c.dir("conf_missing");
    let out = d.join("out.store");
    let missing = d.join("missing.conf");
    c.cases.push(Case {
        name: "conf_missing".into(),
        args: [
            "ingest",
            "--conf",
            s(&missing),
            "-o",
            s(&out),
            "--progress",
            "none",
        ]
        .map(String::from)
        .to_vec(),
        file: "missing.conf".into(),
        loc: NONE,
        out: Some(out),
        pending: None,
        dir: d.clone(),
        code: 1,
    });
    let d = c.dir("conf_is_directory");
    let dir = d.join("dir.conf");
    std::fs::create_dir_all(&dir).unwrap();
    let out = d.join("out.store");
    c.cases.push(Case {
        name: "conf_is_directory".into(),
        args: [
            "ingest",
            "--conf",
            s(&dir),
            "-o",
            s(&out),
            "--progress",
            "none",
        ]
        .map(String::from)
        .to_vec(),
        file: "dir.conf".into(),
        loc: NONE,
        out: Some(out),
        pending: None,
        dir: d.clone(),
        code: 1,
    });
}

/// FIFOs, a character device and directories given as point files: refused by file type,
/// without opening them (a FIFO would block).
pub(super) fn special_cases(c: &mut Corpus) {
    use Cmd::*;
    let d = c.dir("special");
    let fifo = d.join("pipe.ply");
    let made = Command::new("mkfifo").arg(&fifo).status();
    if matches!(made, Ok(s) if s.success()) {
        c.add("fifo_ingest", Ingest, &fifo, NONE);
        c.add("fifo_reconstruct", Reconstruct, &fifo, NONE);
        c.add("fifo_info", Info, &fifo, NONE);
        let d2 = c.dir("fifo_check");
        c.cases.push(Case {
            name: "fifo_check".into(),
            args: ["check", s(&fifo), "--reference", s(&fifo)]
                .map(String::from)
                .to_vec(),
            file: "pipe.ply".into(),
            loc: NONE,
            out: None,
            pending: None,
            dir: d2,
            code: 1,
        });
        let fifo_xyz = d.join("pipe.xyz");
        if matches!(Command::new("mkfifo").arg(&fifo_xyz).status(), Ok(s) if s.success()) {
            c.add("fifo_xyz_ingest", Ingest, &fifo_xyz, NONE);
        }
    } else {
        eprintln!("skipped the FIFO cases: mkfifo is not available");
    }
    let zero = Path::new("/dev/zero");
    if zero.exists() {
        c.add("dev_zero_ingest", Ingest, zero, NONE);
        c.add("dev_zero_reconstruct", Reconstruct, zero, NONE);
        c.add("dev_zero_info", Info, zero, NONE);
    }
    let dir = d.join("folder.ply");
    std::fs::create_dir_all(&dir).unwrap();
    c.add("directory_ingest", Ingest, &dir, NONE);
    c.add("directory_info", Info, &dir, NONE);
    c.add("directory_reconstruct", Reconstruct, &dir, NONE);
}
