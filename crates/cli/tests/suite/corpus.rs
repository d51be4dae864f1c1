//! The malformed-input corpus (issue 13): over 120 broken PLY, XYZ, LAS/LAZ, `.conf` files,
//! FIFOs and devices, and damaged stores, generated here in a temp dir, each run through
//! `ingest`, `reconstruct`, `info`, `info --verify` or `check` under a time limit. Every run must exit
//! non-zero without a panic, name the offending file and, where the defect has one, its
//! location (line, element, byte or cell), and leave no output and no temporary file.
//!
//! Cases whose correct behaviour another change delivers are marked `pending`: they run and
//! their result is printed, but they do not fail the test until that change is in.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use super::common::*;
use super::store_verify::{cell_file, make_store, manifest, set_manifest};

/// Longest a case may run before it counts as a hang.
const TIMEOUT: Duration = Duration::from_secs(60);
/// Threads running cases at once.
const THREADS: usize = 3;

/// Locations an error may give.
const LINE: &[&str] = &["line "];
const ELEMENT: &[&str] = &["element "];
const BYTE: &[&str] = &["byte "];
const ANY_LOC: &[&str] = &["line ", "element ", "byte "];
const CELL: &[&str] = &["cell "];
const NONE: &[&str] = &[];

/// One malformed input and the command run on it.
struct Case {
    name: String,
    args: Vec<String>,
    /// The file name the message must contain.
    file: String,
    /// The message must contain one of these (none: no location required).
    loc: &'static [&'static str],
    /// The output the command would write, which must not appear.
    out: Option<PathBuf>,
    /// Why the case is not yet expected to pass, when another change delivers it.
    pending: Option<&'static str>,
    /// The case's own directory, where no temporary file may be left.
    dir: PathBuf,
    /// The exit status: 1 for a bad input, 2 for a bad command line.
    code: i32,
}

/// Builds the cases, each in its own directory under `root`.
struct Corpus {
    root: PathBuf,
    cases: Vec<Case>,
}

/// Which command a case runs on its file.
#[derive(Clone, Copy)]
enum Cmd {
    Ingest,
    Reconstruct,
    Info,
    Verify,
}

/// No case is pending now: NaN, infinite and zero normals are ingest errors.
const PENDING_NORMALS: Option<&str> = None;

impl Corpus {
    /// A fresh directory for case `name`.
    fn dir(&self, name: &str) -> PathBuf {
        let d = self.root.join(name);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Write `bytes` as `file` in the case's directory.
    fn write(&self, name: &str, file: &str, bytes: &[u8]) -> PathBuf {
        let p = self.dir(name).join(file);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    /// Add a case running `cmd` on `input`; the message must name `input`'s file name.
    fn add(&mut self, name: &str, cmd: Cmd, input: &Path, loc: &'static [&'static str]) {
        self.add_named(name, cmd, input, input, loc, None);
    }

    /// As [`Corpus::add`], with the file the message must name given apart and a reason
    /// why it is pending.
    fn add_named(
        &mut self,
        name: &str,
        cmd: Cmd,
        input: &Path,
        named: &Path,
        loc: &'static [&'static str],
        pending: Option<&'static str>,
    ) {
        let dir = self.dir(name);
        let p = s(input).to_string();
        let (mut args, out) = match cmd {
            Cmd::Ingest => {
                let o = dir.join("out.store");
                (vec!["ingest".into(), p, "-o".into(), s(&o).into()], Some(o))
            }
            Cmd::Reconstruct => {
                let o = dir.join("out.ply");
                let a = vec!["reconstruct".into(), p, "-o".into(), s(&o).into()];
                (a, Some(o))
            }
            Cmd::Info => (vec!["info".into(), p], None),
            Cmd::Verify => (vec!["info".into(), p, "--verify".into()], None),
        };
        if matches!(cmd, Cmd::Reconstruct) {
            args.extend(["--depth".into(), "5".into()]);
        }
        args.extend([
            "--progress".into(),
            "none".into(),
            "--threads".into(),
            "1".into(),
        ]);
        self.cases.push(Case {
            name: name.into(),
            args,
            file: named.file_name().unwrap().to_string_lossy().into_owned(),
            loc,
            out,
            pending,
            dir,
            code: 1,
        });
    }

