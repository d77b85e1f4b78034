//! The corner-touching procedure as a pure state machine, shared by the app's calibrate tool and
//! `leman calibrate`. It is driven by wand samples (tip position in the world, button state,
//! timestamp) and a few commands (accept, redo); it reads no clock and does no I/O.
//!
//! For each corner in turn: prompt; wait for a button press (a press is the button going down)
//! while the wand is still; record the tip positions of the stillness window before the press as
//! that corner's samples; go on. After the last corner: fit and review. In review, a button
//! press (or [`CornerProcedure::accept`]) accepts a good fit, and restarts from the first corner
//! after a failed one; [`CornerProcedure::redo`] re-takes one corner.
//!
//! "Still" means: over the last `still_window`, the tip's least-squares velocity is at most
//! `still_speed_m_per_s` and every sample lies within `still_radius_m` of the window's mean.

use super::fit::{CornerSamples, FitError, FitOptions, ScreenFit, fit_screen};
use super::frames::TrackerFrames;
use super::screen::Corner;
use crate::devices::sample::PoseSample;
use glam::Vec3;
use std::collections::VecDeque;
use std::time::Duration;

/// Tunables of the procedure.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcedureConfig {
    /// Corners to touch, in order (at least three; normally [`Corner::ALL`]).
    pub corners: Vec<Corner>,
    /// The stillness window before a press; its samples become the corner's samples.
    pub still_window: Duration,
    /// Largest tip speed that counts as still (m/s).
    pub still_speed_m_per_s: f32,
    /// Largest distance from the window's mean that counts as still (m).
    pub still_radius_m: f32,
    /// Fewest samples the window must hold.
    pub min_samples: usize,
    /// Tolerances for the fit.
    pub fit: FitOptions,
}

impl Default for ProcedureConfig {
    fn default() -> Self {
        Self {
            corners: Corner::ALL.to_vec(),
            still_window: Duration::from_millis(300),
            still_speed_m_per_s: 0.02,
            still_radius_m: 0.004,
            min_samples: 5,
            fit: FitOptions::default(),
        }
    }
}

/// One wand sample as the procedure needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WandInput {
    /// When the sample was taken (session or clock time).
    pub time: Duration,
    /// The wand tip in the world frame, metres.
    pub tip_world_m: Vec3,
    /// Whether the wand's button is held.
    pub button_down: bool,
}

impl WandInput {
    /// From a decoded tracker sample: the tip through the tracker frames; the button is down
    /// when any button is held on the station.
    pub fn from_pose_sample(time: Duration, sample: &PoseSample, frames: &TrackerFrames) -> Self {
        Self {
            time,
            tip_world_m: frames.wand_tip_in_world_m(&sample.pose),
            button_down: !sample.pressed.is_empty(),
        }
    }
}

/// Where the procedure is.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Waiting for the wand to touch this corner (index into the configured order).
    Touch {
        /// The corner.
        corner: Corner,
        /// Its position in the order (0-based).
        index: usize,
    },
    /// All corners recorded: the fit (or why it failed), waiting for accept or redo.
    Review(Result<ScreenFit, FitError>),
    /// Accepted.
    Done(ScreenFit),
}

/// What a sample or command did.
#[derive(Debug, Clone, PartialEq)]
pub enum ProcedureEvent {
    /// A press was ignored because the wand was moving.
    PressIgnoredMoving {
        /// Estimated tip speed (m/s).
        speed_m_per_s: f32,
        /// Largest distance from the window mean (m).
        spread_m: f32,
    },
    /// A press was ignored because too few samples had arrived in the window.
    PressIgnoredTooFewSamples {
        /// Samples in the window.
        samples: usize,
    },
    /// A non-finite tip position was ignored.
    SampleIgnored,
    /// A corner was recorded.
    Recorded {
        /// The corner.
        corner: Corner,
        /// Its samples' mean.
        mean_m: Vec3,
        /// How many samples.
        samples: usize,
    },
    /// The fit was accepted.
    Accepted,
    /// Starting over (a failed fit was dismissed, or redo of all).
    Restarted,
}

