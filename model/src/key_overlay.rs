//! A key pose shown over a dance: how far the pose shown is turned onto the key due, and off
//! the one let go, frame by frame. The dance under it goes on untouched; each dancer applies
//! the weights to its own pose.
//!
//! The turn onto a key takes its last [`KEY_BLEND_FRAMES`] frames (or the whole of a shorter
//! lead), smoothstep; a key reached, cleared or replaced is let go from wherever its blend stood
//! over [`KEY_RELEASE_FRAMES`], so the pose shown never jumps.

use glam::Quat;

use crate::rig::JOINT_COUNT;
use crate::source::KeyPoseTarget;

/// Most frames before a key pose's deadline over which the rotations shown are turned onto it.
pub const KEY_BLEND_FRAMES: u32 = 50;

/// Frames over which the rotations shown glide from a key pose back onto the dance.
pub const KEY_RELEASE_FRAMES: u32 = 50;

/// The state of a key pose shown over a dance.
#[derive(Clone, Debug)]
pub struct KeyOverlay {
    /// Frames from the current cue's announcement to its deadline, and its last count-down.
    lead: u32,
    last_frames_to_go: Option<u32>,
    /// The rotations of the cue being blended in, and of the one being let go.
    target: [Quat; JOINT_COUNT],
    released: [Quat; JOINT_COUNT],
    /// The blend's weight on the last frame, the release's when it began, and the frames since
    /// it began (`u32::MAX`: none).
    blend_last: f32,
    release_from: f32,
    since_release: u32,
}

/// This frame's weights: how far the pose shown turns off the key let go, then onto the key due
/// (`None`: not at all).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OverlayWeights {
    /// Towards [`KeyOverlay::released`].
    pub release: Option<f32>,
    /// Towards [`KeyOverlay::target`].
    pub blend: Option<f32>,
}

impl OverlayWeights {
    /// Whether either weight acts this frame.
    pub fn acts(&self) -> bool {
        self.release.is_some() || self.blend.is_some()
    }
}

impl Default for KeyOverlay {
    fn default() -> Self {
        KeyOverlay {
            lead: 0,
            last_frames_to_go: None,
            target: [Quat::IDENTITY; JOINT_COUNT],
            released: [Quat::IDENTITY; JOINT_COUNT],
            blend_last: 0.0,
            release_from: 0.0,
            since_release: u32::MAX,
        }
    }
}

fn smoothstep(x: f32) -> f32 {
    x * x * (3.0 - 2.0 * x)
}

impl KeyOverlay {
    /// Forgets every cue.
    pub fn reset(&mut self) {
        *self = KeyOverlay::default();
    }

    /// Reads this frame's cue. A count-down that goes up, or other rotations, make a new cue
    /// (a count that stays put is the live clock's rounding); the cue blended in so far is let
    /// go when it is reached, cleared or replaced.
    pub fn read_cue(&mut self, key: Option<&KeyPoseTarget>) {
        let new_cue = match (key, self.last_frames_to_go) {
            (Some(k), Some(last)) => k.frames_to_go > last || k.rotations != self.target,
            (Some(_), None) => true,
            (None, _) => false,
        };
        if (new_cue || key.is_none()) && self.blend_last > 0.0 {
            self.released = self.target;
            self.release_from = self.blend_last;
            self.since_release = 0;
            self.blend_last = 0.0;
        }
        match key {
            Some(k) if new_cue => {
                self.lead = k.frames_to_go.saturating_add(1);
                self.target = k.rotations;
            }
            Some(_) => {}
            None => self.lead = 0,
        }
        self.last_frames_to_go = key.map(|k| k.frames_to_go);
    }

    /// How far into the current cue's arrival this frame is, blended over at most `frames`
    /// frames (smoothstep), with `frames_to_go` left; `None` before the blend begins.
    pub fn arrival(&self, frames_to_go: Option<u32>, frames: u32) -> Option<f32> {
        let frames = frames.min(self.lead);
        frames_to_go
            .filter(|&f| f < frames)
            .map(|f| smoothstep(1.0 - f as f32 / frames as f32))
    }

    /// Advances one shown frame and returns its weights: the blend over at most `blend_frames`
    /// frames, and the release where `release` (the dance is shown under the key, not fed it).
    pub fn weights(
        &mut self,
        frames_to_go: Option<u32>,
        blend_frames: u32,
        release: bool,
    ) -> OverlayWeights {
        self.since_release = self.since_release.saturating_add(1);
        let released = (release && self.since_release < KEY_RELEASE_FRAMES)
            .then(|| {
                let x = 1.0 - self.since_release as f32 / KEY_RELEASE_FRAMES as f32;
                self.release_from * smoothstep(x)
            })
            .filter(|&r| r > 0.0);
        let blend = self.arrival(frames_to_go, blend_frames);
        self.blend_last = blend.unwrap_or(0.0);
        OverlayWeights {
            release: released,
            blend,
        }
    }

