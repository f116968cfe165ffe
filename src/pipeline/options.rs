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
use crate::solve::{self, LooseParts, Method, SolveParams};

use super::DeformParams;

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
    /// How the Gauss-Newton systems are solved (`--solver`).
    pub solver: Method,
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
            solver: Method::Auto,
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
        let conflict = |a: &str, b: &str| {
            Err(Error::Param(format!(
                "{a} and {b} both size the cells: give one"
            )))
        };
        match (self.cell_size, self.cells, self.min_cell_size) {
            (Some(_), Some(_), _) => return conflict("--cell-size", "--cells"),
            (Some(_), _, Some(_)) => return conflict("--cell-size", "--min-cell-size"),
            (_, Some(_), Some(_)) => return conflict("--cells", "--min-cell-size"),
            _ => {}
        }
        if let Some(size) = self.cell_size {
            crate::cells::check_size(size, "--cell-size")?;
        }
        if let Some(size) = self.min_cell_size {
            crate::cells::check_size(size, "--min-cell-size")?;
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(Error::Param(format!(
                "--tolerance {}: a number of finest cell sizes, 0 or more",
                self.tolerance
            )));
        }
        if self.shell && !matches!(self.inside, Inside::Auto | Inside::None) {
            return Err(Error::Param(format!(
                "--shell keeps no inside; --inside {} asks for one: give one",
                self.inside
            )));
        }
        if let Some(s) = self.refine_strain
            && !(s.is_finite() && s >= 0.0)
        {
            return Err(Error::Param(format!(
                "--refine-strain {s}: a strain, 0 or more"
            )));
        }
        check_rbf_tolerance(self.rbf_tolerance, Some(self.transfer))?;
        let params = self.unchecked();
        let (build, solve) = match self.min_cell_size {
            Some(size) => solve::adaptive(size, &params.build, &params.solve)?,
            None => (params.build, params.solve),
        };
        Ok(DeformParams {
            build,
            solve,
            ..params
        })
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
            carry_loose: self.loose_parts == LooseParts::Carry,
            move_tolerance: self.tolerance,
            coarse_levels: self.coarse_levels,
            refine_strain: self.refine_strain,
            ..Default::default()
        };
        DeformParams {
            build,
            solve,
            transfer: self.transfer,
            rbf_tolerance: self.rbf_tolerance,
            proxy_samples: None,
            check_control_points: self.check_control_points,
            memory: Budget::given(self.memory_limit),
        }
    }
}

/// Refuses an RBF far-field `tolerance` that is not a length, or that comes with a `transfer`
/// other than the RBF (`None`: one not yet known, a saved field's).
pub(super) fn check_rbf_tolerance(
    tolerance: Option<f64>,
    transfer: Option<Transfer>,
) -> Result<()> {
    match (tolerance, transfer) {
        (None, _) => Ok(()),
        (Some(_), Some(t)) if t != Transfer::Rbf => Err(Error::Param(
            "--rbf-tolerance applies to --transfer rbf only".into(),
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
        ] {
            assert!(
                matches!(options.params(), Err(Error::Param(_))),
                "{options:?}"
            );
        }
        let params = DeformParams::default();
        assert!(params.with_proxy_samples(0).is_err());
        assert_eq!(params.with_proxy_samples(5).unwrap().proxy_samples, Some(5));
    }
}
