//! The interactive editor (`rigidcells edit`): the paper's setting, in a browser.
//!
//! The server (`server`) holds an [`Editor`]: a decimated proxy of the input ([`Scene`], at
//! most [`crate::pipeline::PROXY_SAMPLES`] samples) and its live deformation
//! ([`crate::pipeline::Live`]: the cells built once, and a session that re-solves warm —
//! Gauss-Newton from the current motions, the symbolic factorization kept — each time the
//! page moves a handle). The page sends the whole edit
//! ([`Edit`]: its selections and handle poses) on every change; the editor writes it as an edit
//! spec in TOML ([`Editor::spec_text`]) — the file *Save edit* writes and the CLI reads — and
//! parses that same text, so what the page shows and what `deform --edit` computes come from
//! one spec. When only the poses changed, the resolved constraints are kept and only the handle
//! maps are replaced (no pass over the proxy); a new selection resolves them again and starts
//! a new session from rest.
//!
//! While dragging, the page blends the cells' motions itself on the GPU ([`Editor::blend`]:
//! each proxy sample's four nearest cells and weights, the continuous blend of
//! [`crate::field::Blend`], sent once: [`crate::pipeline::Live::blend_weights`]), so drawing
//! costs the same whatever the solver does. On release, [`Editor::release`] runs the chosen
//! transfer on the proxy with the exact constraints, and counts fold-overs as `deform` does.
//!
//! Which samples a selection holds is decided here, never by the page ([`Editor::selected`]):
//! the selection is written as the spec region the CLI reads and evaluated as the solve
//! evaluates it. A box or lasso is a `polygon` + `view` region; drawn with the page's default,
//! it selects only what is visible (`visible = true`): the samples on the polygon whose cell
//! the camera sees — the line from the cell's center toward the camera meets no cell of the
//! shape that does not touch it ([`crate::solve::Sight`]), so the front surface is taken
//! through about one cell of depth, and neither the far side nor what lies behind it. With the
//! page's x-ray, everything that projects into the polygon.
//!
//! Coordinates on the wire are relative to the proxy's center ([`Scene::center`]) in `f32`, so
//! georeferenced scans keep their detail on the GPU; the spec is written in the input's own
//! coordinates in `f64`.

pub mod server;

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::pipeline::{DeformParams, Live, Options, Step};
use crate::progress::{Observer, Silent};
use crate::rigid::Vect;
use crate::said::{Opt, Said, Terms};
use crate::solve;
use crate::spec::EditSpec;

/// The proxy of the input the editor shows and solves on.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// The input file as the user named it, made absolute (links not resolved): the saved
    /// spec's comment names it, the same whatever folder the editor was started in, and the
    /// editor's files go into its folder, not into the folder a link points to.
    pub input: PathBuf,
    /// Samples (world coordinates).
    pub points: Vec<Vect<3>>,
    /// One color per sample (LAS RGB or intensity, a PLY's vertex colors, else gray).
    pub colors: Vec<[u8; 3]>,
    /// LAS classes per sample (empty when the format has none).
    pub classes: Vec<u8>,
    /// Triangles over the samples (a mesh whose vertices the proxy holds all).
    pub triangles: Vec<[u32; 3]>,
    /// The center of the samples' bounds: the origin of the coordinates on the wire.
    pub center: Vect<3>,
    /// Bounds of the samples.
    pub bounds: (Vect<3>, Vect<3>),
    /// Samples in the file.
    pub total: u64,
    /// The vertical axis (0, 1, 2), as `render` decides it.
    pub up: usize,
}

