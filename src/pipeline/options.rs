//! The options a user gives a deformation, as the command line, the Python package, the
//! editor and the Blender add-on take them, and the one place they become [`DeformParams`]
//! (which nothing else makes): the defaults, the conflicts between options and their checks
//! are written here once. Messages name the options by the
//! command line's flags (`--cell-size`); the Python package says them as its keyword
//! arguments.

use crate::cells::{BuildParams, Inside};
use crate::error::{Error, Result};
use crate::field::Transfer;
use crate::memory::Budget;
use crate::said::{Opt, Said};
use crate::solve::{self, LooseParts, Method, SolveParams};

use super::DeformParams;

/// Every option of [`Options`], by the command line's name without its dashes (the Python
/// package's keyword is the same with `_` for `-`): the one list the faces are checked against
/// (the command line's flags and the Python package's keywords and stub, by tests).
pub const OPTION_NAMES: [&str; 17] = [
    "cell-size",
    "cells",
    "min-cell-size",
    "max-level",
    "shell",
    "inside",
    "interior-stiffness",
    "solver",
    "subdomains",
    "tolerance",
    "coarse-levels",
    "loose-parts",
    "refine-strain",
    "transfer",
    "rbf-tolerance",
    "check-gcp",
    "memory-limit",
];

/// A deformation's options, each as the user gives it (`None`: the default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Edge length of the finest cells (`--cell-size`).
    pub cell_size: Option<f64>,
    /// About this many cells (`--cells`).
    pub cells: Option<usize>,
    /// Adaptive cells down to this size (`--min-cell-size`).
    pub min_cell_size: Option<f64>,
    /// Octree levels above the finest cells (`--max-level`).
    pub max_level: Option<u8>,
    /// Occupied cells only (`--shell`, the same as `inside` [`Inside::None`]).
    pub shell: bool,
    /// The inside classification of empty cells (`--inside`).
    pub inside: Inside,
    /// The stiffness of the cells inside the shape (those holding no samples) against the
    /// surface's (`--interior-stiffness`; [`DEFAULT_INTERIOR_STIFFNESS`] unless given, 1 the
    /// paper's uniform solid).
    pub interior_stiffness: f64,
    /// How the Gauss-Newton systems are solved (`--solver`).
    pub solver: Method,
    /// Local-global iterations with the global step solved by this many subdomains
    /// (`--subdomains`; 0: as `solver` says).
    pub subdomains: usize,
    /// The move test of each load step, in finest cell sizes (`--tolerance`).
    pub tolerance: f64,
    /// Coarser complexes solved first (`--coarse-levels`).
    pub coarse_levels: Option<u8>,
    /// Whether parts no constraint reaches are carried by the nearest constrained part
    /// or kept at rest (`--loose-parts`).
    pub loose_parts: LooseParts,
    /// Split cells whose strain exceeds this and solve again (`--refine-strain`).
    pub refine_strain: Option<f64>,
    /// The transfer to the samples (`--transfer`).
    pub transfer: Transfer,
    /// The RBF's far-field tolerance (`--rbf-tolerance`, with the RBF transfer only).
    pub rbf_tolerance: Option<f64>,
    /// The control points' leave-one-out check (`--check-gcp`).
    pub check_control_points: bool,
    /// The memory budget in bytes (`--memory-limit`; `None`: the machine's).
    pub memory_limit: Option<u64>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            cell_size: None,
            cells: None,
            min_cell_size: None,
            max_level: None,
            shell: false,
            inside: Inside::Auto,
            interior_stiffness: DEFAULT_INTERIOR_STIFFNESS,
            solver: Method::Auto,
            subdomains: 0,
            tolerance: solve::MOVE_TOLERANCE,
            coarse_levels: None,
            loose_parts: LooseParts::Carry,
            refine_strain: None,
            transfer: Transfer::Pu,
            rbf_tolerance: None,
            check_control_points: false,
            memory_limit: None,
        }
    }
}

