//! Messages for people that name the library's options and the edit spec's lines as data, so
//! that each face says them in its own words: the command line `--cell-size 0.5` and "line 7",
//! Python `cell_size=0.5` and `spec["handle"][0]`, Blender its panel's names.
//!
//! A [`Said`] is a list of [`Part`]s; [`Terms`] renders one. Its `Display` is the command line's
//! ([`Cli`]), which is also what the JSON report and the editor's page show. No face reads a
//! message back: a face that needs another wording renders the parts again.
//!
//! ```
//! use rigidcells::said::{Opt, Said, Terms};
//! let said = Said::new().set(Opt::CellSize, 0.02).text(": more cells than the memory holds");
//! assert_eq!(said.to_string(), "--cell-size 0.02: more cells than the memory holds");
//! struct Python;
//! impl Terms for Python {
//!     fn option(&self, o: Opt) -> String {
//!         o.keyword().to_string()
//!     }
//!     fn set(&self, o: Opt, value: &str) -> String {
//!         format!("{}={value}", o.keyword())
//!     }
//! }
//! assert_eq!(Python.render(&said), "cell_size=0.02: more cells than the memory holds");
//! ```

use std::fmt;

/// The options: each variant, its docs and its command-line name, written once; the enum,
/// [`Opt::ALL`] and [`Opt::name`] are made from this list.
macro_rules! options {
    ($($(#[$doc:meta])* $variant:ident => $name:literal,)*) => {
        /// An option of the command line and the library, by its meaning; [`Opt::name`] is the
        /// command line's name and [`Opt::keyword`] the Python package's.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[non_exhaustive]
        pub enum Opt {
            $($(#[$doc])* $variant,)*
        }

        impl Opt {
            /// Every option.
            pub const ALL: [Opt; [$($name),*].len()] = [$(Opt::$variant),*];

            /// The command line's name, without its dashes (`cell-size`).
            pub fn name(self) -> &'static str {
                match self {
                    $(Opt::$variant => $name,)*
                }
            }
        }
    };
}

options! {
    /// The edit spec (`--edit`; Python's `spec`).
    Edit => "edit",
    /// The finest cells' edge (`--cell-size`).
    CellSize => "cell-size",
    /// About this many cells (`--cells`).
    Cells => "cells",
    /// Adaptive cells down to this size (`--min-cell-size`).
    MinCellSize => "min-cell-size",
    /// Octree levels above the finest cells (`--max-level`).
    MaxLevel => "max-level",
    /// Occupied cells only (`--shell`).
    Shell => "shell",
    /// The inside classification of empty cells (`--inside`).
    Inside => "inside",
    /// The glue of the cells inside the shape, against its surface's (`--interior-stiffness`).
    InteriorStiffness => "interior-stiffness",
    /// How the Gauss-Newton systems are solved (`--solver`).
    Solver => "solver",
    /// The global step solved by subdomains (`--subdomains`).
    Subdomains => "subdomains",
    /// The move test of each load step (`--tolerance`).
    Tolerance => "tolerance",
    /// What parts no constraint reaches do (`--loose-parts`).
    LooseParts => "loose-parts",
    /// Refinement where the strain is high (`--refine-strain`).
    RefineStrain => "refine-strain",
    /// How the cells' motions reach the samples (`--transfer`).
    Transfer => "transfer",
    /// The RBF transfer's fitting tolerance (`--rbf-tolerance`).
    RbfTolerance => "rbf-tolerance",
    /// The memory budget (`--memory-limit`).
    MemoryLimit => "memory-limit",
    /// Samples beyond the field's cells (`--outside`).
    Outside => "outside",
    /// The field's file (`--save-field`).
    SaveField => "save-field",
    /// The report's file (`--report`).
    Report => "report",
    /// Files in different coordinate systems taken as one (`--same-crs`).
    SameCrs => "same-crs",
    /// Samples per chunk of a streamed file (`--chunk`).
    Chunk => "chunk",
    /// A grid's spacing (`--spacing`).
    Spacing => "spacing",
    /// A grid's extent (`--extent`).
    Extent => "extent",
    /// A grid's height (`--height`).
    Height => "height",
    /// A GeoTIFF's EPSG code (`--epsg`).
    Epsg => "epsg",
    /// A picture's size (`--size`).
    Size => "size",
    /// The camera's azimuth (`--azimuth`).
    Azimuth => "azimuth",
    /// The camera's elevation (`--elevation`).
    Elevation => "elevation",
    /// The camera's zoom (`--zoom`).
    Zoom => "zoom",
    /// The up axis (`--up`).
    Up => "up",
    /// A picture's background (`--background`).
    Background => "background",
    /// The editor's samples shown (`--proxy`).
    Proxy => "proxy",
    /// The editor's port (`--port`).
    Port => "port",
    /// The editor's output folder (`--out-dir`).
    OutDir => "out-dir",
}

impl Opt {
    /// The Python package's keyword argument (`cell_size`; the edit spec is `spec`).
    pub fn keyword(self) -> &'static str {
        match self {
            Opt::Edit => "spec",
            Opt::CellSize => "cell_size",
            Opt::MinCellSize => "min_cell_size",
            Opt::MaxLevel => "max_level",
            Opt::InteriorStiffness => "interior_stiffness",
            Opt::LooseParts => "loose_parts",
            Opt::RefineStrain => "refine_strain",
            Opt::RbfTolerance => "rbf_tolerance",
            Opt::MemoryLimit => "memory_limit",
            Opt::SaveField => "save_field",
            Opt::SameCrs => "same_crs",
            Opt::OutDir => "out_dir",
            o => o.name(),
        }
    }
}

/// One piece of a message.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Part {
    /// Words as they are.
    Text(String),
    /// An option named (`--cell-size`).
    Opt(Opt),
    /// An option with a value (`--cell-size 0.02`), the value as the user would write it.
    Set(Opt, String),
    /// A line of the edit spec (`line 7`).
    Line(usize),
    /// An entry of the edit spec (`handle #2 (line 17)`): the kind of its table (`fixed`,
    /// `handle`, `pin`, `target`, `stiffness`), its place among the entries of that kind (from
    /// 0), and its line (0 for an entry made in code). A face names it as its user made it:
    /// the editor "handle 1, selection 2", Blender "the handle", Python `spec["handle"][1]`.
    Entry {
        /// The kind of entry, its table's name in the spec.
        kind: &'static str,
        /// Its place among the entries of its kind, from 0.
        index: usize,
        /// Its line in the spec (0: made in code).
        line: usize,
    },
    /// A value of the edit spec of the wrong kind: `expected` what, `found` what.
    Mismatch {
        /// The kind the key takes.
        expected: Kind,
        /// The kind given.
        found: Kind,
    },
    /// Words a face says only where it has every option they name ([`Terms::has`]): another
    /// way out (`" or --min-cell-size"`) that a face without that option leaves unsaid, so
    /// that it never advises a setting its user cannot reach.
    Aside(Said),
}

/// The kind of a value of the edit spec, as [`Part::Mismatch`] names it.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Kind {
    /// A table (a dict in Python).
    Table,
    /// An array (a list).
    Array,
    /// A string.
    Text,
    /// A number with a fraction.
    Float,
    /// A whole number.
    Integer,
    /// A number of either kind.
    Number,
    /// `true` or `false`.
    Boolean,
    /// What the parser called it otherwise.
    Other(String),
}

