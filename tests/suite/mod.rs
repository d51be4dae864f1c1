mod bad_input;
mod colour;
mod common;
mod data;
mod field;
mod ingest;
mod normals;
mod recon;