    /// A usage case: `reconstruct` of a good input with the options `extra`, which must exit
    /// 2 naming `named` (an option or a path) before any work.
    fn usage(&mut self, name: &str, input: &Path, out: &str, extra: &[&str], named: &str) {
        let dir = self.dir(name);
        let o = dir.join(out);
        let mut args: Vec<String> = vec!["reconstruct".into(), s(input).into(), "-o".into()];
        args.push(s(&o).into());
        args.extend(extra.iter().map(|a| a.to_string()));
        args.extend(["--progress".into(), "none".into()]);
        self.cases.push(Case {
            name: name.into(),
            args,
            file: named.into(),
            loc: NONE,
            out: Some(o),
            pending: None,
            dir,
            code: 2,
        });
    }

    /// A point file `file` in its own case run by `cmd`.
    fn file(
        &mut self,
        name: &str,
        file: &str,
        bytes: &[u8],
        cmd: Cmd,
        loc: &'static [&'static str],
    ) {
        let p = self.write(name, file, bytes);
        self.add(name, cmd, &p, loc);
    }
}

/// An ascii PLY header of `n` vertices with float properties `props`.
fn ascii_head(n: &str, props: &[&str]) -> String {
    let mut h = format!("ply\nformat ascii 1.0\nelement vertex {n}\n");
    for p in props {
        h += &format!("property float {p}\n");
    }
    h + "end_header\n"
}

/// A binary PLY of float `props`, `records` given as f32 values (byte order by `le`).
fn binary_ply(n: u64, props: &[&str], values: &[f32], le: bool) -> Vec<u8> {
    let fmt = if le {
        "binary_little_endian"
    } else {
        "binary_big_endian"
    };
    let mut h = format!("ply\nformat {fmt} 1.0\nelement vertex {n}\n");
    for p in props {
        h += &format!("property float {p}\n");
    }
    let mut b = (h + "end_header\n").into_bytes();
    for v in values {
        b.extend_from_slice(&if le { v.to_le_bytes() } else { v.to_be_bytes() });
    }
    b
}

