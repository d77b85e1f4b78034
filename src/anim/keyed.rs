//! Keyed motions: key postures interpolated by Kochanek-Bartels splines (tension, continuity,
//! bias; Kochanek & Bartels, SIGGRAPH 1984), per component of the posture (root translation and
//! every joint angle), with the tangent scaling for unevenly spaced keys from that paper.

use serde::{Deserialize, Serialize};

use crate::character::skeleton::{Posture, Skeleton};
use crate::decimal::{difference_as_written, widen_as_written};

/// A key posture at a time, with its spline shape parameters (each in [−1, 1], default 0 =
/// Catmull-Rom).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyPosture {
    /// Time of the key, seconds.
    pub time_s: f32,
    /// The posture at that time.
    pub posture: Posture,
    /// Tension: 1 tightens the curve at the key (zero tangent), −1 loosens it.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub tension: f32,
    /// Continuity: non-zero makes a corner at the key.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub continuity: f32,
    /// Bias: positive overshoots towards the previous key's direction, negative the next.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub bias: f32,
}

fn is_zero(v: &f32) -> bool {
    *v == 0.0
}

impl KeyPosture {
    /// A key with tension, continuity and bias 0.
    pub fn new(time_s: f32, posture: Posture) -> Self {
        Self {
            time_s,
            posture,
            tension: 0.0,
            continuity: 0.0,
            bias: 0.0,
        }
    }
}

/// What a motion does outside its keys' time span.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Extrapolation {
    /// Hold the first posture before the first key and the last after the last key.
    #[default]
    Clamp,
    /// Repeat with period `last.time_s − first.time_s`; the last key must equal the first
    /// posture (it is the first key of the next cycle), and tangents wrap around.
    Loop,
}

/// A named keyed motion of a skeleton.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Motion {
    /// Name (unique within a character), e.g. "bend".
    pub name: String,
    /// Keys in strictly increasing time.
    pub keys: Vec<KeyPosture>,
    /// Behaviour outside the keys.
    #[serde(default)]
    pub extrapolation: Extrapolation,
}

impl Motion {
    /// Simulated time one pass of the motion takes when it is played from t = 0, as its file
    /// writes it, seconds: up to its last key when clamped (before its first key it holds that
    /// key's posture), one period when looping (a loop is periodic, so any period is a whole
    /// pass). 0 for a motion without keys.
    ///
    /// Key times are `f32`; the result is the decimal the file wrote
    /// ([`crate::decimal::widen_as_written`]), and a period is the difference of the written
    /// decimals (keys at 0.3 s and 2.4 s loop every 2.1 s, where their `f32` difference is
    /// 2.1000001 s).
    pub fn pass_s(&self) -> f64 {
        let (Some(first), Some(last)) = (self.keys.first(), self.keys.last()) else {
            return 0.0;
        };
        let end = widen_as_written(last.time_s);
        match self.extrapolation {
            Extrapolation::Clamp => end.max(0.0),
            Extrapolation::Loop => difference_as_written(end, widen_as_written(first.time_s)),
        }
    }

    /// Checks the motion against a skeleton; `Err` names the first problem.
    pub fn validate(&self, skeleton: &Skeleton) -> Result<(), String> {
        let name = &self.name;
        if self.keys.is_empty() {
            return Err(format!("motion \"{name}\": has no keys"));
        }
        let dofs = skeleton.dof_count();
        for (k, key) in self.keys.iter().enumerate() {
            if !key.time_s.is_finite() {
                return Err(format!("motion \"{name}\": key {k} time is not finite"));
            }
            if k > 0 && key.time_s <= self.keys[k - 1].time_s {
                return Err(format!(
                    "motion \"{name}\": key {k} time {} s is not after key {} ({} s)",
                    key.time_s,
                    k - 1,
                    self.keys[k - 1].time_s
                ));
            }
            if key.posture.angles_rad.len() != dofs {
                return Err(format!(
                    "motion \"{name}\": key {k} has {} angles, the skeleton has {dofs} degrees of freedom",
                    key.posture.angles_rad.len()
                ));
            }
            if !key.posture.is_finite() {
                return Err(format!("motion \"{name}\": key {k} posture is not finite"));
            }
            for (what, v) in [
                ("tension", key.tension),
                ("continuity", key.continuity),
                ("bias", key.bias),
            ] {
                if !(-1.0..=1.0).contains(&v) {
                    return Err(format!(
                        "motion \"{name}\": key {k} {what} {v} is outside [-1, 1]"
                    ));
                }
            }
        }
        if self.extrapolation == Extrapolation::Loop {
            if self.keys.len() < 2 {
                return Err(format!(
                    "motion \"{name}\": a looping motion needs at least 2 keys"
                ));
            }
            let (first, last) = (&self.keys[0], &self.keys[self.keys.len() - 1]);
            if first.posture != last.posture {
                return Err(format!(
                    "motion \"{name}\": a looping motion's last key must equal its first posture"
                ));
            }
        }
        Ok(())
    }

