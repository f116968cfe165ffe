//! The maps of a saved field: [`SavedField::deformer`] and its variants, each a transfer over
//! the field's cells with the exact constraints and the policy beyond the margin
//! ([`FieldMap`]), all made by one constructor (`assemble`) but a window's.

use super::{Deformer, Field, FieldMap, Outside, PuRbf, Rbf, SavedField, Transfer};
use crate::error::{Error, Result};
use crate::rigid::{Dim, Rigid};

/// When the PU transfer fits its patches: all at once, or each when a sample first needs it.
#[derive(Clone, Copy)]
pub(super) enum Fits {
    All,
    OnDemand,
}

impl<const D: usize> SavedField<D>
where
    Dim<D>: Rigid<D>,
{
    /// The map of space for `transfer` (`None`: the field's own): the saved RBF coefficients
    /// (evaluated through the far field within `rbf_tolerance`, when given) or a new blend or
    /// RBF, with the prescribed cells exact and samples beyond the margin handled by `outside`.
    ///
    /// Every map of a whole field is made here or by the two methods below, through one
    /// constructor (`SavedField::assemble`): the in-memory deform, the streamed file, the
    /// editor's release, a tile's apply and the Python package's fields. A window of a file
    /// ([`SavedField::load_window`]) is mapped here too, but from the PU patches the file holds
    /// ([`FieldMap::in_window`]), without `assemble`.
    pub fn deformer(
        self,
        transfer: Option<Transfer>,
        rbf_tolerance: Option<f64>,
        outside: Outside,
    ) -> Result<FieldMap<D>> {
        self.deformer_with(transfer, rbf_tolerance, outside, Fits::All)
    }

    /// As [`SavedField::deformer`], keeping the field (the RBF's coefficients are copied): for
    /// a field applied more than once (the Python package's `Field.apply`). A window of a file
    /// ([`SavedField::load_window`]) goes through [`SavedField::deformer`] only.
    pub fn deformer_of(
        &self,
        transfer: Option<Transfer>,
        rbf_tolerance: Option<f64>,
        outside: Outside,
    ) -> Result<FieldMap<D>> {
        if self.window.is_some() {
            return Err(Error::param(
                "a window of a saved field is applied once, through `deformer`",
            ));
        }
        let transfer = transfer.unwrap_or(self.transfer);
        let rbf = self
            .rbf
            .as_ref()
            .filter(|_| transfer == Transfer::Rbf)
            .cloned();
        Self::assemble(
            &self.field,
            transfer,
            rbf,
            Fits::All,
            rbf_tolerance,
            outside,
        )
    }

    /// As [`SavedField::deformer`], but the PU transfer fits its patches only where samples
    /// reach ([`Deformer::on_demand`]): applying a large field to one tile fits the patches
    /// around the tile, with the same bits.
    pub fn tile_deformer(
        self,
        transfer: Option<Transfer>,
        rbf_tolerance: Option<f64>,
        outside: Outside,
    ) -> Result<FieldMap<D>> {
        self.deformer_with(transfer, rbf_tolerance, outside, Fits::OnDemand)
    }

    fn deformer_with(
        self,
        transfer: Option<Transfer>,
        rbf_tolerance: Option<f64>,
        outside: Outside,
        fits: Fits,
    ) -> Result<FieldMap<D>> {
        let transfer = transfer.unwrap_or(self.transfer);
        if let Some(w) = self.window {
            if transfer != Transfer::Pu {
                return Err(Error::solver(
                    "a window of a field serves the PU transfer only",
                ));
            }
            let inner = Deformer::Pu(Box::new(PuRbf::from_layout(&self.field, w.layout)?));
            return FieldMap::in_window(&self.field, inner, outside, &w.frame, w.samples);
        }
        Self::assemble(
            &self.field,
            transfer,
            self.rbf,
            fits,
            rbf_tolerance,
            outside,
        )
    }

    /// The one constructor of a field's map: `transfer` over `field` (the factored `rbf` when
    /// it is given and the transfer is the RBF's, else made here, the PU's patches fitted as
    /// `fits` says), then the far field's tolerance, then the exact constraints and the policy
    /// beyond the margin.
    fn assemble(
        field: &Field<D>,
        transfer: Transfer,
        rbf: Option<Rbf<D>>,
        fits: Fits,
        rbf_tolerance: Option<f64>,
        outside: Outside,
    ) -> Result<FieldMap<D>> {
        let inner = match (transfer, rbf) {
            (Transfer::Rbf, Some(r)) => Deformer::Rbf(r),
            (t, _) => match fits {
                Fits::All => Deformer::new(field, t)?,
                Fits::OnDemand => Deformer::on_demand(field, t)?,
            },
        }
        .with_rbf_tolerance(rbf_tolerance)?;
        FieldMap::new(field, inner, outside)
    }
}
