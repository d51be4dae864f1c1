//! `scanflow check`: the topology of a mesh and, given a truth file or a reference, the
//! distances both ways; [`CheckReport`] prints the summary.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::{
    MeshCheck, Reference, ReferenceParams, TwoSided, check_mesh, mesh_to_reference, mesh_to_truth,
};
use crate::error::{Error, Result};
use crate::io::mesh_read::{is_mesh_file, read_any_mesh};
use crate::synth::Truth;
use crate::types::PointBatch;

/// Parameters of [`run_check_with`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckParams {
    /// Samples each way for distances.
    pub samples: usize,
    /// Seed of the samplers: the report is a function of the inputs and the parameters.
    pub seed: u64,
    /// See [`ReferenceParams::restrict_to_reference`]; only with a reference, finite and > 0.
    pub restrict_to_reference: Option<f64>,
}

impl Default for CheckParams {
    fn default() -> CheckParams {
        CheckParams {
            samples: 100_000,
            seed: 0,
            restrict_to_reference: None,
        }
    }
}

/// What a mesh was compared with.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
// A truth is ~300 bytes (the height field's bumps): one per comparison.
#[allow(clippy::large_enum_variant)]
pub enum Against {
    /// An exact surface from a truth file.
    Truth(Truth),
    /// A reference mesh.
    ReferenceMesh,
    /// A reference point set.
    ReferencePoints,
}

/// Distances between the checked mesh and a truth or reference.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Comparison {
    /// What the mesh was compared with.
    pub against: Against,
    /// The truth or reference file.
    pub path: PathBuf,
    /// Mesh samples farther than this from the reference were left out (input units).
    pub restricted_to: Option<f64>,
    /// Distances in input units.
    pub absolute: TwoSided,
    /// Distances relative to `absolute.diagonal`.
    pub relative: TwoSided,
    /// Symmetric Hausdorff distance as sampled, in input units.
    pub hausdorff: f64,
}

/// The result of `scanflow check`: topology, and distances when a truth or reference is given.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CheckReport {
    /// The mesh file.
    pub mesh: PathBuf,
    /// Its topology.
    pub check: MeshCheck,
    /// Distances to the truth or reference, if one was given.
    pub comparison: Option<Comparison>,
}

/// Check `mesh` and, given a truth file (`*.truth.json` from `scanflow synth`) or a reference
/// (a PLY mesh, or a point file readable by [`crate::io::open`]), measure distances both ways
/// with `samples` samples each; see [`run_check_with`].
pub fn run_check(
    mesh: &Path,
    truth: Option<&Path>,
    reference: Option<&Path>,
    samples: usize,
) -> Result<CheckReport> {
    run_check_with(
        mesh,
        truth,
        reference,
        &CheckParams {
            samples,
            ..CheckParams::default()
        },
    )
}

/// [`run_check`] with every parameter. A reference OBJ or STL, or PLY with at least one
/// face, is read as a mesh ([`read_any_mesh`]); any other reference file as points. Giving
/// both a truth and a reference, or a restriction without a reference or that is not finite and positive, is an
/// [`Error::Usage`].
pub fn run_check_with(
    mesh: &Path,
    truth: Option<&Path>,
    reference: Option<&Path>,
    params: &CheckParams,
) -> Result<CheckReport> {
    if truth.is_some() && reference.is_some() {
        return Err(Error::Usage(
            "give a truth file or a reference, not both".to_string(),
        ));
    }
    if let Some(r) = params.restrict_to_reference {
        if reference.is_none() {
            return Err(Error::Usage(
                "restricting distances to the reference needs a reference".to_string(),
            ));
        }
        if !(r.is_finite() && r > 0.0) {
            return Err(Error::Usage(format!(
                "the restriction distance is {r}, expected a finite positive distance"
            )));
        }
    }
    let m = read_any_mesh(mesh)?;
    let check = check_mesh(&m);
    let comparison = if let Some(path) = truth {
        let t = Truth::load(path)?;
        Some(comparison(
            Against::Truth(t),
            path,
            None,
            mesh_to_truth(&m, &t, params.samples, params.seed),
        ))
    } else if let Some(path) = reference {
        let rp = ReferenceParams {
            samples: params.samples,
            seed: params.seed,
            restrict_to_reference: params.restrict_to_reference,
        };
        let (against, d) = if is_mesh_file(path)? {
            let r = read_any_mesh(path)?;
            (
                Against::ReferenceMesh,
                mesh_to_reference(&m, Reference::Mesh(&r), &rp),
            )
        } else {
            let pts = read_points(path)?;
            if pts.is_empty() {
                return Err(Error::input(path, "holds no point: expected a reference"));
            }
            (
                Against::ReferencePoints,
                mesh_to_reference(&m, Reference::Points(&pts), &rp),
            )
        };
        Some(comparison(against, path, params.restrict_to_reference, d))
    } else {
        None
    };
    Ok(CheckReport {
        mesh: mesh.to_path_buf(),
        check,
        comparison,
    })
}

