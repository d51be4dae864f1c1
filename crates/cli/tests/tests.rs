//! Integration tests: one binary (link time on 2 cores), modules by capability.
#![allow(clippy::needless_range_loop)]
mod suite;