impl Options {
    /// The library's parameters, checked: sizes in range, no two options that
    /// contradict each other.
    pub fn params(&self) -> Result<DeformParams> {
        let conflict = |a: Opt, b: Opt| {
            Err(Error::param(
                Said::new()
                    .opt(a)
                    .text(" and ")
                    .opt(b)
                    .text(" both size the cells: give one"),
            ))
        };
        match (self.cell_size, self.cells, self.min_cell_size) {
            (Some(_), Some(_), _) => return conflict(Opt::CellSize, Opt::Cells),
            (Some(_), _, Some(_)) => return conflict(Opt::CellSize, Opt::MinCellSize),
            (_, Some(_), Some(_)) => return conflict(Opt::Cells, Opt::MinCellSize),
            _ => {}
        }
        if let Some(size) = self.cell_size {
            crate::cells::check_size(size, Some(Opt::CellSize))?;
        }
        if let Some(size) = self.min_cell_size {
            crate::cells::check_size(size, Some(Opt::MinCellSize))?;
        }
        Budget::checked(self.memory_limit)?;
        if let Some(l) = self.max_level.filter(|&l| l > crate::cells::MAX_LEVEL) {
            return Err(Error::param(crate::cells::max_level_refused(l)));
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(Error::param(
                Said::new()
                    .set(Opt::Tolerance, crate::human::typed(self.tolerance))
                    .text(": a number of finest cell sizes, 0 or more"),
            ));
        }
        if self.shell && !matches!(self.inside, Inside::Auto | Inside::None) {
            return Err(Error::param(
                Said::new()
                    .opt(Opt::Shell)
                    .text(" keeps no inside; ")
                    .set(Opt::Inside, self.inside)
                    .text(" asks for one: give one"),
            ));
        }
        let s = self.interior_stiffness;
        if !(s.is_finite() && (MIN_INTERIOR_STIFFNESS..=MAX_INTERIOR_STIFFNESS).contains(&s)) {
            return Err(Error::param(
                Said::new()
                    .set(Opt::InteriorStiffness, crate::human::typed(s))
                    .text(format!(
                        ": a scale of the inside's stiffness, from {MIN_INTERIOR_STIFFNESS} \
                         to {MAX_INTERIOR_STIFFNESS} (1: a uniform solid's)"
                    )),
            ));
        }
        if s != DEFAULT_INTERIOR_STIFFNESS && (self.shell || self.inside == Inside::None) {
            let shell = if self.shell {
                Said::new().opt(Opt::Shell)
            } else {
                Said::new().set(Opt::Inside, self.inside)
            };
            return Err(Error::param(
                shell
                    .text(" keeps no cells inside for ")
                    .set(Opt::InteriorStiffness, crate::human::typed(s))
                    .text(" to scale: give one"),
            ));
        }
        if let Some(s) = self.refine_strain
            && !(s.is_finite() && s >= 0.0)
        {
            return Err(Error::param(
                Said::new()
                    .set(Opt::RefineStrain, crate::human::typed(s))
                    .text(": a strain, 0 or more"),
            ));
        }
        check_rbf_tolerance(self.rbf_tolerance, Some(self.transfer))?;
        let params = self.unchecked();
        let (build, solve) = match self.min_cell_size {
            Some(size) => solve::adaptive(size, &params.build, &params.solve)?,
            None => (params.build, params.solve),
        };
        // The solver's own checks, here too so that every face refuses before any work.
        solve::check_params(&solve)?;
        Ok(DeformParams {
            build,
            solve,
            ..params
        })
    }

    /// These options as a run's report records them (`options`): each of [`OPTION_NAMES`] by
    /// the Python package's keyword (`-` as `_`), with the value the run took it at — `null`
    /// where it was not given and the run decided (the cells' size, a level count, the
    /// machine's memory).
    pub fn recorded(&self) -> std::collections::BTreeMap<String, serde_json::Value> {
        use serde_json::json;
        let values = [
            json!(self.cell_size),
            json!(self.cells),
            json!(self.min_cell_size),
            json!(self.max_level),
            json!(self.shell),
            json!(self.inside.to_string()),
            json!(self.interior_stiffness),
            json!(self.solver.to_string()),
            json!(self.subdomains),
            json!(self.tolerance),
            json!(self.coarse_levels),
            json!(self.loose_parts.to_string()),
            json!(self.refine_strain),
            json!(self.transfer.to_string()),
            json!(self.rbf_tolerance),
            json!(self.check_control_points),
            json!(self.memory_limit),
        ];
        OPTION_NAMES
            .iter()
            .map(|name| name.replace('-', "_"))
            .zip(values)
            .collect()
    }

