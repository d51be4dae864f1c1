//! The pipeline: the only code that chains stages (ARCHITECTURE.md steps 1 to 5). A stage
//! (`store`, `normals`, `recon`, `surface`, `extract`) never imports a sibling; the pipeline
//! reads the store, hands each stage the slices it works on, and owns the work directory,
//! resume, the waves and the writer.
//!
//! - [`ingest`]: point files to a committed store: the store's passes, then normals
//!   ([`normals`](crate::normals)), then the commit; or an existing store opened.
//! - [`reconstruct()`]: a store to a mesh: plan, coarse pass, leaf pass ([`recon`](crate::recon)),
//!   then the tiles (`tiles`: blend and extract, fit and colour ([`surface`](crate::surface)),
//!   weld and write).
//! - [`shard`]: one task's slice of a run split over a cluster array job, and
//!   [`merge()`]: the split run's tiles welded into the mesh one process writes.
//! - [`global_solve`]: the single-solve reference the tests measure the two-level scheme
//!   against.

mod details;
pub mod fit;
pub mod fit_patches;
pub mod fit_tiles;
mod global;
pub mod hexmesh;
pub mod ingest;
pub mod ingest_split;
pub mod merge;
mod points;
pub mod reconstruct;
pub mod shard;
pub mod spectral;
pub mod spectrum;
mod tiles;
pub mod workdir;

pub use global::global_solve;
pub use merge::{MergeStats, merge};
pub use reconstruct::{ReconParams, ReconStats, reconstruct};

#[cfg(test)]
mod tests {
    use crate::extract::field::BlendEval;
    use crate::extract::field::tests::RandomBlend;
    use crate::recon::pou;
    use crate::types::WEIGHT_BITS;

    /// The tile field across stages: recon's partition-of-unity weights (bumps normalised
    /// over the cells meeting at a node, Schall, Belyaev & Seidel 2006 §3.3) blended by
    /// extract's integer evaluation give the field of the definition.
    #[test]
    fn blend_with_recon_weights_matches_the_definition() {
        let one = (1u64 << WEIGHT_BITS) as f64;
        for (seed, lo, dims, e) in [
            (1, [0, 0, 0], [33, 33, 33], 32),
            (2, [64, 32, 96], [65, 17, 40], 32),
            (3, [40, 8, 0], [20, 30, 50], 16),
        ] {
            let mut rb = RandomBlend::new(seed, lo, dims, e, 0.6);
            rb.own = pou::leaf_weights(rb.e, rb.ov);
            // The integer weights are the normalised bumps to within their rounding.
            let (e, ov) = (rb.e, rb.ov);
            let total = |o: i64| -> f64 { (-2..=2).map(|m| pou::bump(e, ov, o - m * e)).sum() };
            for (s, &q) in rb.own.iter().enumerate() {
                let o = s as i64 - ov;
                let want = pou::bump(e, ov, o) / total(o.rem_euclid(e));
                assert!((q as f64 / one - want).abs() <= 1.0 / one, "offset {s}");
            }
            let f = rb.blend().try_eval().unwrap();
            let mut worst = 0f64;
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let v = f[(z * dims[1] + y) * dims[0] + x] as f64;
                        worst = worst.max((v - rb.reference([x, y, z])).abs());
                    }
                }
            }
            // Exact but for the final shift, which rounds down to a whole unit.
            assert!(worst <= rb.unit as f64, "seed {seed}: off by {worst}");
        }
    }
}
