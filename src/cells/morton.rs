//! Morton codes of the cells' coordinates: their bits interleaved, so that sorting the codes
//! sorts the cells along a space-filling curve and a parent's code is its child's shifted.

/// The Morton code of a cell's coordinates: their bits interleaved (axis 0 lowest), so that a
/// parent's code is its child's shifted right by `D` bits.
#[inline]
pub(crate) fn morton<const D: usize>(c: &[i64; D]) -> u64 {
    let masks = spread_of::<D>();
    c.iter()
        .enumerate()
        .fold(0, |code, (a, &v)| code | spread(v as u64, masks) << a)
}

/// The coordinates of a Morton code ([`morton`]).
#[inline]
pub(super) fn coords<const D: usize>(code: u64) -> [i64; D] {
    let masks = spread_of::<D>();
    std::array::from_fn(|a| compact(code >> a, masks) as i64)
}

/// The spreading masks of dimension `D`.
#[inline]
fn spread_of<const D: usize>() -> &'static Spread {
    if D == 3 { &SPREAD3 } else { &SPREAD2 }
}

/// The masks spreading a coordinate's bits apart: the mask of the coordinate's own bits, then
/// each step's shift and the mask after it (3D: 21 bits to every third bit; 2D: 32 bits to
/// every other bit).
type Spread = (u64, [(u32, u64); 5]);
const SPREAD3: Spread = (
    0x1f_ffff,
    [
        (32, 0x001f_0000_0000_ffff),
        (16, 0x001f_0000_ff00_00ff),
        (8, 0x100f_00f0_0f00_f00f),
        (4, 0x10c3_0c30_c30c_30c3),
        (2, 0x1249_2492_4924_9249),
    ],
);
const SPREAD2: Spread = (
    0xffff_ffff,
    [
        (16, 0x0000_ffff_0000_ffff),
        (8, 0x00ff_00ff_00ff_00ff),
        (4, 0x0f0f_0f0f_0f0f_0f0f),
        (2, 0x3333_3333_3333_3333),
        (1, 0x5555_5555_5555_5555),
    ],
);

/// The low bits of `x` spread apart by `masks`.
#[inline]
fn spread(x: u64, (own, steps): &Spread) -> u64 {
    steps
        .iter()
        .fold(x & own, |x, &(shift, mask)| (x | x << shift) & mask)
}

/// The inverse of [`spread`]: the steps undone in reverse.
#[inline]
fn compact(x: u64, (own, steps): &Spread) -> u64 {
    let mut x = x & steps[steps.len() - 1].1;
    for i in (0..steps.len()).rev() {
        let mask = if i == 0 { *own } else { steps[i - 1].1 };
        x = (x | x >> steps[i].0) & mask;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_codes_round_trip_and_nest() {
        for c in [
            [0i64, 0, 0],
            [1, 2, 3],
            [(1 << 21) - 1, 5, (1 << 20) + 7],
            [9, 0, 1 << 20],
        ] {
            let code = morton(&c);
            assert_eq!(coords::<3>(code), c);
            let parent = c.map(|v| v >> 1);
            assert_eq!(code >> 3, morton(&parent));
        }
        for c in [[0i64, 0], [(1 << 31) - 1, 12345], [7, (1 << 30) + 3]] {
            let code = morton(&c);
            assert_eq!(coords::<2>(code), c);
            assert_eq!(code >> 2, morton(&c.map(|v| v >> 1)));
        }
    }
}
