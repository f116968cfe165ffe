//! How the library is built: every module behind the facade of the crate root.
//!
//! The command line, the Python extension, the tools and the tests use these parts directly;
//! a Rust caller starts at the crate root, whose items are the library's promise. Nothing here
//! is: these modules change with the library, without a major version. The crate's own code
//! names them `crate::cells`, `crate::solve`, … (the root re-exports them within the crate);
//! their files stay at `src/<module>`, one folder or file per module.

#[path = "cells/mod.rs"]
pub mod cells;
#[path = "control.rs"]
pub mod control;
#[path = "crs/mod.rs"]
pub mod crs;
#[cfg(feature = "demo")]
#[path = "demo.rs"]
pub mod demo;
#[path = "edit/mod.rs"]
pub mod edit;
#[path = "error.rs"]
pub mod error;
#[path = "estimate.rs"]
pub mod estimate;
#[path = "field/mod.rs"]
pub mod field;
#[path = "human.rs"]
pub mod human;
#[path = "image.rs"]
pub mod image;
#[path = "info.rs"]
pub mod info;
#[path = "interrupt.rs"]
pub mod interrupt;
#[path = "io/mod.rs"]
pub mod io;
#[path = "memory.rs"]
pub mod memory;
#[path = "names.rs"]
pub mod names;
#[path = "pipeline/mod.rs"]
pub mod pipeline;
#[path = "progress.rs"]
pub mod progress;
#[path = "render/mod.rs"]
pub mod render;
#[path = "rigid.rs"]
pub mod rigid;
#[path = "solve/mod.rs"]
pub mod solve;
#[path = "spec/mod.rs"]
pub mod spec;
