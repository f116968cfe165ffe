//! The fast transfers against brute-force references, at every thread count.
//!
//! `cargo run --release -p rigidcells-tools --bin exact [MODEL.ply]` (default: the decimated
//! dragon, resampled to the paper's 480k vertices, bent by `bend_spec` at about 5.5k cells).
//!
//! - **Blend**: the tiled, anchored, parallel blend (`apply`) against a reference written here
//!   from the definition: all centers sorted by `(distance, index)`, the continuous weights
//!   `1/d_k − 1/d_5` of the 4 nearest, `x' = Σ w_k (R_k (x − c_k) + p_k) / Σ w_k`.
//! - **RBF**: the chunked evaluation (`apply`: four points per pass over the centers, the
//!   widest vector unit the CPU has) against a scalar loop over the same coefficients, one
//!   `sqrt` per term, summed in order.
//!
//! The RBF's reference is the exact value of the same sum (double-double arithmetic on the same
//! f64 coefficients), and a plain scalar f64 loop is measured against it too: the sum cancels
//! terms some 10⁴ times larger than its result, so f64 rounding is measured against the terms'
//! size `Σ |a_i| r_i³` (per component), not the extent alone.
//!
//! The RBF's far field (`--rbf-tolerance`) runs at tolerances of 1 to 1e-6 of the extent and
//! must stay within each; the rows give the distance from the model within which it sums
//! exactly.
//!
//! Each runs on pools of 1, 2 and 3 threads; the outputs must be bit-identical across thread
//! counts and within 1e-12 of the scale of the reference (the extent for the blend; checked on
//! the first `CHECKED` vertices, as the references are O(samples × cells)). Prints the times,
//! too.

use std::time::Instant;

use rayon::prelude::*;
use rigidcells::Vect;
use rigidcells::internal::field::{Deformer, Field, Rbf, Transfer, apply};
use rigidcells_tools::{bend_spec, build_at, cell_size_for, load_scan, resampled};

