//! Options whose values are the library's named choices ([`rigidcells::internal::names`]): the names, and
//! the order `--help` lists them in, come from the library; the line of help each value gets in
//! `--help` is written here. Parsing goes through clap's own possible-values check, so a wrong
//! value gets clap's message, with its list and its "a similar value exists" tip.

use std::ffi::OsStr;
use std::marker::PhantomData;

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use rigidcells::Inside;
use rigidcells::internal::names::Named;
use rigidcells::{LooseParts, Method};
use rigidcells::{Outside, Transfer};

/// A named choice with a line of help for each value.
pub(super) trait Help: Named + Send + Sync {
    /// The value's line in `--help`.
    fn help(self) -> &'static str;
}

impl Help for Transfer {
    fn help(self) -> &'static str {
        match self {
            Transfer::Blend => "Continuous blend of the 4 nearest cells (fast preview)",
            Transfer::BlendIdw => {
                "The paper's inverse-distance blend of the 4 nearest cells (seams where the set \
                 changes)"
            }
            Transfer::Rbf => "Triharmonic RBF interpolation (smooth, final)",
            Transfer::Pu => {
                "Partition-of-unity RBF: triharmonic fits on overlapping patches blended \
                 smoothly (C²), for any number of cells"
            }
        }
    }
}

impl Help for Inside {
    fn help(self) -> &'static str {
        match self {
            Inside::Auto => {
                "Winding numbers when the input has triangles or normals, flood fill otherwise"
            }
            Inside::Winding => "Generalized winding number of the triangles or oriented points",
            Inside::Flood => "Exterior flood fill on the finest grid",
            Inside::None => "No interior cells (a shell)",
        }
    }
}

impl Help for Method {
    fn help(self) -> &'static str {
        match self {
            Method::Auto => {
                "Multilevel for cells of one size past 100,000 free cells; else the \
                 factorization where it fits the memory budget, else multilevel"
            }
            Method::Direct => {
                "Sparse Cholesky factorization (fill-in: memory grows faster than the cells)"
            }
            Method::Multilevel => {
                "Conjugate gradients with a rigid-motion multigrid (memory linear in the cells)"
            }
            Method::LocalGlobal => {
                "Local-global iterations on one matrix factored once, Anderson-accelerated \
                 (no Gauss-Newton system)"
            }
        }
    }
}

impl Help for Outside {
    fn help(self) -> &'static str {
        match self {
            Outside::Refuse => {
                "Fail with exit code 4, naming how many samples and how far; write nothing"
            }
            Outside::Keep => "Samples beyond the margin keep their coordinates bit for bit",
            Outside::Extend => "The transfer is evaluated beyond the margin as anywhere",
        }
    }
}

impl Help for LooseParts {
    fn help(self) -> &'static str {
        match self {
            LooseParts::Carry => {
                "Each rides along rigidly with the nearest cell of a constrained part"
            }
            LooseParts::Rest => "Each keeps its rest pose",
        }
    }
}

/// The value parser of an option that takes one of `T`'s names.
pub(super) fn choice<T: Help>() -> Choice<T> {
    Choice(PhantomData)
}

/// See [`choice`].
#[derive(Clone)]
pub(super) struct Choice<T>(PhantomData<T>);

/// `T`'s values as clap lists them.
fn possible<T: Help>() -> impl Iterator<Item = PossibleValue> {
    T::ALL
        .iter()
        .map(|v| PossibleValue::new(v.name()).help(v.help()))
}

impl<T: Help> TypedValueParser for Choice<T> {
    type Value = T;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &OsStr,
    ) -> Result<T, clap::Error> {
        // Not UTF-8: named as best it can be, and refused as no name.
        let value = value.to_string_lossy();
        let name = PossibleValuesParser::new(possible::<T>()).parse_ref(
            cmd,
            arg,
            OsStr::new(value.as_ref()),
        )?;
        T::from_name(&name).map_err(|e| cmd.clone().error(clap::error::ErrorKind::InvalidValue, e))
    }

    fn possible_values(&self) -> Option<Box<dyn Iterator<Item = PossibleValue> + '_>> {
        Some(Box::new(possible::<T>()))
    }
}
