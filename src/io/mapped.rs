//! Memory-mapped input: the one module of rigidcells with `unsafe` code.
//!
//! Contract: a mapped file is opened read-only and must not be truncated or rewritten by
//! another process while it is mapped. If it is, reads of the vanished pages raise `SIGBUS` (a
//! crash, not undefined values); rigidcells itself never writes to an input (outputs go to a
//! temporary file beside the target, and the CLI refuses an output that names the input).

#![allow(unsafe_code)]

use std::fs::File;
use std::path::Path;

use memmap2::Mmap;

use crate::error::{Error, Result};

/// Maps `path` read-only, advising sequential access.
pub fn map(path: &Path) -> Result<Mmap> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    // SAFETY: the file is opened read-only and rigidcells never writes to its inputs; the
    // remaining risk (another process truncating the file meanwhile) is the module's contract.
    let map = unsafe { Mmap::map(&file) }.map_err(|e| Error::io(path, e))?;
    #[cfg(unix)]
    map.advise(memmap2::Advice::Sequential).ok();
    Ok(map)
}
