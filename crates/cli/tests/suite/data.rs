//! The real scans in ../shared/data: every point file ingests with the documented counts,
//! and the ten bunny scans land on each other through bun.conf.

use super::common::*;
use scanflow::io::InputSpec;
use scanflow::metrics::{PointIndex, quantile};
use scanflow::store::Store;
use scanflow::types::{PointBatch, Rigid};

/// Counts from ../shared/data/README.md.
const COUNTS: &[(&str, u64)] = &[
    ("bunny/bun000.ply", 40256),
    ("bunny/bun045.ply", 40097),
    ("bunny/bun090.ply", 30379),
    ("bunny/bun180.ply", 40251),
    ("bunny/bun270.ply", 31701),
    ("bunny/bun315.ply", 35336),
    ("bunny/chin.ply", 37738),
    ("bunny/ear_back.ply", 32193),
    ("bunny/top2.ply", 38298),
    ("bunny/top3.ply", 36023),
    ("bunny/reconstruction/bun_zipper.ply", 35947),
    ("bunny/reconstruction/bun_zipper_res2.ply", 8171),
    ("bunny/reconstruction/bun_zipper_res3.ply", 1889),
    ("bunny/reconstruction/bun_zipper_res4.ply", 453),
    ("lidar/autzen_trim.las", 110000),
    ("scans/face000.ply", 85849),
    ("scans/igea.ply", 134345),
];

#[test]
fn every_shared_point_file_ingests_with_its_count() {
    let d = tempfile::tempdir().unwrap();
    for (i, (rel, n)) in COUNTS.iter().enumerate() {
        let Some(p) = shared(rel) else { return };
        let store = d.path().join(format!("{i}.store"));
        ingest_in_cells(&p, &store, 20000);
        let info: serde_json::Value =
            serde_json::from_str(&ok(&["info", s(&store), "--json"])).unwrap();
        assert_eq!(info["points"].as_u64(), Some(*n), "{rel}");
        let finfo: serde_json::Value =
            serde_json::from_str(&ok(&["info", s(&p), "--json", "--progress", "none"])).unwrap();
        assert_eq!(finfo["points"].as_u64(), Some(*n), "{rel}");
    }
}

#[test]
fn autzen_carries_colour_and_intensity() {
    let Some(p) = shared("lidar/autzen_trim.las") else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let store = d.path().join("a.store");
    ok(&["ingest", s(&p), "-o", s(&store), "--progress", "none"]);
    let st = Store::open(&store).unwrap();
    let m = &st.manifest;
    assert!(m.attributes.color && m.attributes.intensity);
    // Extent from the README (feet), to the LAS scale of 0.01.
    let (lo, hi) = (m.bounds.min, m.bounds.max);
    for (a, b) in [
        (lo[0], 636001.76),
        (lo[1], 848935.20),
        (lo[2], 406.26),
        (hi[0], 637179.22),
        (hi[1], 849497.90),
        (hi[2], 520.51),
    ] {
        assert!((a - b).abs() <= 0.011, "{a} vs {b}");
    }
    let b = st.read_cell(0).unwrap();
    assert!(b.color.iter().any(|c| c[0] != c[1]), "colours carried");
}

fn load(spec: &InputSpec) -> Vec<[f64; 3]> {
    let r = scanflow::io::open(&spec.path).unwrap();
    let mut b = PointBatch::default();
    for c in r.chunks(1 << 16).unwrap() {
        r.read_chunk(&c, false, &mut b).unwrap();
    }
    b.transform(&spec.transform);
    b.pos
}

/// For each scan: the fraction of its points whose nearest point in another scan is within
/// 1 mm, and the median of that distance.
fn overlap(specs: &[InputSpec]) -> Vec<(f64, f64)> {
    let clouds: Vec<Vec<[f64; 3]>> = specs.iter().map(load).collect();
    (0..clouds.len())
        .map(|i| {
            let others: Vec<[f64; 3]> = clouds
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .flat_map(|(_, c)| c.iter().copied())
                .collect();
            let idx = PointIndex::new(&others);
            let mut d: Vec<f64> = clouds[i].iter().map(|p| idx.nearest_distance(*p)).collect();
            let within = d.iter().filter(|&&x| x < 1e-3).count() as f64 / d.len() as f64;
            (within, quantile(&mut d, 0.5))
        })
        .collect()
}

