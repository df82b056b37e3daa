//! Helpers shared by the end-to-end tests.

use model::rig::{JOINT_COUNT, Pose};

/// Frames at which any joint of `x` and `y` differs by more than the rotation whose quaternion
/// dot product is `dot` (e.g. 0.999 ≈ 5°).
pub fn frames_differing(x: &[Pose], y: &[Pose], dot: f32) -> usize {
    x.iter()
        .zip(y)
        .filter(|(p, q)| {
            (0..JOINT_COUNT).any(|j| p.local_rotations[j].dot(q.local_rotations[j]).abs() < dot)
        })
        .count()
}

/// The demo song's streaming feature frames at `fps`, as a dancer hears them live at lead 0
/// (predicted over the data horizon), and its beats, `seconds` long.
#[allow(dead_code)]
pub fn demo_music(seconds: f64, fps: f64) -> (Vec<[f32; dsp::feature::FEATURE_DIM]>, Vec<f64>) {
    let song = daemon::demo_track::demo_track(seconds);
    let a = offline::analysis::analyze_samples(
        "demo",
        &song.samples,
        daemon::demo_track::DEMO_RATE,
        2,
        offline::analysis::AnalyzeOptions::native(Some(fps)),
    )
    .expect("the demo song analyses");
    let horizon = model::horizon::data_horizon(fps);
    (dsp::predicted_stream(&a.features, horizon), song.beats)
}

/// Dances `seconds` of the demo song with `source` (reset with `seed`) at `temperature`, each
/// frame with its look-ahead as the live pipeline hands them over ([`daemon::eval::dance_to`]);
/// returns the poses and the song's beats.
#[allow(dead_code)]
pub fn dance_to_demo(
    source: &mut dyn model::source::MotionSource,
    seconds: f64,
    temperature: f32,
    seed: u64,
) -> (Vec<Pose>, Vec<f64>) {
    let (music, beats) = demo_music(seconds, source.frame_rate());
    let poses = daemon::eval::dance_to(source, &music, music.len(), temperature, seed, &[], 0);
    (poses, beats)
}

/// BeatAlign of 25 fps `poses` on `beats` and on the beats shifted by half a beat of the demo
/// song, skipping the first 5 s (where the tracker locks).
#[allow(dead_code)]
pub fn beat_align_on_and_off(poses: &[Pose], beats: &[f64]) -> (f64, f64) {
    let skip = 5 * 25;
    let positions = model::rig::Skeleton::default_adult().trajectory(&poses[skip..]);
    let track = model::metrics::JointTrack::new(&positions, JOINT_COUNT, 25.0).unwrap();
    let local: Vec<f64> = beats
        .iter()
        .map(|b| b - 5.0)
        .filter(|b| *b >= 0.0)
        .collect();
    let half_beat = 30.0 / daemon::demo_track::DEMO_BPM;
    let shifted: Vec<f64> = local.iter().map(|b| b + half_beat).collect();
    (
        model::metrics::beat_align(&track, &local),
        model::metrics::beat_align(&track, &shifted),
    )
}