const VERTICES: usize = 480_000;
const CELLS: usize = 5_500;
const CHECKED: usize = 100_000;
const TOLERANCE: f64 = 1e-12;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (_, scan) = load_scan("; transfers against brute force")?;
    let mesh = resampled(&scan, VERTICES);
    let points: Vec<Vect<3>> = mesh.vertices.iter().map(|v| Vect::<3>::from(*v)).collect();
    let spec = bend_spec(&points)?;
    let size = cell_size_for(&points, &mesh.triangles, CELLS)?;
    let complex = build_at(&points, &mesh.triangles, size)?;
    let sol = rigidcells_tools::solve_default(complex, &spec, &points)?;
    let field = Field::from_solution(&sol);
    let (lo, hi) = points
        .iter()
        .fold((points[0], points[0]), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    let extent = (hi - lo).max();
    println!(
        "{} vertices, {} cells, extent {extent:.4}; errors against the reference on the first \
         {CHECKED} vertices, tolerance {TOLERANCE:e} of the scale",
        points.len(),
        field.centers.len()
    );
    let local: Vec<Vect<3>> = points[..CHECKED].iter().map(|p| p - field.origin).collect();
    let blend_ref: Vec<Vect<3>> = local
        .par_iter()
        .map(|x| reference_blend(&field, x) + field.origin)
        .collect();
    let rbf = Rbf::new(&field)?;
    let rbf_ref: Vec<Vect<3>> = local
        .par_iter()
        .map(|x| reference_rbf(&rbf, &field, x) + field.origin)
        .collect();
    let extents = vec![Vect::<3>::repeat(extent); CHECKED];
    let magnitudes: Vec<Vect<3>> = local
        .par_iter()
        .map(|x| rbf_magnitude(&rbf, &field, x))
        .collect();
    // The worst |a − b| over the checked vertices' components, against the extent and against
    // the per-component `scale`.
    let errors = |got: &[Vect<3>], reference: &[Vect<3>], scale: &[Vect<3>]| {
        let mut worst = (0.0f64, 0.0f64);
        for ((a, b), s) in got.iter().zip(reference).zip(scale) {
            for k in 0..3 {
                let e = (a[k] - b[k]).abs();
                worst = (worst.0.max(e / extent), worst.1.max(e / s[k]));
            }
        }
        worst
    };
    println!(
        "The RBF's scale is Σ|a_i| r_i³ per component, the terms its sum cancels (mean / extent \
         {:.0}); the blend's is the extent.",
        magnitudes.iter().map(|m| m.sum() / 3.0).sum::<f64>() / CHECKED as f64 / extent
    );
    println!(
        "| transfer | threads | build s | apply s | max error / extent | max error / scale | = 1 thread |"
    );
    println!("|---|---|---|---|---|---|---|");
    let naive: Vec<Vect<3>> = local
        .par_iter()
        .map(|x| naive_rbf(&rbf, &field, x) + field.origin)
        .collect();
    let (e, r) = errors(&naive, &rbf_ref, &magnitudes);
    println!("| RBF, scalar f64 loop (for comparison) | 1 | | | {e:.1e} | {r:.1e} | |");
    let mut failed = false;
    for (transfer, reference, scale) in [
        (Transfer::Blend, &blend_ref, &extents),
        (Transfer::Rbf, &rbf_ref, &magnitudes),
    ] {
        let mut first: Option<Vec<Vect<3>>> = None;
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()?;
            let (moved, build_s, apply_s) = pool.install(|| -> Result<_, rigidcells::Error> {
                let t = Instant::now();
                let deformer = Deformer::new(&field, transfer)?;
                let build_s = t.elapsed().as_secs_f64();
                let mut moved = points.clone();
                let t = Instant::now();
                apply(&deformer, &field.origin, &mut moved);
                Ok((moved, build_s, t.elapsed().as_secs_f64()))
            })?;
            let (e, r) = errors(&moved[..CHECKED], reference, scale);
            let same = first.as_ref().is_none_or(|f| *f == moved);
            println!(
                "| {transfer:?} | {threads} | {build_s:.3} | {apply_s:.3} | {e:.1e} | {r:.1e} | {} |",
                if same { "identical" } else { "DIFFERENT" }
            );
            failed |= !same || r.is_nan() || r > TOLERANCE;
            first.get_or_insert(moved);
        }
    }
    // The far field (`--rbf-tolerance`): each coordinate must stay within the tolerance of
    // the reference (plus the exact evaluation's own rounding, measured above).
    println!();
    println!(
        "| RBF far field | tolerance / extent | build s | apply s | max error / extent | within | \
         exact within (extents of the centroid) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for relative in [1.0, 1e-2, 1e-4, 1e-6] {
        let t = Instant::now();
        let far = rbf.clone().with_tolerance(relative * extent)?;
        let build_s = t.elapsed().as_secs_f64();
        let exact_within = far.far_field_reach().unwrap_or(f64::INFINITY) / extent;
        let far = Deformer::Rbf(far);
        let mut moved = points.clone();
        let t = Instant::now();
        apply(&far, &field.origin, &mut moved);
        let apply_s = t.elapsed().as_secs_f64();
        let (e, _) = errors(&moved[..CHECKED], &rbf_ref, &extents);
        let within = e <= relative + 1e-11;
        println!(
            "| | {relative:.0e} | {build_s:.3} | {apply_s:.3} | {e:.1e} | {} | {exact_within:.0} |",
            if within { "yes" } else { "NO" }
        );
        failed |= !within;
    }
    if failed {
        return Err("a transfer disagrees with its reference or across thread counts".into());
    }
    Ok(())
}

/// The continuous blend from its definition, by sorting every center.
fn reference_blend(field: &Field<3>, x: &Vect<3>) -> Vect<3> {
    let mut order: Vec<(f64, usize)> = field
        .centers
        .iter()
        .enumerate()
        .map(|(i, c)| ((x - c).norm_squared(), i))
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let cut = 1.0 / order[4].0.sqrt();
    let moved = |i: usize| {
        let m = &field.motions[i];
        m.rot * (x - field.centers[i]) + m.pos
    };
    if order[0].0 == 0.0 {
        return moved(order[0].1);
    }
    let (mut sum, mut total) = (Vect::<3>::zeros(), 0.0);
    for &(d2, i) in &order[..4] {
        let w = 1.0 / d2.sqrt() - cut;
        sum += moved(i) * w;
        total += w;
    }
    sum / total
}

