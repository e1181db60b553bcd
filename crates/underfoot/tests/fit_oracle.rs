//! Oracle tests: a known stable filter is recovered from its sampled response.

use num_complex::Complex64;
use underfoot::fit::{FitConfig, MetricGrid, Target, fit_order};
use underfoot::signal::Sos;
use underfoot::signal::sos::{Biquad, RootPair};
use underfoot::units::{Band, Hz, SampleRate};

/// A stable order-`order` filter with resonances spread log-evenly from `f_lo` to `f_hi`
/// (the lowest exactly at `f_lo`), each with its own Q and a pair of zeros between resonances.
fn known_filter(order: usize, rate: SampleRate, f_lo: f64, f_hi: f64) -> Sos {
    let pairs = order / 2;
    let mut sections = Vec::new();
    for i in 0..pairs {
        let t = if pairs > 1 {
            i as f64 / (pairs - 1) as f64
        } else {
            0.0
        };
        let f = f_lo * (f_hi / f_lo).powf(t);
        let q = 4.0 + 6.0 * ((i * 7) % 5) as f64 / 4.0;
        let w = rate.omega(Hz(f));
        let r = (-w / (2.0 * q)).exp();
        let pole = Complex64::from_polar(r, w);
        // Zeros at 1.3x the resonance, less sharp, some outside the unit circle.
        let wz = rate.omega(Hz((f * 1.3).min(0.45 * rate.hz())));
        // Damping of a Q-of-2 resonance; odd sections put their zeros outside the circle.
        let sign = if i % 2 == 0 { -1.0 } else { 1.0 };
        let zero = Complex64::from_polar((sign * wz / 4.0).exp(), wz);
        let gain = if i == 0 { 0.7 } else { 1.0 };
        sections.push(Biquad::from_roots(
            RootPair::Conjugate(zero),
            RootPair::Conjugate(pole),
            gain,
        ));
    }
    if order % 2 == 1 {
        sections.push(Biquad::from_roots(
            RootPair::Single(-0.3),
            RootPair::Single(0.6),
            1.0,
        ));
    }
    Sos::new(sections)
}

fn recover(order: usize, rate: SampleRate, fit_band: Band, f_lo: f64, f_hi: f64) {
    let truth = known_filter(order, rate, f_lo, f_hi);
    assert!(truth.is_stable() && truth.order() == order);
    let freqs = fit_band.log_grid(400);
    let h: Vec<Complex64> = freqs
        .iter()
        .map(|&f| truth.response(rate.omega(f)))
        .collect();
    let target = Target::from_response(rate, &freqs, h.clone()).unwrap();
    let grid_freqs = fit_band.log_grid(96);
    let grid = MetricGrid {
        rate,
        measured: grid_freqs
            .iter()
            .map(|&f| truth.response(rate.omega(f)).norm())
            .collect(),
        freqs: grid_freqs,
    };
    let fit = fit_order(&target, &grid, order, &FitConfig::default()).unwrap();
    assert!(fit.sos.is_stable(), "order {order}: unstable fit");
    assert_eq!(fit.sos.order(), order);
    let worst = freqs
        .iter()
        .zip(&h)
        .map(|(&f, &hk)| (fit.sos.response(rate.omega(f)) - hk).norm() / hk.norm())
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-5,
        "order {order} at {rate}: worst relative error {worst:e} (method {}, lsd {} dB)",
        fit.method,
        fit.metrics.lsd_db
    );
    // The poles themselves are recovered.
    let mut want = truth.poles();
    let mut got = fit.sos.poles();
    let key = |p: &Complex64| (p.arg(), p.norm());
    want.retain(|p| p.norm() > 0.0);
    got.retain(|p| p.norm() > 0.0);
    want.sort_by(|a, b| key(a).partial_cmp(&key(b)).unwrap());
    got.sort_by(|a, b| key(a).partial_cmp(&key(b)).unwrap());
    assert_eq!(want.len(), got.len(), "order {order}: pole count");
    for (w, g) in want.iter().zip(&got) {
        assert!(
            (w - g).norm() < 1e-5,
            "order {order}: pole {g} should be {w}"
        );
    }
}

#[test]
fn recovers_known_filters_of_orders_2_to_16_at_the_analysis_rate() {
    for order in 2..=16 {
        recover(order, SampleRate(2000), Band::new(5.0, 990.0), 30.0, 800.0);
    }
}

#[test]
fn recovers_known_filters_with_a_40_hz_resonance_at_48_khz() {
    for order in [2, 4, 7, 10, 13, 16] {
        recover(
            order,
            SampleRate(48_000),
            Band::new(10.0, 23_000.0),
            40.0,
            12_000.0,
        );
    }
}
