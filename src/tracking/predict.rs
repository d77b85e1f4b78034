//! Prediction of a tracked pose to the expected display time.
//!
//! The predictor keeps the samples of the last `window` (by their own timestamps). The linear
//! velocity is the least-squares slope of position against time over those samples (robust to
//! per-sample jitter); the angular velocity is the rotation from the oldest to the newest
//! sample in the window divided by their time difference (world frame, `q_new · q_old⁻¹`).
//! The prediction extrapolates the newest sample at constant velocity and angular velocity:
//! `p = p_new + v·h`, `q = exp(ω·h) · q_new`, with the horizon `h = display_time − t_new`
//! clamped to `[0, max_horizon]` (beyond a few tens of milliseconds extrapolation does more
//! harm than good). With a single sample, the prediction is that sample.

use crate::pose::Pose;
use glam::{Quat, Vec3};
use std::collections::VecDeque;
use std::time::Duration;

/// Tunables of the predictor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PredictorConfig {
    /// How far back samples are used for the velocity estimate.
    pub window: Duration,
    /// Longest extrapolation.
    pub max_horizon: Duration,
}

impl Default for PredictorConfig {
    fn default() -> Self {
        Self {
            window: Duration::from_millis(50),
            max_horizon: Duration::from_millis(50),
        }
    }
}

/// Constant-velocity pose predictor over timestamped samples.
#[derive(Debug, Clone)]
pub struct PosePredictor {
    config: PredictorConfig,
    history: VecDeque<(Duration, Pose)>,
}

impl PosePredictor {
    /// An empty predictor.
    pub fn new(config: PredictorConfig) -> Self {
        Self {
            config,
            history: VecDeque::new(),
        }
    }

    /// Forgets all samples.
    pub fn reset(&mut self) {
        self.history.clear();
    }

    /// Adds a sample taken at `time`. Non-finite poses are ignored; a sample older than the
    /// newest (a rewound replay) restarts the history.
    pub fn push(&mut self, time: Duration, pose: &Pose) {
        if !(pose.position_m.is_finite()
            && pose.orientation.is_finite()
            && pose.orientation.length_squared() > 1e-6)
        {
            return;
        }
        if self.history.back().is_some_and(|(t, _)| *t > time) {
            self.history.clear();
        }
        if self.history.back().is_some_and(|(t, _)| *t == time) {
            self.history.pop_back();
        }
        self.history.push_back((
            time,
            Pose::new(pose.position_m, pose.orientation.normalize()),
        ));
        while self
            .history
            .front()
            .is_some_and(|(t, _)| time.saturating_sub(*t) > self.config.window)
        {
            self.history.pop_front();
        }
    }

    /// The newest sample and its time.
    pub fn latest(&self) -> Option<(Duration, Pose)> {
        self.history.back().copied()
    }

    /// Estimated (linear velocity m/s, angular velocity rad/s in the world frame).
    pub fn velocity(&self) -> (Vec3, Vec3) {
        let (Some((t_old, old)), Some((t_new, new))) = (self.history.front(), self.history.back())
        else {
            return (Vec3::ZERO, Vec3::ZERO);
        };
        let span = t_new.saturating_sub(*t_old).as_secs_f32();
        if span <= 0.0 {
            return (Vec3::ZERO, Vec3::ZERO);
        }
        let n = self.history.len() as f32;
        let ts: Vec<f32> = self
            .history
            .iter()
            .map(|(t, _)| t.saturating_sub(*t_old).as_secs_f32())
            .collect();
        let mt = ts.iter().sum::<f32>() / n;
        let mp = self.history.iter().map(|(_, p)| p.position_m).sum::<Vec3>() / n;
        let stt: f32 = ts.iter().map(|t| (t - mt) * (t - mt)).sum();
        let stp: Vec3 = ts
            .iter()
            .zip(&self.history)
            .map(|(t, (_, p))| (p.position_m - mp) * (t - mt))
            .sum();
        let v = if stt > 0.0 { stp / stt } else { Vec3::ZERO };
        let mut delta = (new.orientation * old.orientation.conjugate()).normalize();
        if delta.w < 0.0 {
            delta = -delta;
        }
        let (axis, angle) = delta.to_axis_angle();
        let w = axis * (angle / span);
        (
            if v.is_finite() { v } else { Vec3::ZERO },
            if w.is_finite() { w } else { Vec3::ZERO },
        )
    }

