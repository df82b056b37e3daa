//! A smooth beat phase for a dancer to move on. The phase a dancer hears is predicted from the
//! tracker's beat grid some frames earlier, and the tracker re-anchors its grid around every
//! beat by a few tens of ms: frame to frame, the heard phase then steps back and forth right at
//! the beat — where a dancer's motion is slowest, so each step shows as a spurious kinematic
//! beat. The follower advances at the heard tempo and pulls toward the heard phase gently, so
//! its phase runs on; a large disagreement (a new tempo, a re-lock) is taken at once.

/// How far ahead of the heard beat the retrieval dancer's clips are timed, seconds: a clip's
/// visible hit (its slowest point, a kinematic beat) comes about this much after the beat it
/// was cut on. Tuned on rendered songs of seeds ≥ 1000 (BeatAlign 0.40 / 0.45 / 0.47 / 0.44 at
/// 0 / 20 / 40 / 60 ms); the neural dancer times its own hits (best at 0).
pub const HIT_LEAD_S: f32 = 0.04;

/// Share of the disagreement corrected per frame.
const PULL: f32 = 0.25;
/// Disagreement beyond which the heard phase is taken as it is, in beats.
const SNAP_BEATS: f32 = 0.2;

/// Follows a heard beat phase smoothly (see the module docs); allocation-free.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhaseFollower {
    phase: Option<f32>,
}

impl PhaseFollower {
    /// A follower that takes its first heard phase as it is.
    pub fn new() -> Self {
        Self { phase: None }
    }

    /// Forgets the phase followed so far.
    pub fn reset(&mut self) {
        self.phase = None;
    }

    /// Takes the phase heard this frame (in [0, 1)) with the tempo (BPM, 0 = none) at `fps`
    /// frames per second; returns the phase to move on, in [0, 1).
    pub fn follow(&mut self, heard: f32, tempo_bpm: f32, fps: f32) -> f32 {
        let heard = if heard.is_finite() {
            heard.rem_euclid(1.0)
        } else {
            0.0
        };
        let advance = if tempo_bpm.is_finite() && tempo_bpm > 0.0 && fps > 0.0 {
            tempo_bpm / 60.0 / fps
        } else {
            0.0
        };
        let next = match self.phase {
            Some(p) if advance > 0.0 => {
                let ahead = p + advance;
                let error = (heard - ahead + 0.5).rem_euclid(1.0) - 0.5;
                if error.abs() > SNAP_BEATS {
                    heard
                } else {
                    ahead + PULL * error
                }
            }
            _ => heard,
        };
        let next = wrap(next);
        self.phase = Some(next);
        next
    }

    /// [`Self::follow`], then moved `lead_s` seconds ahead at the tempo (see [`HIT_LEAD_S`]).
    pub fn follow_ahead(&mut self, heard: f32, tempo_bpm: f32, fps: f32, lead_s: f32) -> f32 {
        let p = self.follow(heard, tempo_bpm, fps);
        if tempo_bpm.is_finite() && tempo_bpm > 0.0 && lead_s.is_finite() {
            wrap(p + lead_s * tempo_bpm / 60.0)
        } else {
            p
        }
    }
}

/// `x` in [0, 1).
fn wrap(x: f32) -> f32 {
    let x = x.rem_euclid(1.0);
    if x >= 1.0 { 0.0 } else { x }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_on_through_jitter_and_snaps_to_a_new_phase() {
        let mut f = PhaseFollower::new();
        // 120 BPM at 25 fps: 0.08 beats a frame; the heard phase jitters by ±0.035 beats.
        let mut worst_step = 0.0f32;
        let mut prev = f.follow(0.0, 120.0, 25.0);
        for k in 1..200 {
            let jitter = if k % 6 == 0 {
                0.035
            } else if k % 6 == 1 {
                -0.035
            } else {
                0.0
            };
            let p = f.follow((0.08 * k as f32 + jitter).rem_euclid(1.0), 120.0, 25.0);
            let step = (p - prev).rem_euclid(1.0);
            worst_step = worst_step.max((step - 0.08).abs());
            prev = p;
        }
        assert!(worst_step < 0.012, "{worst_step}");
        // A jump of half a beat is taken at once.
        let p = f.follow((prev + 0.08 + 0.5).rem_euclid(1.0), 120.0, 25.0);
        assert!(((p - prev).rem_euclid(1.0) - 0.58).abs() < 1e-5);
        // No tempo: the heard phase as it is.
        assert_eq!(f.follow(0.3, 0.0, 25.0), 0.3);
    }
}
