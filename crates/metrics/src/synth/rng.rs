//! Seeded generators: one PCG64 stream per chunk of work, derived from the seed and the
//! chunk's number only, so that results never depend on the number of threads.
//!
//! Two derivations live here, one per user: [`chunk_rng`] for the points `synth` writes and
//! [`stream_rng`] for the samples of [`crate`]. Each is fixed by the bytes and figures
//! it already produced, so neither may change.

use rand::SeedableRng;
use rand_pcg::Pcg64;

/// `2^64 / φ`, the Weyl increment of SplitMix64.
const GOLDEN: u64 = 0x9e37_79b9_7f4a_7c15;

/// The SplitMix64 finaliser, a bijection of `u64`.
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The generator of `synth` chunk `chunk`: its 128-bit state is an injective function of
/// `(seed, chunk)` built from SplitMix64 steps, so no two chunks or seeds share a stream start.
pub(crate) fn chunk_rng(seed: u64, chunk: u64) -> Pcg64 {
    let hi = mix64(seed.wrapping_add(GOLDEN));
    let lo = mix64(chunk.wrapping_add(GOLDEN) ^ mix64(seed ^ 0x5851_f42d_4c95_7f2d));
    Pcg64::new(
        ((hi as u128) << 64) | lo as u128,
        0xa02b_dbf7_bb3c_0a7a_c28f_a16a_64ab_f96f,
    )
}

/// The generator of chunk `chunk` of sample stream `stream` (the metrics' samplers: one
/// stream per direction of a comparison, so that the two never share random numbers).
pub(crate) fn stream_rng(seed: u64, stream: u64, chunk: u64) -> Pcg64 {
    let s = mix64(seed.wrapping_add(GOLDEN))
        ^ mix64(stream.wrapping_mul(GOLDEN) ^ mix64(chunk.wrapping_add(0x5851_f42d_4c95_7f2d)));
    Pcg64::seed_from_u64(s)
}
