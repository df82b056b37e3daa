//! Music–motion beat metrics: FACT's BeatAlign and Transflower's beat offset.

use super::{JointTrack, beats_within, local_minima, nearest_distance};
use crate::ModelError;

/// Width in seconds of the Gaussian that scores a kinematic beat against its nearest music beat.
///
/// FACT (Li et al. 2021, Eq. 2 and `alignment_score` in google-research/mint) uses σ = 3
/// *frames* on 60 fps sequences and notes σ exists "to normalize sequences with different FPS";
/// 3 / 60 = 0.05 s keeps that meaning at any frame rate because we measure in seconds.
pub const BEAT_ALIGN_SIGMA_S: f64 = 3.0 / 60.0;

/// Half-width in seconds of the neighbourhood a speed minimum must be strictly lowest in.
///
/// FACT's `motion_peak_onehot` calls `argrelextrema(envelope, np.less, order=10)` with the
/// comment "10 for 60FPS", i.e. 1/6 s either side; the order in frames is this value times the
/// track's fps, rounded, at least 1. Minima closer than this are merged into one beat, which caps
/// detectable kinematic beats at about 3 per second. Transflower does not state its neighbourhood,
/// so [`hips_beats`] uses the same one.
pub const BEAT_MINIMA_HALF_WINDOW_S: f64 = 10.0 / 60.0;

/// Mean and spread of the time between each music beat and its nearest kinematic beat.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeatOffset {
    /// Mean absolute offset in seconds.
    pub mean_s: f64,
    /// Population standard deviation (numpy's default `ddof=0`) of the offsets in seconds.
    pub sd_s: f64,
    /// Music beats that were measured (those within the track's time span).
    pub music_beats: usize,
    /// Kinematic beats found in the track.
    pub kinematic_beats: usize,
}

/// `argrelextrema` order in frames for this frame rate.
fn minima_order(fps: f64) -> usize {
    ((BEAT_MINIMA_HALF_WINDOW_S * fps).round() as usize).max(1)
}

/// Music beats may sit up to half a frame outside the track, as frame quantisation would put
/// them on the first or last frame.
fn half_frame(track: &JointTrack<'_>) -> f64 {
    0.5 / track.fps()
}

/// FACT's kinematic beats in seconds: local minima of the summed joint speed.
///
/// The envelope is the speed of every joint between consecutive frames, summed over joints
/// (`np.sum(np.linalg.norm(velocity, axis=2), axis=1)` in FACT), here in m/s rather than FACT's
/// metres per frame, which scales the curve without moving its minima. Each speed sample sits at
/// the midpoint of its two frames. FACT's leading zero velocity (its `velocity[0]`), which hides
/// beats in the first 10 frames, is not reproduced. Fewer than four frames yield no beats.
pub fn kinematic_beats(track: &JointTrack<'_>) -> Vec<f64> {
    let n = track.frames();
    if n < 2 {
        return Vec::new();
    }
    let fps = track.fps();
    local_minima(&summed_joint_speed(track), minima_order(fps))
        .into_iter()
        .map(|k| (k + 0.5) / fps)
        .collect()
}

/// FACT's kinematic-beat envelope: the speed of every joint between consecutive frames, summed
/// over joints, m/s; sample `i` sits at `(i + 0.5) / fps`. Empty for fewer than two frames.
pub fn summed_joint_speed(track: &JointTrack<'_>) -> Vec<f64> {
    let fps = track.fps();
    (0..track.frames().saturating_sub(1))
        .map(|i| {
            (0..track.joints())
                .map(|j| (track.pos(i + 1, j) - track.pos(i, j)).length())
                .sum::<f64>()
                * fps
        })
        .collect()
}

/// AI Choreographer's BeatAlign in [0, 1]: mean over kinematic beats of
/// exp(−d² / 2σ²), d the distance in seconds to the nearest music beat, σ = [`BEAT_ALIGN_SIGMA_S`].
///
/// Averaged over *kinematic* beats as the paper's Eq. 2 and FACT's own `alignment_score` do
/// (every move should land on a beat, not every beat needs a move); Bailando's widely copied
/// `beat_align_score` averages over music beats instead, which is a different metric. Only music
/// beats within the track's time span count, as FACT truncates them to the motion's length.
/// Returns 0 when there is no kinematic beat (FACT's convention) or no music beat.
pub fn beat_align(track: &JointTrack<'_>, music_beats_s: &[f64]) -> f64 {
    let music = beats_within(music_beats_s, track.duration_s(), half_frame(track));
    let kinematic = kinematic_beats(track);
    if music.is_empty() || kinematic.is_empty() {
        return 0.0;
    }
    let two_sigma_sq = 2.0 * BEAT_ALIGN_SIGMA_S * BEAT_ALIGN_SIGMA_S;
    kinematic
        .iter()
        .map(|&t| {
            let d = nearest_distance(&music, t);
            (-d * d / two_sigma_sq).exp()
        })
        .sum::<f64>()
        / kinematic.len() as f64
}

