use super::*;

/// `x'' = −ω² x − c x'` on `n` independent copies.
struct Oscillator {
    omega: f32,
    c: f32,
    n: usize,
}

impl SecondOrderSystem for Oscillator {
    fn dofs(&self) -> usize {
        self.n
    }
    fn position_accel(&mut self, _t: f64, x: &[f32], a: &mut [f32]) {
        for (a, x) in a.iter_mut().zip(x) {
            *a = -self.omega * self.omega * x;
        }
    }
    fn add_velocity_accel(&mut self, _t: f64, _x: &[f32], v: &[f32], a: &mut [f32]) {
        for (a, v) in a.iter_mut().zip(v) {
            *a -= self.c * v;
        }
    }
    fn has_velocity_forces(&self) -> bool {
        self.c != 0.0
    }
}

/// Exact solution of the damped oscillator with x(0)=1, x'(0)=0 (underdamped).
fn exact(omega: f64, c: f64, t: f64) -> f64 {
    let zeta_omega = 0.5 * c;
    let omega_d = (omega * omega - zeta_omega * zeta_omega).sqrt();
    (-zeta_omega * t).exp() * ((omega_d * t).cos() + zeta_omega / omega_d * (omega_d * t).sin())
}

/// Its velocity.
fn exact_velocity(omega: f64, c: f64, t: f64) -> f64 {
    let zeta_omega = 0.5 * c;
    let omega_d = (omega * omega - zeta_omega * zeta_omega).sqrt();
    -(-zeta_omega * t).exp() * (omega_d + zeta_omega * zeta_omega / omega_d) * (omega_d * t).sin()
}

/// Tolerances that force a fixed step `h` for every method.
fn fixed_step(h: f64) -> Tolerances {
    Tolerances {
        fixed_step_s: h,
        min_step_s: h,
        max_step_s: h,
        velocity_tolerance: 1e-7,
        max_velocity_iterations: 50,
        ..Tolerances::default()
    }
}

fn error_at(kind: IntegratorKind, h: f64, c: f32, t_end: f64) -> f64 {
    let mut sys = Oscillator {
        omega: 1.0,
        c,
        n: 1,
    };
    let mut integ = Integrator::new(kind, fixed_step(h));
    let mut x = [1.0f32];
    let mut v = [0.0f32];
    integrate(&mut integ, &mut sys, 0.0, t_end, &mut x, &mut v);
    let ex = f64::from(x[0]) - exact(1.0, f64::from(c), t_end);
    let ev = f64::from(v[0]) - exact_velocity(1.0, f64::from(c), t_end);
    ex.hypot(ev)
}

/// Observed order from errors with `steps`, 2×`steps` and 4×`steps` equal steps up to
/// t = 2.3 s (not a whole period, 2π s): the mean of the two ratios' log2.
fn observed_order(kind: IntegratorKind, steps: u32, c: f32) -> f64 {
    let t_end = 2.3;
    let h = t_end / f64::from(steps);
    let e1 = error_at(kind, h, c, t_end);
    let e2 = error_at(kind, h / 2.0, c, t_end);
    let e3 = error_at(kind, h / 4.0, c, t_end);
    ((e1 / e2).log2() + (e2 / e3).log2()) / 2.0
}

#[test]
fn euler_is_first_order() {
    let p = observed_order(IntegratorKind::Euler, 100, 0.0);
    assert!((0.85..1.15).contains(&p), "Euler order {p}");
    let p = observed_order(IntegratorKind::Euler, 100, 0.3);
    assert!((0.85..1.15).contains(&p), "damped Euler order {p}");
}

#[test]
fn verlet_is_second_order_with_and_without_velocity_forces() {
    let p = observed_order(IntegratorKind::Verlet, 40, 0.0);
    assert!((1.85..2.15).contains(&p), "Verlet order {p}");
    let p = observed_order(IntegratorKind::Verlet, 40, 0.3);
    assert!((1.85..2.15).contains(&p), "damped Verlet order {p}");
}

#[test]
fn rk2_is_second_order() {
    let p = observed_order(IntegratorKind::Rk2, 40, 0.3);
    assert!((1.85..2.15).contains(&p), "RK2 order {p}");
}

#[test]
fn rk4_is_fourth_order() {
    // Large steps so the f32 round-off floor stays far below the truncation error.
    let p = observed_order(IntegratorKind::Rk4, 4, 0.3);
    assert!((3.7..4.3).contains(&p), "RK4 order {p}");
}

fn energy(x: f32, v: f32, omega: f32) -> f32 {
    0.5 * v * v + 0.5 * omega * omega * x * x
}

