//! LAS coordinate encoding: world coordinates to the record integers `X Y Z` of a frame (a
//! scale and an offset per axis) and back, rounded exactly as every writer here writes them,
//! and the re-framing of an axis whose moved coordinates do not fit 32-bit integers.

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::io::stream::{Accepted, Bounds};
use crate::rigid::Vect;

/// `frame`, with the offset of each axis on which `lo`–`hi` (the moved coordinates' bounds)
/// do not fit 32-bit record integers moved to their center (on the old grid, so unmoved bits
/// stay exact) and the scale doubled only as far as their range needs; a note per changed axis.
pub(super) fn reframe(
    (mut scale, mut offset): Frame,
    (lo, hi): Bounds,
    notes: &mut Vec<String>,
) -> ([f64; 3], [f64; 3]) {
    let fits = |s: f64, o: f64, v: f64| {
        let r = ((v - o) / s).round();
        r >= i32::MIN as f64 && r <= i32::MAX as f64
    };
    for a in 0..3 {
        if fits(scale[a], offset[a], lo[a]) && fits(scale[a], offset[a], hi[a]) {
            continue;
        }
        let old = (scale[a], offset[a]);
        while (hi[a] - lo[a]) / scale[a] > 4.0e9 {
            scale[a] *= 2.0;
        }
        // The center, on the old grid of representable values, so unmoved bits stay exact.
        let center = 0.5 * (lo[a] + hi[a]);
        offset[a] = old.1 + ((center - old.1) / old.0).round() * old.0;
        notes.push(format!(
            "axis {}: moved coordinates overflow the input's encoding; offset {} -> {}{}",
            ["x", "y", "z"][a],
            old.1,
            offset[a],
            if scale[a] != old.0 {
                format!(", scale {} -> {}", old.0, scale[a])
            } else {
                String::new()
            }
        ));
    }
    (scale, offset)
}

/// A scale and an offset per axis.
pub(super) type Frame = ([f64; 3], [f64; 3]);

/// `p` as a LAS reader finds it once written in `frame` (rounded as [`encode`] rounds; a
/// coordinate that does not fit is left as it is: such a sink is refused before the end).
pub(super) fn on_frame((scale, offset): &Frame, p: &Vect<3>) -> Vect<3> {
    Vect::<3>::from_fn(|a, _| match round_to_i32((p[a] - offset[a]) / scale[a]) {
        Some(v) => v as f64 * scale[a] + offset[a],
        None => p[a],
    })
}

/// The frame's scale in words, for a table's caption: `the output's scale 0.01` (one figure
/// when the axes share it, else x, y, z).
pub(super) fn frame_words((scale, _): &Frame) -> String {
    if scale[0] == scale[1] && scale[1] == scale[2] {
        format!("the output's scale {}", scale[0])
    } else {
        format!(
            "the output's scale {}, {}, {}",
            scale[0], scale[1], scale[2]
        )
    }
}

/// Records encoded per parallel task.
const ENCODE_RUN: usize = 8192;

/// Writes the moved coordinates into the first 12 bytes of each record of `raw`, tracking
/// the bounds of the encoded values; [`Accepted::Overflow`] (the records partly written) when
/// one does not fit `frame`. Parallel over runs of records.
pub(super) fn encode(
    raw: &mut [u8],
    record_len: usize,
    moved: &[Vect<3>],
    frame: &Frame,
    (lo, hi): (&mut [f64; 3], &mut [f64; 3]),
) -> Accepted {
    let runs: Vec<Option<([f64; 3], [f64; 3])>> = raw
        .par_chunks_mut(record_len * ENCODE_RUN)
        .zip(moved.par_chunks(ENCODE_RUN))
        .map(|(raw, moved)| encode_run(raw, record_len, moved, frame))
        .collect();
    for run in runs {
        let Some((l, h)) = run else {
            return Accepted::Overflow;
        };
        for a in 0..3 {
            lo[a] = lo[a].min(l[a]);
            hi[a] = hi[a].max(h[a]);
        }
    }
    Accepted::Yes
}

/// [`encode`] of one run: the bounds of its encoded values, or `None` when one does not fit.
fn encode_run(
    raw: &mut [u8],
    record_len: usize,
    moved: &[Vect<3>],
    (scale, offset): &Frame,
) -> Option<([f64; 3], [f64; 3])> {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for (rec, p) in raw.chunks_exact_mut(record_len).zip(moved) {
        for a in 0..3 {
            let v = round_to_i32((p[a] - offset[a]) / scale[a])?;
            rec[4 * a..4 * a + 4].copy_from_slice(&v.to_le_bytes());
            let x = v as f64 * scale[a] + offset[a];
            lo[a] = lo[a].min(x);
            hi[a] = hi[a].max(x);
        }
    }
    Some((lo, hi))
}

