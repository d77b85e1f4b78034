//! What the workstation does to a running model between frames, with hostile values: parameter
//! changes from its panels, sliders and scripts (each must be refused as a bad parameter or
//! taken), resolution changes (taken exactly when valid) and snapshots restored after an
//! advance (the same time and skin again). Whatever is taken, the simulator never panics,
//! never lets a non-finite position out, and never spins without progress.

use leman::character::{Posture, Sym2, examples};
use leman::sim::surface::SurfaceModel;
use leman::sim::{
    AdvanceEnd, DeformationModel, FixedPosture, IntegratorKind, MaxAttempts, ParameterChange,
    Selection, SimError, Tolerances,
};
use proptest::prelude::*;

mod common;

/// Values that break naive code, and ordinary ones so that some changes are taken.
fn value() -> impl Strategy<Value = f32> {
    prop_oneof![
        3 => prop::sample::select(vec![
            0.0f32,
            -0.0,
            -1.0,
            1e-30,
            1e-8,
            1e30,
            f32::MAX,
            f32::MIN_POSITIVE,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ]),
        2 => 1e-3f32..10.0,
    ]
}

fn sym2() -> impl Strategy<Value = Sym2> {
    [value(), value(), value()]
}

/// All points, or a few indices, some of them past the end.
fn selection() -> impl Strategy<Value = Selection> {
    prop_oneof![
        Just(Selection::All),
        prop::collection::vec(prop_oneof![0u32..48, Just(u32::MAX), 48u32..100], 0..4)
            .prop_map(Selection::Some),
    ]
}

fn tolerances() -> impl Strategy<Value = Tolerances> {
    let v = || value().prop_map(f64::from);
    (
        (v(), v(), v(), v()),
        (
            v(),
            v(),
            v(),
            prop_oneof![Just(0u32), Just(1), Just(u32::MAX)],
        ),
        (v(), v(), v(), v()),
    )
        .prop_map(|((a, b, c, d), (e, f, g, h), (i, j, k, l))| Tolerances {
            euler_step_s: a,
            rk4_step_s: l,
            min_step_s: b,
            max_step_s: c,
            position_tolerance: d,
            velocity_tolerance: e,
            position_threshold_m: f,
            velocity_threshold_m_per_s: g,
            max_velocity_iterations: h,
            safety: i,
            max_growth: j,
            max_shrink: k,
        })
}

fn change() -> impl Strategy<Value = ParameterChange> {
    prop_oneof![
        (selection(), sym2()).prop_map(|(s, v)| ParameterChange::Stretch(s, v)),
        (selection(), sym2()).prop_map(|(s, v)| ParameterChange::Bending(s, v)),
        (selection(), value()).prop_map(|(s, v)| ParameterChange::RestMetricScale(s, v)),
        (selection(), value()).prop_map(|(s, v)| ParameterChange::Mass(s, v)),
        (selection(), value()).prop_map(|(s, v)| ParameterChange::Damping(s, v)),
        (selection(), value()).prop_map(|(s, v)| ParameterChange::Fat(s, v)),
        (selection(), value()).prop_map(|(s, v)| ParameterChange::TissueStiffness(s, v)),
        (selection(), value()).prop_map(|(s, v)| ParameterChange::TissueDamping(s, v)),
        (value(), value(), value())
            .prop_map(|(x, y, z)| ParameterChange::Gravity(glam::Vec3::new(x, y, z))),
        (value(), value()).prop_map(|(k_parallel, k_perpendicular)| {
            ParameterChange::Contact {
                k_parallel,
                k_perpendicular,
            }
        }),
        value().prop_map(ParameterChange::ConstraintTolerance),
        value().prop_map(ParameterChange::RecheckFraction),
        any::<bool>().prop_map(ParameterChange::HoldContacts),
        prop_oneof![
            Just(IntegratorKind::Euler),
            Just(IntegratorKind::Verlet),
            Just(IntegratorKind::Rk2),
            Just(IntegratorKind::Rk4),
        ]
        .prop_map(ParameterChange::Integrator),
        tolerances().prop_map(ParameterChange::Tolerances),
    ]
}

/// What the workstation does to a running model between frames.
#[derive(Debug, Clone)]
enum Action {
    /// A panel, slider or script change.
    Change(ParameterChange),
    /// The skin resolution changed (`--adapt` or the panel), possibly to an invalid one.
    Resolution(u32, u32),
    /// A snapshot taken now, and restored after the next advance (undo, or a replayed edit).
    SnapshotThenRestore,
}

fn action() -> impl Strategy<Value = Action> {
    prop_oneof![
        8 => change().prop_map(Action::Change),
        1 => (0u32..20, 0u32..20).prop_map(|(a, b)| Action::Resolution(a, b)),
        1 => Just(Action::SnapshotThenRestore),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(common::cases_or(500)))]

    #[test]
    fn hostile_workstation_actions_are_refused_or_run_finite(
        actions in prop::collection::vec(action(), 1..6),
    ) {
        let c = examples::build("wombat", 8, 6).expect("the wombat example");
        let neutral = Posture::neutral(&c.skeleton);
        let mut model = SurfaceModel::new(c, IntegratorKind::Verlet).expect("it simulates");
        let mut poses = FixedPosture(neutral);
        let mut target = 0.0;
        for action in &actions {
            let mut restore = None;
            match action {
                Action::Change(change) => match model.apply(change) {
                    Ok(()) => {}
                    Err(SimError::BadParameter(message)) => prop_assert!(!message.is_empty()),
                    Err(other) => {
                        prop_assert!(false, "{change:?}: not a bad-parameter error: {other}")
                    }
                },
                Action::Resolution(around, along) => {
                    let valid = (3..=1024).contains(around) && (3..=1024).contains(along);
                    let result = model.set_resolution(*around, *along);
                    prop_assert_eq!(result.is_ok(), valid, "{:?}", result);
                    if valid {
                        prop_assert_eq!(model.resolution(), (*around, *along));
                    }
                }
                Action::SnapshotThenRestore => {
                    restore = Some((model.snapshot(), model.time_s(), model.positions_m()));
                }
            }
            target += 0.01;
            let report = model.advance(target, &mut poses, &mut MaxAttempts(300), None);
            prop_assert!(
                report.end != AdvanceEnd::BudgetSpent || report.steps > 0,
                "after {action:?}: attempts without progress: {report:?}"
            );
            for p in model.positions_m() {
                prop_assert!(p.is_finite(), "after {action:?}: a non-finite position");
            }
            if let Some((snapshot, time_s, positions)) = restore {
                let restored = model.restore(&snapshot);
                prop_assert!(restored.is_ok(), "{:?}", restored.err());
                prop_assert_eq!(model.time_s(), time_s);
                prop_assert!(model.positions_m() == positions, "the restored skin differs");
                target = time_s;
            }
        }
    }
}
