//! Stanford/Scanalyze `.conf` scan lists.
//!
//! Each `bmesh FILE tx ty tz qx qy qz qw` line names a scan (relative to the `.conf`'s folder)
//! and its pose: a translation and a quaternion written x, y, z, w. Scanalyze stores the
//! pose such that the scan's points reach the common frame by the rotation of the
//! **conjugate** quaternion followed by the translation: `p_world = R(q)ᵀ p + t`. Checked on
//! the Stanford bunny: with this rule the ten scans land on each other (median distance
//! between overlapping scans ≈ 0.4 mm); with `R(q)` as written eight of them are centimetres
//! off. `camera` lines (the viewer's pose) and blank or `#` lines are ignored.
//!
//! Each scan is a Cyberware range image seen along its local `+z` axis (an orthographic
//! sensor), so its [`Viewpoint`] is the direction `R(q)ᵀ ẑ`. Checked on the bunny against the
//! normals of Stanford's zippered reconstruction: in every one of the ten scans 97.3–98.2% of
//! the points that lie on the reference (within 1 mm) have a reference normal with a positive
//! local `z`; the rest are grazing. A scanner *position* at the local origin is wrong for these
//! files (it agrees with only 3–21% of the normals).

use std::path::Path;

use crate::InputSpec;
use crate::error::{Error, IoContext, Location, Result};
use crate::types::{Rigid, Viewpoint};

/// Read a `.conf` file into inputs with their transforms.
pub fn read_conf(path: &Path) -> Result<Vec<InputSpec>> {
    crate::regular_file(path, "a .conf scan list")?;
    let text = std::fs::read_to_string(path).with_path(path)?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line_no = i as u64 + 1;
        let toks: Vec<&str> = line.split_ascii_whitespace().collect();
        match toks.first().copied() {
            None | Some("camera") | Some("mesh") => continue,
            Some(t) if t.starts_with('#') => continue,
            Some("bmesh") => {
                if toks.len() != 9 {
                    return Err(Error::format(
                        path,
                        Location::Line(line_no),
                        format!(
                            "expected \"bmesh FILE tx ty tz qx qy qz qw\" (9 fields), found {} fields",
                            toks.len()
                        ),
                    ));
                }
                let mut v = [0f64; 7];
                for (k, t) in toks[2..].iter().enumerate() {
                    v[k] = t
                        .parse::<f64>()
                        .ok()
                        .filter(|x| x.is_finite())
                        .ok_or_else(|| {
                            Error::format(
                                path,
                                Location::Line(line_no),
                                format!("field {} \"{}\" is not a finite number", k + 3, t),
                            )
                        })?;
                }
                let norm = (v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6]).sqrt();
                if norm < 1e-9 {
                    return Err(Error::format(
                        path,
                        Location::Line(line_no),
                        "quaternion is zero; expected a rotation",
                    ));
                }
                let file = dir.join(toks[1]);
                if let Some(what) = not_a_scan_file(&file) {
                    return Err(Error::format(
                        path,
                        Location::Line(line_no),
                        format!("scan file {} {what}", file.display()),
                    ));
                }
                // Conjugate: (x, y, z, -w) is the same rotation as (-x, -y, -z, w).
                let transform =
                    Rigid::from_quaternion([v[0], v[1], v[2]], [v[3], v[4], v[5], -v[6]]);
                out.push(InputSpec {
                    path: file,
                    transform,
                    viewpoint: Some(Viewpoint::Direction(transform.rotate([0.0, 0.0, 1.0]))),
                    scan: None,
                });
            }
            Some(other) => {
                return Err(Error::format(
                    path,
                    Location::Line(line_no),
                    format!("unknown .conf keyword \"{other}\"; expected bmesh or camera"),
                ));
            }
        }
    }
    if out.is_empty() {
        return Err(Error::input(
            path,
            "no \"bmesh\" line: the .conf names no scan",
        ));
    }
    Ok(out)
}

/// Why `file` cannot be read as a scan, if it cannot: "does not exist", "is a directory",
/// "is not a regular file (a FIFO)". Looks at the file's type only, so a FIFO does not block.
fn not_a_scan_file(file: &Path) -> Option<String> {
    match std::fs::metadata(file) {
        Ok(m) if m.is_file() => None,
        Ok(m) if m.is_dir() => Some("is a directory, expected a point file".into()),
        Ok(m) => Some(format!(
            "is not a regular file ({})",
            crate::file_kind(m.file_type())
        )),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Some("does not exist".into()),
        Err(e) => Some(format!("cannot be read ({e})")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_scan_names_line() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.conf");
        std::fs::write(
            &p,
            "camera 0 0 0 0 0 0 1\nbmesh nothere.ply 0 0 0 0 0 0 1\n",
        )
        .unwrap();
        let e = read_conf(&p).unwrap_err().to_string();
        assert!(
            e.contains("a.conf: line 2") && e.contains("does not exist"),
            "{e}"
        );
    }

    #[test]
    fn conf_naming_a_directory_says_it_is_a_directory() {
        let d = tempfile::tempdir().unwrap();
        std::fs::create_dir(d.path().join("scans")).unwrap();
        let p = d.path().join("a.conf");
        std::fs::write(&p, "bmesh scans 0 0 0 0 0 0 1\n").unwrap();
        let e = read_conf(&p).unwrap_err().to_string();
        assert!(
            e.contains("a.conf: line 1") && e.contains("is a directory"),
            "{e}"
        );
        assert!(!e.contains("does not exist"), "{e}");
        // The .conf itself a directory.
        let e = read_conf(d.path()).unwrap_err().to_string();
        assert!(e.contains("is a directory"), "{e}");
    }

    #[test]
    fn conjugate_rule() {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(d.path().join("s.ply"), b"ply\n").unwrap();
        let p = d.path().join("a.conf");
        let s = std::f64::consts::FRAC_1_SQRT_2;
        std::fs::write(&p, format!("bmesh s.ply 1 0 0 0 0 {s} {s}\n")).unwrap();
        let v = read_conf(&p).unwrap();
        // q is +90° about z; its conjugate maps x to -y.
        let q = v[0].transform.apply([1.0, 0.0, 0.0]);
        assert!(
            (q[0] - 1.0).abs() < 1e-12 && (q[1] + 1.0).abs() < 1e-12,
            "{q:?}"
        );
    }
}
