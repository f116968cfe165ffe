//! Maps the edit spec onto the cells (paper §4): "surface constraints mapped to the cells that
//! intersect them".
//!
//! A cell gets a region's constraint, for a region of space (box, sphere, half-space, polygon
//! and their combinations: [`Shape`]), when its center lies in the region — so that a box
//! around the end of a solid fixes the interior cells there too, and the cells that straddle
//! its border stay free: the field keeps the region's samples exact to its own border
//! ([`Shapes`], `field::FieldMap`). The cells holding its samples two face steps or more from
//! those (a sliver, a thin part, a loose piece where it holds no cell's center) take it too.
//! The fixed entries are one role: when one of them is a selection of samples, every fixed
//! entry takes the cells it reaches, as a selection does. A selection of samples (indices,
//! classes) constrains the cells that hold them. A screen selection of the visible samples (`visible = true`) is a selection of samples: a
//! cell gets it when it holds a selected sample and the camera sees it ([`super::Sight`]).
//!
//! - `fixed` and `handle` cells are prescribed (0 DoF); a cell two different hard constraints
//!   reach (hold a sample of, or have their center in) is an error that names both and the cell.
//! - a `pin` prescribes one point of the cell containing it; the cell may rotate about it.
//! - a `target` adds a soft residual on the cell containing its `from` point. Its weight is
//!   relative to the glue between two finest cells: `λ · S^(D−1)` with `S` the finest size, so a
//!   weight of 1 pulls as hard as one face of glue whatever the units.
//! - stiffness scales multiply on cells in several regions; a pair's scale is the geometric mean
//!   of its cells' scales. The cells inside the shape (holding no samples) can be scaled as a
//!   whole ([`Constraints::scale_interior`]): part of the way to the paper's shell (its Fig. 10
//!   removes them).
//! - a connected component of cells with no constraint at all keeps its rest pose during the
//!   solve; afterwards it rides along rigidly with the nearest cell of a constrained part
//!   ([`super::carry_loose`], the default) or stays at rest, with a warning either way; no
//!   constrained cell anywhere is [`Error::NoConstraints`].
//!
//! Everything here is in the local frame of the complex.

use super::selections::Selections;
use super::trend::{TrendMap, TrendPoint};
use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::rigid::{Affine, Dim, Mat, Motion, Rigid, Vect};
use crate::said::Said;
use crate::spec::{EditSpec, HandleMotion, Region, Shape, Trend};

use super::sight::seen_cells;

/// What constrains a cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Free: `D + ROT` degrees of freedom.
    Free,
    /// Fixed at its rest pose.
    Fixed,
    /// Follows handle `k` (an index into [`Constraints::handles`]).
    Handle(u32),
    /// Rotates about pin `k` (an index into [`Constraints::pins`]).
    Pin(u32),
    /// In a component without any constraint: kept at its rest pose.
    Rest,
    /// In a component without any constraint, carried rigidly by cell `k` — the nearest
    /// cell of a constrained part ([`super::carry_loose`]).
    Carried(u32),
}

impl Role {
    /// The role's code in exports: 0 free, 1 fixed, 2 handle, 3 pin, 4 rest, 5 carried along.
    pub fn code(&self) -> u8 {
        match self {
            Self::Free => 0,
            Self::Fixed => 1,
            Self::Handle(_) => 2,
            Self::Pin(_) => 3,
            Self::Rest => 4,
            Self::Carried(_) => 5,
        }
    }

    /// Whether the cell's motion is prescribed entirely (no degrees of freedom).
    pub fn is_prescribed(&self) -> bool {
        matches!(
            self,
            Self::Fixed | Self::Handle(_) | Self::Rest | Self::Carried(_)
        )
    }
}

/// A handle in the local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Handle<const D: usize> {
    /// The motion as specified (input coordinates).
    pub motion: HandleMotion<D>,
    /// The pivot in input coordinates (the spec's, or the centroid of the selected samples).
    pub pivot: Vect<D>,
    /// The line of the spec entry.
    pub line: usize,
}

