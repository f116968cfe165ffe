//! Progress reporting. The library never prints; long stages report through an [`Observer`],
//! which the binary implements with a progress bar on a terminal.

/// Receives progress of long stages. A stage of `len` 0 has no known length (a spinner).
pub trait Observer: Sync {
    /// A stage named `name` begins with `len` units of work.
    fn stage(&self, _name: &str, _len: u64) {}
    /// `n` more units are done.
    fn advance(&self, _n: u64) {}
    /// Where the stage is, in words (e.g. a solver's iteration and energy).
    fn message(&self, _text: &str) {}
    /// The stage is done.
    fn finish(&self) {}
}

/// An observer that ignores everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Observer for Silent {}
