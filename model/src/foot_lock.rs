//! [`FootLock`]: moves a generated dancer over the floor so that a planted foot stays where it
//! was put.
//!
//! A network that predicts its root's displacement separately from its legs lets the body
//! glide while the stance foot is on the floor (foot skating: 0.6–1.0 m/s for the neural
//! dancer against 0.43 m/s for the motion captures). Here the root takes the blame: while a
//! toe is planted, the whole body is shifted back by the toe's horizontal drift since the
//! last frame (or a share of it, [`FootLock::strength`]). The legs are untouched (no IK), so
//! the correction costs one forward kinematics pass per frame and cannot bend a joint the wrong
//! way.

use glam::{Quat, Vec3};

use crate::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use crate::source::finite_clamp;

/// A toe lower than this above the floor (y = 0) may be planted, metres (the dance metrics'
/// contact height).
pub const CONTACT_HEIGHT_M: f32 = 0.05;

/// …and only while it moves vertically slower than this, m/s (the metrics' threshold: a toe
/// being lifted or set down moves at 0.3 m/s or more).
pub const CONTACT_VERTICAL_SPEED_MPS: f32 = 0.1;

/// A drift longer than this in one frame is a jump of the pose (a restart), not skating, m.
pub const MAX_CORRECTION_M: f32 = 0.1;

/// Share of a planted toe's drift the neural dancer takes back. The captures' own feet glide
/// (ballroom: 0.43 m/s while planted) and the body's travel is part of how a dance looks:
/// measured on the validation songs at T = 0.5, a full lock cut foot skating from 0.69 to
/// 0.35 m/s but raised FID_k from 30 to 44; 0.6 gave 0.48 m/s at FID_k 31, 0.3 gave 0.58 at 29.
pub const DEFAULT_STRENGTH: f32 = 0.5;

/// The two toes, whose contact is tracked.
const TOES: [Joint; 2] = [Joint::LeftToes, Joint::RightToes];

/// Streaming foot-plant correction of the root position.
pub struct FootLock {
    skeleton: Skeleton,
    frame_rate: f32,
    strength: f32,
    offset: Vec3,
    last_toes: [Vec3; 2],
    primed: bool,
    positions: [Vec3; JOINT_COUNT],
    rotations: [Quat; JOINT_COUNT],
}

impl FootLock {
    /// A foot lock for poses of `skeleton` arriving at `frame_rate` frames per second that takes
    /// back `strength` (in [0, 1]; clamped, non-finite = 0) of a planted toe's drift.
    pub fn new(skeleton: Skeleton, frame_rate: f32, strength: f32) -> Self {
        FootLock {
            skeleton,
            frame_rate,
            strength: finite_clamp(strength, 0.0, 1.0),
            offset: Vec3::ZERO,
            last_toes: [Vec3::ZERO; 2],
            primed: false,
            positions: [Vec3::ZERO; JOINT_COUNT],
            rotations: [Quat::IDENTITY; JOINT_COUNT],
        }
    }

    /// Share of a planted toe's drift taken back.
    pub fn strength(&self) -> f32 {
        self.strength
    }

    /// Sets the share of a planted toe's drift taken back (0 turns the lock off).
    pub fn set_strength(&mut self, strength: f32) {
        self.strength = finite_clamp(strength, 0.0, 1.0);
    }

    /// Forgets the previous frame and the correction so far.
    pub fn reset(&mut self) {
        self.offset = Vec3::ZERO;
        self.primed = false;
    }