/// The procedure's state.
#[derive(Debug, Clone)]
pub struct CornerProcedure {
    config: ProcedureConfig,
    step: Step,
    recorded: CornerSamples,
    window: VecDeque<(Duration, Vec3)>,
    button_was_down: bool,
}

impl CornerProcedure {
    /// A fresh procedure at the first corner. Fewer than three corners in the config fall back
    /// to all four.
    pub fn new(mut config: ProcedureConfig) -> Self {
        let mut seen = Vec::new();
        config.corners.retain(|c| {
            let fresh = !seen.contains(c);
            seen.push(*c);
            fresh
        });
        if config.corners.len() < 3 {
            config.corners = Corner::ALL.to_vec();
        }
        let first = config.corners[0];
        Self {
            config,
            step: Step::Touch {
                corner: first,
                index: 0,
            },
            recorded: CornerSamples::new(),
            window: VecDeque::new(),
            button_was_down: false,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &ProcedureConfig {
        &self.config
    }

    /// Where the procedure is.
    pub fn step(&self) -> &Step {
        &self.step
    }

    /// Samples recorded so far, per corner.
    pub fn recorded(&self) -> &CornerSamples {
        &self.recorded
    }

    /// What to tell the user now.
    pub fn prompt(&self) -> String {
        match &self.step {
            Step::Touch { corner, index } => format!(
                "corner {}/{}: touch the {} corner of the screen with the wand tip, hold still, press the button",
                index + 1,
                self.config.corners.len(),
                corner.name().replace('_', " ")
            ),
            Step::Review(Ok(fit)) => format!(
                "screen {:.3} m x {:.3} m, residual {:.4} m: press the button to accept, or redo a corner",
                fit.screen.width_m(),
                fit.screen.height_m(),
                fit.residual_m
            ),
            Step::Review(Err(e)) => {
                format!("the fit failed: {e}. Press the button to start again")
            }
            Step::Done(_) => "calibration accepted".to_owned(),
        }
    }

    /// The tip's (speed, spread) over the current window, if it spans enough time.
    fn stillness(&self) -> (f32, f32) {
        let n = self.window.len() as f32;
        if self.window.len() < 2 {
            return (0.0, 0.0);
        }
        let t0 = self.window[0].0;
        let ts: Vec<f32> = self
            .window
            .iter()
            .map(|(t, _)| t.saturating_sub(t0).as_secs_f32())
            .collect();
        let mt = ts.iter().sum::<f32>() / n;
        let mp = self.window.iter().map(|(_, p)| *p).sum::<Vec3>() / n;
        let stt: f32 = ts.iter().map(|t| (t - mt) * (t - mt)).sum();
        let stp: Vec3 = ts
            .iter()
            .zip(&self.window)
            .map(|(t, (_, p))| (*p - mp) * (t - mt))
            .sum();
        let speed = if stt > 0.0 { (stp / stt).length() } else { 0.0 };
        let spread = self
            .window
            .iter()
            .map(|(_, p)| (*p - mp).length())
            .fold(0.0, f32::max);
        (speed, spread)
    }

    /// Feeds one wand sample; returns what it caused, if anything.
    pub fn feed(&mut self, input: WandInput) -> Option<ProcedureEvent> {
        let pressed = input.button_down && !self.button_was_down;
        self.button_was_down = input.button_down;
        if !input.tip_world_m.is_finite() {
            return Some(ProcedureEvent::SampleIgnored);
        }
        // Keep the window: samples no older than `still_window` before this one. A sample
        // older than the newest (a rewound replay) starts a fresh window.
        if self.window.back().is_some_and(|(t, _)| *t > input.time) {
            self.window.clear();
        }
        self.window.push_back((input.time, input.tip_world_m));
        while self
            .window
            .front()
            .is_some_and(|(t, _)| input.time.saturating_sub(*t) > self.config.still_window)
        {
            self.window.pop_front();
        }
        if !pressed {
            return None;
        }
        match self.step.clone() {
            Step::Touch { corner, .. } => {
                if self.window.len() < self.config.min_samples.max(2) {
                    return Some(ProcedureEvent::PressIgnoredTooFewSamples {
                        samples: self.window.len(),
                    });
                }
                let (speed, spread) = self.stillness();
                if speed > self.config.still_speed_m_per_s || spread > self.config.still_radius_m {
                    return Some(ProcedureEvent::PressIgnoredMoving {
                        speed_m_per_s: speed,
                        spread_m: spread,
                    });
                }
                let samples: Vec<Vec3> = self.window.iter().map(|(_, p)| *p).collect();
                let mean_m = samples.iter().copied().sum::<Vec3>() / samples.len() as f32;
                let count = samples.len();
                self.recorded.insert(corner, samples);
                self.advance();
                Some(ProcedureEvent::Recorded {
                    corner,
                    mean_m,
                    samples: count,
                })
            }
            Step::Review(Ok(_)) => self.accept().ok().map(|_| ProcedureEvent::Accepted),
            Step::Review(Err(_)) => {
                self.redo_all();
                Some(ProcedureEvent::Restarted)
            }
            Step::Done(_) => None,
        }
    }

    /// Moves on to the first corner (in order) not yet recorded, or to review.
    fn advance(&mut self) {
        let next = self
            .config
            .corners
            .iter()
            .position(|c| !self.recorded.contains_key(c));
        self.step = match next {
            Some(index) => Step::Touch {
                corner: self.config.corners[index],
                index,
            },
            None => Step::Review(fit_screen(&self.recorded, &self.config.fit)),
        };
    }

    /// Accepts the reviewed fit; `Err` (with the state unchanged) unless in review with a good
    /// fit.
    pub fn accept(&mut self) -> Result<ScreenFit, &'static str> {
        match &self.step {
            Step::Review(Ok(fit)) => {
                let fit = fit.clone();
                self.step = Step::Done(fit.clone());
                Ok(fit)
            }
            Step::Review(Err(_)) => Err("the fit failed; redo the corners"),
            Step::Touch { .. } => Err("not all corners are recorded yet"),
            Step::Done(_) => Err("already accepted"),
        }
    }

    /// Re-takes one corner (from review, or an earlier corner while touching): its samples are
    /// dropped and the procedure waits for it; after it, on to the first corner still missing,
    /// or straight back to review. Unknown corners are ignored.
    pub fn redo(&mut self, corner: Corner) {
        let Some(index) = self.config.corners.iter().position(|c| *c == corner) else {
            return;
        };
        self.recorded.remove(&corner);
        self.step = Step::Touch { corner, index };
    }

    /// Drops every sample and starts again at the first corner.
    pub fn redo_all(&mut self) {
        self.recorded.clear();
        self.step = Step::Touch {
            corner: self.config.corners[0],
            index: 0,
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::screen::ScreenRect;

    struct Driver {
        proc: CornerProcedure,
        time: Duration,
        events: Vec<ProcedureEvent>,
    }

    impl Driver {
        fn new() -> Self {
            Self {
                proc: CornerProcedure::new(ProcedureConfig::default()),
                time: Duration::ZERO,
                events: vec![],
            }
        }
        /// Samples at 100 Hz for `ms` milliseconds at positions from `at(t_s)`.
        fn run(&mut self, ms: u64, button_down: bool, at: impl Fn(f32) -> Vec3) {
            for i in 0..ms / 10 {
                self.time += Duration::from_millis(10);
                let input = WandInput {
                    time: self.time,
                    tip_world_m: at(i as f32 * 0.01),
                    button_down,
                };
                if let Some(e) = self.proc.feed(input) {
                    self.events.push(e);
                }
            }
        }
        /// Hold still at `p` for 0.5 s (tiny jitter), press for 0.1 s, release.
        fn touch(&mut self, p: Vec3) {
            let jitter = |t: f32| Vec3::new((t * 91.0).sin(), (t * 37.0).cos(), 0.0) * 0.0005;
            self.run(500, false, |t| p + jitter(t));
            self.run(100, true, |t| p + jitter(t));
            self.run(100, false, |_| p);
        }
    }

    fn screen() -> ScreenRect {
        ScreenRect::desktop(0.53, 0.30).expect("screen")
    }

    #[test]
    fn records_four_corners_then_accepts() {
        let s = screen();
        let mut d = Driver::new();
        for (i, c) in Corner::ALL.into_iter().enumerate() {
            assert_eq!(
                d.proc.step(),
                &Step::Touch {
                    corner: c,
                    index: i
                }
            );
            assert!(d.proc.prompt().contains(&c.name().replace('_', " ")));
            d.touch(s.corner_m(c));
        }
        assert_eq!(d.events.len(), 4);
        assert!(
            d.events
                .iter()
                .all(|e| matches!(e, ProcedureEvent::Recorded { samples: 31, .. }))
        );
        let Step::Review(Ok(fit)) = d.proc.step().clone() else {
            panic!("not in review: {:?}", d.proc.step());
        };
        assert!((fit.screen.width_m() - 0.53).abs() < 0.001);
        assert!(d.proc.prompt().contains("accept"));
        d.touch(Vec3::new(0.0, 0.0, 0.3)); // a press in review accepts
        assert_eq!(d.events.last(), Some(&ProcedureEvent::Accepted));
        assert!(matches!(d.proc.step(), Step::Done(f) if f == &fit));
    }

    #[test]
    fn ignores_presses_while_moving_or_too_early() {
        let mut d = Driver::new();
        // Press right away: too few samples.
        d.run(20, true, |_| Vec3::ZERO);
        assert!(matches!(
            d.events[0],
            ProcedureEvent::PressIgnoredTooFewSamples { samples: 1 }
        ));
        d.run(50, false, |_| Vec3::ZERO);
        // Sweeping at 0.2 m/s while pressing.
        d.run(400, false, |t| Vec3::X * 0.2 * t);
        d.run(50, true, |t| Vec3::X * (0.08 + 0.2 * t));
        let Some(ProcedureEvent::PressIgnoredMoving { speed_m_per_s, .. }) = d.events.last() else {
            panic!("{:?}", d.events);
        };
        assert!((speed_m_per_s - 0.2).abs() < 0.02, "{speed_m_per_s}");
        // A slow drift of 1.5 cm/s is under the 2 cm/s limit, and over the 0.3 s window it
        // spans 4.5 mm, so 2.25 mm from the mean, under the 4 mm radius: recorded.
        d.run(50, false, |_| Vec3::ZERO);
        d.run(400, false, |t| Vec3::Y * 0.015 * t);
        assert_eq!(
            d.proc.step(),
            &Step::Touch {
                corner: Corner::LowerLeft,
                index: 0
            }
        );
        d.run(20, true, |t| Vec3::Y * 0.015 * (0.4 + t));
        assert!(matches!(
            d.events.last(),
            Some(ProcedureEvent::Recorded {
                corner: Corner::LowerLeft,
                ..
            })
        ));
        // Holding the button down does not record the next corner: only a new press does.
        d.run(600, true, |_| Vec3::X);
        assert_eq!(
            d.proc.step(),
            &Step::Touch {
                corner: Corner::LowerRight,
                index: 1
            }
        );
    }

    #[test]
    fn redo_one_corner_returns_to_review() {
        let s = screen();
        let mut d = Driver::new();
        for c in Corner::ALL {
            // The upper right corner is touched 3 cm off: the fit still passes, with a residual.
            let off = if c == Corner::UpperRight {
                Vec3::X * 0.03
            } else {
                Vec3::ZERO
            };
            d.touch(s.corner_m(c) + off);
        }
        let Step::Review(Ok(bad)) = d.proc.step().clone() else {
            panic!("{:?}", d.proc.step());
        };
        assert!(bad.residual_m > 0.005);
        d.proc.redo(Corner::UpperRight);
        assert_eq!(
            d.proc.step(),
            &Step::Touch {
                corner: Corner::UpperRight,
                index: 2
            }
        );
        assert!(d.proc.accept().is_err());
        d.touch(s.corner_m(Corner::UpperRight));
        let Step::Review(Ok(good)) = d.proc.step().clone() else {
            panic!("{:?}", d.proc.step());
        };
        assert!(good.residual_m < 0.001, "{}", good.residual_m);
        assert_eq!(d.proc.accept(), Ok(good));
    }

    #[test]
    fn redo_an_earlier_corner_mid_sequence_then_carry_on() {
        let s = screen();
        let mut d = Driver::new();
        d.touch(s.corner_m(Corner::LowerLeft) + Vec3::Y * 0.05); // a slip
        d.touch(s.corner_m(Corner::LowerRight));
        d.proc.redo(Corner::LowerLeft);
        assert_eq!(
            d.proc.step(),
            &Step::Touch {
                corner: Corner::LowerLeft,
                index: 0
            }
        );
        d.touch(s.corner_m(Corner::LowerLeft));
        // Lower right is kept: on to upper right.
        assert_eq!(
            d.proc.step(),
            &Step::Touch {
                corner: Corner::UpperRight,
                index: 2
            }
        );
        d.touch(s.corner_m(Corner::UpperRight));
        d.touch(s.corner_m(Corner::UpperLeft));
        let fit = d.proc.accept().expect("accept");
        assert!(fit.residual_m < 0.001, "{}", fit.residual_m);
    }

    #[test]
    fn failed_fit_restarts_on_press_and_redo_all_clears() {
        let mut d = Driver::new();
        // All four "corners" touched at nearly the same spot: collinear / too small.
        for i in 0..4 {
            d.touch(Vec3::new(0.001 * i as f32, 0.0, 0.0));
        }
        assert!(matches!(d.proc.step(), Step::Review(Err(_))));
        assert!(d.proc.prompt().contains("failed"));
        assert!(d.proc.accept().is_err());
        d.touch(Vec3::ZERO);
        assert_eq!(d.events.last(), Some(&ProcedureEvent::Restarted));
        assert_eq!(
            d.proc.step(),
            &Step::Touch {
                corner: Corner::LowerLeft,
                index: 0
            }
        );
        assert!(d.proc.recorded().is_empty());
        d.touch(Vec3::ZERO);
        assert_eq!(d.proc.recorded().len(), 1);
        d.proc.redo_all();
        assert!(d.proc.recorded().is_empty());
    }

    #[test]
    fn three_corner_configuration_and_bad_samples() {
        let s = screen();
        let mut d = Driver::new();
        d.proc = CornerProcedure::new(ProcedureConfig {
            corners: vec![Corner::LowerLeft, Corner::LowerRight, Corner::UpperLeft],
            ..ProcedureConfig::default()
        });
        let nan = d.proc.feed(WandInput {
            time: Duration::from_millis(1),
            tip_world_m: Vec3::NAN,
            button_down: false,
        });
        assert_eq!(nan, Some(ProcedureEvent::SampleIgnored));
        for c in [Corner::LowerLeft, Corner::LowerRight, Corner::UpperLeft] {
            d.touch(s.corner_m(c));
        }
        let fit = d.proc.accept().expect("accept");
        assert!((fit.screen.upper_right_m() - s.upper_right_m()).length() < 0.001);
    }
}
