//! An [`AtomicFile`] behind a [`BufWriter`], for the streaming writers ([`super::ply_write`],
//! [`super::mesh_write`]): bytes are buffered into the temporary file, which appears under its
//! final name only on [`AtomicFile::commit`] and is removed if the writer is dropped before.

use std::io::{self, BufWriter, Write};

use super::atomic::AtomicFile;

/// An [`AtomicFile`] as a [`Write`] sink.
#[derive(Debug)]
pub(crate) struct Sink(pub(crate) AtomicFile);

impl Sink {
    /// A buffered writer of `capacity` bytes into `file`.
    pub(crate) fn buffered(file: AtomicFile, capacity: usize) -> BufWriter<Sink> {
        BufWriter::with_capacity(capacity, Sink(file))
    }
}

impl Write for Sink {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.0.file().write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.0.file().flush()
    }
}
