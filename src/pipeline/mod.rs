//! The only code that chains stages (ARCHITECTURE.md): a store is ingested, its normals
//! estimated and the store committed ([`ingest`]), then reconstructed.

pub mod ingest;
