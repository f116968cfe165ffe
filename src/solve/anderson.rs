//! Anderson acceleration of the local-global iterations (Peng et al., "Anderson Acceleration
//! for Geometry Optimization and Physics Simulation", 2018): the next iterate extrapolated
//! from the last few, kept by the caller only while it lowers the energy.

use std::collections::VecDeque;

use nalgebra::{DMatrix, DVector};

/// Anderson acceleration's history (Walker and Ni's type II, as Peng et al. apply it to
/// local-global solvers): the newest residual `f = G(x) − x` and map value `g`, and the
/// differences of the last `depth + 1` of each, with the residual differences' Gram matrix
/// kept as they come and go: a step costs `O(depth · n)`, not `O(depth² · n)`.
pub(super) struct Anderson {
    depth: usize,
    /// The newest residual and map value.
    newest: Option<(Vec<f64>, Vec<f64>)>,
    /// Differences of consecutive residuals (`df`) and map values (`dg`), oldest first.
    df: VecDeque<Vec<f64>>,
    dg: VecDeque<Vec<f64>>,
    /// `gram[i][j] = df[i] · df[j]`.
    gram: VecDeque<VecDeque<f64>>,
}

impl Anderson {
    pub(super) fn new(depth: usize) -> Self {
        Self {
            depth,
            newest: None,
            df: VecDeque::new(),
            dg: VecDeque::new(),
            gram: VecDeque::new(),
        }
    }

    pub(super) fn clear(&mut self) {
        self.newest = None;
        self.df.clear();
        self.dg.clear();
        self.gram.clear();
    }

    /// Records `x` and `g = G(x)` and returns the accelerated iterate, once there are two:
    /// `g − Σ θᵢ Δgᵢ`, with `θ` the least-squares fit of the newest residual by the residual
    /// differences (normal equations, lightly regularized).
    pub(super) fn push(&mut self, x: &[f64], g: &[f64]) -> Option<Vec<f64>> {
        if self.depth == 0 {
            return None;
        }
        let f: Vec<f64> = g.iter().zip(x).map(|(g, x)| g - x).collect();
        // The first push after a clear has nothing to take differences from.
        let (f0, g0) = self.newest.replace((f, g.to_vec()))?;
        let (f, g) = self.newest.as_ref()?;
        if self.df.len() == self.depth {
            self.df.pop_front();
            self.dg.pop_front();
            self.gram.pop_front();
            for row in &mut self.gram {
                row.pop_front();
            }
        }
        let df: Vec<f64> = f.iter().zip(&f0).map(|(a, b)| a - b).collect();
        let dg: Vec<f64> = g.iter().zip(&g0).map(|(a, b)| a - b).collect();
        let dots: Vec<f64> = self.df.iter().map(|d| dot(d, &df)).collect();
        for (row, &d) in self.gram.iter_mut().zip(&dots) {
            row.push_back(d);
        }
        let mut row: VecDeque<f64> = dots.into();
        row.push_back(dot(&df, &df));
        self.gram.push_back(row);
        self.df.push_back(df);
        self.dg.push_back(dg);
        let m = self.df.len();
        let mut normal = DMatrix::from_fn(m, m, |i, j| self.gram[i][j]);
        let scale = normal.diagonal().max().max(f64::MIN_POSITIVE);
        for i in 0..m {
            normal[(i, i)] += 1e-10 * scale;
        }
        let rhs = DVector::from_iterator(m, self.df.iter().map(|d| dot(d, f)));
        let theta = normal.cholesky()?.solve(&rhs);
        let mut out = g.clone();
        for (t, dg) in theta.iter().zip(&self.dg) {
            for (o, d) in out.iter_mut().zip(dg) {
                *o -= t * d;
            }
        }
        out.iter().all(|v| v.is_finite()).then_some(out)
    }
}

/// `a · b`.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The accelerated iterate, computed from scratch: the least-squares fit of the newest
    /// residual by the differences of the last `depth + 1` residuals (normal equations with
    /// the same regularization), applied to the map values' differences.
    fn anderson_from_scratch(xs: &[Vec<f64>], gs: &[Vec<f64>]) -> Vec<f64> {
        let k = xs.len();
        let n = xs[0].len();
        let f = |i: usize| DVector::from_iterator(n, gs[i].iter().zip(&xs[i]).map(|(g, x)| g - x));
        let fs: Vec<DVector<f64>> = (0..k).map(f).collect();
        let df =
            DMatrix::from_columns(&(0..k - 1).map(|i| &fs[i + 1] - &fs[i]).collect::<Vec<_>>());
        let mut normal = df.transpose() * &df;
        let scale = normal.diagonal().max();
        for i in 0..k - 1 {
            normal[(i, i)] += 1e-10 * scale;
        }
        let theta = normal
            .cholesky()
            .unwrap()
            .solve(&(df.transpose() * &fs[k - 1]));
        let mut out = gs[k - 1].clone();
        for (i, t) in theta.iter().enumerate() {
            for (o, (a, b)) in out.iter_mut().zip(gs[i + 1].iter().zip(&gs[i])) {
                *o -= t * (a - b);
            }
        }
        out
    }

    /// The history kept incrementally gives the iterate computed from scratch over its window
    /// (the last `depth + 1` pushes since a clear), as the window fills, slides and restarts.
    #[test]
    fn andersons_history_kept_as_it_goes_is_the_fit_from_scratch() {
        let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
        let mut random = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let (n, depth) = (40, 5);
        let mut history = Anderson::new(depth);
        let (mut xs, mut gs): (Vec<Vec<f64>>, Vec<Vec<f64>>) = (Vec::new(), Vec::new());
        for step in 0..20 {
            if step == 12 {
                history.clear();
                xs.clear();
                gs.clear();
            }
            let x: Vec<f64> = (0..n).map(|_| random()).collect();
            let g: Vec<f64> = (0..n).map(|_| random()).collect();
            let got = history.push(&x, &g);
            xs.push(x);
            gs.push(g);
            if xs.len() > depth + 1 {
                xs.remove(0);
                gs.remove(0);
            }
            match xs.len() {
                1 => assert!(got.is_none(), "step {step}: nothing to fit yet"),
                _ => {
                    let want = anderson_from_scratch(&xs, &gs);
                    let got = got.expect("a fit");
                    let off = got
                        .iter()
                        .zip(&want)
                        .map(|(a, b)| (a - b).abs())
                        .fold(0.0, f64::max);
                    assert!(off < 1e-9, "step {step}: {off}");
                }
            }
        }
    }
}
