//! The frame a receiver gets: a pose on the default rig, forward-kinematised into a
//! [`BodyFrame`] in Unity coordinates and stamped with when it should be shown. The sender
//! thread, the browser view's playback and the lag bench's reference all build frames here.

use std::time::{Duration, SystemTime};

use glam::{Quat, Vec3};
use model::rig::{JOINT_COUNT, Joint, Pose, Skeleton, to_unity_position, to_unity_rotation};
use protocols::{BodyFrame, BoneSample};

/// Builds [`BodyFrame`]s from poses without allocating after the first frame.
pub struct FrameBuilder {
    skeleton: Skeleton,
    frame: BodyFrame,
    positions: [Vec3; JOINT_COUNT],
    rotations: [Quat; JOINT_COUNT],
}

impl Default for FrameBuilder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameBuilder {
    /// A builder on the default adult rig.
    pub fn new() -> Self {
        Self {
            skeleton: Skeleton::default_adult(),
            frame: BodyFrame {
                frame_index: 0,
                audio_time_s: 0.0,
                timetag: SystemTime::UNIX_EPOCH,
                root_position: Vec3::ZERO,
                root_rotation: Quat::IDENTITY,
                bones: Vec::with_capacity(JOINT_COUNT),
            },
            positions: [Vec3::ZERO; JOINT_COUNT],
            rotations: [Quat::IDENTITY; JOINT_COUNT],
        }
    }

    /// The frame for `pose`, stamped with `audio_time_s` and the wall-clock time `lead_s` from
    /// now (when it should be shown).
    pub fn build(&mut self, index: u64, audio_time_s: f64, pose: &Pose, lead_s: f64) -> &BodyFrame {
        self.skeleton
            .forward_kinematics(pose, &mut self.positions, &mut self.rotations);
        let f = &mut self.frame;
        f.frame_index = index;
        f.audio_time_s = audio_time_s;
        let now = SystemTime::now();
        let lead = Duration::from_secs_f64(lead_s.abs().min(10.0));
        f.timetag = if lead_s >= 0.0 {
            now + lead
        } else {
            now.checked_sub(lead).unwrap_or(now)
        };
        f.root_position = to_unity_position(pose.root_position);
        f.root_rotation = to_unity_rotation(self.rotations[0]);
        f.bones.clear();
        for joint in Joint::ALL {
            let i = joint.index();
            let local_position = if joint.parent().is_some() {
                self.skeleton.offsets[i]
            } else {
                pose.root_position
            };
            f.bones.push(BoneSample {
                bone: joint.name(),
                local_position: to_unity_position(local_position),
                local_rotation: to_unity_rotation(pose.local_rotations[i]),
                world_position: to_unity_position(self.positions[i]),
                world_rotation: to_unity_rotation(self.rotations[i]),
            });
        }
        &self.frame
    }
}
