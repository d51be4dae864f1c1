//! Colour and intensity transfer: a vertex takes the inverse-distance blend of its nearest
//! input points' colours and intensities.

use super::fit::Neighbour;

/// Number of input points blended into a vertex's colour.
pub const COLOUR_NEIGHBOURS: usize = 4;

/// The smallest distance a colour weight uses, as a share of the fine spacing: a point on the
/// vertex would otherwise take all the weight (or divide by zero).
const MIN_WEIGHT_DISTANCE: f64 = 0.01;

/// 16-bit to 8-bit channel: `v / 257` maps 65535 to 255 exactly.
const U16_PER_U8: f64 = 257.0;

/// The colour and intensity of a vertex whose neighbours, nearest first, are `nb` (fine
/// spacing `h`): the inverse-distance blend (weights `1/max(d, h/100)`) of the first
/// [`COLOUR_NEIGHBOURS`], 16-bit channels to 8 bits by rounding `v/257`.
pub fn blend_colour(nb: &[Neighbour], h: f64) -> ([u8; 3], f32) {
    let mut acc = [0f64; 4];
    let mut sw = 0.0;
    for (d2, _, c, i) in nb.iter().take(COLOUR_NEIGHBOURS) {
        let w = 1.0 / d2.sqrt().max(h * MIN_WEIGHT_DISTANCE);
        for a in 0..3 {
            acc[a] += w * c[a] as f64;
        }
        acc[3] += w * *i as f64;
        sw += w;
    }
    let color = [0, 1, 2].map(|a| ((acc[a] / sw) / U16_PER_U8).round().clamp(0.0, 255.0) as u8);
    (color, (acc[3] / sw) as f32)
}
