//! The library's error type. Every error names what is wrong and, where a file is involved, the
//! file; the binary turns them into messages and exit codes.

use std::path::PathBuf;

use crate::human::degrees;
use crate::said::{Opt, Said};

/// Everything that can go wrong in rigidcells.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An operating-system error on a file. The OS error is part of the message, not a
    /// `source`, so that a report of the whole chain says it once.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// An output that cannot be written (a full disk, a folder that is read-only or missing):
    /// named by the user's path, not the temporary file's.
    #[error("{path}: cannot write: {error}")]
    Write {
        /// The output the user named.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// A file's content is not what its format requires.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A file has an extension rigidcells does not read or write.
    #[error("{path}: unsupported format (expected .las, .laz, .ply, .obj or .xyz)")]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
    },
    /// The edit spec is malformed, or a file it names cannot be read.
    #[error("{path}: {}", spec_said(*line, *column, message, excerpt.as_deref()))]
    Spec {
        /// The spec file (or `<edit spec>` for an in-memory spec).
        path: PathBuf,
        /// The line of the spec where known (1 for the first).
        line: Option<usize>,
        /// The column on that line where known (1 for the first).
        column: Option<usize>,
        /// What is wrong.
        message: Said,
        /// The TOML parser's picture of the line and where on it, for a spec written as text.
        excerpt: Option<String>,
    },
    /// A parameter is out of range.
    #[error("invalid parameter: {0}")]
    Param(Said),
    /// The input holds no samples, or samples that are not finite.
    #[error("invalid input: {0}")]
    Input(Said),
    /// The cell size divides the input's extent into more finest cells along an axis than cell
    /// coordinates can hold.
    #[error("{}", grid_too_large(*cell_size, *cells, *max))]
    GridTooLarge {
        /// The finest cell size.
        cell_size: f64,
        /// Finest cells along the longest axis that overflows.
        cells: u128,
        /// Finest cells along an axis at most.
        max: u128,
    },
    /// A buffer would exceed the memory budget ([`crate::memory`]).
    #[error("{}", memory(what, needed, limit, advice))]
    Memory {
        /// What would be allocated.
        what: Said,
        /// The estimate.
        needed: String,
        /// The budget.
        limit: String,
        /// Which parameters shrink it.
        advice: Said,
    },
    /// The edit spec constrains nothing.
    #[error(
        "the edit spec has no constraint that selects any cell: add a [[fixed]], [[handle]], [[pin]] or [[target]] entry that touches the shape"
    )]
    NoConstraints,
    /// A cell is claimed by two different hard constraints.
    #[error("{}", conflict(first, second, at, *size))]
    ConstraintConflict {
        /// The first constraint (e.g. `fixed #1`).
        first: Said,
        /// The second constraint.
        second: Said,
        /// The cell's center (input coordinates).
        at: Vec<f64>,
        /// The cell's edge length.
        size: f64,
    },
    /// Samples lie beyond the margin of the field's cells, where the field is not defined.
    #[error("{path}: {}", outside(*count, *margin, *farthest, at))]
    Outside {
        /// The input file.
        path: PathBuf,
        /// How many samples.
        count: u64,
        /// The margin.
        margin: f64,
        /// The largest distance of one from the cells' bounding box.
        farthest: f64,
        /// That sample (input coordinates), as text.
        at: String,
    },
    /// Two files in different coordinate reference systems, where one field must serve both
    /// ([`crate::crs::check`]): tiles solved together, a field and the file it is applied to,
    /// a GeoJSON polygon and the scan.
    #[error("{what}: {first}, but {second}; {advice}")]
    CrsMismatch {
        /// What differs (`the tiles' coordinate systems differ`).
        what: String,
        /// The first system with its file (`EPSG:2903 (…) in a.las`).
        first: String,
        /// The second system with its file.
        second: String,
        /// What to do.
        advice: Said,
    },
    /// A handle's turn that the cells give way under ([`TurnRefusal`]): its message names the
    /// handle by its line in the edit spec, as the command line does; another face names it
    /// its own way before [`TurnRefusal::said`].
    #[error("{0}")]
    TurnNotHeld(TurnRefusal),
    /// A numerical failure that damping could not repair.
    #[error("solver failure: {0}")]
    Solver(Said),
    /// The caller stopped the work ([`crate::progress::Observer::cancelled`]); no output was
    /// left behind.
    #[error("cancelled")]
    Cancelled,
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// The command line's exit status for this error (the README's contract): 3 for an input
    /// that cannot be read or is malformed (a field file included), 4 for the edit spec, a file
    /// it names, or a parameter value, 1 for the rest (writing the output, the solver).
    /// Syntax errors of the command line itself are clap's 2.
    pub fn exit_code(&self) -> u8 {
        match self {
            Error::Io { .. }
            | Error::Format { .. }
            | Error::UnsupportedFormat { .. }
            | Error::Input(_) => 3,
            Error::Spec { .. }
            | Error::Param(_)
            | Error::NoConstraints
            | Error::ConstraintConflict { .. }
            | Error::GridTooLarge { .. }
            | Error::Memory { .. }
            | Error::Outside { .. }
            | Error::CrsMismatch { .. }
            | Error::TurnNotHeld(_) => 4,
            _ => 1,
        }
    }

    /// A parameter out of range ([`Error::Param`]).
    pub fn param(message: impl Into<Said>) -> Self {
        Self::Param(message.into())
    }

    /// An input without samples, or with samples that are not finite ([`Error::Input`]).
    pub fn input(message: impl Into<Said>) -> Self {
        Self::Input(message.into())
    }

    /// A numerical failure ([`Error::Solver`]).
    pub fn solver(message: impl Into<Said>) -> Self {
        Self::Solver(message.into())
    }

    /// A problem of the edit spec `path` (`<edit spec>` for one in memory), at `line` where
    /// known.
    pub fn spec(path: impl Into<PathBuf>, line: Option<usize>, message: impl Into<Said>) -> Self {
        Self::Spec {
            path: path.into(),
            line,
            column: None,
            message: message.into(),
            excerpt: None,
        }
    }

    /// The message with its options and spec lines as data, for a face that says them its
    /// own way; the command line's is `to_string()`. The file an error is about leads it as
    /// text, and a spec's line is its first part ([`crate::said::Part::Line`]) after the
    /// spec's name; the prefixes the command line adds ("invalid parameter:") are left out.
    pub fn said(&self) -> Said {
        match self {
            Error::Param(m) | Error::Input(m) => m.clone(),
            Error::Solver(m) => Said::from("solver failure: ").then(m.clone()),
            Error::Spec {
                path,
                line,
                column,
                message,
                excerpt,
            } => Said::from(format!("{}: ", path.display())).then(spec_said(
                *line,
                *column,
                message,
                excerpt.as_deref(),
            )),
            Error::GridTooLarge {
                cell_size,
                cells,
                max,
            } => grid_too_large(*cell_size, *cells, *max),
            Error::Memory {
                what,
                needed,
                limit,
                advice,
            } => memory(what, needed, limit, advice),
            Error::ConstraintConflict {
                first,
                second,
                at,
                size,
            } => conflict(first, second, at, *size),
            Error::Outside {
                path,
                count,
                margin,
                farthest,
                at,
            } => Said::from(format!("{}: ", path.display()))
                .then(outside(*count, *margin, *farthest, at)),
            Error::CrsMismatch {
                what,
                first,
                second,
                advice,
            } => Said::from(format!("{what}: {first}, but {second}; ")).then(advice.clone()),
            e => Said::from(e.to_string()),
        }
    }

    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            error,
        }
    }

    /// An error writing the output `path` (the user's name for it).
    pub fn write(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Self::Write {
            path: path.into(),
            error,
        }
    }

    /// An edit spec, or a file it names, that cannot be read: a problem of the spec (exit 4).
    pub fn spec_file(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        let message = match error.kind() {
            std::io::ErrorKind::InvalidData => "not UTF-8 text".to_string(),
            _ => error.to_string(),
        };
        Self::spec(path, None, message)
    }

    /// A format error in `path`.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Format {
            path: path.into(),
            message: message.into(),
        }
    }
}