    /// Shifts `pose` over the floor by the correction so far and, if a toe is planted, by that
    /// toe's drift since the last frame (the lower toe when both are).
    pub fn process(&mut self, pose: &mut Pose) -> bool {
        pose.root_position += self.offset;
        self.skeleton
            .forward_kinematics(pose, &mut self.positions, &mut self.rotations);
        let mut toes = TOES.map(|t| self.positions[t.index()]);
        let mut moved = false;
        if self.primed {
            let mut planted: Option<(f32, Vec3)> = None;
            for (now, before) in toes.iter().zip(&self.last_toes) {
                let rising = (now.y - before.y).abs() * self.frame_rate;
                let drift = (*now - *before).with_y(0.0);
                let down = now.y < CONTACT_HEIGHT_M
                    && before.y < CONTACT_HEIGHT_M
                    && rising < CONTACT_VERTICAL_SPEED_MPS
                    && drift.length() < MAX_CORRECTION_M;
                if down && planted.is_none_or(|(y, _)| now.y < y) {
                    planted = Some((now.y, drift));
                }
            }
            if let Some((_, drift)) = planted {
                let drift = self.strength * drift;
                moved = drift != Vec3::ZERO;
                pose.root_position -= drift;
                self.offset -= drift;
                for t in toes.iter_mut() {
                    *t -= drift;
                }
            }
        }
        self.last_toes = toes;
        self.primed = true;
        moved
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pose standing with its toes on the floor, the hips at `x` along the floor.
    fn standing_at(skeleton: &Skeleton, x: f32) -> Pose {
        let mut pose = skeleton.rest_pose();
        let mut p = [Vec3::ZERO; JOINT_COUNT];
        skeleton.world_positions(&pose, &mut p);
        let lowest = TOES.iter().map(|t| p[t.index()].y).fold(f32::MAX, f32::min);
        pose.root_position.y -= lowest;
        pose.root_position.x = x;
        pose
    }

    #[test]
    fn a_gliding_body_with_planted_feet_stays_put() {
        let skeleton = Skeleton::default_adult();
        // The network slides the whole body 1 m/s sideways with both feet down.
        let glide = |strength: f32| {
            let mut lock = FootLock::new(skeleton, 25.0, strength);
            let mut x = 0.0;
            for f in 0..50 {
                let mut pose = standing_at(&skeleton, f as f32 * 0.04);
                lock.process(&mut pose);
                x = pose.root_position.x;
            }
            x
        };
        assert!(glide(1.0).abs() < 1e-4, "{}", glide(1.0));
        assert!((glide(0.5) - 0.98).abs() < 1e-3, "{}", glide(0.5));
        assert!((glide(0.0) - 1.96).abs() < 1e-4, "{}", glide(0.0));
        assert_eq!(glide(f32::NAN), glide(0.0));
    }

    #[test]
    fn a_lifted_body_moves_freely_and_keeps_its_correction() {
        let skeleton = Skeleton::default_adult();
        let mut lock = FootLock::new(skeleton, 25.0, 1.0);
        let mut pose = standing_at(&skeleton, 0.0);
        lock.process(&mut pose);
        let mut pose = standing_at(&skeleton, 0.04);
        assert!(
            lock.process(&mut pose),
            "a planted foot's drift is taken back"
        );
        assert!(pose.root_position.x.abs() < 1e-4);
        // In the air (toes 20 cm up) the body travels as generated, from where it was held.
        for f in 2..10 {
            let mut pose = standing_at(&skeleton, f as f32 * 0.04);
            pose.root_position.y += 0.2;
            assert!(!lock.process(&mut pose), "nothing to take back in the air");
            let want = (f - 1) as f32 * 0.04;
            assert!(
                (pose.root_position.x - want).abs() < 1e-4,
                "{f}: {}",
                pose.root_position.x
            );
        }
        // A jump of the pose (a restart) is not pulled back.
        let mut lock = FootLock::new(skeleton, 25.0, 1.0);
        let mut pose = standing_at(&skeleton, 0.0);
        lock.process(&mut pose);
        let mut pose = standing_at(&skeleton, 0.5);
        lock.process(&mut pose);
        assert!((pose.root_position.x - 0.5).abs() < 1e-4);
        lock.reset();
        let mut pose = standing_at(&skeleton, 0.7);
        lock.process(&mut pose);
        assert!((pose.root_position.x - 0.7).abs() < 1e-4);
    }
}