impl Scene {
    /// Reads at most `max` samples of `input`: a mesh or small PLY/OBJ/XYZ whole (with its
    /// triangles and PLY colors), a streamed file every k-th sample.
    pub fn load(input: &Path, max: usize, observer: &dyn Observer) -> Result<Self> {
        // A file with more samples than the proxy holds is streamed, not read whole first.
        let too_many = crate::io::open(input).is_ok_and(|s| s.len() > max as u64);
        let whole = if too_many {
            None
        } else {
            match crate::io::Document::read(input) {
                Ok(doc) => Some(doc),
                Err(Error::UnsupportedFormat { .. }) => None,
                Err(e) => return Err(e),
            }
        };
        let mut scene = match whole {
            Some(doc) if doc.positions().len() <= max => {
                let colors = match crate::io::extension(input).as_deref() {
                    Some("ply") => crate::io::colors(input)?,
                    _ => None,
                };
                let n = doc.positions().len();
                let colors = match colors {
                    Some(crate::io::Colors::Vertices(c)) if c.len() == n => c,
                    _ => vec![[200, 200, 200]; n],
                };
                Scene {
                    points: doc.positions().to_vec(),
                    colors,
                    triangles: doc.triangles().to_vec(),
                    total: n as u64,
                    ..Default::default()
                }
            }
            _ => {
                let p = crate::render::colored_points(input, max, observer)?;
                Scene {
                    points: p.points,
                    colors: p.colors,
                    classes: p.classes,
                    total: p.total,
                    ..Default::default()
                }
            }
        };
        let Some(bounds) = crate::render::finite_bounds(&scene.points) else {
            return Err(Error::format(input, "no samples to edit"));
        };
        scene.input = std::path::absolute(input).map_err(|e| Error::io(input, e))?;
        scene.center = (bounds.0 + bounds.1) * 0.5;
        scene.bounds = bounds;
        scene.up = crate::render::up_of(input);
        Ok(scene)
    }

    /// The samples relative to [`Scene::center`], as `f32` triples.
    pub fn relative(&self) -> Vec<f32> {
        relative(&self.points, &self.center)
    }
}

/// The most vertices of a selection's polygon: the page's lasso keeps at most this many (it
/// halves a longer one), and the server refuses more.
pub const MAX_POLYGON: usize = 4096;
/// The most selections of an edit (fixed, and every handle's): each is a pass over the proxy's
/// samples.
pub const MAX_SELECTIONS: usize = 256;
/// The most handles of an edit (each has its gizmo on the page).
pub const MAX_HANDLES: usize = 64;
/// The most pins of an edit (each a click on the page).
pub const MAX_PINS: usize = 256;
/// The most LAS classes a selection names (there are 256).
pub const MAX_CLASSES: usize = 256;

/// A selection the page made: a box or lasso on the screen (`polygon` in normalized device
/// coordinates with the `view` it was drawn in), LAS classes, or both (then both must hold).
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Selection {
    /// The polygon on the screen, `[-1, 1]²`.
    #[serde(default)]
    pub polygon: Option<Vec<[f64; 2]>>,
    /// The row-major world-to-clip matrix of the view, in coordinates relative to
    /// [`Scene::center`].
    #[serde(default)]
    pub view: Option<[[f64; 4]; 4]>,
    /// Only what the view sees of the polygon ([`crate::solve::Sight`]; the page's default),
    /// else everything that projects into it (x-ray).
    #[serde(default)]
    pub visible: bool,
    /// LAS classes.
    #[serde(default)]
    pub classification: Option<Vec<u8>>,
}

/// A handle: its selections and its pose.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandleEdit {
    /// What it holds (a union).
    pub selections: Vec<Selection>,
    /// Its translation.
    #[serde(default)]
    pub translate: [f64; 3],
    /// The axis of its rotation.
    #[serde(default = "z_axis")]
    pub axis: [f64; 3],
    /// The angle of its rotation about `pivot`, in degrees.
    #[serde(default)]
    pub degrees: f64,
    /// The center of its rotation, relative to [`Scene::center`].
    #[serde(default)]
    pub pivot: [f64; 3],
}

fn z_axis() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

/// The whole edit as the page holds it.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Edit {
    /// Fixed selections (a union).
    #[serde(default)]
    pub fixed: Vec<Selection>,
    /// Handles.
    #[serde(default)]
    pub handles: Vec<HandleEdit>,
    /// Pins: points (relative) held where they are.
    #[serde(default)]
    pub pins: Vec<[f64; 3]>,
}

