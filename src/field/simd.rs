//! The RBF's sum over centers compiled for AVX-512F and AVX2 and chosen at run time: the second
//! module of rigidcells with `unsafe` code, and its only uses are calling a function compiled
//! for an instruction set extension after checking that the CPU has it, and the masked vector
//! loads of the AVX-512 kernel.
//!
//! The released binary targets baseline x86-64 (SSE2: two doubles per instruction, no FMA).
//! The portable kernel's loops are written with four independent accumulators per component and
//! no reassociation, so the compiler vectorizes them to the width it is allowed; with AVX2 that
//! is four doubles per instruction. Rust never contracts `a * b + c` into a fused multiply-add
//! on its own, and the kernel calls no `mul_add`, so the baseline and AVX2 builds round every
//! operation the same way and give the same bits.
//!
//! The AVX-512 kernel is written with intrinsics: eight centers per step, FMA for `r²` and the
//! accumulation, and up to four points per pass over the centers. Its results differ from the
//! portable kernel's by a few ulps of `Σ |w_i| r_i³` (a unit test bounds it by 8 ε); a field
//! evaluated on different CPUs agrees to that bound, not bit for bit. Measured on the
//! 480k-vertex dragon at 5.5k cells, the evaluation took 1.3 s with AVX2 and 0.74 s here.
//!
//! The AVX-512 kernel takes the square root without `vsqrtpd`, whose throughput bounds the
//! loop: `vrsqrt14pd` refined by two Newton steps (`sqrt_avx512`), ten cheap instructions
//! that measured 1.4–1.7× faster per center than `vsqrtpd` on this machine's CPU (0.60 against
//! 1.03 ns per center and point, four points at a time); other refinements measured are in
//! BENCHMARKS.md §13.
//!
//! [`prefetch`] is the other `unsafe` call: a cache hint, which reads nothing.
//!
//! Contract: [`sum`] and [`sums`] call an extension's build only when
//! `is_x86_feature_detected!` says the running CPU has it (the check is cached by the standard
//! library).

#![allow(unsafe_code)]

/// `Σ_i w_k[i] |y − c_i|³` for each of the `K` weight vectors `w_k`, over centers stored axis by axis (`centers[a]`
/// the `a`-th coordinates) and weights component by component, on the widest vector unit the
/// CPU has.
/// The slices of `N` vectors, as the kernels take them.
pub(crate) fn slices<const N: usize>(v: &[Vec<f64>; N]) -> [&[f64]; N] {
    v.each_ref().map(Vec::as_slice)
}

#[inline]
pub(crate) fn sum<const D: usize, const K: usize>(
    y: &[f64; D],
    centers: &[&[f64]; D],
    weights: &[&[f64]; K],
) -> [f64; K] {
    radial::<D, K, false>(y, centers, weights)
}

/// `Σ_i w_k[i] |y − c_i|` for each of the `K` weight vectors: the sums of the RBF's gradient
/// (`∇ |y − c|³ = 3 |y − c| (y − c)`), on the same vector units as [`sum`].
#[inline]
pub(crate) fn sum_linear<const D: usize, const K: usize>(
    y: &[f64; D],
    centers: &[&[f64]; D],
    weights: &[&[f64]; K],
) -> [f64; K] {
    radial::<D, K, true>(y, centers, weights)
}

/// [`sum`] (`φ(r) = r³`) or, with `LINEAR`, [`sum_linear`] (`φ(r) = r`).
#[inline]
fn radial<const D: usize, const K: usize, const LINEAR: bool>(
    y: &[f64; D],
    centers: &[&[f64]; D],
    weights: &[&[f64]; K],
) -> [f64; K] {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU supports AVX-512F, checked just above (the module's contract).
            let [one] = unsafe {
                sum_avx512::<D, K, 1, LINEAR>(
                    std::slice::from_ref(y).try_into().expect("one point"),
                    centers,
                    weights,
                )
            };
            return one;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above (the module's contract).
            return unsafe { sum_avx2::<D, K, LINEAR>(y, centers, weights) };
        }
    }
    kernel::<D, K, LINEAR>(y, centers, weights)
}