#[test]
fn verlet_energy_stays_bounded_while_euler_grows_it() {
    let omega = 1.0;
    let h = 0.1;
    let run = |kind| {
        let mut sys = Oscillator {
            omega,
            c: 0.0,
            n: 1,
        };
        let mut integ = Integrator::new(kind, fixed_step(h));
        let (mut x, mut v) = ([1.0f32], [0.0f32]);
        let e0 = energy(x[0], v[0], omega);
        let mut max_dev = 0.0f32;
        let mut xn = [0.0f32];
        let mut vn = [0.0f32];
        for i in 0..10_000 {
            let p = integ.propose(&mut sys, i as f64 * h, h, &x, &v, &mut xn, &mut vn);
            assert!(p.accepted);
            x = xn;
            v = vn;
            max_dev = max_dev.max((energy(x[0], v[0], omega) / e0 - 1.0).abs());
        }
        (max_dev, energy(x[0], v[0], omega) / e0)
    };
    let (verlet_dev, _) = run(IntegratorKind::Verlet);
    assert!(verlet_dev < 0.01, "Verlet energy drifted by {verlet_dev}");
    let (_, euler_final) = run(IntegratorKind::Euler);
    // (1 + h²ω²)^n per step: grows enormously.
    assert!(euler_final > 100.0, "Euler energy ratio {euler_final}");
}

fn verlet_amplitude_after(h_omega: f32, steps: usize) -> f32 {
    let omega = 10.0f32;
    let h = f64::from(h_omega / omega);
    let mut sys = Oscillator {
        omega,
        c: 0.0,
        n: 1,
    };
    let mut integ = Integrator::new(IntegratorKind::Verlet, fixed_step(h));
    let (mut x, mut v) = ([1.0f32], [0.0f32]);
    let (mut xn, mut vn) = ([0.0f32], [0.0f32]);
    let mut max_abs = 0.0f32;
    for i in 0..steps {
        integ.propose(&mut sys, i as f64 * h, h, &x, &v, &mut xn, &mut vn);
        x = xn;
        v = vn;
        max_abs = max_abs.max(x[0].abs());
        if !max_abs.is_finite() {
            return f32::INFINITY;
        }
    }
    max_abs
}

#[test]
fn verlet_is_stable_below_h_omega_2_and_unstable_above() {
    for h_omega in [0.5f32, 1.0, 1.5, 1.9, 1.98] {
        let amp = verlet_amplitude_after(h_omega, 5000);
        // Leapfrog keeps |x| bounded by a constant depending on hω (≤ 1/sqrt(1 − (hω/2)²)).
        let bound = 1.0 / (1.0 - (h_omega / 2.0).powi(2)).sqrt() * 1.05;
        assert!(amp <= bound, "hω={h_omega}: amplitude {amp} > {bound}");
    }
    for h_omega in [2.02f32, 2.2, 3.0] {
        let amp = verlet_amplitude_after(h_omega, 2000);
        assert!(amp > 1e6, "hω={h_omega}: amplitude {amp} should blow up");
    }
}

#[test]
fn adaptive_methods_meet_tighter_tolerances_with_smaller_steps() {
    for kind in [IntegratorKind::Verlet, IntegratorKind::Rk2] {
        let mut errs = Vec::new();
        let mut steps = Vec::new();
        for tol in [1e-3, 1e-4, 1e-5] {
            let mut sys = Oscillator {
                omega: 1.0,
                c: 0.3,
                n: 1,
            };
            let t = Tolerances {
                fixed_step_s: 0.5,
                min_step_s: 1e-4,
                max_step_s: 1.0,
                position_tolerance: tol,
                velocity_tolerance: 1e-7,
                max_velocity_iterations: 50,
                ..Tolerances::default()
            };
            let mut integ = Integrator::new(kind, t);
            let (mut x, mut v) = ([1.0f32], [0.0f32]);
            let s = integrate(&mut integ, &mut sys, 0.0, 2.3, &mut x, &mut v);
            assert!(
                s.rejected > 0,
                "{kind:?}: an initial 0.5 s step must be rejected"
            );
            errs.push((f64::from(x[0]) - exact(1.0, 0.3, 2.3)).abs());
            steps.push(s.accepted);
        }
        assert!(errs[2] < errs[0], "{kind:?}: errors {errs:?}");
        assert!(
            steps[0] < steps[1] && steps[1] < steps[2],
            "{kind:?}: steps {steps:?}"
        );
    }
}

#[test]
fn length_mismatch_is_rejected_not_a_panic() {
    let mut sys = Oscillator {
        omega: 1.0,
        c: 0.0,
        n: 2,
    };
    let mut integ = Integrator::new(IntegratorKind::Verlet, Tolerances::default());
    let (x, v) = ([1.0f32], [0.0f32]);
    let (mut xn, mut vn) = ([0.0f32], [0.0f32]);
    let p = integ.propose(&mut sys, 0.0, 0.01, &x, &v, &mut xn, &mut vn);
    assert!(!p.accepted);
}

#[test]
fn names_round_trip() {
    for k in IntegratorKind::ALL {
        assert_eq!(IntegratorKind::from_name(k.name()), Some(k));
    }
    assert_eq!(IntegratorKind::from_name("leapfrog"), None);
}