/// A spec's problem as said after its name: `line 7, column 3: …` and, for the command line,
/// the TOML parser's picture of the line.
fn spec_said(
    line: Option<usize>,
    column: Option<usize>,
    message: &Said,
    excerpt: Option<&str>,
) -> Said {
    let mut said = Said::new();
    if let Some(l) = line {
        said = said.line(l);
        if let Some(c) = column {
            said = said.text(format!(", column {c}"));
        }
        said = said.text(": ");
    }
    said = said.then(message.clone());
    match excerpt {
        Some(e) => said.text(format!("\n{}", e.trim_end())),
        None => said,
    }
}

/// Counts past a trillion as a power of ten (a cell size of 1e-300 gives about 1e300 cells
/// along the extent, not 39 digits of a saturated counter).
fn grid_too_large(cell_size: f64, cells: u128, max: u128) -> Said {
    let cells = match u64::try_from(cells) {
        Ok(n) if n < 1_000_000_000_000 => crate::human::count(n),
        _ => format!("more than 1e{}", (cells as f64).log10().floor() as i64),
    };
    Said::from(format!(
        "the cell size {} gives {cells} finest cells along the input's extent, more than the {} \
         a cell's coordinates can hold; use a larger ",
        crate::human::typed(cell_size),
        crate::human::count(max as u64)
    ))
    .opt(Opt::CellSize)
}

