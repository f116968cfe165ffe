//! Tests of the exact layer's band profile and kernel.

use super::*;

#[test]
fn smooth_step_is_c2() {
    assert_eq!(smooth(0.0), 0.0);
    assert_eq!(smooth(1.0), 1.0);
    let d = |t: f64| 30.0 * t * t * (1.0 - t) * (1.0 - t);
    assert_eq!(d(0.0), 0.0);
    assert_eq!(d(1.0), 0.0);
    let e = 1e-6;
    assert!(((smooth(0.5 + e) - smooth(0.5 - e)) / (2.0 * e) - d(0.5)).abs() < 1e-6);
}

#[test]
fn the_smoothstep_inverts() {
    for k in 0..=1000 {
        let t = k as f64 / 1000.0;
        assert!((smooth_inverse(smooth(t)) - t).abs() < 1e-9, "at {t}");
    }
}

/// The band's profile: 0 at the region, 1 at the band's end, rising, with zero slope at
/// both ends, and a field that leads the region by its head start taken up at a rate at
/// most 1.35 times its own (`((u + a) σ)' ≤ 1.35`; the smoothstep's peaks at 2.1).
#[test]
fn the_band_takes_the_field_up_at_a_steady_rate() {
    let sigma = |u: f64| fall(smooth(u));
    assert_eq!(sigma(0.0), 0.0);
    assert_eq!(sigma(1.0), 1.0);
    let h = 1e-5;
    let slope = |f: &dyn Fn(f64) -> f64, u: f64| (f(u + h) - f(u - h)) / (2.0 * h);
    assert!(slope(&sigma, h).abs() < 1e-3 && slope(&sigma, 1.0 - h).abs() < 1e-3);
    let rate = |f: &dyn Fn(f64) -> f64| {
        let mut last = 0.0;
        let mut peak = 0.0f64;
        for k in 1..1000 {
            let u = k as f64 / 1000.0;
            assert!(f(u) >= last, "falls back at {u}");
            last = f(u);
            peak = peak.max(slope(&|u| (u + HEAD_START) * f(u), u));
        }
        peak
    };
    let peak = rate(&sigma);
    assert!(
        peak > 1.0 && peak <= 1.35,
        "takes the field up {peak} times faster"
    );
    assert!(rate(&smooth) > 2.0);
}

/// The band of a region with a border: the transfer leads the region's map, where it meets the
/// region, by anything from nothing to a whole cell's step (the last prescribed center lies
/// between the border and a cell inside it). The profile is made for the whole cell's lead:
/// over four cells the map takes any of these leads up at most 1.34 times as fast as the field
/// (1.26 for none); over two it would reach 1.61.
#[test]
fn a_shapes_band_takes_up_any_lead_of_up_to_a_cell() {
    let h = 1e-5;
    let peak = |cells: f64, lead: f64| {
        let a = 1.0 / cells;
        let taken = |u: f64| (u + lead / cells) * profile(u, a);
        (1..1000)
            .map(|k| k as f64 / 1000.0)
            .map(|u| (taken(u + h) - taken(u - h)) / (2.0 * h))
            .fold(0.0f64, f64::max)
    };
    for lead in [0.0, 0.25, 0.5, 0.75, 1.0] {
        let p = peak(SHAPE_BAND, lead);
        assert!(p <= 1.34, "a lead of {lead} cell: {p}");
    }
    assert!(peak(2.0, 1.0) > 1.55);
}