/// The cells' motions after a solve, for the page: per cell the affine map
/// `x' = A x + b` of relative coordinates, and its strain.
#[derive(Debug, Clone, Default)]
pub struct Motions {
    /// Per cell: `A` row-major then `b`, 12 numbers.
    pub maps: Vec<f32>,
    /// Per cell: the strain (the glue energy's misfit, as `--preview` colors it).
    pub strain: Vec<f32>,
    /// Gauss-Newton iterations of this solve.
    pub iterations: usize,
    /// Seconds of this solve.
    pub seconds: f64,
    /// The solver's warnings (parts kept at rest, …), in the page's words ([`PageNames`]).
    pub warnings: Vec<String>,
}

/// The proxy deformed by the final transfer.
#[derive(Debug, Clone, Default)]
pub struct Released {
    /// The moved samples, relative, as `f32` triples.
    pub positions: Vec<f32>,
    /// Samples checked for fold-overs and how many fold.
    pub foldovers: (usize, usize),
    /// Warnings (fold-overs), in the page's words ([`PageNames`]).
    pub warnings: Vec<String>,
}

/// The editor's state: the scene, and the live deformation of its samples
/// ([`crate::pipeline::Live`]: the cells, the current spec and its session).
pub struct Editor {
    scene: Scene,
    /// The user's options: the saved spec's comment writes them as `deform`'s flags.
    options: Options,
    /// The parameters of [`Editor::options`], as *Apply* deforms the file with them.
    params: DeformParams,
    /// The live deformation of the proxy, on cells that are not refined
    /// ([`crate::pipeline::Live::new`]).
    live: Live,
    /// The TOML text of the last edit solved.
    text: Option<String>,
    /// What the page calls the entries of that text.
    names: PageNames,
}

pub use crate::pipeline::live::DRAG_ITERATIONS;

impl Editor {
    /// Builds the cells of `scene` with the parameters of `options` ([`Options::params`],
    /// checked as `deform` checks them). With `--min-cell-size` or `--refine-strain` the
    /// page's cells are those the first solve starts on (a live session keeps its cells);
    /// *Apply* refines as `deform` does.
    pub fn new(scene: Scene, options: Options) -> Result<Self> {
        let params = options.params()?;
        let live = live(&scene, &params)?;
        Ok(Self {
            scene,
            options,
            params,
            live,
            text: None,
            names: PageNames::default(),
        })
    }

    /// Ends the live session: the next edit is solved from rest (after a failed solve, whose
    /// session may hold what it did not solve).
    pub fn reset(&mut self) {
        self.text = None;
        // An empty spec constrains nothing: it only drops the session.
        let _ = self
            .live
            .solve(EditSpec::default(), DRAG_ITERATIONS, &Silent);
    }

