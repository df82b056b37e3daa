//! Key poses cued "on the next bar", measured from outside: a song is replayed in real time,
//! cues go in through the control path at chosen heard times, and the motion is received over
//! UDP (native OSC) and put on the replay clock, as for the motion lag
//! ([`super::lag`]). A dancer that stands still and snaps into each key pose on the
//! frame it is due shows exactly when the pipeline made the pose land; that time is compared
//! with the song's true downbeats.

use anyhow::Result;
use glam::{Quat, Vec3};
use model::rig::{JOINT_COUNT, Joint, Pose};
use model::source::{Controls, MotionSource};

use super::lag::{BodyShape, LagRun, body_shapes, replay_and_receive};
use crate::live::sink::MemoryPoseBank;
use crate::live::wire::{ControlEvent, Quantize};

/// A cue counts as on the bar when it lands within this of a true downbeat, seconds.
pub const HIT_TOLERANCE_S: f64 = 0.07;
/// Share of the way from one key pose to the other a frame must show to count as there.
const REACHED: f32 = 0.95;
/// Names of the two key poses the cues alternate between.
const POSES: [&str; 2] = ["cue-a", "cue-b"];

/// Stands in its rest pose and snaps into a key pose on the frame it is due.
pub struct CueSnapper {
    pose: Pose,
}

impl Default for CueSnapper {
    fn default() -> Self {
        Self { pose: Pose::rest() }
    }
}

impl MotionSource for CueSnapper {
    fn frame_rate(&self) -> f64 {
        25.0
    }
    fn lookahead_frames(&self) -> usize {
        0
    }
    fn step(
        &mut self,
        _music: &[[f32; dsp::feature::FEATURE_DIM]],
        controls: &Controls,
        out: &mut Pose,
    ) {
        if let Some(k) = controls.key_pose
            && k.frames_to_go == 0
        {
            self.pose.local_rotations = k.rotations;
        }
        *out = self.pose;
    }
    fn reset(&mut self, _seed: u64) {}
    fn reseed(&mut self, _seed: u64) {}
}

/// The rotations of key pose `i`: the left arm raised (0) or lowered (1).
fn key_rotations(i: usize) -> [Quat; JOINT_COUNT] {
    let mut pose = Pose::rest();
    let angle = if i == 0 { 1.2 } else { -0.6 };
    pose.set_rotation(Joint::LeftUpperArm, Quat::from_rotation_z(angle));
    pose.local_rotations
}

/// One cue and where it landed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CueLanding {
    /// Heard time the cue was sent at, seconds.
    pub cued_s: f64,
    /// Heard time the receiver first saw the pose, seconds (None: never).
    pub landed_s: Option<f64>,
    /// Distance from the landing to the nearest true downbeat, seconds.
    pub error_s: Option<f64>,
    /// Whether that downbeat is the first one at least `min_notice_s` after the cue.
    pub next_bar: bool,
}

impl CueLanding {
    /// Whether the cue landed within [`HIT_TOLERANCE_S`] of a true downbeat.
    pub fn hit(&self) -> bool {
        self.error_s.is_some_and(|e| e.abs() <= HIT_TOLERANCE_S)
    }
}

/// How far along from shape `a` to shape `b` the shape `x` is (0 at `a`, 1 at `b`).
fn progress(x: &[Vec3], a: &[Vec3], b: &[Vec3]) -> f32 {
    let (mut num, mut den) = (0.0f32, 0.0f32);
    for ((x, a), b) in x.iter().zip(a).zip(b) {
        let d = *b - *a;
        num += (*x - *a).dot(d);
        den += d.length_squared();
    }
    if den > 0.0 { num / den } else { 0.0 }
}

/// Replays `run.audio` with a [`CueSnapper`], cueing a key pose on the next bar at each heard
/// time in `cue_times_s`; returns where each landed against the song's `downbeats_s`. A cue
/// whose first downbeat comes sooner than `min_notice_s` after it is expected one bar later.
pub fn measure_bar_cues(
    run: &LagRun<'_>,
    cue_times_s: &[f64],
    downbeats_s: &[f64],
    min_notice_s: f64,
) -> Result<Vec<CueLanding>> {
    let mut bank = MemoryPoseBank::new();
    for (i, name) in POSES.iter().enumerate() {
        bank.insert(*name, key_rotations(i));
    }
    let cues: Vec<(f64, ControlEvent)> = cue_times_s
        .iter()
        .enumerate()
        .map(|(i, &t)| {
            (
                t,
                ControlEvent::KeyPose {
                    name: POSES[i % 2].to_string(),
                    quantize: Quantize::NextBar,
                },
            )
        })
        .collect();
    let got = replay_and_receive(run, Box::new(CueSnapper::default()), &bank, &cues)?;
    // Shapes of the two key poses, then of the rest pose the dancer starts in.
    let shapes: Vec<BodyShape> = body_shapes(
        &[0, 1]
            .map(|i| Pose {
                local_rotations: key_rotations(i),
                ..Pose::rest()
            })
            .into_iter()
            .chain([Pose::rest()])
            .collect::<Vec<_>>(),
    );
    let lead_s = run.lead_ms * 1e-3;
    Ok(cue_times_s
        .iter()
        .enumerate()
        .map(|(i, &cued_s)| {
            let from = if i == 0 {
                &shapes[2]
            } else {
                &shapes[(i + 1) % 2]
            };
            let to = &shapes[i % 2];
            let until = cue_times_s.get(i + 1).copied().unwrap_or(f64::INFINITY);
            let landed_s = got
                .frames
                .iter()
                .filter(|(h, _)| *h >= cued_s && *h < until)
                .find(|(_, s)| progress(s, from, to) >= REACHED)
                .map(|(h, _)| h + lead_s);
            let nearest = landed_s.and_then(|l| {
                downbeats_s
                    .iter()
                    .copied()
                    .min_by(|a, b| (a - l).abs().total_cmp(&(b - l).abs()))
            });
            let expected = downbeats_s
                .iter()
                .copied()
                .find(|&d| d >= cued_s + min_notice_s);
            CueLanding {
                cued_s,
                landed_s,
                error_s: landed_s.zip(nearest).map(|(l, d)| l - d),
                next_bar: nearest.is_some() && nearest == expected,
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_runs_from_one_shape_to_the_other() {
        let a = vec![Vec3::ZERO, Vec3::X];
        let b = vec![Vec3::Y, Vec3::X + Vec3::Y];
        let mid: Vec<Vec3> = a.iter().zip(&b).map(|(a, b)| (*a + *b) / 2.0).collect();
        assert_eq!(progress(&a, &a, &b), 0.0);
        assert_eq!(progress(&b, &a, &b), 1.0);
        assert!((progress(&mid, &a, &b) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn the_snapper_moves_only_on_the_due_frame() {
        let mut s = CueSnapper::default();
        let mut out = Pose::rest();
        let mut controls = Controls {
            key_pose: Some(model::source::KeyPoseTarget {
                rotations: key_rotations(0),
                frames_to_go: 3,
            }),
            ..Controls::default()
        };
        s.step(&[], &controls, &mut out);
        assert_eq!(out.local_rotations, Pose::rest().local_rotations);
        controls.key_pose.as_mut().unwrap().frames_to_go = 0;
        s.step(&[], &controls, &mut out);
        assert_eq!(out.local_rotations, key_rotations(0));
    }
}
