//! [`FootLock`]: keeps a generated dancer's planted foot where it was put, by moving the body
//! over the floor and by bending the stance leg.
//!
//! A network that predicts its root's displacement separately from its legs lets the body
//! glide while the stance foot is on the floor (foot skating: 0.6–1.0 m/s for the neural
//! dancer against 0.43 m/s for the motion captures). Two corrections share the blame. The root:
//! while a toe is planted the whole body is shifted back by a share of the toe's horizontal
//! drift since the last frame ([`FootLock::strength`]); that also stops the body's travel,
//! which is part of how a dance looks. The leg: a share of the drift left
//! ([`FootLock::plant`]) is held by turning the stance leg's hip and knee
//! ([`reach_with_leg`]) so the toe stays put while the body travels on; once the foot lifts,
//! the hold lets go over [`RELEASE_S`], so the foot catches up in the air instead of jumping.

use glam::{Quat, Vec3};

use crate::leg_ik::reach_with_leg;
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

/// Share of a planted toe's drift the neural dancer takes back by moving the body. The
/// captures' own feet glide (ballroom: 0.43 m/s while planted) and the body's travel is part
/// of how a dance looks: with the body alone, a full lock cut the shipped model's foot skating
/// from 0.67 to 0.34 m/s but raised FID_k from 29 to 44 (validation songs, T = 0.5, 3 seeds).
pub const DEFAULT_STRENGTH: f32 = 0.25;

/// Share of the drift left after the body's shift that the stance leg holds by default: the
/// whole. Measured as above (the shipped model, seeds 1–3): the body's half alone (before)
/// skated 0.49 m/s at FID_k 28.0, Dist_k 5.83; a quarter by the body and the rest by the leg
/// skates 0.25 m/s at FID_k 26.6, Dist_k 6.17; the leg alone (no shift) 0.32 m/s at 29.0,
/// since a leg reaches only [`MAX_HOLD_M`].
pub const DEFAULT_PLANT: f32 = 1.0;

/// Farthest a leg holds its toe from where the network puts it, m (a stride's worth; beyond
/// it the toe slides along with the body).
pub const MAX_HOLD_M: f32 = 0.25;

/// Time constant over which a lifted foot's hold lets go, s.
pub const RELEASE_S: f32 = 0.08;

/// The two toes, whose contact is tracked, and the hip joints of their legs.
const TOES: [Joint; 2] = [Joint::LeftToes, Joint::RightToes];
const LEGS: [Joint; 2] = [Joint::LeftUpperLeg, Joint::RightUpperLeg];

/// Streaming foot-plant correction of the root position and the stance leg.
pub struct FootLock {
    skeleton: Skeleton,
    frame_rate: f32,
    strength: f32,
    plant: f32,
    offset: Vec3,
    /// Where each toe is held, relative to where the network (and the body's shift) put it.
    holds: [Vec3; 2],
    last_toes: [Vec3; 2],
    primed: bool,
    positions: [Vec3; JOINT_COUNT],
    rotations: [Quat; JOINT_COUNT],
}

impl FootLock {
    /// A foot lock for poses of `skeleton` arriving at `frame_rate` frames per second that takes
    /// back `strength` (in [0, 1]; clamped, non-finite = 0) of a planted toe's drift by moving
    /// the body; the leg holds nothing until [`FootLock::set_plant`].
    pub fn new(skeleton: Skeleton, frame_rate: f32, strength: f32) -> Self {
        FootLock {
            skeleton,
            frame_rate,
            strength: finite_clamp(strength, 0.0, 1.0),
            plant: 0.0,
            offset: Vec3::ZERO,
            holds: [Vec3::ZERO; 2],
            last_toes: [Vec3::ZERO; 2],
            primed: false,
            positions: [Vec3::ZERO; JOINT_COUNT],
            rotations: [Quat::IDENTITY; JOINT_COUNT],
        }
    }

    /// This lock with the stance leg holding `plant` of the drift (see [`FootLock::set_plant`]).
    pub fn with_plant(mut self, plant: f32) -> Self {
        self.set_plant(plant);
        self
    }

    /// Share of a planted toe's drift taken back by moving the body.
    pub fn strength(&self) -> f32 {
        self.strength
    }

    /// Sets the share of a planted toe's drift taken back by moving the body (0: none).
    pub fn set_strength(&mut self, strength: f32) {
        self.strength = finite_clamp(strength, 0.0, 1.0);
    }

    /// Share of the drift left after the body's shift that the stance leg holds.
    pub fn plant(&self) -> f32 {
        self.plant
    }

