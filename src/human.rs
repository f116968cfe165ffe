//! Numbers printed for people carry the precision they were measured with, not the 17 digits
//! of a 64-bit float: a coordinate to its file's step (a LAS scale of 0.01 keeps two
//! decimals), a length the cells decided (a margin, a chosen cell size, a field's bounds) or
//! measured on them (a residual) to a thousandth of the finest cell, a figure with no step of
//! its own (an energy, a time per iteration) to three significant digits. All in plain
//! notation: people read `37.4`, not `3.740e1`.

/// The decimals that resolve `step`: 0.01 → 2, 0.001 → 3, 0.5 → 1, 1 or more → 0 (6 for a step
/// that is not a positive number, at most 12).
pub fn decimals(step: f64) -> usize {
    if !(step.is_finite() && step > 0.0) {
        return 6;
    }
    (-step.log10() - 1e-9).ceil().clamp(0.0, 12.0) as usize
}

/// `v` with the decimals that resolve `step`, as the bounds of a file or a field are printed
/// (trailing zeros kept, so that columns align).
pub fn to_step(v: f64, step: f64) -> String {
    format!("{v:.*}", decimals(step))
}

/// A length the cells decided, to a thousandth of the finest cell size `cell`, without
/// trailing zeros: a margin of 11.570624999993015 beside cells of 11.57 prints `11.57`.
pub fn length(v: f64, cell: f64) -> String {
    let text = to_step(v, cell / 1000.0);
    match text.contains('.') {
        true => text.trim_end_matches('0').trim_end_matches('.').to_string(),
        false => text,
    }
}

/// A figure with no step of its own (an energy, milliseconds per iteration) in plain notation:
/// every digit before the point and at least three significant ones, without trailing zeros
/// (37.396 → `37.4`, 0.012345 → `0.0123`, 1641.2 → `1641`); a figure that needs more than 12
/// decimals for its first digit prints as `0`.
pub fn figure(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    let magnitude = v.abs().log10().floor();
    let decimals = if v == 0.0 {
        0
    } else {
        (2.0 - magnitude).clamp(0.0, 12.0) as usize
    };
    let text = format!("{v:.decimals$}");
    let text = match text.contains('.') {
        true => text.trim_end_matches('0').trim_end_matches('.'),
        false => &text,
    };
    match text {
        "-0" => "0".into(),
        t => t.into(),
    }
}

/// A number the user typed, as typed: the shortest text that reads back to it, without a
/// trailing `.0` (−1 → `-1`, 1e-300 → `1e-300`, not three hundred digits; 0.25 → `0.25`), and
/// `nan`, `inf` as the command line reads them.
pub fn typed(v: f64) -> String {
    if v.is_nan() {
        return "nan".into();
    }
    if v.is_infinite() {
        return if v > 0.0 { "inf" } else { "-inf" }.into();
    }
    let text = format!("{v:?}");
    match text.strip_suffix(".0") {
        Some(whole) => whole.into(),
        None => text,
    }
}

/// Numbers the user typed, as a list as typed: `[0, 0.5, -1]` (each as [`typed`] says it).
pub fn list(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|&x| typed(x)).collect();
    format!("[{}]", items.join(", "))
}

/// An angle in degrees as people write it, with its sign: as typed where its shortest text has
/// six decimals or fewer (−199.99999 → `-199.99999°`, 22.25 → `22.25°`, −90 → `-90°`), else to
/// a thousandth of a degree at most, without trailing zeros (180.00000000000003 → `180°`, a
/// single-precision 180° read back as 179.9999950954438 → `180°`). Round an angle measured
/// more coarsely before (a matrix's turn to 0.1°, a held turn to 1°).
pub fn degrees(v: f64) -> String {
    let shortest = typed(v);
    let short = shortest
        .split_once('.')
        .is_none_or(|(_, decimals)| decimals.len() <= 6);
    let text = if v.is_finite() && short && !shortest.contains('e') {
        shortest
    } else {
        let text = format!("{v:.3}");
        match text.contains('.') {
            true => text.trim_end_matches('0').trim_end_matches('.').into(),
            false => text,
        }
    };
    match text.as_str() {
        "-0" => "0°".into(),
        t => format!("{t}°"),
    }
}

/// A count with its thousands grouped as people write it: 1255256001 → `1,255,256,001`.
pub fn count(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// A point's coordinates with the decimals that resolve `step`, as `(x, y, z)`.
pub fn point(p: &[f64], step: f64) -> String {
    let parts: Vec<String> = p.iter().map(|&v| to_step(v, step)).collect();
    format!("({})", parts.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_group_their_thousands() {
        assert_eq!(count(0), "0");
        assert_eq!(count(999), "999");
        assert_eq!(count(1000), "1,000");
        assert_eq!(count(1_255_256_001), "1,255,256,001");
    }

    #[test]
    fn lengths_carry_the_cells_precision() {
        assert_eq!(decimals(0.01), 2);
        assert_eq!(decimals(0.001), 3);
        assert_eq!(decimals(0.5), 1);
        assert_eq!(decimals(2.5), 0);
        assert_eq!(decimals(f64::NAN), 6);
        assert_eq!(length(11.570624999993015, 11.57), "11.57");
        assert_eq!(length(2.187449933092767, 2.187449933092767), "2.187");
        assert_eq!(length(2.0, 2.0), "2");
        assert_eq!(to_step(484639.54500000016, 0.001), "484639.545");
        assert_eq!(point(&[1.23456, -2.0], 0.01), "(1.23, -2.00)");
    }

    #[test]
    fn angles_read_as_typed() {
        assert_eq!(degrees(180.0f64.to_radians().to_degrees()), "180°");
        assert_eq!(degrees(179.9999950954438), "180°");
        assert_eq!(degrees(22.25), "22.25°");
        assert_eq!(degrees(-90.0), "-90°");
        assert_eq!(degrees(-0.0001), "-0.0001°");
        assert_eq!(degrees(-1e-8), "0°");
        assert_eq!(degrees(-199.99999), "-199.99999°");
        assert_eq!(degrees(1e-14), "0°");
        assert_eq!(degrees(720.0), "720°");
        assert_eq!(list(&[0.0, 0.5, -1.0, f64::NAN]), "[0, 0.5, -1, nan]");
    }

    #[test]
    fn figures_are_plain_to_three_digits() {
        assert_eq!(figure(37.396), "37.4");
        assert_eq!(figure(37.0), "37");
        assert_eq!(figure(0.012345), "0.0123");
        assert_eq!(figure(1641.2), "1641");
        assert_eq!(figure(9.9996), "10");
        assert_eq!(figure(0.0), "0");
        assert_eq!(figure(-2.5e-20), "0");
        assert_eq!(figure(-0.5), "-0.5");
        assert_eq!(length(0.0, 0.25), "0");
    }
}
