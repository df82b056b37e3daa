//! Dancing to a whole song at once (`danced generate`, `danced eval`, the lag bench's offline
//! reference): the source stepped through the music exactly as the live pipeline hands it over
//! ([`dance_stream`]), with key poses on a timeline: "reach `pose-3` at 12.5 s", announced a
//! fixed lead before, as the live daemon announces one quantised to a coming beat.

use anyhow::{Context, Result, bail};
use glam::Quat;
use model::rig::{JOINT_COUNT, Pose};
use model::source::{Controls, KeyPoseTarget, MotionSource};

/// Steps `source` through `music` (a predicted stream, `dsp::predicted_stream` over `horizon`)
/// as the live pipeline does: the first step makes frame `horizon` (live has no earlier pose;
/// earlier frames hold it), each later frame one step; `controls` gives each frame's controls.
pub fn dance_stream(
    source: &mut dyn MotionSource,
    music: &[[f32; dsp::feature::FEATURE_DIM]],
    horizon: usize,
    frames: usize,
    mut controls: impl FnMut(usize) -> Controls,
) -> Vec<Pose> {
    let look = source.lookahead_frames();
    let frames = frames.min(music.len());
    let mut pose = Pose::rest();
    let mut out = Vec::with_capacity(frames);
    for i in horizon.min(frames)..frames {
        // The frame and its look-ahead (shorter at the end).
        let window = &music[i..(i + look + 1).min(music.len())];
        source.step(window, &controls(i), &mut pose);
        if out.is_empty() {
            out.resize(i, pose);
        }
        out.push(pose);
    }
    out
}

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
}
