//! Progress reporting. The library never prints; long stages report through an [`Observer`],
//! which the binary implements with a progress bar on a terminal; the observer may also ask
//! the work to stop ([`Observer::cancelled`]).

use crate::error::{Error, Result};

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
    /// What the solve about to start will take ([`crate::estimate`]): its cells, memory and
    /// seconds, estimated before its first stage.
    fn estimate(&self, _estimate: &crate::estimate::Estimate) {}
    /// Whether the caller wants the work stopped: long loops ask between their steps (a
    /// solver iteration, a chunk read or written) and end with [`Error::Cancelled`].
    fn cancelled(&self) -> bool {
        false
    }
}

/// [`Error::Cancelled`] once `observer` asks to stop.
pub fn stop_if_cancelled(observer: &dyn Observer) -> Result<()> {
    if observer.cancelled() {
        return Err(Error::Cancelled);
    }
    Ok(())
}

/// An observer that ignores everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Observer for Silent {}
