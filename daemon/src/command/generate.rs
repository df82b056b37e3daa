//! `danced generate`: dance to a song offline, through the streaming analysis, into a BVH.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use offline::analysis::{AnalyzeOptions, analyze_file};

use crate::command::source::SourceArgs;
use crate::dancer::{SourceKind, SourceSettings};
use crate::live::config::Config;

#[derive(clap::Args, Debug)]
/// Options of `danced generate`.
pub struct GenerateArgs {
    /// The song.
    #[arg(long)]
    pub audio: PathBuf,
    /// Output BVH file.
    #[arg(long)]
    pub out: PathBuf,
    /// The dancer.
    #[command(flatten)]
    pub dancer: SourceArgs,
    /// Start dancing this many seconds into the song (the analysis starts there too, as it
    /// would live; key-pose times stay song times).
    #[arg(long, default_value_t = 0.0)]
    pub start: f64,
    /// Stop after this many seconds of audio.
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Sampling temperature (0: always the best-matching clip).
    #[arg(long, default_value_t = 0.5)]
    pub temperature: f32,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Retrieval source: cut the full clip library from this data folder's tang2018 training
    /// split instead of using a library file.
    #[arg(long, conflicts_with = "library")]
    pub data: Option<PathBuf>,
    /// Neural source: start from this bank pose (the "motion prompt") instead of the model's seed.
    #[arg(long)]
    pub seed_pose: Option<String>,
    /// Reach a key pose of the bank at a time: NAME@SECONDS (repeatable), e.g. pose-3@12.5.
    #[arg(long = "keypose")]
    pub key_poses: Vec<String>,
    /// Key-pose bank (TOML; default: the built-in configs/poses/bank.toml).
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// How long before its moment a key pose is announced to the dancer, seconds.
    #[arg(long, default_value_t = 2.0)]
    pub keypose_lead: f64,
    /// Neural source: the network alone, every safety net off (range clamp, speed limit,
    /// restart, beat accent, end blend, foot lock) but the non-finite guard.
    #[arg(long)]
    pub network_only: bool,
}