/// [`sum`] for `S` points at once: on AVX-512F each step's centers and weights are loaded once
/// for all of them, and each point's sum is computed exactly as [`sum`] computes it (the same
/// bits). Other builds sum the points one by one.
#[inline]
pub(crate) fn sums<const D: usize, const K: usize, const S: usize>(
    ys: &[[f64; D]; S],
    centers: &[&[f64]; D],
    weights: &[&[f64]; K],
) -> [[f64; K]; S] {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU supports AVX-512F, checked just above (the module's contract).
        return unsafe { sum_avx512::<D, K, S, false>(ys, centers, weights) };
    }
    std::array::from_fn(|s| sum(&ys[s], centers, weights))
}

/// The sum on AVX-512F: eight centers per step, masked loads for the last, `S` points per pass
/// over the centers (each point's arithmetic is the same whatever `S`, so the same bits), FMA
/// for `r²` and the accumulation. The bits differ from the other builds by the FMA roundings;
/// `tests::every_build_agrees` bounds the difference.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn sum_avx512<const D: usize, const K: usize, const S: usize, const LINEAR: bool>(
    ys: &[[f64; D]; S],
    centers: &[&[f64]; D],
    weights: &[&[f64]; K],
) -> [[f64; K]; S] {
    use std::arch::x86_64::*;
    let n = centers[0].len();
    assert!(centers.iter().all(|c| c.len() == n) && weights.iter().all(|w| w.len() == n));
    let yv: [[__m512d; D]; S] =
        std::array::from_fn(|s| std::array::from_fn(|a| _mm512_set1_pd(ys[s][a])));
    let mut acc = [[_mm512_setzero_pd(); K]; S];
    let mut i = 0;
    while i < n {
        // The last step masks its missing lanes to zero.
        let mask: __mmask8 = if n - i >= 8 {
            0xff
        } else {
            (1u8 << (n - i)) - 1
        };
        // SAFETY (both loads): lanes `i..i + 8` masked to those below `n`, every slice's length.
        let c: [__m512d; D] = std::array::from_fn(|a| unsafe {
            _mm512_maskz_loadu_pd(mask, centers[a].as_ptr().add(i))
        });
        let w: [__m512d; K] = std::array::from_fn(|k| unsafe {
            _mm512_maskz_loadu_pd(mask, weights[k].as_ptr().add(i))
        });
        for s in 0..S {
            let mut r2 = _mm512_setzero_pd();
            for a in 0..D {
                let d = _mm512_sub_pd(yv[s][a], c[a]);
                r2 = _mm512_fmadd_pd(d, d, r2);
            }
            let r = sqrt_avx512(r2);
            let r3 = if LINEAR { r } else { _mm512_mul_pd(r2, r) };
            for k in 0..K {
                acc[s][k] = _mm512_fmadd_pd(w[k], r3, acc[s][k]);
            }
        }
        i += 8;
    }
    std::array::from_fn(|s| std::array::from_fn(|k| _mm512_reduce_add_pd(acc[s][k])))
}

/// `√r2` for `r2 ≥ 0` without `vsqrtpd`: the 14-bit reciprocal square root estimate refined by
/// two Newton steps (each squares the relative error: 2⁻¹⁴ → 2⁻²⁸ → below the rounding), then
/// `r2 · (1/√r2)`. Zero gives zero (the estimate is taken of at least `1e-300`, so it stays
/// finite); the result is within a few ulps of the rounded square root. `vsqrtpd` on eight
/// lanes takes about as long as these ten instructions take twice over.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
fn sqrt_avx512(r2: std::arch::x86_64::__m512d) -> std::arch::x86_64::__m512d {
    use std::arch::x86_64::*;
    let q = _mm512_max_pd(r2, _mm512_set1_pd(1e-300));
    let half = _mm512_mul_pd(q, _mm512_set1_pd(0.5));
    let mut y = _mm512_rsqrt14_pd(q);
    for _ in 0..2 {
        let e = _mm512_fnmadd_pd(half, _mm512_mul_pd(y, y), _mm512_set1_pd(1.5));
        y = _mm512_mul_pd(y, e);
    }
    _mm512_mul_pd(r2, y)
}

/// Asks the CPU to bring `data` into its caches (a hint: no effect on results), so that a
/// sum over it that follows other work does not wait on memory.
#[inline]
pub(crate) fn prefetch(data: &[f64]) {
    #[cfg(target_arch = "x86_64")]
    for line in data.chunks(8) {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: a prefetch reads nothing and faults on nothing; the pointer is in `data`.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(line.as_ptr().cast()) };
    }
}