    /// These options as the words of `rigidcells deform`'s command line, each flag then its
    /// value: options at their defaults are left out, the transfer is always named (it is what
    /// the user reads first). Numbers are written as the shortest text that reads back to the
    /// same value; a memory limit in the largest unit that divides it (`8G`).
    pub fn to_args(&self) -> Vec<String> {
        let d = Self::default();
        let mut out: Vec<String> = Vec::new();
        let mut flag = |name: &str, value: Option<String>| {
            out.push(format!("--{name}"));
            out.extend(value);
        };
        if let Some(size) = self.cell_size {
            flag("cell-size", Some(crate::human::typed(size)));
        }
        if let Some(cells) = self.cells {
            flag("cells", Some(cells.to_string()));
        }
        if let Some(size) = self.min_cell_size {
            flag("min-cell-size", Some(crate::human::typed(size)));
        }
        if let Some(levels) = self.max_level {
            flag("max-level", Some(levels.to_string()));
        }
        if self.shell {
            flag("shell", None);
        }
        if self.inside != d.inside {
            flag("inside", Some(self.inside.to_string()));
        }
        if self.interior_stiffness != d.interior_stiffness {
            flag(
                "interior-stiffness",
                Some(crate::human::typed(self.interior_stiffness)),
            );
        }
        if self.solver != d.solver {
            flag("solver", Some(self.solver.to_string()));
        }
        if self.subdomains != d.subdomains {
            flag("subdomains", Some(self.subdomains.to_string()));
        }
        if self.tolerance != d.tolerance {
            flag("tolerance", Some(crate::human::typed(self.tolerance)));
        }
        if let Some(levels) = self.coarse_levels {
            flag("coarse-levels", Some(levels.to_string()));
        }
        if self.loose_parts != d.loose_parts {
            flag("loose-parts", Some(self.loose_parts.to_string()));
        }
        if let Some(strain) = self.refine_strain {
            flag("refine-strain", Some(crate::human::typed(strain)));
        }
        flag("transfer", Some(self.transfer.to_string()));
        if let Some(tolerance) = self.rbf_tolerance {
            flag("rbf-tolerance", Some(crate::human::typed(tolerance)));
        }
        if self.check_control_points {
            flag("check-gcp", None);
        }
        if let Some(bytes) = self.memory_limit {
            flag("memory-limit", Some(size_words(bytes)));
        }
        out
    }

    /// The parameters these options give, before the checks of [`Options::params`] and without
    /// the adaptive cells of `min_cell_size`.
    pub(super) fn unchecked(&self) -> DeformParams {
        let build = BuildParams {
            cell_size: self.cell_size,
            target_cells: self.cells,
            max_level: self.max_level,
            inside: if self.shell {
                Inside::None
            } else {
                self.inside
            },
        };
        let solve = SolveParams {
            method: self.solver,
            subdomains: self.subdomains,
            carry_loose: self.loose_parts == LooseParts::Carry,
            move_tolerance: self.tolerance,
            coarse_levels: self.coarse_levels,
            refine_strain: self.refine_strain,
            soft_inside: (self.interior_stiffness == DEFAULT_INTERIOR_STIFFNESS
                && !self.shell
                && self.inside != Inside::None)
                .then_some(DEFAULT_INTERIOR_STIFFNESS),
            ..Default::default()
        };
        DeformParams {
            build,
            solve,
            transfer: self.transfer,
            rbf_tolerance: self.rbf_tolerance,
            interior_stiffness: self.interior_stiffness,
            proxy_samples: None,
            check_control_points: self.check_control_points,
            memory: Budget::given(self.memory_limit),
            options: *self,
        }
    }
}

