//! `danced bench model`: the neural dancer's per-frame sampling time on one thread.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;

use dsp::feature::FEATURE_DIM;
use model::neural::dancer::NeuralDancer;
use model::rig::Pose;
use model::source::{Controls, KeyPoseTarget, MotionSource};

/// Options of `danced bench model`.
#[derive(clap::Args, Debug, Clone)]
pub struct BenchModelArgs {
    /// Model file (default: the built-in one).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Frames timed after warm-up.
    #[arg(long, default_value_t = 5000)]
    pub frames: usize,
    /// Sampling temperature.
    #[arg(long, default_value_t = 1.0)]
    pub temperature: f32,
}

/// Music frames of the built-in demo song (30 s) at the dancer's rate: what the timed frames
/// hear (random features would be far outside anything the model has heard).
fn demo_music(rate: f64) -> Result<Vec<[f32; FEATURE_DIM]>> {
    use crate::demo_track::{DEMO_RATE, demo_track};
    let song = demo_track(30.0);
    let a = offline::analysis::analyze_samples(
        "demo",
        &song.samples,
        DEMO_RATE,
        2,
        offline::analysis::AnalyzeOptions::native(Some(rate)),
    )?;
    Ok(a.features.iter().map(|f| f.values).collect())
}

/// Per-frame sampling times after warm-up, sorted, microseconds; the dancer hears `song`
/// (looped) with its look-ahead.
pub fn time_frames(
    dancer: &mut dyn MotionSource,
    song: &[[f32; FEATURE_DIM]],
    frames: usize,
    temperature: f32,
) -> Vec<f64> {
    let look = dancer.lookahead_frames();
    let mut music = vec![[0.0f32; FEATURE_DIM]; look + 1];
    let mut pose = Pose::rest();
    // A pose of the shipped bank (a dancer's pose, as a performer would cue it).
    let rotations = crate::pose_bank::PoseBank::shipped()
        .ok()
        .and_then(|b| b.poses().first().map(|p| p.rotations))
        .unwrap_or(Pose::rest().local_rotations);
    let key = KeyPoseTarget {
        rotations,
        frames_to_go: 50,
    };
    dancer.reset(1);
    let mut times = Vec::with_capacity(frames);
    let warm_up = 200;
    for i in 0..warm_up + frames {
        for (k, frame) in music.iter_mut().enumerate() {
            *frame = song[(i + k) % song.len().max(1)];
        }
        // Half the time with a key pose counting down, as the daemon will drive it.
        let controls = Controls {
            temperature,
            key_pose: ((i / 100) % 2 == 1).then_some(KeyPoseTarget {
                frames_to_go: 99 - (i % 100) as u32,
                ..key
            }),
            ..Controls::default()
        };
        let t = Instant::now();
        dancer.step(&music, &controls, &mut pose);
        let dt = t.elapsed().as_secs_f64() * 1e6;
        if i >= warm_up {
            times.push(dt);
        }
    }
    times.sort_by(f64::total_cmp);
    times
}

/// `danced bench model`.
pub fn bench_model(args: &BenchModelArgs) -> Result<()> {
    let model = crate::dancer::load_model(args.model.as_deref())?;
    let mut dancer = NeuralDancer::new(&model)?;
    let song = demo_music(dancer.frame_rate())?;
    // Where the first frame lands, to diagnose held frames.
    dancer.reset(1);
    let mut pose = Pose::rest();
    let music = &song[..dancer.lookahead_frames() + 1];
    let controls = Controls {
        temperature: args.temperature,
        ..Controls::default()
    };
    dancer.step(music, &controls, &mut pose);
    let (worst, value) = dancer
        .last_sample()
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .map_or((0, 0.0), |(i, v)| (i, *v));
    println!(
        "first frame: largest normalised feature {} = {value:.2} ({} held)",
        model::motion::feature_name(worst).unwrap_or_default(),
        dancer.report().safety.map_or(0, |c| c.held)
    );
    let times = time_frames(&mut dancer, &song, args.frames.max(1), args.temperature);
    let q = |p: f64| times[((times.len() - 1) as f64 * p).round() as usize];
    println!(
        "model {:?}\ntrained by: {}\ntrained on: {} ({} steps; data {})\n{} frames after 200 warm-up: p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms per frame (one thread); {} held frames",
        model.config,
        if model.training.recipe.is_empty() {
            "(not recorded)"
        } else {
            &model.training.recipe
        },
        model.training.data,
        model.training.steps,
        if model.training.data_hash.is_empty() {
            "hash not recorded"
        } else {
            &model.training.data_hash
        },
        times.len(),
        q(0.5) / 1e3,
        q(0.99) / 1e3,
        times[times.len() - 1] / 1e3,
        dancer.report().safety.map_or(0, |c| c.held)
    );
    Ok(())
}
