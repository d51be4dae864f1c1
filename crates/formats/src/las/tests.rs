//! Tests of the LAS / LAZ reader: a written LAS file read back in chunks, the reference
//! file of the shared data set (when present), and truncated or damaged files.

use super::*;

const AUTZEN: &str = "../../../shared/data/lidar/autzen_trim.las";

fn autzen() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(AUTZEN);
    if p.is_file() {
        Some(p)
    } else {
        println!("skipped: reference file {} is absent", p.display());
        None
    }
}

fn read_all(r: &dyn PointReader, target: u64) -> PointBatch {
    let mut b = PointBatch::default();
    for c in r.chunks(target).unwrap() {
        r.read_chunk(&c, false, &mut b).unwrap();
    }
    b
}

/// Points with colour, in a header of point format 3, scale 0.01.
fn write_points(path: &Path, n: usize) -> Vec<las::Point> {
    let mut builder = las::Builder::default();
    builder.version = las::Version::new(1, 2);
    builder.point_format = las::point::Format::new(3).unwrap();
    builder.transforms = las::Vector {
        x: las::Transform {
            scale: 0.01,
            offset: 1000.0,
        },
        y: las::Transform {
            scale: 0.01,
            offset: 0.0,
        },
        z: las::Transform {
            scale: 0.001,
            offset: 0.0,
        },
    };
    let header = builder.into_header().unwrap();
    let mut w = las::Writer::from_path(path, header).unwrap();
    let mut pts = Vec::new();
    for i in 0..n {
        let p = las::Point {
            x: 1000.0 + i as f64 * 0.25,
            y: -(i as f64) * 0.5,
            z: (i % 17) as f64 * 0.125,
            intensity: (i * 7 % 65536) as u16,
            color: Some(las::Color {
                red: (i * 3) as u16,
                green: 65535,
                blue: (i % 256) as u16 * 257,
            }),
            gps_time: Some(i as f64),
            ..Default::default()
        };
        w.write_point(p.clone()).unwrap();
        pts.push(p);
    }
    w.close().unwrap();
    pts
}

fn check_against(b: &PointBatch, pts: &[las::Point]) {
    assert_eq!(b.len(), pts.len());
    for (i, p) in pts.iter().enumerate() {
        for (a, e) in b.pos[i].iter().zip([p.x, p.y, p.z]) {
            assert!((a - e).abs() < 1e-9, "point {i}: {:?} vs {:?}", b.pos[i], p);
        }
        assert_eq!(b.intensity[i], p.intensity as f32);
        let c = p.color.unwrap();
        assert_eq!(b.color[i], [c.red, c.green, c.blue, 65535]);
    }
}

#[test]
fn autzen_count_bounds_attributes_and_chunks() {
    let Some(p) = autzen() else { return };
    let r = LasReader::open(&p).unwrap();
    assert_eq!(r.format(), Format::Las);
    assert_eq!(r.len(), 110_000);
    assert_eq!((r.version(), r.point_format()), ((1, 2), 3));
    let a = r.attributes();
    assert!(a.color && a.intensity && !a.normal && !a.alpha && !a.confidence);
    let b = r.header_bounds().unwrap();
    let want_min = [636001.76, 848935.20, 406.26];
    let want_max = [637179.22, 849497.90, 520.51];
    for i in 0..3 {
        assert!((b.min[i] - want_min[i]).abs() <= 0.01, "{b:?}");
        assert!((b.max[i] - want_max[i]).abs() <= 0.01, "{b:?}");
    }

    let whole = read_all(&r, u64::MAX);
    assert_eq!(whole.len(), 110_000);
    assert_eq!(whole.color.len(), 110_000);
    assert_eq!(whole.intensity.len(), 110_000);
    assert!(whole.normal.is_empty());
    let mut seen = Aabb::EMPTY;
    for p in &whole.pos {
        seen.add(*p);
    }
    for i in 0..3 {
        assert!(seen.min[i] >= b.min[i] - 0.01 && seen.max[i] <= b.max[i] + 0.01);
    }
    // Autzen stores 8-bit colours in the 16-bit fields; they are carried as they are.
    assert!(whole.color.iter().all(|c| c[0] <= 255 && c[3] == 65535));
    assert!(whole.color.iter().any(|c| c[0] > 0));

    let chunks = r.chunks(7_001).unwrap();
    assert_eq!(chunks.len(), 16);
    let mut next = 0;
    for c in &chunks {
        assert_eq!(c.first_index, next);
        assert_eq!(c.byte_start, 2038 + 34 * c.first_index);
        assert_eq!(c.byte_end, c.byte_start + 34 * c.count);
        next += c.count;
    }
    assert_eq!(next, 110_000);
    assert_eq!(read_all(&r, 7_001), whole);

    // The same points as the las crate reads on its own.
    let mut lr = las::Reader::from_path(&p).unwrap();
    let pts: Vec<las::Point> = lr.points().map(|p| p.unwrap()).collect();
    check_against(&whole, &pts);

    let o = crate::open(&p).unwrap();
    assert_eq!((o.format(), o.len()), (Format::Las, 110_000));
}

