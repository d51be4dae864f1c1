//! `scanflow hexmesh` and `scanflow hexcheck`: hexahedra by CubeCover, and their quality.

use std::path::Path;

use anyhow::{Result, bail};

use scanflow::exec::Ctx;
use scanflow::hex::quality::mesh_quality;
use scanflow::pipeline::hexmesh::{HexStats, hexmesh};

use super::args::HexcheckArgs;
use super::config::HexmeshConfig;

/// Mesh, print the summary and the quality table; exit 1 when hexahedra are inverted (they
/// were written only under `--keep-inverted`).
pub fn run(c: &HexmeshConfig, ctx: &Ctx) -> Result<()> {
    let st = hexmesh(&c.job, ctx)?;
    summary(&st, &c.job.output)
}

/// Print what a hexmesh run measured and the quality table; an error when hexahedra are
/// inverted (they were written only under `--keep-inverted`).
pub fn summary(st: &HexStats, output: &Path) -> Result<()> {
    let [v3, v5, v6] = st.singular_by_valence;
    outln!(
        "{} tetrahedra → {} hexahedra ({} vertices) at edge {:.6}",
        st.tets,
        st.quality.hexes,
        st.extract.vertices,
        st.scale
    );
    for t in &st.tries {
        outln!(
            "edge {:.6} given up, a finer one tried: {}",
            t.scale,
            t.error
        );
    }
    outln!(
        "singular edges: {v3} of valence 3, {v5} of valence 5, {v6} of valence 2 or 6; {} nodes",
        st.singularities.nodes.len()
    );
    if let Some(p) = &st.polycube {
        outln!(
            "polycube deformation: boundary normals {:.1}° → {:.1}° from their axes (mean) in {} iterations, {:.0}% of the area within 5°; {} chords split",
            p.mean_deviation_start,
            p.mean_deviation,
            p.iterations,
            100.0 * p.aligned_fraction,
            st.chords_split
        );
    }
    outln!(
        "parameterisation: {} unknowns ({} integer), {} rounding rounds, alignment energy {:.4e} → {:.4e}",
        st.param.unknowns,
        st.param.integer_unknowns,
        st.param.rounds,
        st.param.energy_continuous,
        st.param.energy_final
    );
    if st.grid_fallback.is_some() {
        outln!(
            "grid: the aligned map flipped {} tetrahedra before any rounding, so the hexahedra are the grid of the axes at edge {:.6}, unaligned",
            st.param.flipped_continuous,
            st.scale
        );
    }
    if let Some(p) = &st.pillow {
        outln!(
            "pillowing: {} boundary hexahedra added ({} had two or more faces on the boundary; {} removed first so that it could be pillowed)",
            p.boundary_quads,
            p.multi_face_hexes,
            p.removed
        );
    }
    let s = st.seconds;
    outln!(
        "time: read {:.2} s, frames {:.2} s, parameterisation {:.2} s, extraction {:.2} s, relaxation {:.2} s",
        s[0],
        s[1],
        s[2],
        s[3],
        s[4]
    );
    outln!("{}", st.quality.table());
    outln!("wrote {}", output.display());
    if st.quality.inverted > 0 {
        bail!(
            "{}: {} of {} hexahedra are inverted",
            output.display(),
            st.quality.inverted,
            st.quality.hexes
        );
    }
    Ok(())
}

/// Print the quality of a hexahedral mesh; exit 1 when a hexahedron is inverted.
pub fn check(a: &HexcheckArgs) -> Result<()> {
    let hexes = scanflow::hex::volume::read(&a.input)?.into_hex_mesh(&a.input)?;
    let q = mesh_quality(&hexes);
    if a.json {
        outln!("{}", serde_json::to_string(&q)?);
    } else {
        outln!("{}", q.table());
    }
    if q.inverted > 0 {
        bail!(
            "{}: {} of {} hexahedra are inverted (scaled Jacobian ≤ 0)",
            a.input.display(),
            q.inverted,
            q.hexes
        );
    }
    Ok(())
}