    /// Builds the live deformation again, as [`Editor::new`] did (the same cells): after a
    /// failure that may have left it half-changed.
    pub fn restart(&mut self) -> Result<()> {
        self.text = None;
        self.live = live(&self.scene, &self.params)?;
        Ok(())
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The cells.
    pub fn complex(&self) -> &CellComplex<3> {
        self.live.complex()
    }

    /// The user's options.
    pub fn options(&self) -> &Options {
        &self.options
    }

    /// The parameters of [`Editor::options`] (those *Apply* deforms with).
    pub fn params(&self) -> &DeformParams {
        &self.params
    }

    /// The cells' centers (relative) and edge lengths, `f32`, four per cell.
    pub fn cells(&self) -> Vec<f32> {
        let complex = self.live.complex();
        let shift = complex.grid.origin - self.scene.center;
        complex
            .cells
            .iter()
            .flat_map(|c| {
                let p = c.center + shift;
                [p[0] as f32, p[1] as f32, p[2] as f32, (2.0 * c.half) as f32]
            })
            .collect()
    }

    /// Each proxy sample's four nearest cells and their continuous blend weights (summing to
    /// one; unused slots weigh zero): `(cells, weights)`, four of each per sample.
    pub fn blend(&self) -> Result<(Vec<u32>, Vec<f32>)> {
        let (cells, weights) = self.live.blend_weights()?;
        Ok((cells.concat(), weights.concat()))
    }

    /// The edit spec of `edit` as TOML, in the input's coordinates: what *Save edit* writes.
    pub fn spec_text(&self, edit: &Edit) -> String {
        self.spec_named(edit).0
    }

    /// The edit spec of `edit` as TOML ([`Editor::spec_text`]), and what the page calls each
    /// of its entries.
    pub fn spec_named(&self, edit: &Edit) -> (String, PageNames) {
        spec_text(edit, &self.scene, &self.flags())
    }

    /// A message of the library about the last edit solved, in the page's words: its entries
    /// named as the page names them ("handle 1, selection 2"), not by the spec's lines.
    pub fn said(&self, said: &Said) -> String {
        self.names.render(said)
    }

    /// The user's options as `deform`'s flags ([`Options::to_args`]: those at their defaults
    /// left out): with them, `deform` of the input under a saved spec writes what *Apply*
    /// writes. Each value is one shell word (a number or a name).
    pub fn flags(&self) -> String {
        self.options.to_args().join(" ")
    }

    /// Solves `edit`: warm from the current motions when only the poses changed since the
    /// last call, a drag's step ([`DRAG_ITERATIONS`]), from rest when the
    /// selections did ([`Live::solve`]). `None` when the edit constrains nothing.
    pub fn solve(&mut self, edit: &Edit) -> Result<Option<Motions>> {
        edit.check()?;
        let (text, names) = self.spec_named(edit);
        self.names = names;
        if edit.is_empty() {
            self.text = None;
            self.live
                .solve(EditSpec::default(), DRAG_ITERATIONS, &Silent)?;
            return Ok(None);
        }
        let spec = self.parse(&text)?;
        let Some(step) = self.live.solve(spec, DRAG_ITERATIONS, &Silent)? else {
            self.text = None;
            return Ok(None);
        };
        self.text = Some(text);
        Ok(Some(self.motions(&step)))
    }

    /// `text`, a spec the editor wrote, parsed as the CLI parses it.
    fn parse(&self, text: &str) -> Result<EditSpec<3>> {
        let name = self.scene.input.with_extension("edit.toml");
        let base = name.parent().unwrap_or(Path::new(".")).to_path_buf();
        crate::spec::parse_spec::<3>(text, &base, &name)
    }

    /// Whether the last solve converged (a drag's update may stop after one iteration).
    pub fn converged(&self) -> bool {
        self.live.converged()
    }

    /// One more iteration on the current pose when the last solve stopped short of converging
    /// (the server runs it while no new pose waits); `None` when there is nothing to do.
    pub fn refine(&mut self) -> Result<Option<Motions>> {
        Ok(self.live.refine()?.map(|step| self.motions(&step)))
    }

    /// The page's form of the cells' current motions after `step` ([`Motions`]).
    fn motions(&self, step: &Step) -> Motions {
        let complex = self.live.complex();
        let motions = self.live.motions().unwrap_or_default();
        // x' = origin + R (x − origin − c) + p with x = x_rel + center:
        // x'_rel = R x_rel + R (center − origin − c) + p + origin − center.
        let shift = self.scene.center - complex.grid.origin;
        let mut maps = Vec::with_capacity(12 * motions.len());
        for (m, cell) in motions.iter().zip(&complex.cells) {
            let b = m.rot * (shift - cell.center) + m.pos - shift;
            for r in 0..3 {
                for c in 0..3 {
                    maps.push(m.rot[(r, c)] as f32);
                }
            }
            maps.extend(b.iter().map(|&v| v as f32));
        }
        let strain = solve::cell_strain(complex, motions)
            .into_iter()
            .map(|s| s as f32)
            .collect();
        Motions {
            maps,
            strain,
            iterations: step.solver.iterations,
            seconds: step.seconds,
            warnings: step.warnings.iter().map(|w| self.said(w)).collect(),
        }
    }

    /// The final transfer of the last solve on the proxy, with the fold-over check; the solve
    /// is converged first.
    pub fn release(&mut self) -> Result<Released> {
        let said = self.live.warnings().to_vec();
        let (moved, _, _, mut info) = self.live.release(&[], &Silent)?;
        // The solve's own warnings were said with its motions.
        info.warnings.retain(|w| !said.contains(w));
        Ok(Released {
            positions: relative(&moved, &self.scene.center),
            foldovers: info.foldovers,
            warnings: info.warnings.iter().map(|w| self.said(w)).collect(),
        })
    }

    /// Which proxy samples `selection` holds, as the spec the editor writes for it selects them
    /// (through the same text the CLI reads): on the screen polygon, of the classes, and with
    /// `visible` in a cell the camera sees ([`crate::solve::Sight`]).
    pub fn selected(&self, selection: &Selection) -> Result<Vec<bool>> {
        use rayon::prelude::*;
        selection.check()?;
        let edit = Edit {
            fixed: vec![selection.clone()],
            ..Default::default()
        };
        let (text, _) = spec_text(&edit, &self.scene, "");
        let name = self.scene.input.with_extension("edit.toml");
        let base = name.parent().unwrap_or(Path::new(".")).to_path_buf();
        let spec = crate::spec::parse_spec::<3>(&text, &base, &name)?;
        let region = &spec.fixed[0].region;
        let classes = &self.scene.classes;
        if classes.is_empty() && region.uses_classes() {
            return Err(Error::param(
                "a `classification` region needs an input with LAS classes",
            ));
        }
        let class = |i: usize| classes.get(i).copied();
        let mut out: Vec<bool> = self
            .scene
            .points
            .par_iter()
            .enumerate()
            .map(|(i, p)| region.selects(i as u64, p, class(i)))
            .collect();
        if let Some(view) = region.visible_from() {
            let cells: Vec<Option<usize>> = self
                .scene
                .points
                .par_iter()
                .zip(&out)
                .map(|(p, &on)| {
                    on.then(|| solve::sample_cell(self.live.complex(), p))
                        .flatten()
                })
                .collect();
            let mut candidates: Vec<usize> = cells.iter().flatten().copied().collect();
            candidates.sort_unstable();
            candidates.dedup();
            let seen = solve::seen(self.live.complex(), view, &candidates);
            for (o, c) in out.iter_mut().zip(&cells) {
                *o = c.is_some_and(|c| seen[c]);
            }
        }
        Ok(out)
    }

    /// The spec of the last [`Editor::solve`] (its TOML text).
    pub fn last_spec(&self) -> Option<&str> {
        self.text.as_deref()
    }

    /// The spec of the last [`Editor::solve`].
    pub fn last_parsed(&self) -> Option<&EditSpec<3>> {
        self.live.spec()
    }
}

impl Selection {
    /// Refuses a selection beyond the page's limits ([`MAX_POLYGON`] vertices,
    /// [`MAX_CLASSES`] classes): the work of each message the server takes stays bounded.
    pub fn check(&self) -> Result<()> {
        let vertices = self.polygon.as_ref().map_or(0, Vec::len);
        if vertices > MAX_POLYGON {
            return Err(Error::param(format!(
                "a polygon of {vertices} vertices; the editor takes at most {MAX_POLYGON}: \
                 draw a simpler lasso"
            )));
        }
        let classes = self.classification.as_ref().map_or(0, Vec::len);
        if classes > MAX_CLASSES {
            return Err(Error::param(format!(
                "a selection of {classes} classes; the editor takes at most {MAX_CLASSES}"
            )));
        }
        Ok(())
    }
}

impl Edit {
    /// Refuses an edit beyond the page's limits ([`MAX_HANDLES`] handles, [`MAX_PINS`] pins,
    /// [`MAX_SELECTIONS`] selections, each selection within [`Selection::check`]): the work of
    /// each message the server takes stays bounded.
    pub fn check(&self) -> Result<()> {
        let too_many = |count: usize, what: &str, most: usize| {
            Err(Error::param(format!(
                "an edit of {count} {what}; the editor takes at most {most}"
            )))
        };
        if self.handles.len() > MAX_HANDLES {
            return too_many(self.handles.len(), "handles", MAX_HANDLES);
        }
        if self.pins.len() > MAX_PINS {
            return too_many(self.pins.len(), "pins", MAX_PINS);
        }
        let selections = self.fixed.len()
            + self
                .handles
                .iter()
                .map(|h| h.selections.len())
                .sum::<usize>();
        if selections > MAX_SELECTIONS {
            return too_many(selections, "selections", MAX_SELECTIONS);
        }
        self.fixed
            .iter()
            .chain(self.handles.iter().flat_map(|h| &h.selections))
            .try_for_each(Selection::check)
    }

