//! Hierarchical B-spline surfaces fitted to scattered points (Greiner & Hormann 1997).
//!
//! (Module docs are written with the fitting code.)

pub mod basis;
pub mod block;
pub mod fit;
pub mod graph;
pub mod hier;
pub mod param;
pub mod solve;
pub mod tensor;