/// [`kernel`] compiled with AVX2 enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn sum_avx2<const D: usize, const K: usize, const LINEAR: bool>(
    y: &[f64; D],
    centers: &[&[f64]; D],
    weights: &[&[f64]; K],
) -> [f64; K] {
    kernel::<D, K, LINEAR>(y, centers, weights)
}

/// The sum itself, inlined into each build: blocks of four centers with one accumulator per
/// lane, then the remainder, then the lanes added in order.
#[inline(always)]
fn kernel<const D: usize, const K: usize, const LINEAR: bool>(
    y: &[f64; D],
    centers: &[&[f64]; D],
    weights: &[&[f64]; K],
) -> [f64; K] {
    let n = centers[0].len();
    let mut acc = [[0.0f64; 4]; K];
    let mut i = 0;
    while i + 4 <= n {
        // Lane by lane within each step, so that each step is one vector instruction.
        let mut r2 = [0.0f64; 4];
        for a in 0..D {
            let c: &[f64; 4] = centers[a][i..i + 4].try_into().expect("4 centers");
            for l in 0..4 {
                let d = y[a] - c[l];
                r2[l] += d * d;
            }
        }
        let mut r3 = [0.0f64; 4];
        for l in 0..4 {
            r3[l] = if LINEAR {
                r2[l].sqrt()
            } else {
                r2[l] * r2[l].sqrt()
            };
        }
        for k in 0..K {
            let w: &[f64; 4] = weights[k][i..i + 4].try_into().expect("4 weights");
            for l in 0..4 {
                acc[k][l] += w[l] * r3[l];
            }
        }
        i += 4;
    }
    for j in i..n {
        let r2: f64 = (0..D).map(|a| (y[a] - centers[a][j]).powi(2)).sum();
        for k in 0..K {
            let phi = if LINEAR { r2.sqrt() } else { r2 * r2.sqrt() };
            acc[k][j - i] += weights[k][j] * phi;
        }
    }
    std::array::from_fn(|k| acc[k].iter().sum::<f64>())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX2 build gives the baseline's bits; the AVX-512 build agrees with it to a few ulps
    /// of the sum of the terms' magnitudes, at the centers too (`r = 0`); and the sum of several
    /// points at once gives each point's bits.
    #[test]
    fn every_build_agrees() {
        let mut next = super::super::test_numbers(0x9e37_79b9_7f4a_7c15);
        for n in [1, 3, 4, 7, 8, 9, 64, 1001] {
            let centers: [Vec<f64>; 3] = std::array::from_fn(|_| (0..n).map(|_| next()).collect());
            let weights: [Vec<f64>; 3] = std::array::from_fn(|_| (0..n).map(|_| next()).collect());
            let magnitude: [Vec<f64>; 3] =
                weights.clone().map(|w| w.iter().map(|v| v.abs()).collect());
            let (centers, weights, magnitude) =
                (slices(&centers), slices(&weights), slices(&magnitude));
            for t in 0..50 {
                let y = match t {
                    0 => [centers[0][0], centers[1][0], centers[2][0]],
                    _ => [next(), next(), next()],
                };
                let base = kernel::<3, 3, false>(&y, &centers, &weights);
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: checked just above.
                    let fast = unsafe { sum_avx2::<3, 3, false>(&y, &centers, &weights) };
                    assert_eq!(fast.map(f64::to_bits), base.map(f64::to_bits), "n = {n}");
                }
                let bound = kernel::<3, 3, false>(&y, &centers, &magnitude);
                let linear = sum_linear(&y, &centers, &weights);
                let linear_base = kernel::<3, 3, true>(&y, &centers, &weights);
                let linear_bound = kernel::<3, 3, true>(&y, &centers, &magnitude);
                for k in 0..3 {
                    assert!(
                        (linear[k] - linear_base[k]).abs() <= 8.0 * f64::EPSILON * linear_bound[k]
                    );
                }
                let got = sum(&y, &centers, &weights);
                for k in 0..3 {
                    assert!(
                        (got[k] - base[k]).abs() <= 8.0 * f64::EPSILON * bound[k],
                        "n = {n}"
                    );
                }
                let ys = [y, [next(), next(), next()], y, [0.5, -0.25, 2.0]];
                let many = sums(&ys, &centers, &weights);
                for s in 0..4 {
                    let one = sum(&ys[s], &centers, &weights);
                    assert_eq!(many[s].map(f64::to_bits), one.map(f64::to_bits), "n = {n}");
                }
            }
        }
    }
}