/// The inside's stiffness unless one is given: a twentieth of the surface's glue.
///
/// A solid resists a twist as the fourth power of its radius and a surface as the third, so a
/// uniform solid (1) gathers a head's turn where its neck is thinnest; a soft inside spreads it
/// down the neck as a surface does, and still keeps a bend's volume and section better than
/// ARAP on the surface. Measured (BENCHMARKS.md, "Where the regions end"): a bust with its neck
/// fixed and its head turned 30° stretches 22 of its 33,987 edges past 1.2× (the worst 1.24×)
/// against the uniform solid's 173 (1.39×); a solid cylinder bent by 90° keeps 95.9 % of its
/// volume and its middle ring's radius within 0.906–1.037 (uniform: 98.2 %, 0.977–1.002;
/// libigl's ARAP on its surface: 92.7 %, 0.905–1.079). Softer changes the twist little (0.03:
/// 20 edges) and the bend more (95.4 %, 0.881–1.055).
pub const DEFAULT_INTERIOR_STIFFNESS: f64 = 0.05;

/// The softest interior [`Options::interior_stiffness`] takes: a ten-thousandth of the surface's
/// glue still ties every inside cell to its neighbors (a cell with no glue would float free
/// and leave the system singular).
pub const MIN_INTERIOR_STIFFNESS: f64 = 1e-4;
/// The stiffest: ten thousand times the surface's, past which the inside is as good as rigid
/// and the systems' conditioning suffers for nothing.
pub const MAX_INTERIOR_STIFFNESS: f64 = 1e4;

/// `bytes` in the largest of the units `--memory-limit` reads (K, M, G, T) that divides it.
fn size_words(bytes: u64) -> String {
    [("T", 40), ("G", 30), ("M", 20), ("K", 10)]
        .iter()
        .find(|&&(_, shift)| bytes >= 1 << shift && bytes.is_multiple_of(1 << shift))
        .map_or_else(
            || bytes.to_string(),
            |&(unit, shift)| format!("{}{unit}", bytes >> shift),
        )
}

