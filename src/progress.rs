//! Progress reporting. The library never prints; long stages report through an [`Observer`],
//! which the binary implements with a progress bar on a terminal.

/// Receives progress of long stages.
pub trait Observer: Sync {
    /// A stage named `name` begins with `len` units of work.
    fn stage(&self, _name: &str, _len: u64) {}
    /// `n` more units are done.
    fn advance(&self, _n: u64) {}
    /// The stage is done.
    fn finish(&self) {}
}

/// An observer that ignores everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Observer for Silent {}
