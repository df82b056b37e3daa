//! `danced-train key-probe`: teacher-forced, how much a key pose lowers the NLL of the frames
//! before it on the validation dances — whether the data gives the network any reason to read
//! its key input.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};

use model::neural::file::NeuralModel;

use crate::command::dancer::{load_dances, on_default_rig, pairs};
use crate::train::{Corpus, ProbeKey, Trainer};

/// Options of `danced-train key-probe`.
#[derive(clap::Args, Debug, Clone)]
pub struct KeyProbeArgs {
    /// The model to probe.
    #[arg(long, default_value = "configs/models/default.dnn")]
    pub model: PathBuf,
    /// The shared data directory (tang2018 dances).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Frames from the key pose's announcement to its frame (50 = 2 s; at most 63).
    #[arg(long, default_value_t = 50)]
    pub horizon: usize,
    /// Threads building the dances.
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
}

/// Frames-to-go bins of the report, inclusive.
const BINS: [(usize, usize); 5] = [(0, 0), (1, 5), (6, 12), (13, 25), (26, 63)];

/// Runs `danced-train key-probe`.
pub fn key_probe(args: &KeyProbeArgs) -> Result<()> {
    let model = NeuralModel::load(&args.model)
        .with_context(|| format!("loading {}", args.model.display()))?;
    let dances = on_default_rig(load_dances(&args.data, args.jobs, &[], 0.0, &[])?);
    let val = pairs(&dances, true);
    if val.len() < 2 {
        bail!("the key probe needs two validation dances or more");
    }
    let norm = model.normalizer()?;
    let sequence = 128;
    let corpus = Corpus::new(&val, &norm, &model.config, sequence);
    let at = sequence / 2;
    let horizon = args.horizon.min(sequence - 1 - at);
    let mut trainer = Trainer::new(model)?;
    let mut nll = Vec::new();
    for key in [ProbeKey::Own, ProbeKey::Absent, ProbeKey::Foreign] {
        nll.push(trainer.frame_nll(&corpus.key_probe(horizon, key))?);
    }
    let sequences = nll[0].len() / sequence;
    println!(
        "{}: {sequences} validation sequences, a key pose announced {horizon} frames ahead after {at} frames of past; mean NLL per frame, nats (teacher-forced)",
        args.model.display()
    );
    println!(
        "| frames to the key | with its own future pose | without a key | with another dance's pose | without − own | other − own |"
    );
    println!("| --- | --- | --- | --- | --- | --- |");
    for (lo, hi) in BINS.into_iter().filter(|(lo, _)| *lo <= horizon) {
        let mean = |v: &[f32]| {
            let (mut sum, mut n) = (0.0f64, 0usize);
            for q in 0..sequences {
                for ftg in lo..=hi.min(horizon) {
                    sum += f64::from(v[q * sequence + at + horizon - ftg]);
                    n += 1;
                }
            }
            sum / n.max(1) as f64
        };
        let (own, none, other) = (mean(&nll[0]), mean(&nll[1]), mean(&nll[2]));
        println!(
            "| {lo}–{} | {own:.2} | {none:.2} | {other:.2} | {:+.2} | {:+.2} |",
            hi.min(horizon),
            none - own,
            other - own
        );
    }
    Ok(())
}