impl Kind {
    /// The kind named by the TOML parser's message (serde's names: `map`, `sequence`,
    /// `string`, `floating point`, `f64`, `integer`, `boolean`; with or without an article).
    pub fn from_parser(name: &str) -> Self {
        let name = name.trim();
        let bare = ["a ", "an "]
            .iter()
            .find_map(|a| name.strip_prefix(a))
            .unwrap_or(name);
        let word = bare.split([' ', '`']).next().unwrap_or(bare);
        match word {
            "map" | "table" | "struct" => Kind::Table,
            "sequence" | "array" | "tuple" => Kind::Array,
            "string" | "str" | "char" => Kind::Text,
            "floating" | "f64" | "f32" => Kind::Float,
            "integer" | "i64" | "u64" | "usize" | "u32" | "i32" | "u8" => Kind::Integer,
            "boolean" | "bool" => Kind::Boolean,
            _ => Kind::Other(name.to_string()),
        }
    }

    /// TOML's words: `a table`, `an array`, `a string`, `a number`, `a whole number`,
    /// `a boolean`.
    pub fn toml_words(&self) -> String {
        match self {
            Kind::Table => "a table".into(),
            Kind::Array => "an array".into(),
            Kind::Text => "a string".into(),
            Kind::Float | Kind::Number => "a number".into(),
            Kind::Integer => "a whole number".into(),
            Kind::Boolean => "a boolean".into(),
            Kind::Other(s) => s.clone(),
        }
    }
}

/// A message whose options and spec lines are data ([`Part`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Said {
    parts: Vec<Part>,
}

impl Said {
    /// An empty message.
    pub fn new() -> Self {
        Self::default()
    }

