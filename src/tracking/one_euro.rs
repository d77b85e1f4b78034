//! The One Euro filter (Casiez, Roussel and Vogel, CHI 2012): a first-order low-pass filter
//! whose cutoff rises with speed, so slow motion is smoothed (less jitter) and fast motion
//! follows closely (less lag).
//!
//! For each new sample at interval `dt`: the derivative is estimated and low-passed at
//! `derivative_cutoff_hz`; the cutoff is `min_cutoff_hz + beta·|derivative|`; the value is
//! low-passed with `alpha = 1 / (1 + 1/(2π·cutoff·dt))`.
//!
//! Orientations: the "derivative" is the angular speed (rad/s) of the relative rotation from the
//! previous filtered orientation; the filtered orientation is `slerp(previous, new, alpha)` on
//! the same hemisphere, renormalised, so it stays a unit quaternion and never takes the long way
//! round. Positions use `beta` in 1/m (speed in m/s), orientations `rotation_beta` in 1/rad.

use crate::pose::Pose;
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use std::time::Duration;

/// How one tracked role (head, wand) is filtered.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum FilterConfig {
    /// No filtering: the newest sample as it came.
    Raw,
    /// The One Euro filter.
    OneEuro {
        /// Cutoff at rest, Hz (lower = less jitter, more lag when slow).
        min_cutoff_hz: f32,
        /// Cutoff increase per m/s of speed (higher = less lag when fast).
        beta: f32,
        /// Cutoff increase per rad/s of angular speed, for orientations.
        rotation_beta: f32,
        /// Cutoff for the derivative estimate, Hz.
        derivative_cutoff_hz: f32,
    },
}

impl FilterConfig {
    /// A sensible head setting: smooth at rest, responsive when moving.
    pub const HEAD: FilterConfig = FilterConfig::OneEuro {
        min_cutoff_hz: 1.0,
        beta: 20.0,
        rotation_beta: 0.5,
        derivative_cutoff_hz: 1.0,
    };
    /// A sensible wand setting (a little more responsive than the head).
    pub const WAND: FilterConfig = FilterConfig::OneEuro {
        min_cutoff_hz: 1.5,
        beta: 30.0,
        rotation_beta: 0.8,
        derivative_cutoff_hz: 1.0,
    };

    /// Checks the numbers are finite and positive where they must be; `Err` names the field.
    pub fn validate(&self) -> Result<(), String> {
        if let FilterConfig::OneEuro {
            min_cutoff_hz,
            beta,
            rotation_beta,
            derivative_cutoff_hz,
        } = *self
        {
            for (name, v, positive) in [
                ("min_cutoff_hz", min_cutoff_hz, true),
                ("beta", beta, false),
                ("rotation_beta", rotation_beta, false),
                ("derivative_cutoff_hz", derivative_cutoff_hz, true),
            ] {
                if !v.is_finite() || v < 0.0 || (positive && v == 0.0) {
                    return Err(format!(
                        "{name} = {v} must be finite and {}",
                        if positive { "> 0" } else { ">= 0" }
                    ));
                }
            }
        }
        Ok(())
    }
}

fn alpha(cutoff_hz: f32, dt_s: f32) -> f32 {
    let tau = 1.0 / (2.0 * std::f32::consts::PI * cutoff_hz);
    1.0 / (1.0 + tau / dt_s)
}

/// A One Euro filter (or pass-through) over poses with timestamps.
#[derive(Debug, Clone)]
pub struct PoseFilter {
    config: FilterConfig,
    last_time: Option<Duration>,
    position: Vec3,
    velocity: Vec3,
    orientation: Quat,
    angular_speed: f32,
}

impl PoseFilter {
    /// A filter with no history.
    pub fn new(config: FilterConfig) -> Self {
        Self {
            config,
            last_time: None,
            position: Vec3::ZERO,
            velocity: Vec3::ZERO,
            orientation: Quat::IDENTITY,
            angular_speed: 0.0,
        }
    }

    /// The configuration.
    pub fn config(&self) -> FilterConfig {
        self.config
    }

    /// Forgets the history (after a tracker dropout); the next sample passes through.
    pub fn reset(&mut self) {
        self.last_time = None;
    }