    /// Whether no cue was pending at the last frame and none is being let go: read before
    /// this frame's [`KeyOverlay::read_cue`], the next [`KeyOverlay::weights`] would release
    /// nothing and blend in only a cue that starts now.
    pub fn at_rest(&self) -> bool {
        self.lead == 0
            && self.blend_last == 0.0
            && self.since_release.saturating_add(1) >= KEY_RELEASE_FRAMES
    }

    /// The rotations of the cue being blended in.
    pub fn target(&self) -> &[Quat; JOINT_COUNT] {
        &self.target
    }

    /// The rotations of the cue being let go.
    pub fn released(&self) -> &[Quat; JOINT_COUNT] {
        &self.released
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cue(angle: f32, frames_to_go: u32) -> KeyPoseTarget {
        KeyPoseTarget {
            rotations: [Quat::from_rotation_x(angle); JOINT_COUNT],
            frames_to_go,
        }
    }

    /// A cue of `angle` counted down over `frames_to_go`, one frame each.
    fn countdown(
        angle: f32,
        frames_to_go: std::ops::RangeInclusive<u32>,
    ) -> Vec<Option<KeyPoseTarget>> {
        frames_to_go.rev().map(|f| Some(cue(angle, f))).collect()
    }

    /// Steps `overlay` through `cues` (one per frame) and returns each frame's weights.
    fn run(overlay: &mut KeyOverlay, cues: &[Option<KeyPoseTarget>]) -> Vec<OverlayWeights> {
        cues.iter()
            .map(|c| {
                overlay.read_cue(c.as_ref());
                overlay.weights(c.map(|k| k.frames_to_go), KEY_BLEND_FRAMES, true)
            })
            .collect()
    }

    #[test]
    fn a_short_lead_is_blended_over_its_whole_length_and_a_long_one_over_the_last_50_frames() {
        let mut o = KeyOverlay::default();
        let w = run(&mut o, &countdown(0.5, 0..=10));
        // Announced 10 frames ahead: blended from the first frame, onto the key at the last.
        assert!(w[0].blend.unwrap() < 0.05, "{:?}", w[0]);
        assert_eq!(w[10].blend, Some(1.0));
        let mut o = KeyOverlay::default();
        let w = run(&mut o, &countdown(0.5, 0..=80));
        assert_eq!(w.iter().filter(|w| w.blend.is_some()).count(), 50);
    }

    #[test]
    fn a_key_reached_cleared_or_replaced_is_let_go_from_where_its_blend_stood() {
        // Reached: released from 1 over the next 49 frames, decreasing.
        let mut o = KeyOverlay::default();
        let mut cues = countdown(0.5, 0..=20);
        cues.extend(std::iter::repeat_n(None, 60));
        let w = run(&mut o, &cues);
        let released: Vec<f32> = w[21..].iter().filter_map(|w| w.release).collect();
        assert_eq!(released.len(), (KEY_RELEASE_FRAMES - 1) as usize);
        assert!(released[0] > 0.99 && released.windows(2).all(|p| p[1] < p[0]));
        assert_eq!(o.released()[0], Quat::from_rotation_x(0.5));
        // Replaced halfway by another pose due later: the first is released from the weight
        // it had, the second blended from its own start.
        let mut o = KeyOverlay::default();
        let mut cues = countdown(0.5, 10..=20);
        cues.extend(countdown(-0.5, 0..=30));
        let w = run(&mut o, &cues);
        let had = w[10].blend.unwrap();
        assert!(had > 0.3, "{had}");
        assert!(
            (w[11].release.unwrap() - had).abs() < 0.01,
            "{:?} vs {had}",
            w[11]
        );
        assert!(w[11].blend.unwrap() < 0.05, "{:?}", w[11]);
        assert_eq!(o.target()[0], Quat::from_rotation_x(-0.5));
        assert_eq!(o.released()[0], Quat::from_rotation_x(0.5));
        // A count-down that stays put for a frame (the live clock's rounding) is the same cue.
        let mut o = KeyOverlay::default();
        let w = run(
            &mut o,
            &[Some(cue(0.5, 4)), Some(cue(0.5, 3)), Some(cue(0.5, 3))],
        );
        assert!(w.iter().all(|w| w.release.is_none()), "{w:?}");
    }
}
