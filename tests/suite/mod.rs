mod bad_input;
mod cli;
mod colour;
mod common;
mod data;
mod ingest;
mod normals;
mod recon;