fn comparison(
    against: Against,
    path: &Path,
    restricted_to: Option<f64>,
    d: TwoSided,
) -> Comparison {
    Comparison {
        against,
        path: path.to_path_buf(),
        restricted_to,
        relative: d.relative(),
        hausdorff: d.hausdorff(),
        absolute: d,
    }
}

/// Most points reserved up front for a reference point set (384 MiB of positions), so that
/// a header announcing more than the file holds cannot reserve without bound.
const MAX_RESERVED_POINTS: u64 = 1 << 24;
/// Points read per chunk from a reference point file.
const READ_CHUNK_POINTS: u64 = 1 << 20;

/// Every point of a point file.
pub(super) fn read_points(path: &Path) -> Result<Vec<[f64; 3]>> {
    let reader = crate::io::open(path)?;
    let mut pts = Vec::with_capacity(reader.len().min(MAX_RESERVED_POINTS) as usize);
    let mut batch = PointBatch::default();
    for chunk in reader.chunks(READ_CHUNK_POINTS)? {
        batch.clear();
        reader.read_chunk(&chunk, false, &mut batch)?;
        pts.extend_from_slice(&batch.pos);
    }
    Ok(pts)
}

impl fmt::Display for CheckReport {
    /// A readable summary, one fact a line.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.check;
        let yes = |b: bool| if b { "yes" } else { "no" };
        writeln!(f, "mesh {}", self.mesh.display())?;
        writeln!(
            f,
            "  {} vertices, {} triangles, {} component{}",
            c.vertices,
            c.triangles,
            c.components,
            if c.components == 1 { "" } else { "s" }
        )?;
        writeln!(
            f,
            "  watertight: {}, edge-manifold: {}, vertex-manifold: {}, oriented: {}",
            yes(c.watertight),
            yes(c.edge_manifold),
            yes(c.vertex_manifold),
            yes(c.oriented)
        )?;
        writeln!(
            f,
            "  boundary edges {}, non-manifold edges {}, inconsistent edges {}, non-manifold vertices {}",
            c.boundary_edges, c.non_manifold_edges, c.inconsistent_edges, c.non_manifold_vertices
        )?;
        writeln!(
            f,
            "  degenerate triangles {}, unreferenced vertices {}{}",
            c.degenerate_triangles,
            c.unreferenced_vertices,
            if c.invalid_triangles > 0 {
                format!(
                    ", triangles with an index out of range {}",
                    c.invalid_triangles
                )
            } else {
                String::new()
            }
        )?;
        if c.bounds.is_empty() {
            writeln!(f, "  bounds: empty")?;
        } else {
            let p = |v: [f64; 3]| format!("[{:.6}, {:.6}, {:.6}]", v[0], v[1], v[2]);
            writeln!(
                f,
                "  bounds {} .. {}, diagonal {:.6}",
                p(c.bounds.min),
                p(c.bounds.max),
                c.diagonal
            )?;
        }
        let Some(cmp) = &self.comparison else {
            return Ok(());
        };
        let (what, other) = match cmp.against {
            Against::Truth(t) => (format!("exact {} surface", t.shape()), "truth"),
            Against::ReferenceMesh => ("reference mesh".to_string(), "reference"),
            Against::ReferencePoints => ("reference points".to_string(), "reference"),
        };
        writeln!(
            f,
            "distances to the {what} {} (reference diagonal {:.6}{}):",
            cmp.path.display(),
            cmp.absolute.diagonal,
            match cmp.restricted_to {
                Some(r) => format!("; mesh samples farther than {r} from it left out"),
                None => String::new(),
            }
        )?;
        writeln!(
            f,
            "  {:<16} {:>9} {:>11} {:>11} {:>11} {:>11}   (relative to the diagonal: mean, max)",
            "", "samples", "mean", "rms", "p95", "max"
        )?;
        for (label, a, r) in [
            (
                format!("mesh → {other}"),
                &cmp.absolute.to_reference,
                &cmp.relative.to_reference,
            ),
            (
                format!("{other} → mesh"),
                &cmp.absolute.from_reference,
                &cmp.relative.from_reference,
            ),
        ] {
            writeln!(
                f,
                "  {label:<16} {:>9} {:>11.4e} {:>11.4e} {:>11.4e} {:>11.4e}   ({:.3e}, {:.3e})",
                a.samples, a.mean, a.rms, a.p95, a.max, r.mean, r.max
            )?;
        }
        write!(
            f,
            "  Hausdorff distance {:.4e} ({:.3e} of the diagonal)",
            cmp.hausdorff,
            cmp.hausdorff / cmp.absolute.diagonal
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{chord_error, uv_sphere, write_ascii_mesh};

    #[test]
    fn run_check_end_to_end() {
        let d = tempfile::tempdir().unwrap();
        let sphere = uv_sphere(16, 32);
        let mp = d.path().join("s.ply");
        write_ascii_mesh(&mp, &sphere);

        let r = run_check(&mp, None, None, 1000).unwrap();
        assert!(r.comparison.is_none() && r.check.watertight);
        let text = r.to_string();
        assert!(
            text.contains("s.ply") && text.contains("watertight: yes"),
            "{text}"
        );

        let t = Truth::Sphere { radius: 1.0 };
        let tp = d.path().join("s.truth.json");
        crate::synth::TruthFile {
            truth: t,
            noise: 0.0,
            noise_sigma: 0.0,
            points: 0,
            seed: 0,
            bounding_box: t.bounding_box(),
            sample_bounding_box: None,
        }
        .save(&tp)
        .unwrap();
        let r = run_check(&mp, Some(&tp), None, 1000).unwrap();
        let cmp = r.comparison.as_ref().unwrap();
        assert_eq!(cmp.against, Against::Truth(t));
        assert!(cmp.hausdorff <= chord_error(&sphere) * (1.0 + 1e-9));
        assert!(
            (cmp.relative.to_reference.mean * cmp.absolute.diagonal
                - cmp.absolute.to_reference.mean)
                .abs()
                < 1e-15
        );
        let text = r.to_string();
        assert!(
            text.contains("exact sphere surface") && text.contains("Hausdorff"),
            "{text}"
        );
        let json = serde_json::to_string(&r).unwrap();
        assert!(
            json.contains("\"watertight\":true") && json.contains("\"shape\":\"sphere\""),
            "{json}"
        );

        // The same mesh as a reference mesh, and its vertices as a point file.
        let r = run_check(&mp, None, Some(&mp), 1000).unwrap();
        let cmp = r.comparison.unwrap();
        assert_eq!(cmp.against, Against::ReferenceMesh);
        assert!(cmp.hausdorff < 1e-12);
        let xp = d.path().join("v.xyz");
        let pts: String = sphere
            .vertices
            .iter()
            .map(|p| format!("{} {} {}\n", p[0], p[1], p[2]))
            .collect();
        std::fs::write(&xp, pts).unwrap();
        let r = run_check_with(
            &mp,
            None,
            Some(&xp),
            &CheckParams {
                samples: 1000,
                restrict_to_reference: Some(0.5),
                ..CheckParams::default()
            },
        )
        .unwrap();
        let cmp = r.comparison.as_ref().unwrap();
        assert_eq!(cmp.against, Against::ReferencePoints);
        assert_eq!(cmp.absolute.from_reference.samples, sphere.vertices.len());
        assert!(r.to_string().contains("left out"));

        // Usage and input errors.
        let both = run_check(&mp, Some(&tp), Some(&mp), 10).unwrap_err();
        assert!(matches!(both, Error::Usage(_)), "{both}");
        let bad = run_check_with(
            &mp,
            Some(&tp),
            None,
            &CheckParams {
                restrict_to_reference: Some(1.0),
                ..CheckParams::default()
            },
        )
        .unwrap_err();
        assert!(matches!(bad, Error::Usage(_)), "{bad}");
        let e = run_check(&xp, None, None, 10).unwrap_err().to_string();
        assert!(e.contains("v.xyz"), "{e}");
        let e = run_check(&mp, Some(&xp), None, 10).unwrap_err().to_string();
        assert!(e.contains("v.xyz"), "{e}");
    }

    #[test]
    fn bunny_res4_topology_and_distance_to_res3() {
        let dir =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/bunny/reconstruction");
        let (p4, p3) = (
            dir.join("bun_zipper_res4.ply"),
            dir.join("bun_zipper_res3.ply"),
        );
        if !(p4.is_file() && p3.is_file()) {
            eprintln!("skipped: {} not found", dir.display());
            return;
        }
        // Counts checked independently (a Python edge count): the decimated bunny has holes
        // at its base and duplicated triangles, whose edges are used 4 or 6 times.
        let r = run_check(&p4, None, Some(&p3), 5000).unwrap();
        let c = &r.check;
        assert_eq!((c.vertices, c.triangles, c.components), (453, 948, 1));
        assert_eq!(
            (c.boundary_edges, c.non_manifold_edges, c.inconsistent_edges),
            (26, 70, 0)
        );
        assert!(!c.watertight && !c.edge_manifold && c.oriented);
        let cmp = r.comparison.unwrap();
        assert_eq!(cmp.against, Against::ReferenceMesh);
        assert!(cmp.relative.to_reference.mean < 0.01 && cmp.relative.from_reference.mean < 0.01);
    }
}
