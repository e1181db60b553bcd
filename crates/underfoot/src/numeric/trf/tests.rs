use super::*;

/// `y = a e^{-b t} + c`, with its analytic Jacobian.
struct Decay {
    t: Vec<f64>,
    y: Vec<f64>,
    analytic: bool,
}

impl LeastSquares for Decay {
    fn residual_count(&self) -> usize {
        self.t.len()
    }
    fn residuals(&self, x: &[f64], r: &mut [f64]) {
        for ((ri, t), y) in r.iter_mut().zip(&self.t).zip(&self.y) {
            *ri = x[0] * (-x[1] * t).exp() + x[2] - y;
        }
    }
    fn jacobian(&self, x: &[f64], j: &mut DMatrix<f64>) -> bool {
        if !self.analytic {
            return false;
        }
        for (i, t) in self.t.iter().enumerate() {
            let e = (-x[1] * t).exp();
            j[(i, 0)] = e;
            j[(i, 1)] = -x[0] * t * e;
            j[(i, 2)] = 1.0;
        }
        true
    }
}

fn decay(analytic: bool) -> Decay {
    let t: Vec<f64> = (0..40).map(|i| f64::from(i) * 0.1).collect();
    let y = t.iter().map(|t| 2.5 * (-1.3 * t).exp() + 0.4).collect();
    Decay { t, y, analytic }
}

#[test]
fn recovers_exponential_decay_exactly() {
    for analytic in [true, false] {
        let p = decay(analytic);
        let sol = least_squares_bounded(
            &p,
            &[1.0, 0.5, 0.0],
            &[0.0, 0.0, -10.0],
            &[10.0, 10.0, 10.0],
            &TrfOptions::default(),
        )
        .unwrap();
        eprintln!(
            "decay (analytic {analytic}): x = {:?}, cost {:.2e}, {} iterations, {:?}",
            sol.x, sol.cost, sol.iterations, sol.status
        );
        for (got, want) in sol.x.iter().zip([2.5, 1.3, 0.4]) {
            assert!((got - want).abs() < 1e-7, "{got} vs {want}");
        }
        assert!(sol.cost < 1e-18);
        assert_ne!(sol.status, TrfStatus::MaxIterations);
    }
}

fn rosenbrock() -> FnResiduals<impl Fn(&[f64], &mut [f64])> {
    FnResiduals {
        m: 2,
        f: |x: &[f64], r: &mut [f64]| {
            r[0] = 10.0 * (x[1] - x[0] * x[0]);
            r[1] = 1.0 - x[0];
        },
    }
}

#[test]
fn optimum_on_a_bound_satisfies_kkt() {
    // x1 <= 0.5 excludes (1, 1); the constrained optimum is (≈0.7071, 0.5).
    let p = rosenbrock();
    let lo = [-2.0, -1.0];
    let hi = [2.0, 0.5];
    let sol = least_squares_bounded(&p, &[-1.2, 0.0], &lo, &hi, &TrfOptions::default()).unwrap();
    eprintln!(
        "bounded rosenbrock: x = {:?}, g = {:?}, {} iterations, {:?}",
        sol.x, sol.gradient, sol.iterations, sol.status
    );
    assert!((sol.x[1] - 0.5).abs() < 1e-6, "{:?}", sol.x);
    assert!(sol.x[1] < 0.5, "strictly interior");
    // On the upper bound the gradient of the cost must point out of the box's interior
    // (g < 0: decreasing x1 would raise the cost), and vanish in the free component.
    assert!(sol.gradient[1] < -1e-3, "{:?}", sol.gradient);
    assert!(sol.gradient[0].abs() < 1e-6, "{:?}", sol.gradient);
    // The free component's optimum along x1 = 0.5: d/dx0 of the cost is zero.
    let x0 = sol.x[0];
    let grad0 = -400.0 * x0 * (0.5 - x0 * x0) - 2.0 * (1.0 - x0);
    assert!(grad0.abs() < 1e-5, "{grad0}");

    // Lower bound active: x0 >= 1.2 excludes (1, 1).
    let sol = least_squares_bounded(
        &p,
        &[1.5, 2.0],
        &[1.2, -5.0],
        &[3.0, 5.0],
        &TrfOptions::default(),
    )
    .unwrap();
    assert!((sol.x[0] - 1.2).abs() < 1e-6, "{:?}", sol.x);
    assert!(sol.gradient[0] > 1e-3 && sol.gradient[1].abs() < 1e-6);
    assert!((sol.x[1] - 1.44).abs() < 1e-5, "{:?}", sol.x);
}

#[test]
fn unconstrained_rosenbrock_converges() {
    let p = rosenbrock();
    let inf = f64::INFINITY;
    let sol = least_squares_bounded(
        &p,
        &[-1.2, 1.0],
        &[-inf, -inf],
        &[inf, inf],
        &Default::default(),
    )
    .unwrap();
    assert!((sol.x[0] - 1.0).abs() < 1e-8 && (sol.x[1] - 1.0).abs() < 1e-8);
}

#[test]
fn malformed_problems_are_errors() {
    let p = rosenbrock();
    let o = TrfOptions::default();
    assert!(matches!(
        least_squares_bounded(&p, &[3.0, 0.0], &[-2.0, -1.0], &[2.0, 1.0], &o),
        Err(TrfError::Infeasible { index: 0, .. })
    ));
    assert!(matches!(
        least_squares_bounded(&p, &[0.0, 0.0], &[1.0, -1.0], &[1.0, 1.0], &o),
        Err(TrfError::InvalidBounds { index: 0, .. })
    ));
    assert!(matches!(
        least_squares_bounded(&p, &[0.0], &[-1.0, -1.0], &[1.0, 1.0], &o),
        Err(TrfError::Dimension { .. })
    ));
    assert!(matches!(
        least_squares_bounded(&p, &[f64::NAN, 0.0], &[-1.0, -1.0], &[1.0, 1.0], &o),
        Err(TrfError::Infeasible { .. })
    ));
    let bad = TrfOptions {
        ftol: f64::NAN,
        ..o
    };
    assert!(least_squares_bounded(&p, &[0.0, 0.0], &[-1.0, -1.0], &[1.0, 1.0], &bad).is_err());
    // A start on a bound is moved inside, not refused.
    let sol = least_squares_bounded(&p, &[2.0, 0.5], &[-2.0, -1.0], &[2.0, 0.5], &o).unwrap();
    assert!((sol.x[1] - 0.5).abs() < 1e-6);
}

#[test]
fn non_finite_residuals_are_errors() {
    let nan = FnResiduals {
        m: 3,
        f: |_: &[f64], r: &mut [f64]| r.fill(f64::NAN),
    };
    assert_eq!(
        least_squares_bounded(&nan, &[0.5], &[0.0], &[1.0], &TrfOptions::default()),
        Err(TrfError::NonFinite {
            what: "residual vector"
        })
    );
    // Finite at the start, NaN beyond x > 0.6: the search retreats and still ends well.
    let cliff = FnResiduals {
        m: 1,
        f: |x: &[f64], r: &mut [f64]| {
            r[0] = if x[0] > 0.6 { f64::NAN } else { x[0] - 2.0 };
        },
    };
    let sol = least_squares_bounded(&cliff, &[0.1], &[0.0], &[10.0], &TrfOptions::default());
    match sol {
        Ok(s) => assert!(s.x[0] <= 0.6 && s.cost.is_finite()),
        Err(e) => assert!(matches!(
            e,
            TrfError::Numerical(_) | TrfError::NonFinite { .. }
        )),
    }
}