/// Refuses an RBF far-field `tolerance` that is not a length, or that comes with a `transfer`
/// other than the RBF (`None`: one not yet known, a saved field's).
pub(super) fn check_rbf_tolerance(
    tolerance: Option<f64>,
    transfer: Option<Transfer>,
) -> Result<()> {
    match (tolerance, transfer) {
        (None, _) => Ok(()),
        (Some(_), Some(t)) if t != Transfer::Rbf => Err(Error::param(
            Said::new()
                .opt(Opt::RbfTolerance)
                .text(" applies to ")
                .set(Opt::Transfer, "rbf")
                .text(" only"),
        )),
        (Some(t), _) => crate::field::Rbf::<3>::check_tolerance(t),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The parameters a Rust caller gets by default are those of the user's default options
    /// (the partition-of-unity transfer, the machine's memory budget), checked or not.
    #[test]
    fn the_default_parameters_are_the_default_options() {
        let checked = Options::default().params().unwrap();
        assert_eq!(DeformParams::default(), checked);
        assert_eq!(checked.transfer(), Transfer::Pu);
        assert_eq!(checked.proxy_samples, None);
    }

    /// Every check of the options holds for the parameters: they cannot be made without it.
    #[test]
    fn options_that_contradict_or_are_out_of_range_make_no_parameters() {
        for options in [
            Options {
                cell_size: Some(0.1),
                cells: Some(100),
                ..Default::default()
            },
            Options {
                cell_size: Some(-1.0),
                ..Default::default()
            },
            Options {
                tolerance: f64::NAN,
                ..Default::default()
            },
            Options {
                rbf_tolerance: Some(0.01),
                ..Default::default()
            },
            Options {
                subdomains: 4,
                solver: Method::Direct,
                ..Default::default()
            },
            Options {
                interior_stiffness: 0.0,
                ..Default::default()
            },
            Options {
                interior_stiffness: f64::INFINITY,
                ..Default::default()
            },
            Options {
                interior_stiffness: MAX_INTERIOR_STIFFNESS * 1.0001,
                ..Default::default()
            },
            Options {
                interior_stiffness: f64::NAN,
                ..Default::default()
            },
            Options {
                interior_stiffness: 0.5,
                inside: Inside::None,
                ..Default::default()
            },
            Options {
                interior_stiffness: 0.5,
                shell: true,
                ..Default::default()
            },
        ] {
            assert!(
                matches!(options.params(), Err(Error::Param(_))),
                "{options:?}"
            );
        }
        let params = DeformParams::default();
        // The inside's scale at either end of its range, and a shell at the default.
        for options in [
            Options {
                interior_stiffness: MIN_INTERIOR_STIFFNESS,
                ..Default::default()
            },
            Options {
                interior_stiffness: MAX_INTERIOR_STIFFNESS,
                ..Default::default()
            },
            Options {
                shell: true,
                ..Default::default()
            },
        ] {
            let params = options.params().unwrap();
            assert_eq!(params.interior_stiffness(), options.interior_stiffness);
        }
        assert!(params.with_proxy_samples(0).is_err());
        assert_eq!(params.with_proxy_samples(5).unwrap().proxy_samples, Some(5));
    }

    /// `words` read back as the command line reads them: each flag the inverse of
    /// [`Options::to_args`]'s, the rest at its default.
    fn read_back(words: &[String]) -> Options {
        let mut o = Options::default();
        let mut words = words.iter().map(String::as_str);
        while let Some(flag) = words.next() {
            let mut value = || words.next().unwrap();
            match flag {
                "--cell-size" => o.cell_size = Some(value().parse().unwrap()),
                "--cells" => o.cells = Some(value().parse().unwrap()),
                "--min-cell-size" => o.min_cell_size = Some(value().parse().unwrap()),
                "--max-level" => o.max_level = Some(value().parse().unwrap()),
                "--shell" => o.shell = true,
                "--inside" => o.inside = value().parse().unwrap(),
                "--interior-stiffness" => o.interior_stiffness = value().parse().unwrap(),
                "--solver" => o.solver = value().parse().unwrap(),
                "--subdomains" => o.subdomains = value().parse().unwrap(),
                "--tolerance" => o.tolerance = value().parse().unwrap(),
                "--coarse-levels" => o.coarse_levels = Some(value().parse().unwrap()),
                "--loose-parts" => o.loose_parts = value().parse().unwrap(),
                "--refine-strain" => o.refine_strain = Some(value().parse().unwrap()),
                "--transfer" => o.transfer = value().parse().unwrap(),
                "--rbf-tolerance" => o.rbf_tolerance = Some(value().parse().unwrap()),
                "--check-gcp" => o.check_control_points = true,
                "--memory-limit" => {
                    o.memory_limit = Some(crate::memory::parse_size(value()).unwrap());
                }
                other => panic!("{other}: not a flag of deform"),
            }
        }
        o
    }

    /// The command line's words of the options read back to the same options; only the
    /// transfer is named at the defaults.
    #[test]
    fn options_as_words_read_back() {
        assert_eq!(Options::default().to_args(), ["--transfer", "pu"]);
        let every = Options {
            min_cell_size: Some(0.1 + 0.2),
            max_level: Some(3),
            shell: true,
            interior_stiffness: 0.1,
            solver: Method::LocalGlobal,
            subdomains: 4,
            tolerance: 0.05,
            coarse_levels: Some(0),
            loose_parts: LooseParts::Rest,
            refine_strain: Some(1e-3),
            transfer: Transfer::Rbf,
            rbf_tolerance: Some(0.01),
            check_control_points: true,
            memory_limit: Some(3 << 30),
            ..Default::default()
        };
        let words = every.to_args();
        assert_eq!(read_back(&words), every, "{words:?}");
        // Every option is in the faces' list, and the list names nothing else.
        let all = Options {
            cell_size: Some(0.5),
            cells: Some(10),
            inside: Inside::Flood,
            ..every
        };
        let flags: Vec<&str> = all
            .to_args()
            .iter()
            .filter_map(|w| w.strip_prefix("--"))
            .map(|f| {
                OPTION_NAMES
                    .iter()
                    .find(|n| **n == f)
                    .copied()
                    .unwrap_or("?")
            })
            .collect();
        assert_eq!(flags, OPTION_NAMES, "{:?}", all.to_args());
        assert_eq!(words[words.len() - 2..], ["--memory-limit", "3G"]);
        for other in [
            Options {
                cell_size: Some(0.25),
                inside: Inside::Flood,
                memory_limit: Some(1000),
                ..Default::default()
            },
            Options {
                cells: Some(5000),
                transfer: Transfer::Blend,
                memory_limit: Some(1536 << 20),
                ..Default::default()
            },
        ] {
            let words = other.to_args();
            assert_eq!(read_back(&words), other, "{words:?}");
        }
    }
}