/// `r` rounded half away from zero (as `f64::round`), if it fits an `i32`. `f64::round` is a
/// libm call on baseline x86-64, three per record; truncation is one instruction, and `r − t`
/// is exact for `|r| < 2^52`, so the comparisons decide the rounding exactly.
#[inline(always)]
fn round_to_i32(r: f64) -> Option<i32> {
    if !(r > i32::MIN as f64 - 0.5 && r < i32::MAX as f64 + 0.5) {
        return None;
    }
    let t = r as i64;
    let frac = r - t as f64;
    // Branch-free: the fraction of a moved coordinate is random, and a branch on it would miss
    // half the time (a fifth of pass 2, measured).
    let v = t + i64::from(frac >= 0.5) - i64::from(frac <= -0.5);
    i32::try_from(v).ok()
}

/// Why `scale` and `offset` cannot frame LAS coordinates, if they cannot: scales are positive
/// (the record's integers times the scale, plus the offset, are the coordinates), from 1e-15
/// to 1e100, and offsets finite, within ±1e100. A scale of 5e-324 or −1, or an offset of
/// −1.8e308, left no frame that could hold the moved coordinates (exit 1 after the whole
/// solve); the upper bounds are far past what the writers make of any spec's motions (a 1e15
/// translation gave a scale of 2.3e9 and an offset past 1e18), so every output reads back.
pub fn frame_error(scale: &[f64; 3], offset: &[f64; 3]) -> Option<String> {
    let ok = scale.iter().all(|s| (1e-15..=1e100).contains(s))
        && offset.iter().all(|o| o.is_finite() && o.abs() <= 1e100);
    (!ok).then(|| {
        format!(
            "scale {scale:?} / offset {offset:?} are out of range (scales positive, 1e-15 to \
             1e100; offsets finite, within ±1e100)"
        )
    })
}

/// The coordinates of LAS record integers `X Y Z` (any integer type that holds them) in the
/// frame `scale`, `offset`: `X · scale + offset` per axis, as every LAS reader here decodes
/// them. A frame that [`frame_error`] refuses is an [`Error::Param`].
pub fn decode_coordinates(
    records: &[[i64; 3]],
    scale: [f64; 3],
    offset: [f64; 3],
) -> Result<Vec<Vect<3>>> {
    if let Some(why) = frame_error(&scale, &offset) {
        return Err(Error::param(why));
    }
    Ok(records
        .iter()
        .map(|r| {
            Vect::<3>::new(
                r[0] as f64 * scale[0] + offset[0],
                r[1] as f64 * scale[1] + offset[1],
                r[2] as f64 * scale[2] + offset[2],
            )
        })
        .collect())
}

/// Coordinates encoded as LAS record integers by [`encode_coordinates`].
#[derive(Debug, Clone, PartialEq)]
pub struct Encoded {
    /// `X Y Z` of each sample: `(coordinate − offset) / scale` rounded to the nearest integer,
    /// halves away from zero.
    pub records: Vec<[i32; 3]>,
    /// The scale the records are in: the one asked for unless re-framing doubled it.
    pub scale: [f64; 3],
    /// The offset the records are in: the one asked for unless re-framing moved it.
    pub offset: [f64; 3],
    /// One line per re-framed axis (the old and new offset and scale).
    pub notes: Vec<String>,
}