    /// The message with `words` added.
    pub fn text(mut self, words: impl Into<String>) -> Self {
        let words = words.into();
        match self.parts.last_mut() {
            Some(Part::Text(t)) => t.push_str(&words),
            _ if words.is_empty() => {}
            _ => self.parts.push(Part::Text(words)),
        }
        self
    }

    /// The message with option `o` named.
    pub fn opt(mut self, o: Opt) -> Self {
        self.parts.push(Part::Opt(o));
        self
    }

    /// The message with option `o` given `value`.
    pub fn set(mut self, o: Opt, value: impl fmt::Display) -> Self {
        self.parts.push(Part::Set(o, value.to_string()));
        self
    }

    /// The message with line `n` of the edit spec named.
    pub fn line(mut self, n: usize) -> Self {
        self.parts.push(Part::Line(n));
        self
    }

    /// The message with the `index`-th entry (from 0) of kind `kind` named, written on `line`
    /// of the spec (0: made in code).
    pub fn entry(mut self, kind: &'static str, index: usize, line: usize) -> Self {
        self.parts.push(Part::Entry { kind, index, line });
        self
    }

    /// The message with a value of kind `found` where the spec takes `expected`.
    pub fn mismatch(mut self, expected: Kind, found: Kind) -> Self {
        self.parts.push(Part::Mismatch { expected, found });
        self
    }

    /// The message with `aside` added, said only by a face that has every option it names
    /// ([`Part::Aside`]).
    pub fn aside(mut self, aside: Said) -> Self {
        self.parts.push(Part::Aside(aside));
        self
    }

    /// The options the message names, its asides' among them.
    pub fn options(&self) -> Vec<Opt> {
        let mut out = Vec::new();
        for p in &self.parts {
            match p {
                Part::Opt(o) | Part::Set(o, _) => out.push(*o),
                Part::Aside(aside) => out.extend(aside.options()),
                _ => {}
            }
        }
        out
    }

    /// The message with `other` added.
    pub fn then(mut self, other: Said) -> Self {
        for p in other.parts {
            self = match p {
                Part::Text(t) => self.text(t),
                p => {
                    self.parts.push(p);
                    self
                }
            };
        }
        self
    }

    /// The message without `words` at its end, when it ends with them.
    pub fn strip_suffix(&self, words: &str) -> Option<Said> {
        let (Part::Text(last), head) = self.parts.split_last()? else {
            return None;
        };
        let rest = last.strip_suffix(words)?;
        Some(
            Said {
                parts: head.to_vec(),
            }
            .text(rest),
        )
    }

    /// The parts, in order.
    pub fn parts(&self) -> &[Part] {
        &self.parts
    }

    /// The message without spaces and line ends at its end.
    pub fn trimmed(mut self) -> Self {
        if let Some(Part::Text(t)) = self.parts.last_mut() {
            t.truncate(t.trim_end().len());
        }
        self
    }

    /// Whether the message says nothing.
    pub fn is_empty(&self) -> bool {
        self.parts
            .iter()
            .all(|p| matches!(p, Part::Text(t) if t.is_empty()))
    }
}

impl From<String> for Said {
    fn from(words: String) -> Self {
        Said::new().text(words)
    }
}

impl From<&Said> for Said {
    fn from(said: &Said) -> Self {
        said.clone()
    }
}

impl From<&String> for Said {
    fn from(words: &String) -> Self {
        Said::new().text(words.as_str())
    }
}

impl From<&str> for Said {
    fn from(words: &str) -> Self {
        Said::new().text(words)
    }
}

/// How a face says an option, a value and a spec line; [`Terms::render`] says a whole message.
pub trait Terms {
    /// Option `o` named.
    fn option(&self, o: Opt) -> String;

    /// Whether this face's user can set option `o` (every option, unless a face says
    /// otherwise): a [`Part::Aside`] naming one it lacks is left unsaid.
    fn has(&self, o: Opt) -> bool {
        let _ = o;
        true
    }

    /// Option `o` given `value` (`--cell-size 0.02`, `cell_size=0.02`).
    fn set(&self, o: Opt, value: &str) -> String {
        format!("{} {value}", self.option(o))
    }

    /// Line `n` of the edit spec.
    fn line(&self, n: usize) -> String {
        format!("line {n}")
    }

    /// The `index`-th entry (from 0) of kind `kind`, on `line` (0: made in code):
    /// `handle #2 (line 17)`, `handle #2`.
    fn entry(&self, kind: &str, index: usize, line: usize) -> String {
        match line {
            0 => format!("{kind} #{}", index + 1),
            n => format!("{kind} #{} ({})", index + 1, self.line(n)),
        }
    }