    /// Whether the edit selects nothing yet.
    pub fn is_empty(&self) -> bool {
        self.fixed.is_empty()
            && self.pins.is_empty()
            && self.handles.iter().all(|h| h.selections.is_empty())
    }
}

/// The live deformation of `scene`'s samples with `params`, on cells that are not refined
/// ([`Live::new`] refuses refinement; *Apply* refines).
fn live(scene: &Scene, params: &DeformParams) -> Result<Live> {
    let unrefined = DeformParams {
        solve: crate::solve::SolveParams {
            refine_strain: None,
            refine_fraction: None,
            ..params.solve
        },
        ..*params
    };
    Live::new(
        scene.points.clone(),
        &scene.triangles,
        scene.classes.clone(),
        unrefined,
    )
}

/// `path` as one word of a POSIX shell, on one line: as it is when it needs no quoting, else in
/// single quotes, and with bash's `$'…'` escapes when it holds a control character (a comment
/// line of TOML holds none).
fn shell_word(path: &Path) -> String {
    let text = path.to_string_lossy();
    let plain = |c: char| c.is_ascii_alphanumeric() || "/._-+,:@%=".contains(c);
    if !text.is_empty() && text.chars().all(plain) {
        return text.into_owned();
    }
    if !text.chars().any(char::is_control) {
        return format!("'{}'", text.replace('\'', r"'\''"));
    }
    let mut out = String::from("$'");
    for c in text.chars() {
        match c {
            '\'' | '\\' => {
                out.push('\\');
                out.push(c);
            }
            c if c.is_control() => out += &format!("\\u{:04x}", u32::from(c)),
            c => out.push(c),
        }
    }
    out.push('\'');
    out
}

/// `points − center` as `f32` triples: coordinates on the wire.
fn relative(points: &[Vect<3>], center: &Vect<3>) -> Vec<f32> {
    points
        .iter()
        .flat_map(|p| {
            let d = p - center;
            [d[0] as f32, d[1] as f32, d[2] as f32]
        })
        .collect()
}

/// `v` as a TOML array of the shortest round-trip numbers.
fn array(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
    format!("[{}]", items.join(", "))
}

/// The region keys of a selection, in the input's coordinates (`center` undone).
fn region_keys(s: &Selection, center: &Vect<3>) -> String {
    let mut keys = String::new();
    if let Some(polygon) = &s.polygon {
        let ring: Vec<String> = polygon.iter().map(|p| array(p)).collect();
        keys += &format!("polygon = [{}]\n", ring.join(", "));
        if let Some(view) = &s.view {
            // clip = V (x − center): the last column takes −V·center.
            let rows: Vec<String> = view
                .iter()
                .map(|r| {
                    let t = r[3] - (r[0] * center[0] + r[1] * center[1] + r[2] * center[2]);
                    array(&[r[0], r[1], r[2], t])
                })
                .collect();
            keys += &format!("view = [{}]\n", rows.join(", "));
            if s.visible {
                keys += "visible = true\n";
            }
        }
    }
    if let Some(classes) = &s.classification {
        let list: Vec<String> = classes.iter().map(|c| c.to_string()).collect();
        keys += &format!("classification = [{}]\n", list.join(", "));
    }
    keys
}

/// What the page calls the entries of a spec the editor wrote ("fixed, selection 1",
/// "handle 2, selection 1", "pin 1"), each with the line its table starts on: the terms
/// ([`Terms`]) the page's messages are said in, so that a warning names what the user made on
/// the page and not the saved spec's numbering. Options keep the command line's names, which
/// the page shows in the saved spec's comment.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PageNames(Vec<(usize, String)>);

impl PageNames {
    /// The name of the entry whose table holds `line`.
    fn at(&self, line: usize) -> Option<&str> {
        let k = self.0.partition_point(|&(start, _)| start <= line);
        k.checked_sub(1).map(|k| self.0[k].1.as_str())
    }
}

impl Terms for PageNames {
    fn option(&self, o: Opt) -> String {
        format!("--{}", o.name())
    }

