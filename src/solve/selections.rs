//! What the samples select, gathered in one streaming pass: the finest grid cells of each
//! region's samples, their sums for a handle's pivot, and each control point's nearest sample
//! for snapping ([`Selections`]); [`super::constraints`] maps them onto the cells.

use rustc_hash::{FxHashMap as HashMap, FxHashSet as HashSet};

use crate::cells::Grid;
use crate::error::{Error, Result};
use crate::rigid::Vect;
use crate::spec::{EditSpec, Region};

/// What the samples select, region by region (in the order fixed, handles, stiffness), gathered
/// a batch of samples at a time so that a streaming pass needs no sample twice: the finest grid
/// cells holding selected samples, and their sum and count (a handle's default pivot is their
/// centroid).
#[derive(Debug, Clone)]
pub struct Selections<const D: usize> {
    pub(super) regions: Vec<RegionSamples<D>>,
    pub(super) snaps: Snaps<D>,
}

/// The nearest sample of each target that asks to be snapped (`snap`, or a horizontal control
/// point), within its distance: the targets sit in buckets of a hash grid twice the largest
/// distance wide, so that each sample looks in one bucket (two with both kinds of target).
#[derive(Debug, Clone, Default)]
pub(super) struct Snaps<const D: usize> {
    /// Per target: the distance it looks within (`None`: not snapped), whether horizontally.
    wanted: Vec<Option<(f64, bool)>>,
    /// Per target: the squared distance and position of the nearest sample so far.
    best: Vec<Option<(f64, Vect<D>)>>,
    /// The bucket size (0 until the first samples come, when the finest cell size is known).
    size: f64,
    buckets: rustc_hash::FxHashMap<[i64; D], Vec<u32>>,
    any_horizontal: bool,
    any_spatial: bool,
}

impl<const D: usize> Snaps<D> {
    fn new(spec: &EditSpec<D>) -> Self {
        let wanted = spec
            .targets
            .iter()
            .map(|t| match (t.snap, t.horizontal) {
                (Some(d), h) => Some((d, h)),
                // Filled in with the finest cell size when the grid is known.
                (None, true) => Some((f64::NAN, true)),
                (None, false) => None,
            })
            .collect::<Vec<_>>();
        Self {
            best: vec![None; wanted.len()],
            any_horizontal: wanted.iter().flatten().any(|w| w.1),
            any_spatial: wanted.iter().flatten().any(|w| !w.1),
            wanted,
            ..Default::default()
        }
    }

    /// The bucket of `p` (horizontally: its last coordinate's key is `i64::MIN`).
    fn key(&self, p: &Vect<D>, horizontal: bool) -> [i64; D] {
        let mut k = [0i64; D];
        for a in 0..D {
            k[a] = (p[a] / self.size).floor() as i64;
        }
        if horizontal {
            k[D - 1] = i64::MIN;
        }
        k
    }

    fn place(&mut self, spec: &EditSpec<D>, finest: f64) {
        for w in self.wanted.iter_mut().flatten() {
            if w.0.is_nan() {
                w.0 = crate::spec::HORIZONTAL_SNAP * finest;
            }
        }
        let largest = self.wanted.iter().flatten().fold(0.0f64, |m, w| m.max(w.0));
        self.size = (2.0 * largest).max(f64::MIN_POSITIVE);
        for (i, w) in self.wanted.iter().enumerate() {
            let Some((r, horizontal)) = *w else { continue };
            let p = spec.targets[i].from;
            let axes = if horizontal { D - 1 } else { D };
            // Every bucket the ball (or disc) of radius r about p meets: at most 2 per axis.
            let lo = self.key(&p.map(|v| v - r), horizontal);
            let hi = self.key(&p.map(|v| v + r), horizontal);
            let mut k = lo;
            'cells: loop {
                self.buckets.entry(k).or_default().push(i as u32);
                for a in 0..axes {
                    if k[a] < hi[a] {
                        k[a] += 1;
                        continue 'cells;
                    }
                    k[a] = lo[a];
                }
                break;
            }
        }
    }

    fn add(&mut self, spec: &EditSpec<D>, finest: f64, points: &[Vect<D>]) {
        if self.wanted.iter().all(Option::is_none) {
            return;
        }
        if self.size == 0.0 {
            self.place(spec, finest);
        }
        for p in points {
            for horizontal in [false, true] {
                if !(if horizontal {
                    self.any_horizontal
                } else {
                    self.any_spatial
                }) {
                    continue;
                }
                let Some(list) = self.buckets.get(&self.key(p, horizontal)) else {
                    continue;
                };
                for &i in list {
                    let i = i as usize;
                    let Some((r, h)) = self.wanted[i] else {
                        continue;
                    };
                    if h != horizontal {
                        continue;
                    }
                    let mut d = p - spec.targets[i].from;
                    if h {
                        d[D - 1] = 0.0;
                    }
                    let d2 = d.norm_squared();
                    if d2 <= r * r && self.best[i].is_none_or(|(b, _)| d2 < b) {
                        self.best[i] = Some((d2, *p));
                    }
                }
            }
        }
    }

    /// Where target `i` starts — snapped to its nearest sample, or as given — and the point
    /// whose cell carries it: the sample (a horizontal point at the sample's height may lie in
    /// no cell, on a steep slope), or the point itself. An error when it asked to be snapped
    /// and no sample lies within its distance.
    pub(super) fn from(&self, i: usize, t: &crate::spec::Target<D>) -> Result<(Vect<D>, Vect<D>)> {
        let Some((r, horizontal)) = self.wanted[i] else {
            return Ok((t.from, t.from));
        };
        match self.best[i] {
            Some((_, p)) if horizontal => {
                let mut q = t.from;
                q[D - 1] = p[D - 1];
                Ok((q, p))
            }
            Some((_, p)) => Ok((p, p)),
            None => Err(Error::param(format!(
                "control point {} ({}) at {:?}: no sample within {r:.6}{}; give it a larger \
                 `snap` distance",
                t.id,
                t.place,
                t.from
                    .iter()
                    .take(if horizontal { D - 1 } else { D })
                    .collect::<Vec<_>>(),
                if horizontal { " horizontally" } else { "" },
            ))),
        }
    }
}