    /// The pose expected at `display_time`; `None` before the first sample.
    pub fn predict(&self, display_time: Duration) -> Option<Pose> {
        let (t_new, newest) = self.latest()?;
        let h = display_time
            .saturating_sub(t_new)
            .min(self.config.max_horizon)
            .as_secs_f32();
        let (v, w) = self.velocity();
        let turn = if w.length_squared() > 0.0 {
            Quat::from_scaled_axis(w * h)
        } else {
            Quat::IDENTITY
        };
        Some(Pose::new(
            newest.position_m + v * h,
            (turn * newest.orientation).normalize(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn motion(t: f32) -> Pose {
        // 0.3 m/s sideways, 0.1 m/s up, turning 1.5 rad/s about a tilted axis.
        Pose::new(
            Vec3::new(0.3 * t, 0.1 * t, 0.6),
            Quat::from_scaled_axis(Vec3::new(0.2, 1.0, 0.1).normalize() * 1.5 * t),
        )
    }

    #[test]
    fn constant_motion_is_predicted_almost_exactly() {
        let mut p = PosePredictor::new(PredictorConfig::default());
        assert_eq!(p.predict(Duration::ZERO), None);
        for i in 0..30 {
            let t = i as f32 / 120.0;
            p.push(Duration::from_secs_f32(t), &motion(t));
        }
        let t_last = 29.0 / 120.0;
        let display = t_last + 0.03; // 30 ms ahead
        let got = p.predict(Duration::from_secs_f32(display)).expect("pose");
        let want = motion(display);
        // Seen: exact (0 m, 0 rad); without prediction the error would be 9.5 mm and
        // 0.045 rad.
        assert!((got.position_m - want.position_m).length() < 1e-4);
        assert!(got.orientation.angle_between(want.orientation) < 1e-3);
        let stale = (motion(t_last).position_m - want.position_m).length();
        assert!(stale > 0.009);
    }

    #[test]
    fn curved_motion_error_is_bounded_and_better_than_none() {
        // A head swaying ±5 cm at 1 Hz with ±0.5 mm jitter, sampled at 120 Hz, predicted 20 ms
        // ahead. Seen: RMS error 1.0 mm predicted vs 4.4 mm using the newest sample.
        let sway = |t: f32| Vec3::new(0.05 * (std::f32::consts::TAU * t).sin(), 0.0, 0.6);
        let mut p = PosePredictor::new(PredictorConfig::default());
        let mut state = 7u64;
        let (mut err_pred, mut err_none, mut n) = (0.0, 0.0, 0.0);
        for i in 0..600 {
            let t = i as f32 / 120.0;
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let jitter = ((state % 1001) as f32 / 1000.0 - 0.5) * 0.001;
            p.push(
                Duration::from_secs_f32(t),
                &Pose::from_translation(sway(t) + Vec3::X * jitter),
            );
            if i > 12 {
                let want = sway(t + 0.02);
                let got = p.predict(Duration::from_secs_f32(t + 0.02)).expect("pose");
                err_pred += (got.position_m - want).length_squared();
                err_none += (sway(t) - want).length_squared();
                n += 1.0;
            }
        }
        let (rms_pred, rms_none) = ((err_pred / n).sqrt(), (err_none / n).sqrt());
        assert!(rms_pred < 0.002, "{rms_pred}");
        assert!(rms_pred < rms_none / 2.5, "{rms_pred} vs {rms_none}");
    }

    #[test]
    fn horizon_is_clamped_and_bad_samples_ignored() {
        let mut p = PosePredictor::new(PredictorConfig::default());
        for i in 0..10 {
            let t = i as f32 / 100.0;
            p.push(Duration::from_secs_f32(t), &motion(t));
        }
        p.push(
            Duration::from_secs_f32(0.095),
            &Pose::from_translation(Vec3::NAN),
        );
        let far = p.predict(Duration::from_secs(10)).expect("pose");
        let clamp = p
            .predict(Duration::from_secs_f32(0.09 + 0.05))
            .expect("pose");
        assert!((far.position_m - clamp.position_m).length() < 1e-6);
        // A display time before the newest sample predicts the newest sample.
        let past = p.predict(Duration::ZERO).expect("pose");
        assert!((past.position_m - motion(0.09).position_m).length() < 1e-5);
        // A rewound replay starts over.
        p.push(Duration::ZERO, &Pose::IDENTITY);
        assert_eq!(p.velocity(), (Vec3::ZERO, Vec3::ZERO));
    }
}