    fn line(&self, n: usize) -> String {
        self.at(n)
            .map_or_else(|| format!("line {n} of the saved edit"), str::to_string)
    }

    fn entry(&self, kind: &str, index: usize, line: usize) -> String {
        self.at(line)
            .map_or_else(|| format!("{kind} {}", index + 1), str::to_string)
    }
}

/// The edit spec of `edit` on `scene`, as TOML, and what the page calls its entries; `flags`
/// the options of the command that reproduces it, in a comment.
fn spec_text(edit: &Edit, scene: &Scene, flags: &str) -> (String, PageNames) {
    let c = scene.center;
    let input = shell_word(&scene.input);
    let mut out = format!(
        "# rigidcells edit of {input}: the CLI reproduces it with\n\
         #   rigidcells deform {input} -o OUT --edit THIS.toml {flags}\n"
    );
    let mut names = Vec::new();
    // Each entry starts with an empty line: its table is on the line after.
    let mut entry = |out: &mut String, name: String, text: String| {
        names.push((out.matches('\n').count() + 2, name));
        *out += &text;
    };
    for (j, s) in edit.fixed.iter().enumerate() {
        let text = format!("\n[[fixed]]\n{}", region_keys(s, &c));
        entry(&mut out, format!("fixed, selection {}", j + 1), text);
    }
    for (k, h) in edit.handles.iter().enumerate() {
        let pivot = [h.pivot[0] + c[0], h.pivot[1] + c[1], h.pivot[2] + c[2]];
        for (j, s) in h.selections.iter().enumerate() {
            let text = format!(
                "\n[[handle]] # handle {}\n{}translate = {}\n\
                 rotate = {{ axis = {}, degrees = {:?} }}\npivot = {}\n",
                k + 1,
                region_keys(s, &c),
                array(&h.translate),
                array(&h.axis),
                h.degrees,
                array(&pivot)
            );
            entry(
                &mut out,
                format!("handle {}, selection {}", k + 1, j + 1),
                text,
            );
        }
    }
    for (k, p) in edit.pins.iter().enumerate() {
        let at = array(&[p[0] + c[0], p[1] + c[1], p[2] + c[2]]);
        let text = format!("\n[[pin]]\npoint = {at}\nto = {at}\n");
        entry(&mut out, format!("pin {}", k + 1), text);
    }
    (out, PageNames(names))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_are_one_shell_word_on_one_line() {
        let word = |p: &str| shell_word(Path::new(p));
        assert_eq!(word("/data/scan_01.las"), "/data/scan_01.las");
        assert_eq!(word("/data/my scan.las"), "'/data/my scan.las'");
        assert_eq!(word("/data/it's.las"), r"'/data/it'\''s.las'");
        assert_eq!(word("/data/a\nb.las"), r"$'/data/a\u000ab.las'");
        assert!(!word("/x/'\r\n\t'").contains(char::is_control));
    }
}
