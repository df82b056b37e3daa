//! Key poses on a timeline, for offline generation and evaluation: "reach `pose-3` at 12.5 s",
//! announced a fixed lead before, as the live daemon announces one quantised to a coming beat.

use anyhow::{Context, Result, bail};
use glam::{Quat, Vec3};
use model::motion::{heading, yaw};
use model::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use model::source::KeyPoseTarget;

/// One key pose to reach at a moment.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyCue {
    /// Its name in the pose bank (for messages).
    pub name: String,
    /// Target rotations.
    pub rotations: [Quat; JOINT_COUNT],
    /// Frame at which it must be reached.
    pub frame: usize,
}

/// Parses `NAME@SECONDS` (e.g. `pose-3@12.5`).
pub fn parse_cue_spec(spec: &str) -> Result<(String, f64)> {
    let Some((name, at)) = spec.rsplit_once('@') else {
        bail!("key pose {spec:?}: expected NAME@SECONDS, e.g. pose-3@12.5");
    };
    let at: f64 = at
        .parse()
        .with_context(|| format!("key pose {spec:?}: {at:?} is not a time in seconds"))?;
    if !(at.is_finite() && at >= 0.0) {
        bail!("key pose {spec:?}: the time must be ≥ 0 s");
    }
    Ok((name.to_string(), at))
}

/// The key-pose control for `frame`: the next cue not yet passed, once it is at most
/// `lead_frames` away.
pub fn target_at(cues: &[KeyCue], frame: usize, lead_frames: usize) -> Option<KeyPoseTarget> {
    cues.iter()
        .filter(|c| c.frame >= frame && c.frame - frame <= lead_frames)
        .min_by_key(|c| c.frame)
        .map(|c| KeyPoseTarget {
            rotations: c.rotations,
            frames_to_go: (c.frame - frame) as u32,
        })
}

/// A pose's body shape: joint positions relative to the hips with the heading removed, on the
/// default rig (what a key pose fixes; where the dancer stands and faces is not part of it).
pub fn body_shape(rotations: &[Quat; JOINT_COUNT]) -> [Vec3; JOINT_COUNT] {
    let mut pose = Pose::rest();
    pose.local_rotations = *rotations;
    let h = heading(pose.local_rotations[0]);
    pose.local_rotations[0] = (yaw(-h) * pose.local_rotations[0]).normalize();
    pose.root_position = Vec3::ZERO;
    let mut w = [Vec3::ZERO; JOINT_COUNT];
    Skeleton::default_adult().world_positions(&pose, &mut w);
    let hips = w[Joint::Hips.index()];
    w.map(|p| p - hips)
}

/// Mean joint position error between a pose and a key pose, cm (body shape only: where the
/// dancer stands and which way it faces are not part of a key pose).
pub fn key_pose_error_cm(pose: &Pose, target: &[Quat; JOINT_COUNT]) -> f64 {
    let (a, b) = (body_shape(&pose.local_rotations), body_shape(target));
    100.0
        * a.iter()
            .zip(&b)
            .map(|(x, y)| x.distance(*y) as f64)
            .sum::<f64>()
        / JOINT_COUNT as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_or_name_the_problem() {
        assert_eq!(
            parse_cue_spec("pose-3@12.5").unwrap(),
            ("pose-3".into(), 12.5)
        );
        assert_eq!(parse_cue_spec("a@b@2").unwrap(), ("a@b".into(), 2.0));
        for bad in ["pose-3", "pose-3@x", "pose-3@-1", "p@nan"] {
            let e = format!("{:#}", parse_cue_spec(bad).unwrap_err());
            assert!(e.contains(bad), "{e}");
        }
    }

    #[test]
    fn targets_count_down_to_their_frame_and_stop() {
        let cue = |frame| KeyCue {
            name: "x".into(),
            rotations: [Quat::IDENTITY; JOINT_COUNT],
            frame,
        };
        let cues = [cue(100), cue(130)];
        assert!(target_at(&cues, 40, 50).is_none());
        assert_eq!(target_at(&cues, 50, 50).unwrap().frames_to_go, 50);
        assert_eq!(target_at(&cues, 100, 50).unwrap().frames_to_go, 0);
        assert_eq!(target_at(&cues, 101, 50).unwrap().frames_to_go, 29);
        assert!(target_at(&cues, 131, 50).is_none());
    }

    #[test]
    fn error_ignores_heading_and_sees_an_arm() {
        let rest = [Quat::IDENTITY; JOINT_COUNT];
        let mut turned = Pose::rest();
        turned.local_rotations[0] = Quat::from_rotation_y(1.3);
        assert!(key_pose_error_cm(&turned, &rest) < 1e-3);
        let mut arm = Pose::rest();
        arm.set_rotation(Joint::LeftUpperArm, Quat::from_rotation_z(1.0));
        let e = key_pose_error_cm(&arm, &rest);
        // Elbow, hand move by tens of cm; averaged over 22 joints it is a few cm.
        assert!(e > 1.0 && e < 10.0, "{e}");
    }
}
