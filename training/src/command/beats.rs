//! `danced-train beats`: trains the learned beat activation by the analysis recipe.
//!
//! Every song is streamed through the same analysis that runs live (so the network learns from
//! exactly the inputs it will see on stage), as it is and through drawn recording conditions;
//! the networks of the ensemble are written atomically in the format `dsp::BeatNetEnsemble`
//! reads.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use dsp::BEAT_INPUT_DIM;
use dsp::BeatNetEnsemble;
use offline::analysis::AnalyzeOptions;
use offline::files::{read_times, write_atomic};

use crate::analysis_recipe::AnalysisRecipe;
use crate::beat_training::{BeatSong, BeatTrainConfig, SongPool, train_beat_activation};
use crate::song_files::{SongHearing, analyse, hearings};

/// Options of `danced-train beats`.
#[derive(Args, Debug, Clone)]
pub struct TrainBeatsArgs {
    /// The recipe (default: the shipped networks', `configs/analysis.recipe.toml`, built in).
    #[arg(long)]
    pub recipe: Option<PathBuf>,
    /// Where to write the weights.
    #[arg(long, default_value = "beat_activation.dnba")]
    pub out: PathBuf,
    /// Songs analysed in parallel.
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
    /// A quick check of the recipe: N steps per network on a few songs per folder.
    #[arg(long, hide = true)]
    pub check: Option<usize>,
}

/// Streams one hearing through the analysis and pairs its hops with beat targets.
fn load_song(hearing: &SongHearing) -> Result<BeatSong> {
    let beats_file = hearing.audio.with_extension("beats");
    let beats = read_times(&beats_file)
        .with_context(|| format!("reading beats {}", beats_file.display()))?;
    let options = AnalyzeOptions {
        keep_beat_inputs: true,
        ..AnalyzeOptions::default()
    };
    let a = analyse(hearing, options)?;
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
    let recipe = AnalysisRecipe::read_or_shipped(args.recipe.as_deref())?;
    let r = &recipe.beats;
    let hearings = hearings(&r.songs, &r.ensemble, args.check.is_some())?;
    let t = Instant::now();
    let loaded = offline::pool::parallel_map(&hearings, args.jobs.max(1), load_song);
    let mut pools: Vec<SongPool> = r
        .songs
        .iter()
        .map(|f| SongPool {
            songs: Vec::new(),
            share: f.share,
        })
        .collect();
    let mut valid = Vec::new();
    for (hearing, song) in hearings.iter().zip(loaded) {
        let song = song?;
        if hearing.validation {
            valid.push(song);
        } else {
            pools[hearing.pool].songs.push(song);
        }
    }
    pools.retain(|p| !p.songs.is_empty());
    let hours = |songs: &mut dyn Iterator<Item = &BeatSong>| {
        songs.map(|s| s.frames() as f64).sum::<f64>() / dsp::hop_rate() / 3600.0
    };
    eprintln!(
        "analysed {} hearings of the songs in {:.0} s: {:.2} h for training, {:.2} h for validation",
        hearings.len(),
        t.elapsed().as_secs_f64(),
        hours(&mut pools.iter().flat_map(|p| &p.songs)),
        hours(&mut valid.iter())
    );
    let config = BeatTrainConfig {
        channels: r.channels,
        kernel: r.kernel,
        dilations: r.dilations.clone(),
        batch: r.batch,
        sequence: r.sequence,
        steps: args.check.unwrap_or(r.steps),
        learning_rate: r.learning_rate,
        seed: r.ensemble.seed,
    };
    let t = Instant::now();
    let mut nets = Vec::new();
    for member in 0..r.ensemble.members {
        let config = BeatTrainConfig {
            seed: r.ensemble.member_seed(member),
            ..config.clone()
        };
        nets.push(train_beat_activation(
            &pools,
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
