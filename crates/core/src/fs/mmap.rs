//! Memory-mapped windows onto input files.
//!
//! A reader never maps a whole file for the life of a run: each chunk maps the pages it
//! reads and unmaps them when done, so resident memory is bounded by the chunks in flight
//! (the memory budget admits them) and not by the size of the inputs.

use std::fs::File;
use std::ops::Deref;
use std::path::Path;

use memmap2::{Mmap, MmapOptions};

use crate::error::{Error, Result};

/// A read-only mapping of bytes `[start, end)` of a file.
pub struct Window {
    map: Option<Mmap>,
    /// Offset of the first wanted byte inside `map`.
    skip: usize,
    len: usize,
}

impl Window {
    /// Map bytes `[start, end)` of `file` (which is `path`). An empty range maps nothing.
    pub fn map(file: &File, path: &Path, start: u64, end: u64) -> Result<Window> {
        if end <= start {
            return Ok(Window {
                map: None,
                skip: 0,
                len: 0,
            });
        }
        let page = page_size();
        let aligned = start - start % page;
        let skip = (start - aligned) as usize;
        let len = (end - start) as usize;
        // SAFETY: the mapping is read-only and private to this process. Another process
        // truncating or rewriting an input while scanflow reads it is outside the contract
        // (as for every mmap-based reader); readers bounds-check every access against the
        // length recorded at open time, so a shorter file yields SIGBUS only if changed under us.
        let map = unsafe {
            MmapOptions::new()
                .offset(aligned)
                .len(skip + len)
                .map(file)
                .map_err(|e| Error::io(path, e))?
        };
        Ok(Window {
            map: Some(map),
            skip,
            len,
        })
    }
}

impl Deref for Window {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match &self.map {
            Some(m) => &m[self.skip..self.skip + self.len],
            None => &[],
        }
    }
}

fn page_size() -> u64 {
    // Mappings must start on a page boundary; 64 KiB is a multiple of every page size
    // Linux, macOS and Windows (allocation granularity) use.
    65536
}
