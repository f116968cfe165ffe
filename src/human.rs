//! Numbers printed for people carry the precision they were measured with, not the 17 digits
//! of a 64-bit float: a coordinate to its file's step (a LAS scale of 0.01 keeps two
//! decimals), a length the cells decided (a margin, a chosen cell size, a field's bounds) to a
//! thousandth of the finest cell.

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

/// A point's coordinates with the decimals that resolve `step`, as `(x, y, z)`.
pub fn point(p: &[f64], step: f64) -> String {
    let parts: Vec<String> = p.iter().map(|&v| to_step(v, step)).collect();
    format!("({})", parts.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