#[test]
fn autzen_truncated_fails_cleanly() {
    let Some(p) = autzen() else { return };
    let d = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let t = d.path().join("trunc.las");
    std::fs::write(&t, &bytes[..5000]).unwrap();
    let e = LasReader::open(&t).err().unwrap().to_string();
    assert!(
        e.contains("trunc.las: element 87 (byte 4996): truncated"),
        "{e}"
    );
    for len in [0, 3, 100, 300, 2000] {
        std::fs::write(&t, &bytes[..len]).unwrap();
        let e = LasReader::open(&t).err().unwrap().to_string();
        assert!(e.contains("trunc.las"), "{len}: {e}");
    }
}

#[test]
fn wrong_signature_and_bad_header() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("fake.las");
    std::fs::write(&p, b"PK\x03\x04 this is a zip").unwrap();
    let e = LasReader::open(&p).err().unwrap().to_string();
    assert!(
        e.contains("fake.las: byte 0: not a LAS file") && e.contains("PK\\x03\\x04"),
        "{e}"
    );
    let e = crate::open(&p).err().unwrap().to_string();
    assert!(e.contains("not a LAS file"), "{e}");

    let good = d.path().join("good.las");
    write_points(&good, 3);
    let bytes = std::fs::read(&good).unwrap();
    let mut bad = bytes.clone();
    bad[131..139].copy_from_slice(&0f64.to_le_bytes());
    std::fs::write(&p, &bad).unwrap();
    let e = LasReader::open(&p).err().unwrap().to_string();
    assert!(e.contains("byte 131: x scale factor is 0"), "{e}");
    let mut bad = bytes.clone();
    bad[24] = 2;
    std::fs::write(&p, &bad).unwrap();
    let e = LasReader::open(&p).err().unwrap().to_string();
    assert!(e.contains("unsupported LAS version 2.2"), "{e}");
    let mut bad = bytes;
    bad[104] = 42;
    std::fs::write(&p, &bad).unwrap();
    let e = LasReader::open(&p).err().unwrap().to_string();
    assert!(
        e.contains("fake.las") && e.contains("byte 104: point data format 42"),
        "{e}"
    );
}

#[test]
fn every_prefix_of_a_small_las_fails_cleanly() {
    let d = tempfile::tempdir().unwrap();
    let full = d.path().join("full.las");
    write_points(&full, 5);
    let bytes = std::fs::read(&full).unwrap();
    let t = d.path().join("t.las");
    for len in 0..bytes.len() {
        std::fs::write(&t, &bytes[..len]).unwrap();
        if let Ok(r) = LasReader::open(&t) {
            panic!("prefix of {len} bytes opened with {} points", r.len());
        }
    }
    std::fs::write(&t, &bytes).unwrap();
    assert_eq!(LasReader::open(&t).unwrap().len(), 5);
}