/// A pin in the local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinLocal<const D: usize> {
    /// The pinned point (local rest position).
    pub point: Vect<D>,
    /// Where the cells send it at full load (local): `T⁻¹` of where the edit sends it, for the
    /// trend `T` ([`Constraints::trend`]).
    pub to: Vect<D>,
    /// Where the edit sends it (local).
    pub wanted: Vect<D>,
    /// The cell holding it.
    pub cell: u32,
    /// The control point it makes exact (an index into [`Constraints::targets`]; `None` for a
    /// `[[pin]]`): its destination is the target's, and leaving the target out unpins it.
    pub target: Option<u32>,
}

/// A soft target in the local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetLocal<const D: usize> {
    /// The point (local rest position).
    pub from: Vect<D>,
    /// Where the cells should send it at full load (local): `T⁻¹` of where it is wanted, for
    /// the trend `T` ([`Constraints::trend`]).
    pub to: Vect<D>,
    /// Where it is wanted (local; a 2D point at its own height).
    pub wanted: Vect<D>,
    /// The effective weight `λ · S^(D−1)`.
    pub weight: f64,
    /// The cell holding `from`.
    pub cell: u32,
    /// Per axis, how hard the target pulls ([`crate::spec::Target::mask`]): the residual is
    /// `mask ∘ (value − to)`.
    pub mask: Vect<D>,
}

/// The edit spec resolved onto a cell complex.
#[derive(Debug, Clone, PartialEq)]
pub struct Constraints<const D: usize> {
    /// One role per cell.
    pub roles: Vec<Role>,
    /// Handles.
    pub handles: Vec<Handle<D>>,
    /// Pins.
    pub pins: Vec<PinLocal<D>>,
    /// Soft targets.
    pub targets: Vec<TargetLocal<D>>,
    /// Stiffness scale per cell: the spec's regions' scales, times [`Constraints::inside`] on
    /// the cells inside the shape.
    pub stiffness: Vec<f64>,
    /// The scale [`Constraints::scale_interior`] put on the inside's cells (1: a uniform
    /// solid), which [`coarsen_stage`](super::coarsen_stage) takes out to tell a region's
    /// stiffness from the inside's.
    pub inside: f64,
    /// The world position of the local frame's origin.
    pub origin: Vect<D>,
    /// Messages for the user (e.g. components kept at rest).
    pub warnings: Vec<Said>,
    /// The targets' global trend `T` (local frame; [`super::trend`]): the edit is `T ∘ F`,
    /// and the cells solve `F`, their fixed and resting cells following `T⁻¹` and each handle
    /// `T⁻¹ ∘ H`. The identity without targets or a trend.
    pub trend: TrendMap<D>,
    /// The kind of trend the spec asked for (fitted again without a point by
    /// [`Constraints::without_target`]).
    pub trend_kind: Trend,
    /// The regions of space that the fixed cells and each handle's hold to their own border.
    pub shapes: Shapes<D>,
}

/// The regions of space (input coordinates) that the fixed role and each handle hold to their
/// own border: the field keeps a sample inside exact and blends out from the region itself,
/// while the role's cells are those whose centers lie inside (see the module docs). `None`
/// where the role is a selection of samples (indices, classes, what a camera sees), whose
/// cells are every cell holding one of them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Shapes<const D: usize> {
    /// The fixed entries' regions together, when every one of them is a region of space.
    pub fixed: Option<Shape<D>>,
    /// Each handle's region, when it is one.
    pub handles: Vec<Option<Shape<D>>>,
}

