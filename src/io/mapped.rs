//! Memory-mapped input.
//!
//! Contract: a mapped file is opened read-only and must not be truncated or rewritten by
//! another process while it is mapped. If it is, the behaviour is undefined: the map's bytes are
//! read as if they could not change, so a rewritten page may be read as old and new bytes at
//! once, and on Linux a read past a truncated end raises `SIGBUS`. rigidcells itself never
//! writes to an input (outputs go to a temporary file beside the target, and the CLI refuses an
//! output that names the input); another program writing to it is the caller's to prevent.

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
