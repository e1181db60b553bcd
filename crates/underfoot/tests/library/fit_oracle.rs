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

/// A filter with one resonance of e-fold decay `tau` at `f0` and a broad one at 300 Hz.
fn ringing(rate: SampleRate, f0: f64, tau: f64) -> Sos {
    let pole = |f: f64, tau: f64| {
        Complex64::from_polar((-1.0 / (tau * rate.hz())).exp(), rate.omega(Hz(f)))
    };
    Sos::new(vec![
        Biquad::from_roots(
            RootPair::Conjugate(Complex64::from_polar(0.7, rate.omega(Hz(f0 * 1.5)))),
            RootPair::Conjugate(pole(f0, tau)),
            0.5,
        ),
        Biquad::from_roots(
            RootPair::Conjugate(Complex64::from_polar(0.5, rate.omega(Hz(600.0)))),
            RootPair::Conjugate(pole(300.0, 0.01)),
            1.0,
        ),
    ])
}

fn fit_of(truth: &Sos, rate: SampleRate, band: Band) -> underfoot::fit::OrderFit {
    let freqs = band.log_grid(400);
    let h = freqs
        .iter()
        .map(|&f| truth.response(rate.omega(f)))
        .collect();
    let target = Target::from_response(rate, &freqs, h).unwrap();
    let grid_freqs = band.log_grid(96);
    let grid = MetricGrid {
        rate,
        measured: grid_freqs
            .iter()
            .map(|&f| truth.response(rate.omega(f)).norm())
            .collect(),
        freqs: grid_freqs,
    };
    fit_order(&target, &grid, truth.order(), &FitConfig::default()).unwrap()
}

/// A resonance that decays within the limit (0.3 s against 0.5 s) is recovered exactly:
/// the limit is a bound, not a bias.
#[test]
fn a_decay_inside_the_limit_is_recovered_exactly() {
    let rate = SampleRate(2000);
    let truth = ringing(rate, 40.0, 0.3);
    let fit = fit_of(&truth, rate, Band::new(10.0, 990.0));
    let slowest = fit.sos.poles().iter().map(|p| p.norm()).fold(0.0, f64::max);
    let want = (-1.0 / (0.3 * rate.hz())).exp();
    assert!((slowest - want).abs() < 1e-7, "{slowest} vs {want}");
}

/// A resonance that rings far longer than the limit (20 s) is fitted with every pole inside
/// the limit's radius: the search never leaves it, so nothing is pulled in afterwards.
#[test]
fn no_fitted_pole_rings_longer_than_the_limit() {
    let rate = SampleRate(2000);
    let cfg = FitConfig::default();
    let rho = underfoot::fit::decay_radius(rate, cfg.longest_decay);
    for f0 in [17.5, 40.0, 120.0] {
        let truth = ringing(rate, f0, 20.0);
        let fit = fit_of(&truth, rate, Band::new(10.0, 990.0));
        for p in fit.sos.poles() {
            assert!(
                p.norm() < rho,
                "{f0} Hz: pole {p} of radius {} > {rho}",
                p.norm()
            );
        }
        // It still finds the resonance, as sharp as the limit allows.
        let slowest = fit
            .sos
            .poles()
            .into_iter()
            .max_by(|a, b| a.norm().total_cmp(&b.norm()))
            .unwrap();
        let at = slowest.arg().abs() * rate.hz() / std::f64::consts::TAU;
        assert!(
            (at - f0).abs() < 0.05 * f0,
            "{f0} Hz: slowest pole at {at} Hz"
        );
        assert!(slowest.norm() > rho.powi(2), "{f0} Hz: {slowest}");
    }
}