impl<const D: usize> Constraints<D> {
    /// The roles a region of the spec holds: fixed, then each handle.
    pub fn region_roles(&self) -> impl Iterator<Item = Role> + '_ {
        std::iter::once(Role::Fixed).chain((0..self.handles.len()).map(|k| Role::Handle(k as u32)))
    }

    /// The region with a border that `role` holds ([`Shapes`]): the fixed entries' or a
    /// handle's, when it is one.
    pub fn shape_of(&self, role: Role) -> Option<&Shape<D>> {
        match role {
            Role::Fixed => self.shapes.fixed.as_ref(),
            Role::Handle(k) => self.shapes.handles.get(k as usize)?.as_ref(),
            _ => None,
        }
    }

    /// Constraints that only hold `complex`'s cells in their `roles` (no handles, pins or
    /// targets; every cell's stiffness 1): what the solver's tests build by hand.
    #[cfg(test)]
    pub(crate) fn held(complex: &crate::cells::CellComplex<D>, roles: Vec<Role>) -> Self {
        Self {
            stiffness: vec![1.0; roles.len()],
            roles,
            handles: vec![],
            pins: vec![],
            targets: vec![],
            inside: 1.0,
            origin: complex.grid.origin,
            warnings: vec![],
            trend: Default::default(),
            trend_kind: crate::spec::Trend::None,
            shapes: Default::default(),
        }
    }
}

