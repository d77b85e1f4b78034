//! Parameter changes from the workstation's panels, sliders and scripts, with hostile values:
//! each is applied between short advances of a small running character and must either be
//! refused as a bad parameter or taken; whatever is taken, the simulator
//! never panics, never lets a non-finite position out, and never spins without progress.

use leman::character::{Posture, Sym2, examples};
use leman::sim::surface::SurfaceModel;
use leman::sim::{
    AdvanceEnd, DeformationModel, FixedPosture, IntegratorKind, MaxAttempts, ParameterChange,
    Selection, SimError, Tolerances,
};
use proptest::prelude::*;

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
        (v(), v(), v()),
    )
        .prop_map(|((a, b, c, d), (e, f, g, h), (i, j, k))| Tolerances {
            fixed_step_s: a,
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

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    #[test]
    fn hostile_parameter_changes_are_refused_or_run_finite(
        changes in prop::collection::vec(change(), 1..6),
    ) {
        let c = examples::build("wombat", 8, 6).expect("the wombat example");
        let neutral = Posture::neutral(&c.skeleton);
        let mut model = SurfaceModel::new(c, IntegratorKind::Verlet).expect("it simulates");
        let mut poses = FixedPosture(neutral);
        let mut target = 0.0;
        for change in &changes {
            match model.apply(change) {
                Ok(()) => {}
                Err(SimError::BadParameter(message)) => prop_assert!(!message.is_empty()),
                Err(other) => prop_assert!(false, "{change:?}: not a bad-parameter error: {other}"),
            }
            target += 0.01;
            let report = model.advance(target, &mut poses, &mut MaxAttempts(300), None);
            prop_assert!(
                report.end != AdvanceEnd::BudgetSpent || report.steps > 0,
                "after {change:?}: attempts without progress: {report:?}"
            );
            for p in model.positions_m() {
                prop_assert!(p.is_finite(), "after {change:?}: a non-finite position");
            }
        }
    }
}