/// The RBF's displacement from its coefficients, every term and the sum in double-double
/// arithmetic (about 106 bits) on the same f64 inputs: the evaluation's exact value, to which
/// any f64 evaluation's rounding is compared.
fn reference_rbf(rbf: &Rbf<3>, field: &Field<3>, x: &Vect<3>) -> Vect<3> {
    let (shift, inv_scale, _, _, weights) = rbf.parts();
    let y = (x - shift) * inv_scale;
    let mut sums = [Dd::default(); 3];
    for (i, c) in field.centers.iter().enumerate() {
        let c = (c - shift) * inv_scale;
        let mut r2 = Dd::default();
        for a in 0..3 {
            let d = Dd::sum(y[a], -c[a]);
            r2 = r2.add(d.mul(d));
        }
        let r3 = r2.mul(r2.sqrt());
        for k in 0..3 {
            sums[k] = sums[k].add(r3.scale(weights[k][i]));
        }
    }
    x + displacement(rbf, &y, sums.map(|s| s.hi + s.lo))
}

/// `Σ_i |a_i| |y − c_i|³` per component, in world units: the size of the terms the RBF's sum
/// cancels down to its result, against which f64 rounding is measured.
fn rbf_magnitude(rbf: &Rbf<3>, field: &Field<3>, x: &Vect<3>) -> Vect<3> {
    let (shift, inv_scale, _, _, weights) = rbf.parts();
    let y = (x - shift) * inv_scale;
    let mut m = Vect::<3>::zeros();
    for (i, c) in field.centers.iter().enumerate() {
        let r = (y - (c - shift) * inv_scale).norm();
        for k in 0..3 {
            m[k] += (weights[k][i] * r * r * r).abs();
        }
    }
    m / inv_scale
}

/// The RBF's displacement summed term by term in f64, in order: the naive evaluation.
fn naive_rbf(rbf: &Rbf<3>, field: &Field<3>, x: &Vect<3>) -> Vect<3> {
    let (shift, inv_scale, _, _, weights) = rbf.parts();
    let y = (x - shift) * inv_scale;
    let mut sums = [0.0; 3];
    for (i, c) in field.centers.iter().enumerate() {
        let r = (y - (c - shift) * inv_scale).norm();
        for k in 0..3 {
            sums[k] += weights[k][i] * (r * r * r);
        }
    }
    x + displacement(rbf, &y, sums)
}

/// The displacement at the scaled point `y` from the kernel `sums`: the polynomial part added
/// and the scale undone, as `Rbf::displacement` does.
fn displacement(rbf: &Rbf<3>, y: &Vect<3>, sums: [f64; 3]) -> Vect<3> {
    let (_, inv_scale, constant, linear, _) = rbf.parts();
    Vect::<3>::from_fn(|k, _| {
        let lin: f64 = (0..3).map(|a| linear[k][a] * y[a]).sum();
        (sums[k] + constant[k] + lin) / inv_scale
    })
}

/// A double-double number `hi + lo`, `|lo| ≤ ulp(hi) / 2`.
#[derive(Clone, Copy, Default)]
struct Dd {
    hi: f64,
    lo: f64,
}

impl Dd {
    /// `a + b` exactly (Knuth's two-sum).
    fn sum(a: f64, b: f64) -> Self {
        let s = a + b;
        let bb = s - a;
        Self {
            hi: s,
            lo: (a - (s - bb)) + (b - bb),
        }
    }

    fn renormalized(hi: f64, lo: f64) -> Self {
        let s = hi + lo;
        Self {
            hi: s,
            lo: lo - (s - hi),
        }
    }

    fn add(self, o: Self) -> Self {
        let s = Self::sum(self.hi, o.hi);
        Self::renormalized(s.hi, s.lo + self.lo + o.lo)
    }

    fn mul(self, o: Self) -> Self {
        let p = self.hi * o.hi;
        let e = self.hi.mul_add(o.hi, -p) + (self.hi * o.lo + self.lo * o.hi);
        Self::renormalized(p, e)
    }

    fn scale(self, w: f64) -> Self {
        self.mul(Self { hi: w, lo: 0.0 })
    }

    fn sqrt(self) -> Self {
        if self.hi <= 0.0 {
            return Self::default();
        }
        let s = self.hi.sqrt();
        let residual = Self::sum(self.hi, -s * s).hi - s.mul_add(s, -(s * s)) + self.lo;
        Self::renormalized(s, residual / (2.0 * s))
    }
}