    /// The posture at time `t_s`, seconds (not clamped to joint limits; forward kinematics
    /// clamps). The time is `f64` because it is a running simulation clock: a looping motion
    /// wraps it into one period before it is narrowed to the keys' `f32` (an `f32` clock a day
    /// in is only good to about 8 ms, and so would the posture's time be).
    pub fn posture_at(&self, t_s: f64) -> Posture {
        let mut out = Posture::default();
        self.posture_at_into(t_s, &mut out);
        out
    }

    /// [`Motion::posture_at`] writing into `out` (reuses its storage).
    pub fn posture_at_into(&self, t_s: f64, out: &mut Posture) {
        let n = self.keys.len();
        let Some(first) = self.keys.first() else {
            out.angles_rad.clear();
            out.root_translation_m = glam::Vec3::ZERO;
            return;
        };
        let dofs = first.posture.angles_rad.len();
        out.angles_rad.resize(dofs, 0.0);
        let last = &self.keys[n - 1];
        let (first_s, last_s) = (f64::from(first.time_s), f64::from(last.time_s));
        let t_s = if t_s.is_finite() { t_s } else { first_s };
        let looping = self.extrapolation == Extrapolation::Loop && n >= 2;
        // Wrapped or clamped into the keys' span in f64, then narrowed: within the first
        // period of a motion whose first key is at 0 this is the clock's own f32.
        let t = if looping {
            let period = last_s - first_s;
            if period > 0.0 {
                (first_s + (t_s - first_s).rem_euclid(period)) as f32
            } else {
                first.time_s
            }
        } else {
            t_s.clamp(first_s, last_s) as f32
        };
        if n == 1 || t <= first.time_s {
            copy_posture(&first.posture, out);
            return;
        }
        if t >= last.time_s {
            copy_posture(&last.posture, out);
            return;
        }
        // Segment i: keys[i] .. keys[i+1].
        let i = self
            .keys
            .windows(2)
            .position(|w| t < w[1].time_s)
            .unwrap_or(n - 2);
        // Neighbour indices and time gaps, wrapping for loops, duplicating ends otherwise.
        // For loops keys[n-1] is keys[0] again, so the cycle has n-1 distinct keys.
        let (prev, next2, dt_prev, dt_next) = if looping {
            let m = n - 1;
            let prev = if i == 0 { m - 1 } else { i - 1 };
            let next2 = if i + 2 > m { (i + 2) - m } else { i + 2 };
            let dt_prev = if i == 0 {
                self.keys[m].time_s - self.keys[m - 1].time_s
            } else {
                self.keys[i].time_s - self.keys[i - 1].time_s
            };
            let dt_next = if i + 2 > m {
                self.keys[(i + 2) - m].time_s - self.keys[(i + 1) - m].time_s
            } else {
                self.keys[i + 2].time_s - self.keys[i + 1].time_s
            };
            (prev, next2, dt_prev, dt_next)
        } else {
            let dt = self.keys[i + 1].time_s - self.keys[i].time_s;
            let prev = i.saturating_sub(1);
            let next2 = (i + 2).min(n - 1);
            let dt_prev = if i == 0 {
                dt
            } else {
                self.keys[i].time_s - self.keys[i - 1].time_s
            };
            let dt_next = if i + 2 >= n {
                dt
            } else {
                self.keys[i + 2].time_s - self.keys[i + 1].time_s
            };
            (prev, next2, dt_prev, dt_next)
        };
        let k0 = &self.keys[i];
        let k1 = &self.keys[i + 1];
        let dt = k1.time_s - k0.time_s;
        let s = (t - k0.time_s) / dt;
        // Hermite basis.
        let (s2, s3) = (s * s, s * s * s);
        let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
        let h10 = s3 - 2.0 * s2 + s;
        let h01 = -2.0 * s3 + 3.0 * s2;
        let h11 = s3 - s2;
        // Outgoing tangent at k0: a·(P_i − P_prev) + b·(P_next − P_i), scaled for spacing.
        let sc_out = 2.0 * dt / (dt_prev + dt);
        let a = 0.5 * (1.0 - k0.tension) * (1.0 + k0.bias) * (1.0 + k0.continuity) * sc_out;
        let b = 0.5 * (1.0 - k0.tension) * (1.0 - k0.bias) * (1.0 - k0.continuity) * sc_out;
        // Incoming tangent at k1: c·(P_next − P_i) + d·(P_next2 − P_next).
        let sc_in = 2.0 * dt / (dt + dt_next);
        let c = 0.5 * (1.0 - k1.tension) * (1.0 + k1.bias) * (1.0 - k1.continuity) * sc_in;
        let d = 0.5 * (1.0 - k1.tension) * (1.0 - k1.bias) * (1.0 + k1.continuity) * sc_in;
        let w_prev = -h10 * a;
        let w0 = h00 + h10 * (a - b) - h11 * c;
        let w1 = h01 + h10 * b + h11 * (c - d);
        let w2 = h11 * d;
        let (pp, p0, p1, p2) = (
            &self.keys[prev].posture,
            &k0.posture,
            &k1.posture,
            &self.keys[next2].posture,
        );
        out.root_translation_m = pp.root_translation_m * w_prev
            + p0.root_translation_m * w0
            + p1.root_translation_m * w1
            + p2.root_translation_m * w2;
        for (k, slot) in out.angles_rad.iter_mut().enumerate() {
            let g = |p: &Posture| p.angles_rad.get(k).copied().unwrap_or(0.0);
            *slot = g(pp) * w_prev + g(p0) * w0 + g(p1) * w1 + g(p2) * w2;
        }
    }
}

