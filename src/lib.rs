//! rigidcells
pub mod cells;
pub mod error;
pub mod progress;
pub mod rigid;
pub mod solve;
pub mod spec;
pub use error::{Error, Result};