    /// Filters one sample taken at `time` (the sample's own timestamp). Non-finite samples are
    /// ignored (the last output is returned; `None` if there is none yet). A sample not newer
    /// than the previous one replaces nothing and returns the last output.
    pub fn filter(&mut self, time: Duration, sample: &Pose) -> Option<Pose> {
        let valid = sample.position_m.is_finite()
            && sample.orientation.is_finite()
            && sample.orientation.length_squared() > 1e-6;
        let last = self
            .last_time
            .map(|_| Pose::new(self.position, self.orientation));
        if !valid {
            return last;
        }
        let q_new = sample.orientation.normalize();
        let Some(t0) = self.last_time else {
            self.last_time = Some(time);
            self.position = sample.position_m;
            self.velocity = Vec3::ZERO;
            self.orientation = q_new;
            self.angular_speed = 0.0;
            return Some(*sample);
        };
        if time <= t0 {
            return last;
        }
        let dt = (time - t0).as_secs_f32().max(1e-6);
        self.last_time = Some(time);
        match self.config {
            FilterConfig::Raw => {
                self.position = sample.position_m;
                self.orientation = q_new;
            }
            FilterConfig::OneEuro {
                min_cutoff_hz,
                beta,
                rotation_beta,
                derivative_cutoff_hz,
            } => {
                let a_d = alpha(derivative_cutoff_hz, dt);
                // Position.
                let raw_velocity = (sample.position_m - self.position) / dt;
                self.velocity = self.velocity.lerp(raw_velocity, a_d);
                let cutoff = min_cutoff_hz + beta * self.velocity.length();
                self.position = self.position.lerp(sample.position_m, alpha(cutoff, dt));
                // Orientation, on the previous output's hemisphere.
                let q = if self.orientation.dot(q_new) < 0.0 {
                    -q_new
                } else {
                    q_new
                };
                let delta = (self.orientation.conjugate() * q).normalize();
                let raw_speed = delta.to_axis_angle().1.abs() / dt;
                self.angular_speed += (raw_speed - self.angular_speed) * a_d;
                let cutoff = min_cutoff_hz + rotation_beta * self.angular_speed;
                self.orientation = self.orientation.slerp(q, alpha(cutoff, dt)).normalize();
            }
        }
        Some(Pose::new(self.position, self.orientation))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_noise::Noise;

    fn rms(v: &[f32]) -> f32 {
        (v.iter().map(|x| x * x).sum::<f32>() / v.len() as f32).sqrt()
    }

    #[test]
    fn jitter_at_rest_is_reduced() {
        // A still head at 120 Hz with ±1 mm uniform jitter (RMS 0.577 mm).
        let mut f = PoseFilter::new(FilterConfig::HEAD);
        let mut noise = Noise(12345);
        let (mut raw_err, mut out_err) = (vec![], vec![]);
        for i in 0..1200 {
            let t = Duration::from_micros(i * 8333);
            let p = Vec3::new(noise.next(), noise.next(), noise.next()) * 0.001;
            let out = f.filter(t, &Pose::from_translation(p)).expect("out");
            if i > 240 {
                raw_err.push(p.x);
                out_err.push(out.position_m.x);
            }
        }
        // Measured: 0.11 mm RMS filtered vs 0.58 mm raw (5.1 times less).
        assert!(
            rms(&out_err) < rms(&raw_err) / 4.0,
            "{} vs {}",
            rms(&out_err),
            rms(&raw_err)
        );
    }

    #[test]
    fn lag_on_fast_motion_is_small_and_raw_has_none() {
        // The head sweeps at 0.5 m/s; after settling, the lag behind the true position.
        let mut f = PoseFilter::new(FilterConfig::HEAD);
        let mut raw = PoseFilter::new(FilterConfig::Raw);
        let mut lag = 0.0;
        for i in 0..240 {
            let t = i as f32 / 120.0;
            let p = Pose::from_translation(Vec3::new(0.5 * t, 0.0, 0.6));
            let d = Duration::from_secs_f32(t);
            lag = p.position_m.x - f.filter(d, &p).expect("out").position_m.x;
            assert_eq!(raw.filter(d, &p), Some(p));
        }
        // Measured: 3.9 mm. The speed is estimated against the previous filtered value (as in
        // the reference implementation), so lag itself raises the cutoff; a plain 1 Hz
        // low-pass would lag 80 mm.
        assert!(lag > 0.0 && lag < 0.006, "lag {lag}");
    }

    #[test]
    fn orientation_stays_unit_and_follows_across_the_hemisphere() {
        let mut f = PoseFilter::new(FilterConfig::HEAD);
        let mut noise = Noise(99);
        let mut last = Quat::IDENTITY;
        for i in 0..600 {
            let t = i as f32 / 120.0;
            let angle = 1.0 * t; // 1 rad/s about Y
            let mut q = Quat::from_rotation_y(angle) * Quat::from_rotation_x(noise.next() * 0.002);
            if i % 2 == 0 {
                q = -q; // the same rotation, other sign: must not flip the output
            }
            let out = f
                .filter(Duration::from_secs_f32(t), &Pose::new(Vec3::ZERO, q))
                .expect("out");
            assert!((out.orientation.length() - 1.0).abs() < 1e-5);
            if i > 0 {
                assert!(last.angle_between(out.orientation) < 0.05, "step at {i}");
            }
            last = out.orientation;
            if i > 120 {
                let err = out.orientation.angle_between(Quat::from_rotation_y(angle));
                assert!(err < 0.05, "orientation lag {err} rad at {i}");
            }
        }
    }

    #[test]
    fn bad_samples_are_ignored_and_config_is_validated() {
        let mut f = PoseFilter::new(FilterConfig::WAND);
        let good = Pose::from_translation(Vec3::new(0.1, 0.2, 0.3));
        assert_eq!(
            f.filter(Duration::ZERO, &Pose::from_translation(Vec3::NAN)),
            None
        );
        assert_eq!(f.filter(Duration::from_millis(1), &good), Some(good));
        let bad = Pose::new(Vec3::ZERO, Quat::from_xyzw(0.0, 0.0, 0.0, 0.0));
        assert_eq!(f.filter(Duration::from_millis(2), &bad), Some(good));
        assert!(FilterConfig::HEAD.validate().is_ok());
        let e = FilterConfig::OneEuro {
            min_cutoff_hz: 0.0,
            beta: 1.0,
            rotation_beta: 1.0,
            derivative_cutoff_hz: 1.0,
        }
        .validate()
        .expect_err("zero cutoff");
        assert!(e.contains("min_cutoff_hz"));
    }
}