fn copy_posture(src: &Posture, out: &mut Posture) {
    out.root_translation_m = src.root_translation_m;
    out.angles_rad.clear();
    out.angles_rad.extend_from_slice(&src.angles_rad);
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn posture(a: f32) -> Posture {
        Posture {
            root_translation_m: Vec3::new(a * 0.1, 0.0, 0.0),
            angles_rad: vec![a, -a],
        }
    }

    fn motion(extrapolation: Extrapolation) -> Motion {
        Motion {
            name: "m".into(),
            keys: vec![
                KeyPosture::new(0.0, posture(0.0)),
                KeyPosture::new(1.0, posture(1.0)),
                KeyPosture::new(1.5, posture(0.2)),
                KeyPosture::new(3.0, posture(0.0)),
            ],
            extrapolation,
        }
    }

    #[test]
    fn passes_through_every_key() {
        for ex in [Extrapolation::Clamp, Extrapolation::Loop] {
            let m = motion(ex);
            for key in &m.keys {
                let p = m.posture_at(key.time_s.into());
                for (a, b) in p.angles_rad.iter().zip(&key.posture.angles_rad) {
                    assert!((a - b).abs() < 1e-6, "{ex:?} at {}: {a} vs {b}", key.time_s);
                }
                assert!((p.root_translation_m - key.posture.root_translation_m).length() < 1e-6);
            }
        }
    }

    #[test]
    fn is_continuous_and_smooth_between_keys() {
        let m = motion(Extrapolation::Clamp);
        let h = 1e-3;
        let mut t = 0.01;
        while t < 2.99 {
            let a = m.posture_at(t).angles_rad[0];
            let b = m.posture_at(t + h).angles_rad[0];
            assert!((a - b).abs() < 0.01, "jump at {t}");
            t += 0.013;
        }
        // C1 across key 1 (tension, continuity, bias 0): one-sided slopes agree.
        let left =
            (m.posture_at(1.0).angles_rad[0] - m.posture_at(1.0 - h).angles_rad[0]) / h as f32;
        let right =
            (m.posture_at(1.0 + h).angles_rad[0] - m.posture_at(1.0).angles_rad[0]) / h as f32;
        assert!((left - right).abs() < 0.05, "{left} vs {right}");
    }

    #[test]
    fn loops_and_clamps_outside_the_keys() {
        let looped = motion(Extrapolation::Loop);
        let a = looped.posture_at(0.7).angles_rad[0];
        let b = looped.posture_at(0.7 + 3.0 * 5.0).angles_rad[0];
        let c = looped.posture_at(0.7 - 3.0).angles_rad[0];
        assert!((a - b).abs() < 1e-4 && (a - c).abs() < 1e-4);
        let clamped = motion(Extrapolation::Clamp);
        assert_eq!(clamped.posture_at(-5.0), posture(0.0));
        assert_eq!(clamped.posture_at(50.0), posture(0.0));
    }

    #[test]
    fn a_loop_a_day_in_shows_the_posture_of_its_first_period() {
        // 86 400.7 s as an f32 is 86 400.703125 s: 3 ms late, where the first key's angle
        // moves at about 1 rad/s. Wrapped in f64 first, it is the same f32 time as 0.7 s.
        let looped = motion(Extrapolation::Loop);
        assert_eq!(
            looped.posture_at(0.7 + 3.0 * 28_800.0),
            looped.posture_at(0.7)
        );
        assert_eq!(
            looped.posture_at(0.7 - 3.0 * 28_800.0),
            looped.posture_at(0.7)
        );
    }

    #[test]
    fn a_pass_ends_at_the_last_key_or_lasts_one_period() {
        let mut m = motion(Extrapolation::Clamp);
        for (key, t) in m.keys.iter_mut().zip([0.3, 1.3, 1.8, 3.3]) {
            key.time_s = t;
        }
        // Keys from 0.3 s to 3.3 s: played from 0, the clamped motion ends at its last key,
        // the loop repeats every 3 s.
        assert_eq!(m.pass_s(), 3.3);
        assert!(
            m.keys[3].time_s - m.keys[0].time_s < 3.1,
            "the keys' span is shorter than the pass"
        );
        m.extrapolation = Extrapolation::Loop;
        assert_eq!(m.pass_s(), 3.0);
        m.keys[3].time_s = 2.4;
        assert_eq!(
            m.pass_s(),
            2.1,
            "as written, not the f32 difference 2.1000001"
        );
        m.keys.clear();
        assert_eq!(m.pass_s(), 0.0);
    }

    #[test]
    fn tension_one_gives_zero_tangent_at_the_key() {
        let mut m = motion(Extrapolation::Clamp);
        m.keys[1].tension = 1.0;
        let h = 1e-3;
        let right =
            (m.posture_at(1.0 + h).angles_rad[0] - m.posture_at(1.0).angles_rad[0]) / h as f32;
        assert!(right.abs() < 0.05, "{right}");
    }

    #[test]
    fn validation_names_the_problem() {
        let skeleton = Skeleton {
            joints: vec![crate::character::skeleton::Joint {
                name: "r".into(),
                parent: None,
                offset_m: Vec3::ZERO,
                dofs: vec![
                    crate::character::skeleton::Dof::new(Vec3::X, -2.0, 2.0),
                    crate::character::skeleton::Dof::new(Vec3::Y, -2.0, 2.0),
                ],
            }],
        };
        assert!(motion(Extrapolation::Loop).validate(&skeleton).is_ok());
        let mut bad = motion(Extrapolation::Clamp);
        bad.keys[2].time_s = 0.5;
        assert!(
            bad.validate(&skeleton)
                .expect_err("invalid")
                .contains("key 2 time")
        );
        let mut bad = motion(Extrapolation::Loop);
        bad.keys[3].posture = posture(0.3);
        assert!(
            bad.validate(&skeleton)
                .expect_err("invalid")
                .contains("last key")
        );
        let mut bad = motion(Extrapolation::Clamp);
        bad.keys[0].posture.angles_rad.push(0.0);
        assert!(
            bad.validate(&skeleton)
                .expect_err("invalid")
                .contains("3 angles")
        );
    }
}