    /// Sets the share of the drift left after the body's shift that the stance leg holds
    /// (in [0, 1]; clamped, non-finite = 0; 0: the legs are never touched).
    pub fn set_plant(&mut self, plant: f32) {
        self.plant = finite_clamp(plant, 0.0, 1.0);
    }

    /// Forgets the previous frame and the corrections so far.
    pub fn reset(&mut self) {
        self.offset = Vec3::ZERO;
        self.holds = [Vec3::ZERO; 2];
        self.primed = false;
    }

    /// Shifts `pose` over the floor by the correction so far and, if a toe is planted, by that
    /// toe's drift since the last frame (the lower toe when both are); then bends each leg
    /// whose toe is held. Each frame keeps `hold` (in [0, 1]) of the holds so far: below 1 the
    /// legs let go and come out as generated at 0 (a key pose's blend must land the pose as
    /// given, and nothing is left to spring back after it). True if anything moved.
    pub fn process(&mut self, pose: &mut Pose, hold: f32) -> bool {
        pose.root_position += self.offset;
        self.skeleton
            .forward_kinematics(pose, &mut self.positions, &mut self.rotations);
        let mut toes = TOES.map(|t| self.positions[t.index()]);
        let mut moved = false;
        let mut down = [false; 2];
        let mut drifts = [Vec3::ZERO; 2];
        if self.primed {
            let mut planted: Option<(f32, Vec3)> = None;
            for (i, (now, before)) in toes.iter().zip(&self.last_toes).enumerate() {
                let rising = (now.y - before.y).abs() * self.frame_rate;
                drifts[i] = (*now - *before).with_y(0.0);
                down[i] = now.y < CONTACT_HEIGHT_M
                    && before.y < CONTACT_HEIGHT_M
                    && rising < CONTACT_VERTICAL_SPEED_MPS
                    && drifts[i].length() < MAX_CORRECTION_M;
                if down[i] && planted.is_none_or(|(y, _)| now.y < y) {
                    planted = Some((now.y, drifts[i]));
                }
            }
            if let Some((_, drift)) = planted {
                let drift = self.strength * drift;
                moved = drift != Vec3::ZERO;
                pose.root_position -= drift;
                self.offset -= drift;
                for (t, d) in toes.iter_mut().zip(drifts.iter_mut()) {
                    *t -= drift;
                    *d -= drift;
                }
                for p in self.positions.iter_mut() {
                    *p -= drift;
                }
            }
        }
        self.last_toes = toes;
        self.primed = true;
        if self.plant > 0.0 || self.holds != [Vec3::ZERO; 2] {
            moved |= self.hold_legs(pose, down, drifts, finite_clamp(hold, 0.0, 1.0));
        }
        moved
    }