/// `moved` as LAS record integers in the frame `scale`, `offset`, rounded to the nearest step
/// exactly as the LAS and LAZ writers here write them. When a coordinate does not fit a 32-bit
/// record integer, `reframe` moves that axis' offset (and doubles its scale if the range needs
/// it) as `rigidcells deform` does for its output, with a note; without `reframe` that is an
/// [`Error::Param`] naming the axis, its moved range and the range the frame holds. A frame
/// that [`frame_error`] refuses is an [`Error::Param`] too.
pub fn encode_coordinates(
    moved: &[Vect<3>],
    scale: [f64; 3],
    offset: [f64; 3],
    reframe: bool,
) -> Result<Encoded> {
    if let Some(why) = frame_error(&scale, &offset) {
        return Err(Error::param(why));
    }
    let records = |(scale, offset): Frame| -> Option<Vec<[i32; 3]>> {
        moved
            .iter()
            .map(|p| {
                Some([
                    round_to_i32((p[0] - offset[0]) / scale[0])?,
                    round_to_i32((p[1] - offset[1]) / scale[1])?,
                    round_to_i32((p[2] - offset[2]) / scale[2])?,
                ])
            })
            .collect()
    };
    if let Some(records) = records((scale, offset)) {
        return Ok(Encoded {
            records,
            scale,
            offset,
            notes: Vec::new(),
        });
    }
    let mut bounds = (
        Vect::<3>::repeat(f64::INFINITY),
        Vect::<3>::repeat(f64::NEG_INFINITY),
    );
    for p in moved {
        bounds.0 = bounds.0.inf(p);
        bounds.1 = bounds.1.sup(p);
    }
    if !moved.iter().all(|p| p.iter().all(|v| v.is_finite())) {
        return Err(Error::param("a moved coordinate is not finite"));
    }
    if !reframe {
        let a = (0..3)
            .find(|&a| {
                [bounds.0[a], bounds.1[a]]
                    .iter()
                    .any(|v| round_to_i32((v - offset[a]) / scale[a]).is_none())
            })
            .expect("a finite coordinate that does not fit lies on the bounds");
        let step = |i: i32| i as f64 * scale[a] + offset[a];
        return Err(Error::param(format!(
            "axis {}: the moved coordinates span {} to {}, but 32-bit record integers with \
             scale {} and offset {} hold {} to {}",
            ["x", "y", "z"][a],
            bounds.0[a],
            bounds.1[a],
            scale[a],
            offset[a],
            step(i32::MIN),
            step(i32::MAX),
        )));
    }
    let mut notes = Vec::new();
    let (scale, offset) = self::reframe((scale, offset), bounds, &mut notes);
    let records = records((scale, offset)).ok_or_else(|| {
        Error::param(format!(
            "the moved coordinates span {:?} to {:?}, more than 32-bit record integers can hold",
            <[f64; 3]>::from(bounds.0),
            <[f64; 3]>::from(bounds.1)
        ))
    })?;
    Ok(Encoded {
        records,
        scale,
        offset,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::{decode_coordinates, encode_coordinates, round_to_i32};
    use crate::rigid::Vect;

    #[test]
    fn coordinates_round_to_the_nearest_step_and_decode_back() {
        let moved = [
            Vect::<3>::new(1000.006, -1000.006, 0.004),
            Vect::<3>::new(999.994, -999.994, -0.005),
        ];
        let e = encode_coordinates(&moved, [0.01; 3], [1000.0, 0.0, 0.0], false).unwrap();
        assert_eq!(e.records, vec![[1, -100001, 0], [-1, -99999, -1]]);
        assert_eq!((e.scale, e.offset), ([0.01; 3], [1000.0, 0.0, 0.0]));
        assert!(e.notes.is_empty());
        let back = decode_coordinates(&[[1, -100001, 0], [-1, -99999, -1]], e.scale, e.offset);
        assert_eq!(
            back.unwrap(),
            vec![
                Vect::<3>::new(1000.01, -1000.01, 0.0),
                Vect::<3>::new(999.99, -999.99, -0.01)
            ]
        );
    }

    #[test]
    fn an_overflow_is_reframed_as_the_writer_does_or_refused() {
        let moved = [
            Vect::<3>::new(0.0, 0.0, 3.0e7),
            Vect::<3>::new(1.0, 0.0, 3.0e7 + 100.0),
        ];
        let e = encode_coordinates(&moved, [0.01; 3], [0.0; 3], true).unwrap();
        assert_eq!(e.scale, [0.01; 3]);
        assert_eq!(e.offset, [0.0, 0.0, 30000050.0]);
        assert_eq!(e.records, vec![[0, 0, -5000], [100, 0, 5000]]);
        assert_eq!(
            e.notes,
            ["axis z: moved coordinates overflow the input's encoding; offset 0 -> 30000050"]
        );
        let refused = encode_coordinates(&moved, [0.01; 3], [0.0; 3], false).unwrap_err();
        let text = refused.to_string();
        assert!(
            text.contains("axis z") && text.contains("30000100"),
            "{text}"
        );
        assert!(encode_coordinates(&moved, [0.0, 0.01, 0.01], [0.0; 3], true).is_err());
        assert!(decode_coordinates(&[[0; 3]], [0.01; 3], [f64::NAN, 0.0, 0.0]).is_err());
    }

    #[test]
    fn rounding_matches_f64_round() {
        let mut values = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            0.49999999999999994,
            -0.49999999999999994,
            4503599627370495.5,
            i32::MAX as f64,
            i32::MAX as f64 + 0.49,
            i32::MAX as f64 + 0.5,
            i32::MIN as f64,
            i32::MIN as f64 - 0.49,
            i32::MIN as f64 - 0.5,
            f64::NAN,
            f64::INFINITY,
            -f64::INFINITY,
        ];
        let mut x = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let unit = (x >> 11) as f64 / (1u64 << 53) as f64;
            values.push((unit - 0.5) * 5e9);
            values.push((unit - 0.5) * 20.0);
        }
        for r in values {
            let reference = r.round();
            let expected = (reference >= i32::MIN as f64 && reference <= i32::MAX as f64)
                .then_some(reference as i32);
            assert_eq!(round_to_i32(r), expected, "{r}");
        }
    }
}
