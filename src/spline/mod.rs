//! Hierarchical B-spline surfaces fitted to scattered points (Greiner & Hormann 1997).
//!
//! (Module docs are written with the fitting code.)

pub mod graph;
pub mod param;