/// Runs `danced generate`.
pub fn generate(args: &GenerateArgs) -> Result<()> {
    use model::source::{Controls, MotionSource};
    let GenerateArgs {
        audio,
        out,
        dancer: source_args,
        start,
        seconds,
        temperature,
        seed,
        data,
        key_poses,
        poses: bank_path,
        keypose_lead,
        seed_pose,
        network_only,
    } = args;
    let (seconds, temperature, seed) = (*seconds, *temperature, *seed);
    let start = *start;
    if !(start.is_finite() && start >= 0.0) {
        bail!("--start {start}: must be a time in the song, ≥ 0 s");
    }
    let fps = model::retrieval::RETRIEVAL_FPS;
    let needs_bank = !key_poses.is_empty() || seed_pose.is_some();
    let bank = match (needs_bank, bank_path) {
        (false, _) => crate::pose_bank::PoseBank::default(),
        (true, Some(p)) => crate::pose_bank::PoseBank::load(p)?,
        (true, None) => crate::pose_bank::PoseBank::shipped()?,
    };
    let bank_pose = |name: &str| -> Result<&crate::pose_bank::NamedPose> {
        bank.get(name).with_context(|| {
            let names: Vec<&str> = bank.poses().iter().map(|p| p.name.as_str()).collect();
            format!(
                "key pose {name:?} is not in the bank (it has {})",
                names.join(", ")
            )
        })
    };
    let mut cues = Vec::new();
    for spec in key_poses {
        let (name, at) = crate::offline_dance::parse_cue_spec(spec)?;
        let rotations = bank_pose(&name)?.rotations;
        cues.push(crate::offline_dance::KeyCue {
            name,
            rotations,
            frame: ((at - start) * fps).round().max(0.0) as usize,
        });
    }
    let lead_frames = (keypose_lead.max(0.0) * fps).round() as usize;
    let mut config = Config::default();
    source_args.apply(&mut config);
    config.validate("command line")?;
    let style = config.dancer.style_request();
    let kind = if data.is_some() {
        SourceKind::Retrieval
    } else {
        SourceKind::parse(&config.dancer.source).unwrap_or(SourceKind::DEFAULT)
    };
    if seed_pose.is_some() && kind != SourceKind::Neural {
        bail!("--seed-pose is for the neural source");
    }
    if *network_only && kind != SourceKind::Neural {
        bail!("--network-only is for the neural source: the retrieval dancer has no network");
    }
    let settings = SourceSettings {
        model: config.dancer.model.as_deref(),
        libraries: &config.dancer.libraries,
        beat_accent: Some(config.dancer.beat_accent),
        foot_plant: Some(config.dancer.foot_plant),
        network_only: *network_only,
        key_route: Some(config.dancer.key_pose_route()),
        stage: config.stage.settings(),
    };
    let started = Instant::now();
    let stage = settings.stage;
    let mut dancer: Box<dyn MotionSource> = match (kind, data) {
        // The full library, cut from the training split now (slow, needs ../shared).
        (SourceKind::Retrieval, Some(data)) => crate::dancer::on_stage(
            model::retrieval::RetrievalDancer::new(
                crate::dancer::training_library(data, 2)?.0,
                seed,
            )
            .context("starting the retrieval dancer")?,
            stage,
        ),
        (SourceKind::Neural, _) if seed_pose.is_some() => {
            let mut d = crate::dancer::configured_neural_dancer(&settings, seed)?;
            if let Some(name) = seed_pose {
                d.set_seed_pose(&crate::dancer::standing_features(
                    &bank_pose(name)?.rotations,
                ));
                d.reset(seed);
            }
            crate::dancer::on_stage(d, stage)
        }
        _ => crate::dancer::open_source(kind, &settings, seed)?,
    };
    crate::dancer::check_style(dancer.as_ref(), style)?;
    let load_s = started.elapsed().as_secs_f64();
    let opts = AnalyzeOptions {
        start_s: start,
        ..AnalyzeOptions::native(Some(dancer.frame_rate()))
    };
    let a = analyze_file(audio, opts, &mut |_, _| {})
        .with_context(|| format!("analysing {}", audio.display()))?;
    if a.features.is_empty() {
        bail!(
            "{}: nothing to dance to after {start} s (the song lasts {:.1} s)",
            audio.display(),
            start + a.duration_s
        );
    }
    let limit = seconds.map_or(usize::MAX, |s| (s * dancer.frame_rate()) as usize);
    // What the live pipeline hands the dancer at lead 0: each frame predicted from the analysis
    // `horizon` frames earlier.
    let horizon = model::horizon::offline_horizon(&*dancer);
    let music = dsp::predicted_stream(&a.features, horizon);
    let step_start = Instant::now();
    let poses = crate::offline_dance::dance_stream(
        &mut *dancer,
        &music,
        horizon,
        music.len().min(limit),
        |i| Controls {
            temperature,
            key_pose: crate::offline_dance::target_at(&cues, i, lead_frames),
            beat_accent: None,
            style,
            key_route: None,
        },
    );
    let step_s = step_start.elapsed().as_secs_f64();
    for c in &cues {
        match poses.get(c.frame) {
            Some(p) => println!(
                "key pose {} at {:.2} s: mean joint error {:.2} cm",
                c.name,
                start + c.frame as f64 / fps,
                model::body_shape::key_pose_error_cm(p, &c.rotations)
            ),
            None => println!("key pose {} lies after the end of the motion", c.name),
        }
    }
    let skeleton = model::rig::Skeleton::default_adult();
    model::bvh::export(&skeleton, &poses, dancer.frame_rate())
        .write(out)
        .with_context(|| format!("writing {}", out.display()))?;
    println!(
        "{}: {} frames ({:.1} s) at {} fps by the {} dancer → {} (loaded in {:.1} s, {:.1} µs per frame)",
        audio.display(),
        poses.len(),
        poses.len() as f64 / dancer.frame_rate(),
        dancer.frame_rate(),
        kind.name(),
        out.display(),
        load_s,
        1e6 * step_s / poses.len().max(1) as f64
    );
    let report = dancer.report();
    if let Some(c) = report
        .stage
        .filter(|_| stage.mode != model::stage::StageMode::Free)
    {
        println!(
            "stage ({}, radius {} m): steered {:.1} % of frames, glided back {:.1} %, clamped {:.2} %, turning at most {:.0}°/s",
            stage.mode.name(),
            stage.radius_m,
            100.0 * c.steered as f64 / c.frames.max(1) as f64,
            100.0 * c.glided as f64 / c.frames.max(1) as f64,
            100.0 * c.clamped as f64 / c.frames.max(1) as f64,
            c.max_turn_deg_per_s
        );
    }
    if let Some(c) = report.safety {
        let nets = if *network_only {
            "network only (nets off)"
        } else {
            "safety nets"
        };
        println!("{nets}: {}", c.summary());
    }
    Ok(())
}