impl<const D: usize> Constraints<D>
where
    Dim<D>: Rigid<D>,
{
    /// Scales the stiffness of the cells inside the shape (those holding no samples:
    /// [`crate::cells::CellKind::Interior`]) by `scale`, on top of the spec's stiffness regions:
    /// a face between two of them weighs `scale`, one between an inside and a surface cell
    /// `√scale`. Softer than 1, a twist spreads along a thin part as it does on a surface
    /// instead of gathering where the part is thinnest (a solid's torsion grows as the fourth
    /// power of its radius, a surface's as the third), at the cost of some of a solid's volume
    /// where it bends (BENCHMARKS.md, "Where the regions end": at a tenth, a bent cylinder keeps
    /// 96.5 % of its volume against 98.2 %).
    pub fn scale_interior(&mut self, complex: &CellComplex<D>, scale: f64) {
        if scale == 1.0 {
            return;
        }
        self.inside *= scale;
        for (s, cell) in self.stiffness.iter_mut().zip(&complex.cells) {
            if cell.kind == crate::cells::CellKind::Interior {
                *s *= scale;
            }
        }
    }

    /// These constraints without target `i`: a part of the shape held by that target alone
    /// keeps its rest pose. `None` when nothing else constrains any part.
    pub fn without_target(&self, complex: &CellComplex<D>, i: usize) -> Option<Self> {
        let mut c = self.clone();
        c.targets.remove(i);
        // An exact control point left out frees its cell.
        if let Some(k) = c.pins.iter().position(|p| p.target == Some(i as u32)) {
            let pin = c.pins.remove(k);
            c.roles[pin.cell as usize] = Role::Free;
            for r in &mut c.roles {
                if let Role::Pin(j) = r {
                    *j -= u32::from(*j > k as u32);
                }
            }
        }
        for t in c.pins.iter_mut().filter_map(|p| p.target.as_mut()) {
            *t -= u32::from(*t > i as u32);
        }
        c.fit_trend(self.trend_kind);
        let (parts, count, _) = anchor(complex, &mut c.roles, &c.targets);
        (parts < count).then_some(c)
    }

    /// Fits the trend of `kind` to the targets ([`super::trend`]) and sets what the cells
    /// solve for: each target's and pin's destination taken back by the trend. A trend that
    /// cannot be taken back at every destination (points all at one place, a scale of
    /// nothing) is not used.
    pub fn fit_trend(&mut self, kind: Trend) {
        let points: Vec<TrendPoint<D>> = self
            .targets
            .iter()
            .map(|t| TrendPoint {
                from: t.from,
                to: t.wanted,
                weight: t.weight,
                horizontal: t.mask[D - 1] < 1.0,
            })
            .collect();
        let trend = super::trend::fit(kind, &points);
        if kind == Trend::Spline && points.len() > super::trend::SPLINE_POINTS_MOST {
            let warning = format!(
                "trend \"spline\" takes at most {} control points, not {}: the trend is affine",
                super::trend::SPLINE_POINTS_MOST,
                points.len()
            );
            let warning = Said::from(warning);
            if !self.warnings.contains(&warning) {
                self.warnings.push(warning);
            }
        }
        let wanted = |t: &TargetLocal<D>| {
            let mut wanted = t.wanted;
            if t.mask[D - 1] < 1.0 {
                // A 2D point's height is the trend's, which its light hold keeps.
                wanted[D - 1] = trend.apply(&t.from)[D - 1];
            }
            wanted
        };
        let back: Option<(Vec<Vect<D>>, Vec<Vect<D>>)> = (|| {
            let targets = self
                .targets
                .iter()
                .map(|t| trend.back(&wanted(t)))
                .collect::<Option<_>>()?;
            let pins = self
                .pins
                .iter()
                .map(|p| match p.target {
                    Some(t) => trend.back(&wanted(&self.targets[t as usize])),
                    None => trend.back(&p.wanted),
                })
                .collect::<Option<_>>()?;
            Some((targets, pins))
        })();
        // A survey's trend scales areas by about 1: one that shrinks or grows them tenfold at
        // a control point, or folds them (points nearly on one line, where a few metres of
        // snapping turn the fit into a shear; a blunder of kilometres), is no trend.
        let sane = self.targets.iter().all(|t| {
            let j = trend.jacobian(&t.from);
            let area = j[(0, 0)] * j[(1, 1)] - j[(0, 1)] * j[(1, 0)];
            (0.1..=10.0).contains(&area)
        });
        let back = back.filter(|_| sane);
        if back.is_none() {
            let warning = format!(
                "trend \"{kind}\" folds or collapses the plane where the control points want \
                 to go (its areas scale by less than 0.1 or more than 10 there: points nearly on \
                 one line, or a blunder): no trend is used, the cells carry the whole motion"
            );
            let warning = Said::from(warning);
            if !self.warnings.contains(&warning) {
                self.warnings.push(warning);
            }
        }
        let (trend, (targets, pins)) = match back {
            Some(back) => (trend, back),
            None => (
                TrendMap::default(),
                (
                    self.targets.iter().map(wanted).collect(),
                    self.pins
                        .iter()
                        .map(|p| match p.target {
                            Some(t) => wanted(&self.targets[t as usize]),
                            None => p.wanted,
                        })
                        .collect(),
                ),
            ),
        };
        for (t, to) in self.targets.iter_mut().zip(targets) {
            t.to = to;
        }
        for (p, to) in self.pins.iter_mut().zip(pins) {
            p.to = to;
        }
        self.trend = trend;
        self.trend_kind = kind;
    }

    /// The motion at load fraction `f` of a cell with rest center `center` that follows `map`
    /// (`None`: the fixed and resting cells' identity) in the edit: in the cells' frame, `map`
    /// then the trend taken back, the trend's part taken up with the load. Without a trend,
    /// `map`'s own cell motion (the rest pose for `None`).
    pub fn prescribed_motion(&self, map: Option<&Affine<D>>, center: &Vect<D>, f: f64) -> Motion<D>
    where
        Dim<D>: Rigid<D>,
    {
        let Some(map) = map else {
            if self.trend.is_identity() {
                return Motion::rest(center);
            }
            return self.taken_back(&Affine::identity(), center, f);
        };
        if self.trend.is_identity() {
            return map.cell_motion(center);
        }
        self.taken_back(map, center, f)
    }

    /// `T⁻¹ ∘ map` to first order about `center`, the trend's part scaled by `f`.
    fn taken_back(&self, map: &Affine<D>, center: &Vect<D>, f: f64) -> Motion<D>
    where
        Dim<D>: Rigid<D>,
    {
        let y = map.apply(center);
        let back = self.trend.back(&y).unwrap_or(y);
        let undo = self
            .trend
            .jacobian(&back)
            .try_inverse()
            .unwrap_or_else(Mat::<D>::identity);
        let identity = Mat::<D>::identity();
        let linear = (identity + (undo - identity) * f) * map.linear;
        Motion {
            rot: <Dim<D> as Rigid<D>>::nearest_rotation(&linear),
            pos: y + (back - y) * f,
        }
    }

    /// The direction from the fixed cells to handle `k`'s cells: the difference of the means
    /// of their centers. `None` without fixed cells or cells of the handle.
    pub fn arm(&self, complex: &CellComplex<D>, k: usize) -> Option<Vect<D>> {
        Some(
            self.mean_center(complex, Role::Handle(k as u32))?
                - self.mean_center(complex, Role::Fixed)?,
        )
    }

    /// The mean of the centers of the cells of `role`, if any.
    fn mean_center(&self, complex: &CellComplex<D>, role: Role) -> Option<Vect<D>> {
        let (sum, n) = self
            .roles
            .iter()
            .zip(&complex.cells)
            .filter(|(r, _)| **r == role)
            .fold((Vect::<D>::zeros(), 0usize), |(s, n), (_, c)| {
                (s + c.center, n + 1)
            });
        (n > 0).then(|| sum / n as f64)
    }

    /// Handle `k`'s motion, its half turn taken the way round the handle moves where the
    /// matrix does not say ([`HandleMotion::undirected`]): the turn that carries the handle,
    /// seen from the fixed cells, the way its map moves its cells' center — a bar's end brought
    /// back beside its fixed end bends round into a U, not into a loop the other way.
    fn directed(&self, complex: &CellComplex<D>, k: usize) -> HandleMotion<D> {
        let motion = self.handles[k].motion;
        let (true, Some(arm), Some(center)) = (
            motion.undirected(),
            self.arm(complex, k),
            self.mean_center(complex, Role::Handle(k as u32)),
        ) else {
            return motion;
        };
        let moved = self.handle_map(k, 1.0).apply(&center) - center;
        let turn = <Dim<D> as Rigid<D>>::axis_3d(&motion.turn.0) * motion.turn.1.signum();
        match turn.dot(&in_3d(&arm).cross(&in_3d(&moved))) < 0.0 {
            true => motion.the_other_way(),
            false => motion,
        }
    }

    /// The affine map of handle `k` at load fraction `f`, in the local frame.
    pub fn handle_map(&self, k: usize, f: f64) -> Affine<D> {
        let h = &self.handles[k];
        let world = h.motion.at(f, &h.pivot);
        // A_local(x) = A(x + o) − o.
        Affine {
            linear: world.linear,
            translation: world.linear * self.origin + world.translation - self.origin,
        }
    }
}

