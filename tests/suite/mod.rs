mod bad_input;
mod common;
mod data;
mod ingest;
mod normals;
mod recon;