fn memory(what: &Said, needed: &str, limit: &str, advice: &Said) -> Said {
    what.clone()
        .text(format!(
            " would need about {needed}, over the memory limit of {limit} ("
        ))
        .opt(Opt::MemoryLimit)
        .text("): ")
        .then(advice.clone())
}

fn conflict(first: &Said, second: &Said, at: &[f64], size: f64) -> Said {
    first
        .clone()
        .text(" and ")
        .then(second.clone())
        .text(format!(
            " both claim the cell at {} (size {}); move the regions apart or use a smaller ",
            crate::human::point(at, size / 1000.0),
            crate::human::length(size, size)
        ))
        .opt(Opt::CellSize)
}

fn outside(count: u64, margin: f64, farthest: f64, at: &str) -> Said {
    Said::from(format!(
        "{count} samples lie farther than {} outside the field's cells (the farthest, at {at}, \
         lies {} from the cells' bounding box); nothing was written. Solve a field over these \
         samples, or pass ",
        crate::human::length(margin, margin),
        crate::human::length(farthest, margin)
    ))
    .set(Opt::Outside, "keep")
    .text(" (they keep their coordinates) or ")
    .set(Opt::Outside, "extend")
    .text(" (the transfer is extrapolated)")
}

/// What a handle's turn does to the shape between it and the fixed cells, as its messages say.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TurnKind {
    /// The handle turns about an axis across the direction from the fixed cells to it.
    Bend,
    /// The handle turns about an axis along that direction.
    Twist,
}

impl TurnKind {
    /// The word: `bend` or `twist`.
    pub fn name(self) -> &'static str {
        match self {
            TurnKind::Bend => "bend",
            TurnKind::Twist => "twist",
        }
    }
}

/// The command line's name for the `handle`-th handle (from 0), on `line` of the edit spec:
/// `handle #1 (line 3)`, as it names every entry of the spec ([`crate::said::Part::Entry`]).
pub fn handle_named(handle: usize, line: usize) -> String {
    use crate::said::Terms;
    crate::said::Cli.entry("handle", handle, line)
}

/// A turn the shape gives way under ([`crate::Error::TurnNotHeld`]): past `held_degrees` the
/// shape between the handle and the fixed cells turns back the short way round at every load
/// step the solver tries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurnRefusal {
    /// The handle's index among the spec's handles (0 for the first).
    pub handle: usize,
    /// The handle's line in the edit spec.
    pub line: usize,
    /// A bend or a twist.
    pub kind: TurnKind,
    /// The turn asked, in degrees, as in [`crate::solve::HandleTurn::asked_degrees`].
    pub asked_degrees: f64,
    /// The largest turn the load path held, in whole degrees, of the sign of `asked_degrees`.
    pub held_degrees: f64,
    /// The turn that reaches the same pose the other way round, offered for a half turn
    /// typed in a spec (a matrix's is taken both ways before it is refused).
    pub other_way_degrees: Option<f64>,
}

impl TurnRefusal {
    /// The message after the handle's name (a face names the handle its own way):
    /// `twists by 360°, but the shape …`.
    pub fn said(&self) -> String {
        let (word, back, across) = match self.kind {
            TurnKind::Bend => ("bend", "turns back", "thickness"),
            TurnKind::Twist => ("twist", "untwists", "width"),
        };
        let held = degrees(self.held_degrees);
        let mut advice = Vec::new();
        if let Some(other) = self.other_way_degrees {
            let other = degrees(other);
            advice.push(format!(
                "{word} it the other way round instead (by {other}, to the same pose)"
            ));
        }
        advice.push(format!("{word} it well short of {held}"));
        if self.kind == TurnKind::Twist {
            advice.push("twist a longer span (the fixed and handle regions farther apart)".into());
        }
        advice.push(format!(
            "{word} it in several runs, each deforming the last output"
        ));
        let last = advice.pop().unwrap_or_default();
        let mut advice = format!("{}, or {last}", advice.join(", "));
        advice[..1].make_ascii_uppercase();
        format!(
            "{word}s by {}, but the shape between it and the fixed cells gives way past {held} \
             and {back} the short way round: rigid cells glued face to face hold a {word} only \
             so far over a part this short for its {across}, and smaller or larger cells change \
             that little. {advice}",
            degrees(self.asked_degrees),
        )
    }
}

impl std::fmt::Display for TurnRefusal {
    /// The message as the command line says it: the handle named by its place and line.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {}",
            handle_named(self.handle, self.line),
            self.said()
        )
    }
}