/// Transflower's kinematic beats in seconds: local minima of the hips' vertical velocity.
///
/// The paper takes "the local minima of the y-velocity of the Hips-joint", i.e. the instants of
/// fastest downward motion (after Toiviainen et al. 2010), signed and without any threshold. The
/// velocity is in m/s between consecutive frames, placed at their midpoint; the minima
/// neighbourhood is [`BEAT_MINIMA_HALF_WINDOW_S`] as the paper gives none.
pub fn hips_beats(track: &JointTrack<'_>, hips_joint: usize) -> Result<Vec<f64>, ModelError> {
    track.check_joint(hips_joint)?;
    let n = track.frames();
    if n < 2 {
        return Ok(Vec::new());
    }
    let fps = track.fps();
    let vy: Vec<f64> = (0..n - 1)
        .map(|i| (track.pos(i + 1, hips_joint).y - track.pos(i, hips_joint).y) * fps)
        .collect();
    Ok(local_minima(&vy, minima_order(fps))
        .into_iter()
        .map(|k| (k + 0.5) / fps)
        .collect())
}

/// Transflower's beat offset: mean and sd of |music beat − nearest kinematic beat| in seconds.
///
/// Runs from each music beat (within the track's time span) to the nearest [`hips_beats`] beat,
/// the direction the paper describes, so a dance that skips beats is penalised.
pub fn beat_offset(
    track: &JointTrack<'_>,
    hips_joint: usize,
    music_beats_s: &[f64],
) -> Result<BeatOffset, ModelError> {
    let kinematic = hips_beats(track, hips_joint)?;
    if kinematic.is_empty() {
        return Err(ModelError::NoKinematicBeats);
    }
    let music = beats_within(music_beats_s, track.duration_s(), half_frame(track));
    if music.is_empty() {
        return Err(ModelError::NoMusicBeats);
    }
    let offsets: Vec<f64> = music
        .iter()
        .map(|&t| nearest_distance(&kinematic, t))
        .collect();
    let n = offsets.len() as f64;
    let mean_s = offsets.iter().sum::<f64>() / n;
    let var = offsets.iter().map(|o| (o - mean_s).powi(2)).sum::<f64>() / n;
    Ok(BeatOffset {
        mean_s,
        sd_s: var.sqrt(),
        music_beats: music.len(),
        kinematic_beats: kinematic.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use std::f64::consts::PI;

    const JOINTS: usize = 5;

    /// Every joint bobs vertically as `-amp * cos(π (t - phase) / beat)` (plus a per-joint
    /// offset), so it is at rest exactly at `phase + k * beat`.
    fn bounce(fps: f64, seconds: f64, beat_s: f64, phase_s: f64) -> Vec<Vec3> {
        let frames = (seconds * fps).round() as usize + 1;
        let mut p = Vec::with_capacity(frames * JOINTS);
        for i in 0..frames {
            let t = i as f64 / fps;
            let y = -0.1 * (PI * (t - phase_s) / beat_s).cos();
            for j in 0..JOINTS {
                let amp = 1.0 + 0.2 * j as f64;
                p.push(Vec3::new(j as f32 * 0.1, (0.9 + amp * y) as f32, 0.0));
            }
        }
        p
    }

    fn clicks(beat_s: f64, seconds: f64) -> Vec<f64> {
        (0..)
            .map(|k| k as f64 * beat_s)
            .take_while(|&t| t <= seconds)
            .collect()
    }

    #[test]
    fn on_beat_bounce_scores_near_one() {
        for fps in [30.0, 60.0, 120.0] {
            let p = bounce(fps, 10.0, 0.5, 0.0);
            let track = JointTrack::new(&p, JOINTS, fps).unwrap();
            let beats = kinematic_beats(&track);
            // Rest points at 0.5, 1.0, …, 9.5 s (0 and 10 s lie on the track's ends).
            assert_eq!(beats.len(), 19, "fps {fps}: {beats:?}");
            let score = beat_align(&track, &clicks(0.5, 10.0));
            assert!(score > 0.98, "fps {fps}: {score}");
        }
    }

    #[test]
    fn half_beat_shift_scores_far_lower() {
        let p = bounce(60.0, 10.0, 0.5, 0.25);
        let track = JointTrack::new(&p, JOINTS, 60.0).unwrap();
        let score = beat_align(&track, &clicks(0.5, 10.0));
        // 0.25 s from every click: exp(-0.25² / (2 · 0.05²)) = exp(-12.5) ≈ 4e-6.
        assert!(score < 1e-4, "{score}");
        // σ is in seconds: every move exactly σ = 50 ms (3 frames) late scores exp(-1/2).
        let p = bounce(60.0, 10.0, 0.5, BEAT_ALIGN_SIGMA_S);
        let track = JointTrack::new(&p, JOINTS, 60.0).unwrap();
        let score = beat_align(&track, &clicks(0.5, 10.0));
        assert!((score - (-0.5f64).exp()).abs() < 0.01, "{score}");
    }

    #[test]
    fn beat_align_degenerate_inputs_are_zero() {
        let still = vec![Vec3::ONE; JOINTS * 100];
        let track = JointTrack::new(&still, JOINTS, 60.0).unwrap();
        assert_eq!(beat_align(&track, &clicks(0.5, 2.0)), 0.0);
        let p = bounce(60.0, 4.0, 0.5, 0.0);
        let track = JointTrack::new(&p, JOINTS, 60.0).unwrap();
        assert_eq!(beat_align(&track, &[]), 0.0);
        assert_eq!(beat_align(&track, &[f64::NAN, 100.0, -3.0]), 0.0);
        let empty = JointTrack::new(&[], JOINTS, 60.0).unwrap();
        assert_eq!(beat_align(&empty, &[0.0]), 0.0);
        let one = JointTrack::new(&p[..JOINTS], JOINTS, 60.0).unwrap();
        assert_eq!(beat_align(&one, &[0.0]), 0.0);
    }

    /// Hips (joint 0) move as `-amp * sin(2π (t - phase) / beat)`: fastest downward at
    /// `phase + k * beat`.
    fn hips_dip(fps: f64, seconds: f64, beat_s: f64, phase_s: f64) -> Vec<Vec3> {
        let frames = (seconds * fps).round() as usize + 1;
        let mut p = Vec::with_capacity(frames * 2);
        for i in 0..frames {
            let t = i as f64 / fps;
            let y = 1.0 - 0.05 * (2.0 * PI * (t - phase_s) / beat_s).sin();
            p.push(Vec3::new(0.0, y as f32, 0.0));
            p.push(Vec3::new(0.3, 0.05, 0.0));
        }
        p
    }

    #[test]
    fn beat_offset_measures_the_shift() {
        // Dips at 0 s and 10 s lie on the track's ends, where no minimum can be found.
        let beats: Vec<f64> = (1..20).map(|k| k as f64 * 0.5).collect();
        let p = hips_dip(60.0, 10.0, 0.5, 0.0);
        let track = JointTrack::new(&p, 2, 60.0).unwrap();
        let on = beat_offset(&track, 0, &beats).unwrap();
        assert!(on.mean_s < 0.01 && on.sd_s < 0.01, "{on:?}");
        let p = hips_dip(60.0, 10.0, 0.5, 0.1);
        let track = JointTrack::new(&p, 2, 60.0).unwrap();
        let off = beat_offset(&track, 0, &beats).unwrap();
        // Each beat k/2 s has its nearest dip 0.1 s later.
        assert!(
            (off.mean_s - 0.1).abs() < 0.01 && off.sd_s < 0.01,
            "{off:?}"
        );
        assert_eq!(off.music_beats, 19);
        assert_eq!(off.kinematic_beats, 20);
    }

    #[test]
    fn beat_offset_errors() {
        let p = hips_dip(60.0, 2.0, 0.5, 0.0);
        let track = JointTrack::new(&p, 2, 60.0).unwrap();
        assert!(matches!(
            beat_offset(&track, 2, &[0.5]).unwrap_err(),
            ModelError::JointOutOfRange {
                joint: 2,
                joints: 2
            }
        ));
        assert!(matches!(
            beat_offset(&track, 0, &[]).unwrap_err(),
            ModelError::NoMusicBeats
        ));
        let still = vec![Vec3::ONE; 2 * 50];
        let track = JointTrack::new(&still, 2, 60.0).unwrap();
        assert!(matches!(
            beat_offset(&track, 0, &[0.5]).unwrap_err(),
            ModelError::NoKinematicBeats
        ));
    }
}