/// The cell of the complex that takes the constraints of a sample at `x` (input coordinates):
/// the one holding its finest grid cell, as [`resolve_selected`] maps selected samples.
pub fn sample_cell<const D: usize>(complex: &CellComplex<D>, x: &Vect<D>) -> Option<usize> {
    let grid = &complex.grid;
    let key = grid.locate(&(x - grid.origin), grid.max_level)?;
    complex.finest_cell(&key.coord)
}

/// Resolves `spec` onto `complex`. `points` are the samples in input coordinates; `classes`
/// their LAS classes when the input has them.
pub fn resolve<const D: usize>(
    complex: &CellComplex<D>,
    spec: &EditSpec<D>,
    points: &[Vect<D>],
    classes: Option<&[u8]>,
) -> Result<Constraints<D>>
where
    Dim<D>: Rigid<D>,
{
    let mut selections = Selections::new(spec, classes.is_some(), points.len() as u64)?;
    selections.add(spec, &complex.grid, 0, points, classes);
    resolve_selected(complex, spec, &selections)
}

/// Resolves `spec` onto `complex` from the samples' [`Selections`].
pub fn resolve_selected<const D: usize>(
    complex: &CellComplex<D>,
    spec: &EditSpec<D>,
    selections: &Selections<D>,
) -> Result<Constraints<D>>
where
    Dim<D>: Rigid<D>,
{
    let n = complex.len();
    let origin = complex.grid.origin;
    let mut owner: Vec<Option<(Said, Role)>> = vec![None; n];
    let mut stiffness = vec![1.0f64; n];
    let mut warnings = Vec::new();

    let mut taken: Vec<Option<Role>> = vec![None; n];
    // Whether a face neighbor of each cell is marked.
    let beside = |centered: &[bool]| {
        let mut near = vec![false; n];
        for p in &complex.pairs {
            let (i, j) = (p.i as usize, p.j as usize);
            near[i] |= centered[j];
            near[j] |= centered[i];
        }
        near
    };
    // Cells selected by a region: the cells it takes (`Taken::cells`) and those it reaches
    // (`Taken::reach`: a cell holding a selected sample, or for a geometric region a cell whose
    // center lies in it), whose claims must not conflict.
    let select = |k: usize, region: &Region<D>| -> Taken<D> {
        let acc = &selections.regions[k];
        let mut hit = vec![false; n];
        if let (Some(view), Some(per_cell)) = (region.visible_from(), &acc.per_cell) {
            let seen = seen_cells(complex, view, per_cell.keys());
            let (mut sum, mut count) = (Vect::<D>::zeros(), 0);
            for (coord, (s, m)) in per_cell {
                if let Some(c) = complex.finest_cell(coord)
                    && seen[c]
                {
                    hit[c] = true;
                    sum += s;
                    count += m;
                }
            }
            return Taken::whole(hit, sum, count);
        }
        for coord in &acc.cells {
            if let Some(c) = complex.finest_cell(coord) {
                hit[c] = true;
            }
        }
        if !region.is_geometric() {
            return Taken::whole(hit, acc.sum, acc.count);
        }
        let centered: Vec<bool> = complex
            .cells
            .iter()
            .map(|cell| region.contains_point(&(cell.center + origin)))
            .collect();
        let shape = Shape::of(region);
        let cells = match shape {
            // A region with a border takes the cells whose centers it holds, and the cells of
            // its samples two face steps or more from those (a sliver, or a part where it holds
            // no center).
            Some(_) => {
                let one = beside(&centered);
                let within: Vec<bool> = (0..n).map(|c| one[c] || centered[c]).collect();
                let near = beside(&within);
                (0..n)
                    .map(|c| centered[c] || (hit[c] && !near[c]))
                    .collect()
            }
            None => (0..n).map(|c| centered[c] || hit[c]).collect(),
        };
        let reach = (0..n).map(|c| centered[c] || hit[c]).collect();
        Taken {
            cells,
            reach,
            shape,
            sum: acc.sum,
            count: acc.count,
        }
    };
    let (nf, nh) = (spec.fixed.len(), spec.handles.len());

    // Handles first, so that two handles with the same motion may share cells.
    let mut handles = Vec::new();
    let mut handle_hits = Vec::new();
    for (k, e) in spec.handles.iter().enumerate() {
        let hit = select(nf + k, &e.region);
        let (sum, count) = (hit.sum, hit.count);
        if !hit.reach.iter().any(|&h| h) {
            warnings.push(entry_named("handle", k, e.line).text(" selects no cell"));
        }
        let pivot = match e.value.pivot {
            Some(p) if !e.value.from_matrix => p,
            _ if count > 0 => sum / count as f64,
            _ => {
                let (s, m) = (0..n)
                    .filter(|&c| hit.cells[c])
                    .fold((Vect::<D>::zeros(), 0usize), |(s, m), c| {
                        (s + complex.cells[c].center + origin, m + 1)
                    });
                s / m.max(1) as f64
            }
        };
        handles.push(Handle {
            motion: e.value,
            pivot,
            line: e.line,
        });
        handle_hits.push(hit);
    }
    let same = |a: Role, b: Role| match (a, b) {
        (Role::Handle(x), Role::Handle(y)) => {
            // The same map at full load and halfway: the same motion whatever the pivots.
            let (hx, hy) = (&handles[x as usize], &handles[y as usize]);
            [0.5, 1.0].iter().all(|&f| {
                let (a, b) = (hx.motion.at(f, &hx.pivot), hy.motion.at(f, &hy.pivot));
                (a.linear - b.linear).norm() <= 1e-12
                    && (a.translation - b.translation).norm()
                        <= 1e-12 * (1.0 + a.translation.norm())
            })
        }
        _ => a == b,
    };
    let mut claim = |cell: usize, name: &Said, role: Role| -> Result<()> {
        match &owner[cell] {
            Some((other, r)) if !same(*r, role) => Err(Error::ConstraintConflict {
                first: other.clone(),
                second: name.clone(),
                at: (complex.cells[cell].center + origin)
                    .iter()
                    .copied()
                    .collect(),
                size: 2.0 * complex.cells[cell].half,
            }),
            Some(_) => Ok(()),
            None => {
                owner[cell] = Some((name.clone(), role));
                Ok(())
            }
        }
    };

    // The fixed entries are one role: held to their own border when every one of them is a
    // region of space, else every entry by the cells it reaches.
    let mut fixed_hits = Vec::new();
    for (k, e) in spec.fixed.iter().enumerate() {
        let name = entry_named("fixed", k, e.line);
        let hit = select(k, &e.region);
        if !hit.reach.iter().any(|&h| h) {
            warnings.push(name.clone().text(" selects no cell"));
        }
        for c in (0..n).filter(|&c| hit.reach[c]) {
            claim(c, &name, Role::Fixed)?;
        }
        fixed_hits.push(hit);
    }
    let bordered = fixed_hits.iter().all(|h| h.shape.is_some());
    let mut fixed_shapes = Vec::new();
    for mut hit in fixed_hits {
        match hit.shape.take() {
            Some(shape) if bordered => fixed_shapes.push(shape),
            _ => hit.cells.clone_from(&hit.reach),
        }
        hit.take(&mut taken, Role::Fixed);
    }
    let mut shapes = Shapes {
        fixed: (!fixed_shapes.is_empty()).then_some(Shape::Any(fixed_shapes)),
        handles: Vec::new(),
    };
    for (k, hit) in handle_hits.into_iter().enumerate() {
        let name = entry_named("handle", k, handles[k].line);
        for c in (0..n).filter(|&c| hit.reach[c]) {
            claim(c, &name, Role::Handle(k as u32))?;
        }
        hit.take(&mut taken, Role::Handle(k as u32));
        shapes.handles.push(hit.shape);
    }
    let locate = |x: &Vect<D>, what: Said, hint: &str| {
        complex.locate(&(x - origin)).ok_or_else(|| {
            Error::param(what.text(format!(
                " at {:?} lies outside every cell of the shape{hint}",
                x.iter().collect::<Vec<_>>()
            )))
        })
    };
    let mut pins = Vec::new();
    for (k, p) in spec.pins.iter().enumerate() {
        let cell = locate(&p.point, entry_named("pin", k, p.line), "")?;
        claim(cell, &entry_named("pin", k, p.line), Role::Pin(k as u32))?;
        taken[cell] = Some(Role::Pin(k as u32));
        pins.push(PinLocal {
            point: p.point - origin,
            to: p.to - origin,
            wanted: p.to - origin,
            cell: cell as u32,
            target: None,
        });
    }
    let glue = complex.grid.finest_size().powi(D as i32 - 1);
    let targets = spec
        .targets
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let (from, carrier) = selections.snaps.from(i, t)?;
            let mut to = t.to;
            if t.horizontal {
                to[D - 1] = from[D - 1];
            }
            let what = format!("control point {} ({})", t.id, t.place);
            let hint = if t.snap.is_none() {
                "; give its `[[target]]` a `snap` distance to move it onto the nearest samples"
            } else {
                ""
            };
            Ok(TargetLocal {
                from: from - origin,
                to: to - origin,
                wanted: to - origin,
                // A checkpoint is scored, not solved for.
                weight: if t.check { 0.0 } else { t.weight * glue },
                cell: locate(&carrier, Said::from(&what), hint)? as u32,
                mask: t.mask(),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    // An exact control point pins the cell holding it: the cell turns about the point, which
    // goes where it is wanted. A checkpoint stays a checkpoint.
    for (i, (t, local)) in spec.targets.iter().zip(&targets).enumerate() {
        if !t.exact || t.check {
            continue;
        }
        let what = format!("exact control point {} ({})", t.id, t.place);
        let cell = locate(&(local.from + origin), Said::from(&what), "")?;
        claim(cell, &Said::from(&what), Role::Pin(pins.len() as u32))?;
        taken[cell] = Some(Role::Pin(pins.len() as u32));
        pins.push(PinLocal {
            point: local.from,
            to: local.wanted,
            wanted: local.wanted,
            cell: cell as u32,
            target: Some(i as u32),
        });
    }
    for (k, e) in spec.stiffness.iter().enumerate() {
        let hit = select(nf + nh + k, &e.region);
        for c in (0..n).filter(|&c| hit.reach[c]) {
            stiffness[c] *= e.value;
        }
    }

    let mut roles: Vec<Role> = taken.into_iter().map(|r| r.unwrap_or(Role::Free)).collect();
    let (parts, count, loose) = anchor(complex, &mut roles, &targets);
    if parts == count {
        return Err(Error::NoConstraints);
    }
    warnings.extend(loose);
    let mut constraints = Constraints {
        roles,
        handles,
        pins,
        targets,
        stiffness,
        inside: 1.0,
        origin,
        warnings,
        trend: TrendMap::default(),
        trend_kind: Trend::None,
        shapes,
    };
    constraints.fit_trend(spec.trend);
    for k in 0..constraints.handles.len() {
        constraints.handles[k].motion = constraints.directed(complex, k);
    }
    Ok(constraints)
}

/// The cells a region selects ([`resolve_selected`]).
struct Taken<const D: usize> {
    /// The cells that take its role.
    cells: Vec<bool>,
    /// The cells it reaches: those that take its role, and the cells of its samples whose
    /// centers lie outside a region with a border. Two roles that reach one cell conflict.
    reach: Vec<bool>,
    /// Its border, when it has one.
    shape: Option<Shape<D>>,
    /// The sum and count of its samples (a handle's pivot).
    sum: Vect<D>,
    count: u64,
}

impl<const D: usize> Taken<D> {
    /// A selection whose cells are the cells it reaches.
    fn whole(hit: Vec<bool>, sum: Vect<D>, count: u64) -> Self {
        Self {
            cells: hit.clone(),
            reach: hit,
            shape: None,
            sum,
            count,
        }
    }

    /// Gives its cells `role` in `taken`.
    fn take(&self, taken: &mut [Option<Role>], role: Role) {
        for (t, _) in taken.iter_mut().zip(&self.cells).filter(|(_, c)| **c) {
            *t = Some(role);
        }
    }
}

/// An entry of the edit spec as its messages name it ([`crate::said::Part::Entry`]):
/// `handle #2 (line 9)` on the command line.
fn entry_named(kind: &'static str, k: usize, line: usize) -> Said {
    Said::new().entry(kind, k, line)
}

/// `v` in 3D (a 2D vector in the plane z = 0).
pub(crate) fn in_3d<const D: usize>(v: &Vect<D>) -> nalgebra::Vector3<f64> {
    nalgebra::Vector3::from_fn(|i, _| if i < D { v[i] } else { 0.0 })
}

/// The end of the warning [`anchor`] gives.
pub(super) const LOOSE_WARNING: &str = "have no constraint and keep their rest pose";

/// Gives [`Role::Rest`] to the cells of every connected part of `complex` that holds no
/// constraint (no role other than free or rest, no target), and [`Role::Free`] to rest cells
/// of parts that do. Returns the parts without a constraint, all parts, and the warning that
/// names them (none when every part holds a constraint).
pub(super) fn anchor<const D: usize>(
    complex: &CellComplex<D>,
    roles: &mut [Role],
    targets: &[TargetLocal<D>],
) -> (usize, usize, Option<Said>) {
    let (component, count) = complex.components();
    let mut anchored = vec![false; count];
    for (c, r) in roles.iter().enumerate() {
        anchored[component[c] as usize] |= !matches!(r, Role::Free | Role::Rest);
    }
    // A checkpoint (weight 0) pulls nothing.
    for t in targets.iter().filter(|t| t.weight > 0.0) {
        anchored[component[t.cell as usize] as usize] = true;
    }
    let mut loose = 0;
    for (c, r) in roles.iter_mut().enumerate() {
        if !anchored[component[c] as usize] {
            *r = Role::Rest;
            loose += 1;
        } else if *r == Role::Rest {
            *r = Role::Free;
        }
    }
    let parts = anchored.iter().filter(|&&a| !a).count();
    let warning = (loose > 0)
        .then(|| format!("{parts} of {count} connected parts ({loose} cells) {LOOSE_WARNING}"));
    (parts, count, warning.map(Said::from))
}
