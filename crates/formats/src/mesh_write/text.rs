//! Numbers as text, for the text encoders: ASCII PLY (the mesh encoder of [`crate::ply`]) and
//! OBJ. Each is written in the shortest form that reads back to the same value.

use std::fmt::Write as _;

/// A float written as text: the shortest form that reads back to the same value.
pub(crate) fn num(s: &mut String, v: f64, double: bool) {
    if double {
        let _ = write!(s, "{v:?}");
    } else {
        let _ = write!(s, "{:?}", v as f32);
    }
}