/// Deterministic junk bytes.
fn junk(n: usize, seed: u64) -> Vec<u8> {
    let mut x = seed | 1;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

const XYZ: [&str; 3] = ["x", "y", "z"];
const XYZN: [&str; 6] = ["x", "y", "z", "nx", "ny", "nz"];

/// PLY headers.
fn ply_header_cases(c: &mut Corpus) {
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
fn ply_data_cases(c: &mut Corpus) {
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
fn ply_binary_cases(c: &mut Corpus) {
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
fn ply_normal_cases(c: &mut Corpus) {
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

fn xyz_cases(c: &mut Corpus) {
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
fn las_bytes(dir: &Path, file: &str, n: usize) -> Vec<u8> {
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

fn las_cases(c: &mut Corpus) {
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

fn conf_cases(c: &mut Corpus) {
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
fn special_cases(c: &mut Corpus) {
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

/// Copy a store directory (and its `cells/`).
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let dst = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &dst);
        } else {
            std::fs::copy(e.path(), dst).unwrap();
        }
    }
}

/// A damage that edits a store's manifest.
fn edit(f: impl Fn(&mut serde_json::Value)) -> impl Fn(&Path) -> PathBuf {
    move |st: &Path| {
        let mut m = manifest(st);
        f(&mut m);
        set_manifest(st, &m);
        st.to_path_buf()
    }
}

impl Corpus {
    /// A case on a copy of the store `base`, damaged by `damage`, which returns the file the
    /// message must name.
    fn store(
        &mut self,
        base: &Path,
        name: &str,
        cmd: Cmd,
        loc: &'static [&'static str],
        damage: &dyn Fn(&Path) -> PathBuf,
    ) {
        let st = self.dir(name).join(format!("{name}.store"));
        copy_dir(base, &st);
        let named = damage(&st);
        self.add_named(name, cmd, &st, &named, loc, None);
    }
}

/// Damaged manifests: refused when the store is opened.
fn store_manifest_cases(c: &mut Corpus, base: &Path) {
    use Cmd::*;
    let dup = |m: &mut serde_json::Value| {
        let c1 = m["cells"][1].clone();
        m["cells"].as_array_mut().unwrap().insert(2, c1);
    };
    c.store(base, "store_duplicate_cell", Info, CELL, &edit(dup));
    c.store(
        base,
        "store_duplicate_cell_reconstruct",
        Reconstruct,
        CELL,
        &edit(dup),
    );
    c.store(
        base,
        "store_wrong_point_count",
        Info,
        NONE,
        &edit(|m| {
            m["point_count"] = (m["point_count"].as_u64().unwrap() * 2).into();
        }),
    );
    c.store(
        base,
        "store_wrong_cell_count",
        Verify,
        NONE,
        &edit(|m| {
            // Counts still adding up: only reading the cells finds the difference.
            let a = m["cells"][0]["count"].as_u64().unwrap();
            let b = m["cells"][1]["count"].as_u64().unwrap();
            m["cells"][0]["count"] = (a + 1).into();
            m["cells"][1]["count"] = (b - 1).into();
        }),
    );
    c.store(
        base,
        "store_escape_path",
        Info,
        CELL,
        &edit(|m| {
            m["cells"][0]["file"] = "../../../../etc/passwd".into();
        }),
    );
    c.store(
        base,
        "store_escape_path_reconstruct",
        Reconstruct,
        CELL,
        &edit(|m| {
            m["cells"][0]["file"] = "../../../../etc/passwd".into();
        }),
    );
    c.store(
        base,
        "store_absolute_path",
        Info,
        CELL,
        &edit(|m| {
            m["cells"][3]["file"] = "/etc/passwd".into();
        }),
    );
    c.store(
        base,
        "store_bad_key",
        Info,
        CELL,
        &edit(|m| m["cells"][0]["key"] = 0.into()),
    );
    c.store(
        base,
        "store_zero_count_cell",
        Info,
        CELL,
        &edit(|m| {
            let a = m["cells"][0]["count"].as_u64().unwrap();
            let b = m["cells"][1]["count"].as_u64().unwrap();
            m["cells"][0]["count"] = 0.into();
            m["cells"][1]["count"] = (a + b).into();
        }),
    );
    c.store(
        base,
        "store_huge_cell_count",
        Reconstruct,
        CELL,
        &edit(|m| {
            // Counts, total and inputs forged to agree on far more points than the file holds.
            let huge = 1u64 << 62;
            let a = m["cells"][0]["count"].as_u64().unwrap();
            let n = m["point_count"].as_u64().unwrap() - a + huge;
            m["cells"][0]["count"] = huge.into();
            m["point_count"] = n.into();
            m["inputs"][0]["points"] = (n + m["skipped_invalid"].as_u64().unwrap()).into();
        }),
    );
    c.store(
        base,
        "store_bad_compression",
        Info,
        NONE,
        &edit(|m| m["compression"] = "lz4".into()),
    );
    c.store(
        base,
        "store_bad_record_fields",
        Info,
        NONE,
        &edit(|m| {
            m["record_fields"][0] = "x:f16".into();
        }),
    );
    c.store(
        base,
        "store_unsorted_cells",
        Info,
        CELL,
        &edit(|m| {
            m["cells"].as_array_mut().unwrap().swap(0, 1);
        }),
    );
}

/// Damaged cell files and store directories.
fn store_file_cases(c: &mut Corpus, base: &Path) {
    use Cmd::*;
    #[cfg(unix)]
    c.store(base, "store_symlink_out", Info, CELL, &|st: &Path| {
        let cell = cell_file(st, 1);
        let outside = st.parent().unwrap().join("outside.zst");
        std::fs::rename(&cell, &outside).unwrap();
        std::os::unix::fs::symlink(&outside, &cell).unwrap();
        st.to_path_buf()
    });
    c.store(base, "store_missing_cell", Info, CELL, &|st: &Path| {
        std::fs::remove_file(cell_file(st, 2)).unwrap();
        st.to_path_buf()
    });
    c.store(base, "store_truncated_cell", Info, CELL, &|st: &Path| {
        let cell = cell_file(st, 2);
        let b = std::fs::read(&cell).unwrap();
        std::fs::write(&cell, &b[..b.len() / 3]).unwrap();
        st.to_path_buf()
    });
    let corrupt = |st: &Path| {
        let cell = cell_file(st, 1);
        let mut b = std::fs::read(&cell).unwrap();
        let mid = b.len() / 2;
        b[mid] ^= 0x33;
        std::fs::write(&cell, &b).unwrap();
        cell
    };
    c.store(base, "store_corrupt_cell_verify", Verify, NONE, &corrupt);
    c.store(
        base,
        "store_corrupt_cell_reconstruct",
        Reconstruct,
        NONE,
        &corrupt,
    );
    let junk_cell = |st: &Path| {
        let cell = cell_file(st, 0);
        let n = std::fs::metadata(&cell).unwrap().len() as usize;
        std::fs::write(&cell, junk(n, 3)).unwrap();
        cell
    };
    c.store(base, "store_junk_cell_verify", Verify, NONE, &junk_cell);
    let manifest_bytes = |bytes: Vec<u8>| {
        move |st: &Path| {
            std::fs::write(st.join("manifest.json"), &bytes).unwrap();
            st.join("manifest.json")
        }
    };
    c.store(
        base,
        "store_garbage_manifest",
        Info,
        NONE,
        &manifest_bytes(junk(2000, 9)),
    );
    c.store(
        base,
        "store_empty_json_manifest",
        Info,
        NONE,
        &manifest_bytes(b"{}".to_vec()),
    );
    let half = std::fs::read(base.join("manifest.json")).unwrap();
    let half = half[..half.len() / 2].to_vec();
    c.store(
        base,
        "store_truncated_manifest",
        Info,
        LINE,
        &manifest_bytes(half.clone()),
    );
    c.store(
        base,
        "store_truncated_manifest_reconstruct",
        Reconstruct,
        LINE,
        &manifest_bytes(half),
    );
    c.store(
        base,
        "store_wrong_version",
        Info,
        NONE,
        &edit(|m| m["version"] = 99.into()),
    );
    c.store(base, "store_missing_manifest", Info, NONE, &|st: &Path| {
        std::fs::remove_file(st.join("manifest.json")).unwrap();
        st.to_path_buf()
    });
    #[cfg(unix)]
    c.store(base, "store_fifo_manifest", Info, NONE, &|st: &Path| {
        let m = st.join("manifest.json");
        std::fs::remove_file(&m).unwrap();
        // A FIFO (reading it would block), or a directory where mkfifo is missing.
        let made = Command::new("mkfifo").arg(&m).status();
        if !matches!(made, Ok(s) if s.success()) {
            std::fs::create_dir(&m).unwrap();
        }
        m
    });
    c.store(base, "store_missing_cells_dir", Info, NONE, &|st: &Path| {
        std::fs::remove_dir_all(st.join("cells")).unwrap();
        st.to_path_buf()
    });
}

/// Run one case; `Ok` holds its message, `Err` says what was wrong.
fn run_case(c: &Case) -> Result<String, String> {
    let t0 = Instant::now();
    let mut child = bin()
        .args(&c.args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot run scanflow: {e}"))?;
    // Drain stderr on a thread so a chatty child cannot block on a full pipe.
    let mut err_pipe = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut err_pipe, &mut s);
        s
    });
    let status = loop {
        if let Some(st) = child.try_wait().map_err(|e| e.to_string())? {
            break st;
        }
        if t0.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("hung: killed after {TIMEOUT:?}"));
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let err = reader.join().unwrap_or_default();
    let mut wrong = Vec::new();
    if status.code() != Some(c.code) {
        wrong.push(format!("exit status {status}, expected {}", c.code));
    }
    if err.contains("panicked") {
        wrong.push("panicked".into());
    }
    if !err.contains(&c.file) {
        wrong.push(format!("the message does not name {}", c.file));
    }
    if !c.loc.is_empty() && !c.loc.iter().any(|l| err.contains(l)) {
        wrong.push(format!(
            "the message gives no location ({})",
            c.loc.join("/")
        ));
    }
    if let Some(o) = &c.out
        && o.exists()
    {
        wrong.push(format!("output {} exists", o.display()));
    }
    if let Some(o) = &c.out {
        let mut w = o.as_os_str().to_owned();
        w.push(".work");
        if Path::new(&w).exists() {
            wrong.push(format!("work directory {} left", Path::new(&w).display()));
        }
    }
    let tmp = temp_files(&c.dir);
    if !tmp.is_empty() {
        wrong.push(format!("temporary files left: {tmp:?}"));
    }
    if wrong.is_empty() {
        Ok(err.trim().to_string())
    } else {
        Err(format!("{}\n    stderr: {}", wrong.join("; "), err.trim()))
    }
}

/// Bad options and output paths, on a good input: usage errors, found before any work.
fn option_cases(c: &mut Corpus) {
    let good = c.write(
        "opt_input",
        "good.xyz",
        "0 0 0\n1 0 0\n0 1 0\n0 0 1\n".as_bytes(),
    );
    let cases: [(&str, &str, &[&str], &str); 18] = [
        ("opt_depth_low", "o.ply", &["--depth", "2"], "--depth 2"),
        (
            "opt_coarse_depth_deep",
            "o.ply",
            &["--depth", "9", "--coarse-depth", "8"],
            "--coarse-depth 8: expected 4 to 7",
        ),
        (
            "opt_coarse_depth_shallow",
            "o.ply",
            &["--coarse-depth", "3"],
            "--coarse-depth 3",
        ),
        ("opt_depth_high", "o.ply", &["--depth", "14"], "--depth 14"),
        (
            "opt_tile_not_pow2",
            "o.ply",
            &["--tile", "100"],
            "--tile 100",
        ),
        ("opt_tile_zero", "o.ply", &["--tile", "0"], "--tile 0"),
        (
            "opt_threads_huge",
            "o.ply",
            &["--threads", "100000"],
            "--threads",
        ),
        ("opt_mem_word", "o.ply", &["--mem", "lots"], "--mem"),
        ("opt_mem_zero", "o.ply", &["--mem", "0"], "--mem"),
        ("opt_smooth_neg", "o.ply", &["--smooth=-1"], "--smooth"),
        ("opt_error_nan", "o.ply", &["--error", "NaN"], "--error"),
        (
            "opt_point_weight_nan",
            "o.ply",
            &["--point-weight", "NaN"],
            "--point-weight",
        ),
        (
            "opt_viewpoint_two",
            "o.ply",
            &["--viewpoint", "1,2"],
            "--viewpoint",
        ),
        (
            "opt_neighbours_two",
            "o.ply",
            &["--neighbours", "2"],
            "--neighbours",
        ),
        ("opt_gpu_word", "o.ply", &["--gpu", "maybe"], "--gpu"),
        (
            "opt_gpu_solve_word",
            "o.ply",
            &["--gpu-solve", "maybe"],
            "--gpu-solve",
        ),
        ("opt_out_off", "o.off", &[], "o.off"),
        ("opt_out_no_dir", "missing/o.ply", &[], "missing"),
    ];
    for (name, out, extra, named) in cases {
        c.usage(name, &good, out, extra, named);
    }
    let input_out = c.dir("opt_out_is_input").join("in.ply");
    std::fs::copy(&good, &input_out).unwrap();
    let args: Vec<String> = ["reconstruct", s(&input_out), "-o", s(&input_out)]
        .iter()
        .map(|a| a.to_string())
        .collect();
    c.cases.push(Case {
        name: "opt_out_is_input".into(),
        args,
        file: "in.ply".into(),
        loc: NONE,
        out: None,
        pending: None,
        dir: c.dir("opt_out_is_input"),
        code: 2,
    });
}

#[test]
fn malformed_inputs_fail_cleanly_naming_file_and_place() {
    let t0 = Instant::now();
    let d = tempfile::tempdir().unwrap();
    let mut c = Corpus {
        root: d.path().to_path_buf(),
        cases: Vec::new(),
    };
    ply_header_cases(&mut c);
    ply_data_cases(&mut c);
    ply_binary_cases(&mut c);
    ply_normal_cases(&mut c);
    xyz_cases(&mut c);
    las_cases(&mut c);
    conf_cases(&mut c);
    special_cases(&mut c);
    let base = make_store(&c.dir("store_base"));
    store_manifest_cases(&mut c, &base);
    store_file_cases(&mut c, &base);
    option_cases(&mut c);
    let cases = c.cases;
    assert!(cases.len() >= 60, "only {} cases", cases.len());
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, Result<String, String>)>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..THREADS {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(case) = cases.get(i) else { break };
                    let r = run_case(case);
                    results.lock().unwrap().push((i, r));
                }
            });
        }
    });
    let mut results = results.into_inner().unwrap();
    results.sort_by_key(|r| r.0);
    let mut failed = Vec::new();
    // SCANFLOW_CORPUS_SHOW=1 prints every case's message.
    let show = std::env::var_os("SCANFLOW_CORPUS_SHOW").is_some();
    for (i, r) in results {
        let case = &cases[i];
        match (r, case.pending) {
            (Ok(_), Some(why)) => eprintln!("pending case {} now passes ({why})", case.name),
            (Ok(msg), None) => {
                if show {
                    eprintln!("{}: {msg}", case.name);
                }
            }
            (Err(e), Some(why)) => eprintln!("pending case {} fails ({why}): {e}", case.name),
            (Err(e), None) => failed.push(format!("{}: {e}", case.name)),
        }
    }
    eprintln!(
        "{} cases in {:.1} s",
        cases.len(),
        t0.elapsed().as_secs_f64()
    );
    assert!(
        failed.is_empty(),
        "{} of {} cases failed:\n{}",
        failed.len(),
        cases.len(),
        failed.join("\n")
    );
}
