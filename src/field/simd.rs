//! The RBF's sum over centers compiled for AVX2 and chosen at run time: the second module of
//! rigidcells with `unsafe` code, and its only use is calling a function compiled for an
//! instruction set extension after checking that the CPU has it.
//!
//! The released binary targets baseline x86-64 (SSE2: two doubles per instruction, no FMA).
//! The kernel's loops are written with four independent accumulators per component and no
//! reassociation, so the compiler vectorizes them to the width it is allowed; with AVX2 that is
//! four doubles per instruction. Rust never contracts `a * b + c` into a fused multiply-add on
//! its own, and the kernel calls no `mul_add`, so both builds round every operation the same
//! way and give the same bits: a saved field applied on any x86-64 machine gives the same
//! output.
//!
//! Contract: [`sum`] calls the AVX2 build only when `is_x86_feature_detected!("avx2")` says the
//! running CPU has it (the check is cached by the standard library).

#![allow(unsafe_code)]

/// `Σ_i w_k[i] |y − c_i|³` for each component `k`, over centers stored axis by axis (`centers[a]`
/// the `a`-th coordinates) and weights component by component, on the widest vector unit the
/// CPU has.
#[inline]
pub(crate) fn sum<const D: usize>(
    y: &[f64; D],
    centers: &[Vec<f64>; D],
    weights: &[Vec<f64>; D],
) -> [f64; D] {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above (the module's contract).
        return unsafe { sum_avx2(y, centers, weights) };
    }
    kernel(y, centers, weights)
}

/// [`kernel`] compiled with AVX2 enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn sum_avx2<const D: usize>(
    y: &[f64; D],
    centers: &[Vec<f64>; D],
    weights: &[Vec<f64>; D],
) -> [f64; D] {
    kernel(y, centers, weights)
}

/// The sum itself, inlined into each build: blocks of four centers with one accumulator per
/// lane, then the remainder, then the lanes added in order.
#[inline(always)]
fn kernel<const D: usize>(
    y: &[f64; D],
    centers: &[Vec<f64>; D],
    weights: &[Vec<f64>; D],
) -> [f64; D] {
    let n = centers[0].len();
    let mut acc = [[0.0f64; 4]; D];
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
            r3[l] = r2[l] * r2[l].sqrt();
        }
        for k in 0..D {
            let w: &[f64; 4] = weights[k][i..i + 4].try_into().expect("4 weights");
            for l in 0..4 {
                acc[k][l] += w[l] * r3[l];
            }
        }
        i += 4;
    }
    for j in i..n {
        let r2: f64 = (0..D).map(|a| (y[a] - centers[a][j]).powi(2)).sum();
        for k in 0..D {
            acc[k][j - i] += weights[k][j] * r2 * r2.sqrt();
        }
    }
    std::array::from_fn(|k| acc[k].iter().sum::<f64>())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The dispatched sum (AVX2 where the CPU has it) and the baseline build give the same bits.
    #[test]
    fn every_build_gives_the_same_bits() {
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for n in [1, 3, 4, 7, 64, 1001] {
            let centers: [Vec<f64>; 3] = std::array::from_fn(|_| (0..n).map(|_| next()).collect());
            let weights: [Vec<f64>; 3] = std::array::from_fn(|_| (0..n).map(|_| next()).collect());
            for _ in 0..50 {
                let y = [next(), next(), next()];
                let (fast, base) = (sum(&y, &centers, &weights), kernel(&y, &centers, &weights));
                assert_eq!(fast.map(f64::to_bits), base.map(f64::to_bits), "n = {n}");
            }
        }
    }
}