#[test]
fn bunny_scans_align_through_conf() {
    let Some(conf) = shared("bunny/bun.conf") else {
        return;
    };
    let specs = scanflow::io::conf::read_conf(&conf).unwrap();
    assert_eq!(specs.len(), 10);
    for (i, (within, median)) in overlap(&specs).into_iter().enumerate() {
        eprintln!(
            "{}: {:.1}% within 1 mm, median {:.3} mm",
            specs[i].path.display(),
            within * 100.0,
            median * 1e3
        );
        // "Most points": chin.ply sees the underside, which few other scans cover (67%).
        assert!(
            within > 0.6 && median < 0.6e-3,
            "{}: only {:.1}% within 1 mm",
            specs[i].path.display(),
            within * 100.0
        );
    }
    // The rotation as written (not conjugated) does not align them: the test can fail.
    let wrong: Vec<InputSpec> = specs
        .iter()
        .map(|s| {
            let r = s.transform.rotation;
            let transposed = [0, 1, 2].map(|a| [0, 1, 2].map(|b| r[b][a]));
            InputSpec {
                path: s.path.clone(),
                transform: Rigid {
                    rotation: transposed,
                    translation: s.transform.translation,
                },
                viewpoint: s.viewpoint,
                scan: None,
            }
        })
        .collect();
    let wrong_overlap = overlap(&wrong);
    eprintln!("unconjugated: {wrong_overlap:?}");
    let bad = wrong_overlap.iter().filter(|(w, _)| *w < 0.5).count();
    assert!(bad >= 5, "the unconjugated rule should misalign most scans");
    // And the store built from the .conf holds every point.
    let d = tempfile::tempdir().unwrap();
    let store = d.path().join("b.store");
    ok(&[
        "ingest",
        "--conf",
        s(&conf),
        "-o",
        s(&store),
        "--progress",
        "none",
    ]);
    assert_eq!(Store::open(&store).unwrap().manifest.point_count, 362272);
}

#[test]
fn info_gives_the_las_header_crs_classes_and_returns_as_laspy_reads_them() {
    let Some(p) = shared("lidar/autzen_trim.las") else {
        return;
    };
    let json: serde_json::Value =
        serde_json::from_str(&ok(&["info", s(&p), "--json", "--progress", "none"])).unwrap();
    let las = &json["las"];
    assert_eq!(las["version"], "1.2");
    assert_eq!(las["point_format"], 3);
    assert_eq!(las["generating_software"], "PDAL 1.0.0 (9e8465)");
    let wkt = las["crs"]["wkt"].as_str().unwrap();
    assert!(wkt.starts_with("PROJCS[\"NAD_1983_HARN_Lambert_Conformal_Conic\""));
    assert!(las["warnings"].as_array().unwrap().is_empty());
    let sum = |v: &serde_json::Value| {
        v.as_object()
            .unwrap()
            .values()
            .map(|n| n.as_u64().unwrap())
            .sum::<u64>()
    };
    assert_eq!(sum(&las["classes"]), 110_000);
    assert_eq!(sum(&las["returns"]), 110_000);
    let text = ok(&["info", s(&p), "--progress", "none"]);
    for want in [
        "las         version 1.2, point format 3",
        "scale       0.01 0.01 0.01",
        "crs         projected user-defined, geographic user-defined, WKT \"NAD_1983_HARN_Lambert_Conformal_Conic\"",
        "classes     1 unclassified: ",
    ] {
        assert!(text.contains(want), "{want}\n{text}");
    }
    // The same figures from an independent reader.
    let script = r#"
import json, sys
import numpy as np
import laspy
f = laspy.read(sys.argv[1])
h = f.header
cls, cn = np.unique(np.asarray(f.classification), return_counts=True)
ret, rn = np.unique(np.asarray(f.return_number), return_counts=True)
wkt = [v.string for v in h.vlrs if v.record_id == 2112]
print(json.dumps(dict(version="%d.%d" % (h.version.major, h.version.minor),
    point_format=h.point_format.id, scale=list(map(float, h.scales)),
    offset=list(map(float, h.offsets)), software=h.generating_software,
    classes={str(int(c)): int(n) for c, n in zip(cls, cn)},
    returns={str(int(r)): int(n) for r, n in zip(ret, rn)},
    wkt=wkt[0] if wkt else None)))
"#;
    let out = std::process::Command::new("python3")
        .args(["-c", script, s(&p)])
        .output()
        .ok()
        .filter(|o| o.status.success());
    let Some(out) = out else {
        eprintln!("skipped the laspy comparison: python3 with laspy and numpy is not available");
        return;
    };
    let want: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(las["version"], want["version"]);
    assert_eq!(las["point_format"], want["point_format"]);
    assert_eq!(las["scale"], want["scale"]);
    assert_eq!(las["offset"], want["offset"]);
    assert_eq!(las["generating_software"], want["software"]);
    assert_eq!(las["classes"], want["classes"]);
    assert_eq!(las["returns"], want["returns"]);
    assert_eq!(
        las["crs"]["wkt"].as_str().map(str::trim),
        want["wkt"]
            .as_str()
            .map(|w| w.trim_end_matches('\0').trim())
    );
}
