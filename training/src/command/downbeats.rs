//! `danced-train downbeats`: trains the downbeat network on songs whose beats are annotated
//! with their position in the bar.
//!
//! Every song is streamed through the same analysis that runs live, with the shipped beat
//! tracker, so the network learns from the features of the beats the tracker really finds
//! (with their jitter and their mistakes); the ensemble is written atomically in the format
//! `dsp::DownbeatNetEnsemble` reads.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use dsp::{BarFeatures, DownbeatNetEnsemble};
use offline::analysis::{AnalyzeOptions, analyze_file};
use offline::files::{read_beat_positions, write_atomic};

use crate::downbeat_training::{
    DownbeatExamples, DownbeatTrainConfig, accuracy, train_downbeat_net,
};
use crate::song_files::{EnsembleArgs, annotated_songs};

/// Options of `danced-train downbeats`.
#[derive(Args, Debug, Clone)]
pub struct TrainDownbeatsArgs {
    /// Folders of songs with beats and their positions in the bar: `NAME.flac|wav|mp3|ogg`
    /// beside `NAME.beats` (`time_s<TAB>beat_in_bar` per line), e.g. rendered by
    /// `../shared/tools/synth_beats.py --seed 1000`.
    #[arg(long, required = true, num_args = 1..)]
    pub songs: Vec<PathBuf>,
    /// Where to write the weights.
    #[arg(long, default_value = "downbeat.dndb")]
    pub out: PathBuf,
    /// Optimiser steps per network.
    #[arg(long, default_value_t = DownbeatTrainConfig::default().steps)]
    pub steps: usize,
    /// Width of each hidden layer.
    #[arg(long, value_delimiter = ',', default_values_t = DownbeatTrainConfig::default().hidden)]
    pub hidden: Vec<usize>,
    /// Rows per batch.
    #[arg(long, default_value_t = DownbeatTrainConfig::default().batch)]
    pub batch: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = DownbeatTrainConfig::default().learning_rate)]
    pub learning_rate: f64,
    /// Standard deviation of the noise added to the inputs.
    #[arg(long, default_value_t = DownbeatTrainConfig::default().input_noise)]
    pub input_noise: f32,
    /// How many networks are trained, and how.
    #[command(flatten)]
    pub ensemble: EnsembleArgs,
}

/// One analysed song: its tracked beats' bar features and its annotation.
struct LabelledSong {
    features: Vec<BarFeatures>,
    reference: Vec<(f64, usize)>,
    meter: usize,
}

fn load_song(audio: &Path) -> Result<LabelledSong> {
    let beats = audio.with_extension("beats");
    let reference = read_beat_positions(&beats).with_context(|| {
        format!(
            "{}: no positions in the bar (second column)",
            beats.display()
        )
    })?;
    let meter = reference.iter().map(|r| r.1).max().unwrap_or(4);
    let options = AnalyzeOptions {
        keep_bar_features: true,
        ..AnalyzeOptions::default()
    };
    let a = analyze_file(audio, options, &mut |_, _| {})
        .with_context(|| format!("analysing {}", audio.display()))?;
    Ok(LabelledSong {
        features: a.bar_features,
        reference,
        meter,
    })
}

/// Runs `danced-train downbeats`.
pub fn train_downbeats(args: &TrainDownbeatsArgs) -> Result<()> {
    let songs = annotated_songs(&args.songs)?;
    let t = Instant::now();
    let loaded = offline::pool::parallel_map(&songs, args.ensemble.jobs.max(1), |p| load_song(p));
    let (mut train, mut valid) = (DownbeatExamples::default(), DownbeatExamples::default());
    for (i, song) in loaded.into_iter().enumerate() {
        let s = song?;
        let held_out = args.ensemble.held_out(i);
        let into = if held_out { &mut valid } else { &mut train };
        into.add_song(&s.features, &s.reference, s.meter);
    }
    eprintln!(
        "analysed {} songs in {:.0} s: {} labelled beats for training, {} for validation",
        songs.len(),
        t.elapsed().as_secs_f64(),
        train.len(),
        valid.len()
    );
    let config = DownbeatTrainConfig {
        hidden: args.hidden.clone(),
        batch: args.batch,
        steps: args.steps,
        learning_rate: args.learning_rate,
        input_noise: args.input_noise,
        seed: args.ensemble.seed,
    };
    let class_prior = train.class_frequencies();
    let t = Instant::now();
    let mut nets = Vec::new();
    for member in 0..args.ensemble.members() {
        let config = DownbeatTrainConfig {
            seed: args.ensemble.member_seed(member),
            ..config.clone()
        };
        nets.push(train_downbeat_net(&train, &config, 500, |step, loss, w| {
            let one = DownbeatNetEnsemble {
                nets: vec![w.clone()],
                class_prior,
            };
            eprintln!(
                "network {}  step {step:5}  loss {loss:.4}  validation accuracy {:.3}  ({:.0} s)",
                member + 1,
                accuracy(&one, &valid),
                t.elapsed().as_secs_f64()
            );
        }));
    }
    let ensemble = DownbeatNetEnsemble { nets, class_prior };
    eprintln!(
        "ensemble: training accuracy {:.3}, validation accuracy {:.3}",
        accuracy(&ensemble, &train),
        accuracy(&ensemble, &valid)
    );
    write_atomic(&args.out, &ensemble.to_bytes())
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!(
        "wrote {} ({} networks, hidden {:?})",
        args.out.display(),
        ensemble.nets.len(),
        config.hidden
    );
    Ok(())
}