#[test]
fn laz_round_trip() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("small.laz");
    let pts = write_points(&p, 1234);
    let r = LasReader::open(&p).unwrap();
    assert_eq!(r.format(), Format::Laz);
    assert_eq!(r.len(), 1234);
    assert_eq!(r.point_format(), 3);
    assert!(r.attributes().color && r.attributes().intensity);
    let b = r.header_bounds().unwrap();
    assert!((b.min[0] - 1000.0).abs() < 1e-9 && (b.max[0] - (1000.0 + 1233.0 * 0.25)).abs() < 1e-9);
    let whole = read_all(&r, u64::MAX);
    check_against(&whole, &pts);
    let chunks = r.chunks(100).unwrap();
    assert_eq!(chunks.len(), 13);
    assert!(chunks.iter().all(|c| c.byte_start == 0 && c.byte_end == 0));
    assert_eq!(read_all(&r, 100), whole);
    // Chunks read out of order, each by its own reader.
    let mut b = PointBatch::default();
    r.read_chunk(&chunks[7], false, &mut b).unwrap();
    assert_eq!(b.pos[0], whole.pos[700]);
    let o = crate::open(&p).unwrap();
    assert_eq!(o.format(), Format::Laz);
}

#[test]
fn truncated_laz_fails_cleanly() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("full.laz");
    write_points(&p, 300);
    let bytes = std::fs::read(&p).unwrap();
    let t = d.path().join("t.laz");
    let step = (bytes.len() / 40).max(1);
    for len in (0..bytes.len()).step_by(step) {
        std::fs::write(&t, &bytes[..len]).unwrap();
        let res = LasReader::open(&t).and_then(|r| {
            let mut b = PointBatch::default();
            for c in r.chunks(64)? {
                r.read_chunk(&c, false, &mut b)?;
            }
            Ok(b.len())
        });
        if let Err(e) = res {
            assert!(e.to_string().contains("t.laz"), "{len}: {e}");
        }
    }
}

#[test]
fn corrupt_laz_data_gives_errors_or_points_never_panics() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("full.laz");
    write_points(&p, 2000);
    let bytes = std::fs::read(&p).unwrap();
    let r = LasReader::open(&p).unwrap();
    let data_start = r.data_start as usize;
    let t = d.path().join("c.laz");
    let mut errors = 0;
    for k in 1..8 {
        let mut bad = bytes.clone();
        let at = data_start + 8 + (bytes.len() - data_start - 8) * k / 10;
        for b in &mut bad[at..at + 16] {
            *b ^= 0xa5;
        }
        std::fs::write(&t, &bad).unwrap();
        let res = LasReader::open(&t).and_then(|r| {
            let mut b = PointBatch::default();
            for c in r.chunks(500)? {
                r.read_chunk(&c, true, &mut b)?;
            }
            Ok(b.len())
        });
        match res {
            Ok(n) => assert_eq!(n, 2000),
            Err(e) => {
                errors += 1;
                assert!(e.to_string().contains("c.laz"), "{e}");
            }
        }
    }
    println!("{errors} of 7 corruptions reported as errors");
}

#[test]
fn laz_chunks_follow_laszip_chunks() {
    assert_eq!(aligned_target(0, None), 1);
    assert_eq!(aligned_target(7, Some(50_000)), 7);
    assert_eq!(aligned_target(50_000, Some(50_000)), 50_000);
    assert_eq!(aligned_target(74_999, Some(50_000)), 50_000);
    assert_eq!(aligned_target(1_000_000, Some(50_000)), 1_000_000);
    assert_eq!(aligned_target(1_030_000, Some(50_000)), 1_050_000);
    assert_eq!(aligned_target(u64::MAX, Some(50_000)) % 50_000, 0);
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("a.laz");
    write_points(&p, 10);
    assert_eq!(LasReader::open(&p).unwrap().laz_chunk, Some(50_000));
}

#[test]
fn chunk_past_the_end_is_an_error() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("s.las");
    write_points(&p, 4);
    let r = LasReader::open(&p).unwrap();
    let mut c = r.chunks(10).unwrap()[0];
    c.count = 5;
    let mut b = PointBatch::default();
    assert!(r.read_chunk(&c, false, &mut b).is_err());
}
