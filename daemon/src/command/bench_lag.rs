//! `danced bench lag`: how far the dancer a receiver sees trails the music a listener hears,
//! measured from outside (`crate::motion_lag`), per song, dancer and output lead; and how long
//! the dancer's beat takes to come back after a sudden tempo change.

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::command::source::SourceArgs;
use crate::dancer::{SourceKind, SourceSettings, open_source};
use crate::live::config::Config;
use crate::live::replay::ReplayAudio;
use crate::motion_lag::{LagRun, body_shapes, dance_stream, measure_live_lag};
use crate::offline::{AnalyzeOptions, analyze_samples};

/// Options of `danced bench lag`.
#[derive(clap::Args, Debug)]
pub struct BenchLagArgs {
    /// Data folder: songs of `synth-beats` across 70–170 BPM (the built-in demo song without).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Audio files to measure instead of the data set's songs.
    #[arg(long)]
    pub input: Vec<PathBuf>,
    /// Songs taken from the data set (constant tempo, spread over the tempo range).
    #[arg(long, default_value_t = 5)]
    pub songs: usize,
    /// Seconds of each song replayed.
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Seconds at the start left out (the tracker locking on).
    #[arg(long, default_value_t = 6.0)]
    pub settle: f64,
    /// Output leads to measure, ms (comma-separated).
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        default_value = "0,50"
    )]
    pub lead_ms: Vec<f64>,
    /// Dancers to measure (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "neural,retrieval")]
    pub sources: Vec<String>,
    #[command(flatten)]
    pub dancer: SourceArgs,
}

/// One song to measure.
struct Song {
    name: String,
    bpm: Option<f64>,
    audio: ReplayAudio,
}

fn songs(args: &BenchLagArgs) -> Result<Vec<Song>> {
    if !args.input.is_empty() {
        return args
            .input
            .iter()
            .map(|p| {
                Ok(Song {
                    name: p.file_stem().unwrap_or_default().to_string_lossy().into(),
                    bpm: None,
                    audio: ReplayAudio::from_file(p)?,
                })
            })
            .collect();
    }
    let set = crate::bench::synth_set(&args.data);
    if set.items.is_empty() {
        eprintln!(
            "no songs under {} — measuring the built-in demo song",
            args.data.join("synth-beats").display()
        );
        return Ok(vec![Song {
            name: "demo".into(),
            bpm: Some(crate::demo_track::DEMO_BPM),
            audio: ReplayAudio::demo(args.seconds + 1.0),
        }]);
    }
    // Constant-tempo songs, spread evenly over their tempo range.
    let mut steady: Vec<(f64, &crate::bench::BenchItem)> = set
        .items
        .iter()
        .filter_map(|i| {
            let json = std::fs::read_to_string(i.audio.with_extension("json")).ok()?;
            let v: serde_json::Value = serde_json::from_str(&json).ok()?;
            let constant = v["tempo_curve"].as_str() == Some("constant")
                && v["drumless_intro_bars"].as_u64().unwrap_or(0) == 0;
            let bpm = v["tempo_start_bpm"].as_f64()?;
            (constant && (70.0..=170.0).contains(&bpm)).then_some((bpm, i))
        })
        .collect();
    steady.sort_by(|a, b| a.0.total_cmp(&b.0));
    let n = args.songs.max(1).min(steady.len());
    let picked: Vec<_> = (0..n)
        .map(|k| steady[k * (steady.len() - 1) / (n - 1).max(1)])
        .collect();
    picked
        .into_iter()
        .map(|(bpm, i)| {
            Ok(Song {
                name: i.name.clone(),
                bpm: Some(bpm),
                audio: ReplayAudio::from_file(&i.audio)?,
            })
        })
        .collect()
}

/// Runs `danced bench lag`.
pub fn bench_lag(args: BenchLagArgs) -> Result<()> {
    let mut config = Config::default();
    args.dancer.apply(&mut config);
    let songs = songs(&args)?;
    println!("| song | BPM | dancer | lead ms | lag ms | correlation | frames | late frames |");
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    for song in &songs {
        let a = analyze_samples(
            &song.name,
            &song.audio.samples,
            song.audio.sample_rate,
            song.audio.channels,
            AnalyzeOptions::native(Some(model::retrieval::RETRIEVAL_FPS)),
        )
        .with_context(|| format!("analysing {}", song.name))?;
        for name in &args.sources {
            let kind = SourceKind::parse(name).with_context(|| format!("unknown dancer {name}"))?;
            let settings = SourceSettings {
                model: if kind == SourceKind::Neural {
                    config.dancer.model.as_deref()
                } else {
                    None
                },
                library: if kind == SourceKind::Retrieval {
                    config.dancer.library.as_deref()
                } else {
                    None
                },
                beat_accent: Some(config.dancer.beat_accent),
            };
            for &lead_ms in &args.lead_ms {
                let seed = config.dancer.seed;
                // The reference: the same song danced offline at the horizon the run uses.
                let mut offline = open_source(kind, &settings, seed)?;
                let rate = offline.frame_rate();
                let horizon = crate::horizon::source_horizon(
                    &*offline,
                    lead_ms * 1e-3,
                    crate::horizon::DEFAULT_MARGIN_S,
                );
                let music = dsp::predicted_stream(&a.features, horizon);
                let frames = ((args.seconds + 1.0) * rate) as usize;
                let poses = dance_stream(&mut *offline, &music, horizon, frames, |_| {
                    model::source::Controls::default()
                });
                let reference = body_shapes(&poses);
                let run = LagRun {
                    audio: &song.audio,
                    seconds: args.seconds,
                    settle_s: args.settle,
                    lead_ms,
                    rate_hz: config.output.rate_hz,
                };
                let live =
                    measure_live_lag(&run, open_source(kind, &settings, seed)?, &reference, rate)
                        .with_context(|| format!("{} with the {name} dancer", song.name))?;
                let e = live.estimate;
                println!(
                    "| {} | {} | {} | {lead_ms:.0} | {:+.1} | {:.3} | {} | {}{} |",
                    song.name,
                    song.bpm.map_or("?".into(), |b| format!("{b:.0}")),
                    kind.name(),
                    e.lag_s * 1e3,
                    e.correlation,
                    e.frames,
                    live.late_frames,
                    if live.replay_rebases > 0 {
                        format!(" (replay fell behind {} times)", live.replay_rebases)
                    } else {
                        String::new()
                    }
                );
            }
        }
    }
    Ok(())
}
