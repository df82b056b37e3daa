//! `danced-train downbeats`: trains the downbeat network on songs whose beats are annotated
//! with their position in the bar.
//!
//! Every song is streamed through the same analysis that runs live, with the shipped beat
//! tracker, so the network learns from the features of the beats the tracker really finds
//! (with their jitter and their mistakes); the ensemble is written atomically in the format
//! `dsp::DownbeatNetEnsemble` reads.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use dsp::{BarFeatures, DownbeatNetEnsemble};
use offline::analysis::AnalyzeOptions;
use offline::files::{read_beat_positions, write_atomic};

use crate::analysis_recipe::AnalysisRecipe;
use crate::downbeat_training::{
    DownbeatExamples, DownbeatTrainConfig, accuracy, train_downbeat_net,
};
use crate::song_files::{SongHearing, analyse, hearings};

/// Options of `danced-train downbeats`.
#[derive(Args, Debug, Clone)]
pub struct TrainDownbeatsArgs {
    /// The recipe (default: the shipped networks', `configs/analysis.recipe.toml`, built in).
    #[arg(long)]
    pub recipe: Option<PathBuf>,
    /// Where to write the weights.
    #[arg(long, default_value = "downbeat.dndb")]
    pub out: PathBuf,
    /// Beat activation weights the analysis runs while it collects the bar features (default:
    /// the shipped ones; after `danced-train beats`, its output, as the shipped pair is made).
    #[arg(long)]
    pub beat_net: Option<PathBuf>,
    /// Songs analysed in parallel.
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
    /// A quick check of the recipe: N steps per network on a few songs per folder.
    #[arg(long, hide = true)]
    pub check: Option<usize>,
}

/// One analysed song: its tracked beats' bar features and its annotation.
struct LabelledSong {
    features: Vec<BarFeatures>,
    reference: Vec<(f64, usize)>,
    meter: usize,
}

fn load_song(hearing: &SongHearing, networks: dsp::AnalysisNetworks) -> Result<LabelledSong> {
    let beats = hearing.audio.with_extension("beats");
    let reference = read_beat_positions(&beats).with_context(|| {
        format!(
            "{}: no positions in the bar (second column)",
            beats.display()
        )
    })?;
    let meter = reference.iter().map(|r| r.1).max().unwrap_or(4);
    let options = AnalyzeOptions {
        keep_bar_features: true,
        networks,
        ..AnalyzeOptions::default()
    };
    let a = analyse(hearing, options)?;
    Ok(LabelledSong {
        features: a.bar_features,
        reference,
        meter,
    })
}

/// Runs `danced-train downbeats`.
pub fn train_downbeats(args: &TrainDownbeatsArgs) -> Result<()> {
    let recipe = AnalysisRecipe::read_or_shipped(args.recipe.as_deref())?;
    let r = &recipe.downbeats;
    let hearings = hearings(&r.songs, &r.ensemble, args.check.is_some())?;
    let t = Instant::now();
    let networks = offline::analysis::networks_from_files(args.beat_net.as_deref(), None)?;
    let loaded =
        offline::pool::parallel_map(&hearings, args.jobs.max(1), |h| load_song(h, networks));
    let (mut train, mut valid) = (DownbeatExamples::default(), DownbeatExamples::default());
    for (hearing, song) in hearings.iter().zip(loaded) {
        let s = song?;
        let into = if hearing.validation {
            &mut valid
        } else {
            &mut train
        };
        into.add_song(&s.features, &s.reference, s.meter);
    }
    eprintln!(
        "analysed {} hearings of the songs in {:.0} s: {} labelled beats for training, {} for validation",
        hearings.len(),
        t.elapsed().as_secs_f64(),
        train.len(),
        valid.len()
    );
    let config = DownbeatTrainConfig {
        hidden: r.hidden.clone(),
        batch: r.batch,
        steps: args.check.unwrap_or(r.steps),
        learning_rate: r.learning_rate,
        input_noise: r.input_noise,
        seed: r.ensemble.seed,
    };
    let class_prior = train.class_frequencies();
    let t = Instant::now();
    let mut nets = Vec::new();
    for member in 0..r.ensemble.members {
        let config = DownbeatTrainConfig {
            seed: r.ensemble.member_seed(member),
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
