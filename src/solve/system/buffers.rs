//! The storage a Gauss-Newton iteration keeps from one iteration to the next.

use faer::dyn_stack::MemBuffer;
use faer::sparse::SymbolicSparseColMat;

/// The storage of an iteration: the assembled values (one slot per block entry), the numeric
/// factor and faer's scratch. Kept with the system: allocating the factor (45 MB at 29k
/// unknowns) and its scratch anew each iteration faulted its pages in every time, and the step
/// took 119 ms instead of 87–94.
pub(super) struct Buffers {
    pub(super) values: Vec<f64>,
    pub(super) factor: Vec<f64>,
    pub(super) scratch: MemBuffer,
    /// The matrix's sparsity, moved into each iteration's matrix and taken back from it (a
    /// clone per iteration held 0.3 GiB more at the peak at 1.14M cells).
    pub(super) pattern: Option<SymbolicSparseColMat<u32>>,
    /// Each pair's gradient and curvature terms for its two cells, summed into the cells'
    /// after the pairs' parallel pass (192 bytes a pair: kept from one iteration of a
    /// minimization to the next, so that their pages are not mapped and zeroed anew every
    /// iteration).
    pub(super) pair_grad: Vec<f64>,
    pub(super) pair_curv: Vec<[f64; 6]>,
}

impl Default for Buffers {
    fn default() -> Self {
        Self {
            values: Vec::new(),
            factor: Vec::new(),
            scratch: MemBuffer::new(faer::dyn_stack::StackReq::EMPTY),
            pattern: None,
            pair_grad: Vec::new(),
            pair_curv: Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::System;
    use crate::internal::solve::iteration::Ask;
    use crate::internal::solve::steps::prescribe;
    use crate::internal::solve::turns::tests::edited;
    use crate::internal::solve::{Method, SolveParams};
    use crate::memory::Budget;
    use crate::rigid::{Motion, Vect};
    use crate::said::Said;

    /// A step assembled into what the last step kept (the pairs' terms, the multilevel
    /// path's matrix) is the step assembled anew: two systems take the same two steps from
    /// the same motions, one freeing what it kept in between ([`System::release_spare`]), and
    /// their second steps have the same bits. The bar's ~3,000 free cells give the hierarchy
    /// a level below its coarsest factor, whose matrix is the one handed back.
    #[test]
    fn a_step_into_the_kept_storage_is_the_step_assembled_anew() {
        let pts: Vec<Vect<3>> = (0..=50)
            .flat_map(|i| (0..=25).flat_map(move |j| (0..=25).map(move |k| (i, j, k))))
            .map(|(i, j, k)| Vect::<3>::new(i as f64, j as f64, k as f64) * 0.04)
            .collect();
        let text = "[[fixed]]\nbox = { min = [-1, -1, -1], max = [0.2, 2, 2] }\n\
                    [[handle]]\nbox = { min = [1.8, -1, -1], max = [3, 2, 2] }\n\
                    rotate = { axis = [1, 0, 0], degrees = 30 }\ntranslate = [0, 0.2, 0]\n";
        let (complex, constraints) = edited(&pts, 0.08, text);
        let params = SolveParams {
            method: Method::Multilevel,
            ..Default::default()
        };
        let mut motions: Vec<Motion<3>> = complex
            .cells
            .iter()
            .map(|c| Motion::rest(&c.center))
            .collect();
        prescribe(&complex, &constraints, &mut motions, 1.0);
        let ask = Ask {
            settled: false,
            enough: 0.0,
        };
        let step = |system: &mut System<3>| {
            let (delta, _) = system
                .step(&complex, &constraints, &motions, &[], true, ask)
                .unwrap();
            delta
        };
        let second = |release: bool| {
            let mut system = System::new(
                &complex,
                &constraints,
                &params,
                Budget::default(),
                &Said::new(),
            )
            .unwrap();
            step(&mut system);
            if release {
                system.release_spare();
            }
            step(&mut system)
        };
        let (kept, anew) = (second(false), second(true));
        assert!(kept.iter().any(|&v| v != 0.0));
        assert_eq!(kept, anew);
    }
}
