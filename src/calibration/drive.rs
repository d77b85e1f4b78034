//! Driving the corner procedure from the device hub's snapshots, live or from a recorded
//! session, so the app, `leman calibrate` and the replay tests feed it the same way: each new
//! wand sample (a new arrival time in the wand role) becomes one [`WandInput`], its pose taken
//! through the profile's tracker frames (tracker to world, sensor to tip).

use super::frames::TrackerFrames;
use super::procedure::{CornerProcedure, ProcedureConfig, ProcedureEvent, Step, WandInput};
use crate::devices::hub::{DeviceState, HubSnapshot};
use crate::devices::profile::Role;
use crate::devices::replay::{ReplayError, Replayer};
use crate::devices::session::{Record, Session};
use std::time::Duration;

/// Turns successive hub snapshots into procedure inputs, each wand sample once.
#[derive(Debug, Clone, Default)]
pub struct SnapshotFeeder {
    last_at: Option<Duration>,
}

impl SnapshotFeeder {
    /// A feeder that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds the wand's newest sample in `snapshot` if it is new, its device is not lost and it
    /// is not the desktop mouse, bound to the wand or standing in for it
    /// ([`HubSnapshot::from_desktop`]: the mouse has no 3D position to touch a corner with);
    /// returns what the procedure made of it.
    pub fn feed(
        &mut self,
        procedure: &mut CornerProcedure,
        snapshot: &HubSnapshot,
        frames: &TrackerFrames,
    ) -> Option<ProcedureEvent> {
        let wand = snapshot.role(Role::Wand);
        let (Some(at), Some(pose)) = (wand.at, wand.pose) else {
            return None;
        };
        if wand.state == DeviceState::Lost
            || snapshot.from_desktop(Role::Wand)
            || self.last_at == Some(at)
        {
            return None;
        }
        self.last_at = Some(at);
        procedure.feed(WandInput {
            time: at,
            tip_world_m: frames.wand_tip_in_world_m(&pose),
            button_down: !wand.pressed.is_empty(),
        })
    }
}

/// What a replayed procedure did.
#[derive(Debug, Clone)]
pub struct ReplayOutcome {
    /// The procedure at the end (look at [`CornerProcedure::step`]).
    pub procedure: CornerProcedure,
    /// Every event with the session time of the sample that caused it.
    pub events: Vec<(Duration, ProcedureEvent)>,
}

/// Runs the corner procedure over a recorded session until it is accepted or the session ends.
pub fn run_on_session(
    session: Session,
    config: ProcedureConfig,
    frames: &TrackerFrames,
) -> Result<ReplayOutcome, ReplayError> {
    let mut events = Vec::new();
    let procedure = run_on_session_with(session, config, frames, |at, e, _| {
        events.push((at, e.clone()));
    })?;
    Ok(ReplayOutcome { procedure, events })
}

/// [`run_on_session`] calling `observer(session time, event, procedure after it)` for every
/// event as it happens (for narrating a replay).
pub fn run_on_session_with(
    session: Session,
    config: ProcedureConfig,
    frames: &TrackerFrames,
    mut observer: impl FnMut(Duration, &ProcedureEvent, &CornerProcedure),
) -> Result<CornerProcedure, ReplayError> {
    let mut replayer = Replayer::new(session)?;
    let mut procedure = CornerProcedure::new(config);
    let mut feeder = SnapshotFeeder::new();
    loop {
        let at = match replayer.step() {
            None => break,
            Some(Record::Chunk { at, .. } | Record::Desktop { at, .. }) => *at,
            Some(_) => continue,
        };
        let snapshot = replayer.snapshot(at);
        if let Some(e) = feeder.feed(&mut procedure, &snapshot, frames) {
            observer(at, &e, &procedure);
        }
        if matches!(procedure.step(), Step::Done(_)) {
            break;
        }
    }
    Ok(procedure)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::hub::RoleSample;
    use crate::pose::Pose;

    fn snapshot(stand_in: bool) -> HubSnapshot {
        let sample = |role| RoleSample {
            role,
            device: Some(0),
            pose: Some(Pose::IDENTITY),
            axes: [0.0; 6],
            pressed: vec![0],
            at: Some(Duration::from_millis(5)),
            state: DeviceState::Running,
            stand_in,
        };
        HubSnapshot {
            now: Duration::from_millis(5),
            roles: Role::ALL.map(sample),
            devices: Vec::new(),
        }
    }

    #[test]
    fn the_mouse_standing_in_for_a_lost_wand_touches_no_corner() {
        let frames = TrackerFrames::default();
        let mut procedure = CornerProcedure::new(ProcedureConfig::default());
        let mut feeder = SnapshotFeeder::new();
        assert_eq!(
            feeder.feed(&mut procedure, &snapshot(true), &frames),
            None,
            "ignored"
        );
        // The same sample from the wand's own tracker is taken (a press, too early to record).
        assert_eq!(
            feeder.feed(&mut procedure, &snapshot(false), &frames),
            Some(ProcedureEvent::PressIgnoredTooFewSamples { samples: 1 })
        );
    }

    #[test]
    fn a_wand_bound_to_the_desktop_mouse_touches_no_corner() {
        use crate::devices::desktop::DesktopEvent;
        use crate::devices::hub::HubState;
        use crate::devices::profile::Profile;
        let mut state = HubState::new(Profile::desktop_default());
        state.opened(0, Duration::ZERO);
        let press = DesktopEvent::MouseButton {
            button: 0,
            pressed: true,
        };
        assert!(state.desktop_event(Duration::from_millis(5), &press));
        let snapshot = state.snapshot(Duration::from_millis(5));
        let wand = snapshot.role(Role::Wand);
        assert!(!wand.stand_in && wand.pose.is_some() && !wand.pressed.is_empty());
        let mut procedure = CornerProcedure::new(ProcedureConfig::default());
        let mut feeder = SnapshotFeeder::new();
        assert_eq!(
            feeder.feed(&mut procedure, &snapshot, &TrackerFrames::default()),
            None
        );
    }
}
