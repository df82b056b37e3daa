//! `danced-train beats`: trains the learned beat activation on songs with exact beats.
//!
//! Every song is streamed through the same analysis that runs live (so the network learns from
//! exactly the inputs it will see on stage); the networks of the ensemble are written atomically
//! in the format `dsp::BeatNetEnsemble` reads.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use dsp::BEAT_INPUT_DIM;
use dsp::BeatNetEnsemble;
use offline::analysis::{AnalyzeOptions, analyze_file};
use offline::files::{read_times, write_atomic};

use crate::beat_training::{BeatSong, BeatTrainConfig, train_beat_activation};
use crate::song_files::{EnsembleArgs, annotated_songs};

/// Options of `danced-train beats`.
#[derive(Args, Debug, Clone)]
pub struct TrainBeatsArgs {
    /// Folder of songs with beats: `NAME.flac|wav|mp3|ogg` beside `NAME.beats` (time in seconds
    /// first on each line), e.g. rendered by `../shared/tools/synth_beats.py --seed 1000`.
    #[arg(long, required = true, num_args = 1..)]
    pub songs: Vec<PathBuf>,
    /// Where to write the weights.
    #[arg(long, default_value = "beat_activation.dnba")]
    pub out: PathBuf,
    /// Optimiser steps.
    #[arg(long, default_value_t = BeatTrainConfig::default().steps)]
    pub steps: usize,
    /// Hidden channels.
    #[arg(long, default_value_t = BeatTrainConfig::default().channels)]
    pub channels: usize,
    /// Dilation of each causal convolution layer (the receptive field is 1 + 2·their sum hops).
    #[arg(long, value_delimiter = ',', default_values_t = BeatTrainConfig::default().dilations)]
    pub dilations: Vec<usize>,
    /// Hops per training sequence.
    #[arg(long, default_value_t = BeatTrainConfig::default().sequence)]
    pub sequence: usize,
    /// Sequences per batch.
    #[arg(long, default_value_t = BeatTrainConfig::default().batch)]
    pub batch: usize,
    /// Augmentation: standard deviation of a random log gain per sequence and band group.
    #[arg(long, default_value_t = BeatTrainConfig::default().gain_jitter)]
    pub gain_jitter: f32,
    /// How many networks are trained, and how.
    #[command(flatten)]
    pub ensemble: EnsembleArgs,
}

/// Streams one song through the analysis and pairs its hops with beat targets.
fn load_song(audio: &Path, beats: &Path) -> Result<BeatSong> {
    let beats = read_times(beats).with_context(|| format!("reading beats {}", beats.display()))?;
    let options = AnalyzeOptions {
        keep_beat_inputs: true,
        ..AnalyzeOptions::default()
    };
    let a = analyze_file(audio, options, &mut |_, _| {})
        .with_context(|| format!("analysing {}", audio.display()))?;
    let frames = a.beat_inputs.len() / BEAT_INPUT_DIM;
    let first = a.first_hop_s.unwrap_or(0.0) + dsp::tracker::EVENT_TIME_OFFSET_S;
    let shifted: Vec<f64> = beats.iter().map(|b| b - first).collect();
    Ok(BeatSong {
        targets: BeatSong::targets_from_beats(&shifted, frames, dsp::hop_rate()),
        inputs: a.beat_inputs,
    })
}

/// Runs `danced-train beats`.
pub fn train_beats(args: &TrainBeatsArgs) -> Result<()> {
    let pairs = annotated_songs(&args.songs)?;
    let t = Instant::now();
    let loaded = offline::pool::parallel_map(&pairs, args.ensemble.jobs.max(1), |p| {
        load_song(p, &p.with_extension("beats"))
    });
    let (mut train, mut valid) = (Vec::new(), Vec::new());
    for (i, song) in loaded.into_iter().enumerate() {
        let song = song?;
        if args.ensemble.held_out(i) {
            valid.push(song);
        } else {
            train.push(song);
        }
    }
    let hours: f64 =
        train.iter().map(|s| s.frames() as f64).sum::<f64>() / dsp::hop_rate() / 3600.0;
    eprintln!(
        "analysed {} songs in {:.0} s: {} for training ({hours:.2} h), {} for validation",
        pairs.len(),
        t.elapsed().as_secs_f64(),
        train.len(),
        valid.len()
    );
    let config = BeatTrainConfig {
        steps: args.steps,
        channels: args.channels,
        dilations: args.dilations.clone(),
        sequence: args.sequence,
        batch: args.batch,
        gain_jitter: args.gain_jitter,
        seed: args.ensemble.seed,
        ..BeatTrainConfig::default()
    };
    let t = Instant::now();
    let mut nets = Vec::new();
    for member in 0..args.ensemble.members() {
        let config = BeatTrainConfig {
            seed: args.ensemble.member_seed(member),
            ..config.clone()
        };
        nets.push(train_beat_activation(
            &train,
            &valid,
            &config,
            500,
            |step, loss, val| {
                if let Some(v) = val {
                    eprintln!(
                        "network {}  step {step:5}  loss {loss:.4}  validation {v:.4}  ({:.0} s)",
                        member + 1,
                        t.elapsed().as_secs_f64()
                    );
                }
            },
        ));
    }
    let ensemble = BeatNetEnsemble { nets };
    write_atomic(&args.out, &ensemble.to_bytes())
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!(
        "wrote {} ({} networks, {} channels, receptive field {} hops)",
        args.out.display(),
        ensemble.nets.len(),
        config.channels,
        ensemble.receptive_field()
    );
    Ok(())
}