    /// A value of kind `found` where the spec takes `expected`.
    fn mismatch(&self, expected: &Kind, found: &Kind) -> String {
        format!(
            "expected {}, found {}",
            expected.toml_words(),
            found.toml_words()
        )
    }

    /// One part of a message.
    fn part(&self, part: &Part) -> String {
        match part {
            Part::Text(t) => t.clone(),
            Part::Opt(o) => self.option(*o),
            Part::Set(o, v) => self.set(*o, v),
            Part::Line(n) => self.line(*n),
            Part::Entry { kind, index, line } => self.entry(kind, *index, *line),
            Part::Mismatch { expected, found } => self.mismatch(expected, found),
            Part::Aside(aside) => match aside.options().into_iter().all(|o| self.has(o)) {
                true => self.render(aside),
                false => String::new(),
            },
        }
    }

    /// The whole message.
    fn render(&self, said: &Said) -> String {
        said.parts.iter().map(|p| self.part(p)).collect()
    }
}

/// The command line's terms: `--cell-size 0.02`, `line 7`.
#[derive(Debug, Clone, Copy, Default)]
pub struct Cli;

impl Terms for Cli {
    fn option(&self, o: Opt) -> String {
        format!("--{}", o.name())
    }
}

impl fmt::Display for Said {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&Cli.render(self))
    }
}

impl serde::Serialize for Said {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_command_line_says_flags_and_lines() {
        let said = Said::new()
            .line(4)
            .text(": use a larger ")
            .opt(Opt::CellSize)
            .text(" or ")
            .set(Opt::Outside, "keep");
        assert_eq!(
            said.to_string(),
            "line 4: use a larger --cell-size or --outside keep"
        );
    }

    #[test]
    fn an_entry_is_named_by_its_kind_place_and_line() {
        let said = Said::new().entry("handle", 1, 17).text(" selects no cell");
        assert_eq!(said.to_string(), "handle #2 (line 17) selects no cell");
        assert_eq!(Said::new().entry("pin", 0, 0).to_string(), "pin #1");
        struct Page;
        impl Terms for Page {
            fn option(&self, o: Opt) -> String {
                o.name().into()
            }
            fn entry(&self, kind: &str, index: usize, _line: usize) -> String {
                format!("{kind} {}", index + 1)
            }
        }
        assert_eq!(Page.render(&said), "handle 2 selects no cell");
    }

    #[test]
    fn an_aside_is_said_only_where_its_options_are_had() {
        let said = Said::from("use a larger ")
            .opt(Opt::CellSize)
            .aside(Said::from(" or ").opt(Opt::MinCellSize))
            .text(".");
        assert_eq!(
            said.to_string(),
            "use a larger --cell-size or --min-cell-size."
        );
        assert_eq!(said.options(), [Opt::CellSize, Opt::MinCellSize]);
        struct Panel;
        impl Terms for Panel {
            fn option(&self, o: Opt) -> String {
                format!("\"{}\"", o.keyword())
            }
            fn has(&self, o: Opt) -> bool {
                o == Opt::CellSize
            }
        }
        assert_eq!(Panel.render(&said), "use a larger \"cell_size\".");
    }

    #[test]
    fn the_parsers_kinds_are_named_in_tomls_words() {
        let kinds = |e: &str, f: &str| {
            Cli.render(&Said::new().mismatch(Kind::from_parser(e), Kind::from_parser(f)))
        };
        assert_eq!(
            kinds("a sequence", "map"),
            "expected an array, found a table"
        );
        assert_eq!(
            kinds("f64", "string \"x\""),
            "expected a number, found a string"
        );
        assert_eq!(
            kinds("a boolean", "integer `3`"),
            "expected a boolean, found a whole number"
        );
        assert_eq!(
            kinds("a unicorn", "map"),
            "expected a unicorn, found a table"
        );
    }

    #[test]
    fn text_added_to_text_is_one_part() {
        let said = Said::from("a").text("b").text("").opt(Opt::Up).text("c");
        assert_eq!(said.parts().len(), 3);
        assert!(Said::new().text("").is_empty());
        assert_eq!(Said::from("x \n").trimmed().to_string(), "x");
    }

    #[test]
    fn every_option_has_one_name_and_one_keyword() {
        let names: std::collections::HashSet<_> = Opt::ALL.iter().map(|o| o.name()).collect();
        let words: std::collections::HashSet<_> = Opt::ALL.iter().map(|o| o.keyword()).collect();
        assert_eq!(names.len(), Opt::ALL.len());
        assert_eq!(words.len(), Opt::ALL.len());
        for o in Opt::ALL {
            assert!(!o.keyword().contains('-'), "{o:?}");
        }
    }
}