    /// Updates each toe's hold from its contact and drift and bends the legs to it.
    fn hold_legs(
        &mut self,
        pose: &mut Pose,
        down: [bool; 2],
        drifts: [Vec3; 2],
        hold: f32,
    ) -> bool {
        let release = (-1.0 / (self.frame_rate * RELEASE_S)).exp();
        let mut moved = false;
        for i in 0..2 {
            let h = &mut self.holds[i];
            if down[i] && self.plant > 0.0 {
                *h -= self.plant * drifts[i];
            } else {
                *h *= release;
            }
            *h *= hold;
            *h = h.clamp_length_max(MAX_HOLD_M);
            if h.length() < 1e-4 {
                *h = Vec3::ZERO;
                continue;
            }
            moved |= reach_with_leg(
                &self.skeleton,
                pose,
                &mut self.positions,
                &mut self.rotations,
                LEGS[i],
                *h,
            );
        }
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
                lock.process(&mut pose, 1.0);
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
        lock.process(&mut pose, 1.0);
        let mut pose = standing_at(&skeleton, 0.04);
        assert!(
            lock.process(&mut pose, 1.0),
            "a planted foot's drift is taken back"
        );
        assert!(pose.root_position.x.abs() < 1e-4);
        // In the air (toes 20 cm up) the body travels as generated, from where it was held.
        for f in 2..10 {
            let mut pose = standing_at(&skeleton, f as f32 * 0.04);
            pose.root_position.y += 0.2;
            assert!(
                !lock.process(&mut pose, 1.0),
                "nothing to take back in the air"
            );
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
        lock.process(&mut pose, 1.0);
        let mut pose = standing_at(&skeleton, 0.5);
        lock.process(&mut pose, 1.0);
        assert!((pose.root_position.x - 0.5).abs() < 1e-4);
        lock.reset();
        let mut pose = standing_at(&skeleton, 0.7);
        lock.process(&mut pose, 1.0);
        assert!((pose.root_position.x - 0.7).abs() < 1e-4);
    }

    /// As [`standing_at`], knees bent (a straight leg cannot hold a toe that the body leaves
    /// behind: it would have to stretch).
    fn crouching_at(skeleton: &Skeleton, x: f32) -> Pose {
        let mut pose = skeleton.rest_pose();
        crate::leg_ik::tests::bend_knees(&mut pose);
        let lowest = toes(skeleton, &pose)
            .iter()
            .map(|t| t.y)
            .fold(f32::MAX, f32::min);
        pose.root_position.y -= lowest;
        pose.root_position.x = x;
        pose
    }

    fn toes(skeleton: &Skeleton, pose: &Pose) -> [Vec3; 2] {
        let mut p = [Vec3::ZERO; JOINT_COUNT];
        skeleton.world_positions(pose, &mut p);
        TOES.map(|t| p[t.index()])
    }

    #[test]
    fn a_planted_leg_holds_its_toe_while_the_body_travels_on() {
        let skeleton = Skeleton::default_adult();
        // The body glides 0.5 m/s (2 cm a frame) with both feet down: nothing but the legs holds.
        let mut lock = FootLock::new(skeleton, 25.0, 0.0).with_plant(1.0);
        let start = toes(&skeleton, &crouching_at(&skeleton, 0.0));
        for f in 0..10 {
            let mut pose = crouching_at(&skeleton, f as f32 * 0.02);
            assert_eq!(lock.process(&mut pose, 1.0), f > 0);
            assert!(
                (pose.root_position.x - f as f32 * 0.02).abs() < 1e-6,
                "the body travels"
            );
            for (now, was) in toes(&skeleton, &pose).iter().zip(&start) {
                assert!(now.distance(*was) < 1e-3, "{f}: {now} from {was}");
            }
        }
        // Half the plant: the toes move half as far as the body.
        let mut half = FootLock::new(skeleton, 25.0, 0.0).with_plant(0.5);
        let mut pose = crouching_at(&skeleton, 0.0);
        for f in 0..10 {
            pose = crouching_at(&skeleton, f as f32 * 0.02);
            half.process(&mut pose, 1.0);
        }
        let moved = toes(&skeleton, &pose)[0].x - start[0].x;
        assert!((moved - 0.09).abs() < 1e-3, "{moved}");
        // No plant: the legs are never touched.
        let mut off = FootLock::new(skeleton, 25.0, 0.0);
        let mut pose = crouching_at(&skeleton, 0.1);
        off.process(&mut pose, 1.0);
        let mut pose = crouching_at(&skeleton, 0.12);
        let generated = pose;
        assert!(!off.process(&mut pose, 1.0));
        assert_eq!(pose, generated);
    }

    #[test]
    fn a_held_foot_lets_go_smoothly_in_the_air_and_at_once_for_a_key_pose() {
        let skeleton = Skeleton::default_adult();
        let hold_then_lift = |lock: &mut FootLock| {
            for f in 0..8 {
                lock.process(&mut crouching_at(&skeleton, f as f32 * 0.02), 1.0);
            }
        };
        let mut lock = FootLock::new(skeleton, 25.0, 0.0).with_plant(1.0);
        hold_then_lift(&mut lock);
        // Lifted 20 cm and still travelling: the toes catch up with the generated ones
        // without a jump.
        let mut last = toes(&skeleton, &crouching_at(&skeleton, 0.0));
        let mut behind = 0.0;
        for f in 8..20 {
            let mut pose = crouching_at(&skeleton, f as f32 * 0.02);
            pose.root_position.y += 0.2;
            let generated = toes(&skeleton, &pose);
            lock.process(&mut pose, 1.0);
            let now = toes(&skeleton, &pose);
            assert!(
                now[0].with_y(0.0).distance(last[0].with_y(0.0)) < 0.12,
                "{f}: a jump"
            );
            behind = now[0].distance(generated[0]);
            last = now;
        }
        assert!(behind < 0.005, "{behind}");
        // A key pose's blend (hold 0) gives the generated legs back on that frame.
        let mut lock = FootLock::new(skeleton, 25.0, 0.0).with_plant(1.0);
        hold_then_lift(&mut lock);
        let mut pose = crouching_at(&skeleton, 0.16);
        let generated = pose;
        lock.process(&mut pose, 0.0);
        assert_eq!(pose.local_rotations, generated.local_rotations);
    }
}
