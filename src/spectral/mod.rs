//! Spectral processing of point-sampled geometry (Pauly & Gross, SIGGRAPH 2001), out of core.

pub mod cone;
pub mod fft;
pub mod filter;
pub mod layout;
pub mod pattern;
pub mod rect;
pub mod sda;