#[derive(Debug, Clone)]
pub(super) struct RegionSamples<const D: usize> {
    pub(super) cells: HashSet<[i64; D]>,
    pub(super) sum: Vect<D>,
    pub(super) count: u64,
    /// For a region of the visible samples ([`Region::visible_from`]): the sum and count per
    /// finest grid cell, so that those of the cells the camera does not see can be left out.
    pub(super) per_cell: Option<HashMap<[i64; D], (Vect<D>, u64)>>,
}

impl<const D: usize> Selections<D>
where
    crate::rigid::Dim<D>: crate::rigid::Rigid<D>,
{
    /// Empty selections for `spec` over an input of `samples` samples: where every run starts
    /// with its spec, before any pass over the samples. Fails when the spec is not one a
    /// parser would have made ([`EditSpec::validate`]), when a region selects by LAS class and
    /// the input has no classes, or lists an index past its samples.
    pub fn new(spec: &EditSpec<D>, has_classes: bool, samples: u64) -> Result<Self> {
        spec.validate()?;
        spec.check_indices(samples)?;
        let regions: Vec<&Region<D>> = regions(spec).collect();
        if !has_classes && regions.iter().any(|r| r.uses_classes()) {
            return Err(Error::param(
                "a `classification` region needs an input with LAS classes",
            ));
        }
        Ok(Self {
            regions: regions
                .iter()
                .map(|r| RegionSamples {
                    cells: HashSet::default(),
                    sum: Vect::<D>::zeros(),
                    count: 0,
                    per_cell: r.visible_from().map(|_| HashMap::default()),
                })
                .collect(),
            snaps: Snaps::new(spec),
        })
    }

    /// Adds the samples `points` (world coordinates), numbered from `first`, with their LAS
    /// `classes` when the input has them; `grid` is the frame of the cells to come.
    pub fn add(
        &mut self,
        spec: &EditSpec<D>,
        grid: &Grid<D>,
        first: u64,
        points: &[Vect<D>],
        classes: Option<&[u8]>,
    ) {
        self.snaps.add(spec, grid.finest_size(), points);
        for (region, acc) in regions(spec).zip(&mut self.regions) {
            // Consecutive samples of a scan mostly share a cell: one set insertion per run.
            let mut last = None;
            for (i, p) in points.iter().enumerate() {
                if region.selects(first + i as u64, p, classes.map(|c| c[i])) {
                    acc.sum += p;
                    acc.count += 1;
                    let key = grid.locate(&(p - grid.origin), grid.max_level);
                    if let (Some(k), Some(per_cell)) = (key, acc.per_cell.as_mut()) {
                        let e = per_cell.entry(k.coord).or_insert((Vect::<D>::zeros(), 0));
                        e.0 += p;
                        e.1 += 1;
                    }
                    if let Some(k) = key
                        && last != Some(k.coord)
                    {
                        acc.cells.insert(k.coord);
                        last = Some(k.coord);
                    }
                }
            }
        }
    }
}

/// The sample-selecting regions of `spec`, in the order of [`Selections`].
pub(super) fn regions<const D: usize>(spec: &EditSpec<D>) -> impl Iterator<Item = &Region<D>> {
    spec.fixed
        .iter()
        .map(|e| &e.region)
        .chain(spec.handles.iter().map(|e| &e.region))
        .chain(spec.stiffness.iter().map(|e| &e.region))
}
