//! `danced-train dancer`: trains the neural dancer by a recipe, stage by stage (data, progress,
//! validation, checkpoints).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use sha2::{Digest, Sha256};

use model::neural::config::NetConfig;
use model::neural::file::{NeuralModel, TrainingSummary};
use model::neural::rng::Rng;
use model::neural::tensors::init_net;
use model::neural::token::Normalizer;
use offline::dataset::BuiltDance;

use crate::net::{FreeRun, InputPath};
use crate::recipe::{
    DancerRecipe, DancerStage, RolloutSettings, SHIPPED_DANCER_RECIPE, SHIPPED_DANCER_RECIPE_PATH,
    TrainOnly,
};
use crate::train::{
    Batch, Corpus, CriticTerm, DanceInput, KEY_HORIZON_MIN, KeyRollout, StepLoss, Trainer,
    add_key_to_flow,
};

/// Options of `danced-train dancer`.
#[derive(clap::Args, Debug, Clone)]
pub struct TrainArgs {
    /// The recipe to train by (TOML: its stages and their settings); default: the shipped
    /// dancer's, `configs/models/default.recipe.toml`, built in.
    #[arg(long, value_name = "FILE")]
    pub recipe: Option<PathBuf>,
    /// The shared data folder (tang2018 dances are built from it).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Where the model is written (at every epoch, so an interrupted run leaves the latest).
    #[arg(long, default_value = "danced-model.dnn")]
    pub out: PathBuf,
    /// Threads building the dances.
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// Check a recipe quickly instead of training by it: every stage stops after this many
    /// steps, on three training dances and one validation dance (a model for tests, not for a
    /// show; the file says so).
    #[arg(long, value_name = "STEPS", hide = true)]
    pub check: Option<u64>,
}

/// Training dances a `--check` run takes (and one validation dance).
const CHECK_DANCES: usize = 3;

/// The tang2018 dances with music (training and validation; the split is the whole data
/// set's), all of them or, with `check`, the first [`CHECK_DANCES`] training dances and the
/// first validation dance in name order.
pub(crate) fn load_dances(data: &Path, jobs: usize, check: bool) -> Result<Vec<BuiltDance>> {
    let mut listed = offline::dataset::dances_with_split(data)
        .with_context(|| format!("reading {}", data.join("tang2018").display()))?;
    if check {
        let (mut train, mut val) = (0, 0);
        listed.retain(|(dir, _, validation)| {
            let has_song = dir.join("audio.mp3").is_file();
            let keep = has_song
                && if *validation {
                    val < 1
                } else {
                    train < CHECK_DANCES
                };
            if keep {
                *if *validation { &mut val } else { &mut train } += 1;
            }
            keep
        });
    }
    let pb = offline::progress::count_bar(listed.len() as u64);
    let built: Vec<BuiltDance> = offline::dataset::build_dances(
        data,
        &listed,
        jobs,
        |_, _| true,
        |name| {
            pb.set_message(name.to_string());
            pb.inc(1);
        },
    )
    .into_iter()
    .filter_map(|(_, r)| r.ok())
    .filter(|d| !d.music.is_empty())
    .map(|mut d| {
        d.motion = d.motion_on_default_rig();
        d
    })
    .collect();
    pb.finish_and_clear();
    if built.iter().all(|d| d.validation) {
        bail!(
            "no training dance with music could be built from {}",
            data.display()
        );
    }
    Ok(built)
}

/// The (motion, music, style) of the training or the validation dances.
pub(crate) fn pairs(dances: &[BuiltDance], validation: bool) -> Vec<DanceInput<'_>> {
    dances
        .iter()
        .filter(|d| d.validation == validation)
        .map(|d| {
            let style = model::style::DanceStyle::of_tang_dance(&d.name).map(|s| s.index());
            (&d.motion[..], &d.music[..], style)
        })
        .collect()
}

/// `mean` moved 2 % towards `x` (`x` itself while `mean` is NaN, i.e. unset): the smoothing of
/// the progress line's figures.
fn running_mean(mean: f64, x: f64) -> f64 {
    if mean.is_nan() {
        x
    } else {
        0.98 * mean + 0.02 * x
    }
}

/// Warm-up, then cosine decay to a tenth of the peak over the run (`progress` 0 to 1).
fn learning_rate(peak: f64, step: u64, progress: f64) -> f64 {
    let warm = ((step + 1) as f64 / 200.0).min(1.0);
    let cosine = 0.5 * (1.0 + (std::f64::consts::PI * progress.clamp(0.0, 1.0)).cos());
    peak * warm * (0.1 + 0.9 * cosine)
}

/// Feeds the training frames (each dance's name, motion and music, as little-endian f32)
/// into `hash`.
fn hash_frames(hash: &mut Sha256, dances: &[&BuiltDance]) {
    for d in dances {
        hash.update(d.name.as_bytes());
        for frame in &d.motion {
            for v in frame {
                hash.update(v.to_le_bytes());
            }
        }
        for frame in &d.music {
            for v in frame {
                hash.update(v.to_le_bytes());
            }
        }
    }
}

/// Runs `danced-train dancer`: every stage of the recipe, each continuing from the weights the
/// one before it left.
pub fn train(args: &TrainArgs) -> Result<()> {
    let (recipe, text, origin) = match &args.recipe {
        Some(path) => {
            let (recipe, text) = DancerRecipe::read(path)?;
            (recipe, text, path.display().to_string())
        }
        None => (
            DancerRecipe::shipped(),
            SHIPPED_DANCER_RECIPE.to_string(),
            format!("the shipped recipe ({SHIPPED_DANCER_RECIPE_PATH})"),
        ),
    };
    let recorded = match args.check {
        Some(steps) => format!(
            "# A check of this recipe, not a model for a show: every stage stopped after {steps} steps, on {CHECK_DANCES} training dances and one validation dance.\n{text}"
        ),
        None => text,
    };
    eprintln!(
        "training by {origin}: {} stages, {} steps",
        recipe.stages.len(),
        recipe
            .stages
            .iter()
            .map(|s| args.check.map_or(s.steps, |c| s.steps.min(c)))
            .sum::<u64>()
    );
    let started_loading = Instant::now();
    let dances = load_dances(&args.data, args.jobs, args.check.is_some())?;
    eprintln!(
        "data: {} dances loaded in {:.0} s",
        dances.len(),
        started_loading.elapsed().as_secs_f64()
    );
    let mut data_hash = Sha256::new();
    let mut model: Option<NeuralModel> = None;
    let mut retimed: Option<(f64, Vec<BuiltDance>)> = None;
    for (i, stage) in recipe.stages.iter().enumerate() {
        let steps = args.check.map_or(stage.steps, |c| stage.steps.min(c));
        eprintln!(
            "stage {}/{} ({}): {steps} steps",
            i + 1,
            recipe.stages.len(),
            stage.name
        );
        // Stages that retime alike (the shipped three all do) share one retimed copy.
        if stage.beat_retime > 0.0 && retimed.as_ref().is_none_or(|r| r.0 != stage.beat_retime) {
            let copy = dances
                .iter()
                .map(|d| {
                    if d.validation {
                        d.clone()
                    } else {
                        d.beat_retimed(stage.beat_retime)
                    }
                })
                .collect();
            retimed = Some((stage.beat_retime, copy));
        }
        let stage_dances: &[BuiltDance] = match &retimed {
            Some((depth, copy)) if stage.beat_retime > 0.0 && *depth == stage.beat_retime => copy,
            _ => &dances,
        };
        let training: Vec<&BuiltDance> = stage_dances.iter().filter(|d| !d.validation).collect();
        hash_frames(&mut data_hash, &training);
        let digest = data_hash.clone().finalize();
        let hash: String = digest.iter().map(|b| format!("{b:02x}")).collect();
        let trained = train_stage(
            args,
            stage,
            steps,
            stage_dances,
            model.take(),
            &recorded,
            &format!("sha256:{hash}"),
        )
        .with_context(|| format!("stage {} ({})", i + 1, stage.name))?;
        model = Some(trained);
    }
    Ok(())
}

/// The model a stage starts from: the one the stage before left, its flow given the key pose
/// if the stage asks for it, or (`start` None) a new network normalised to `train_pairs`.
fn stage_model(
    stage: &DancerStage,
    start: Option<NeuralModel>,
    train_pairs: &[DanceInput<'_>],
) -> Result<NeuralModel> {
    if let Some(mut model) = start {
        if stage.key_to_flow && !model.config.key_to_flow {
            add_key_to_flow(&mut model).context("giving the flow the key pose")?;
            eprintln!(
                "the flow now also reads the key pose (new weights zero: the same dancer until trained)"
            );
        }
        return Ok(model);
    }
    let config = NetConfig {
        key_to_flow: stage.key_to_flow,
        ..NetConfig::default()
    };
    let mut m = NeuralModel {
        config,
        tensors: init_net(&config, stage.seed),
        training: TrainingSummary::default(),
    };
    let motion: Vec<_> = train_pairs
        .iter()
        .flat_map(|p| p.0.iter().copied())
        .collect();
    let music: Vec<_> = train_pairs
        .iter()
        .flat_map(|p| p.1.iter().copied())
        .collect();
    m.set_normalizer(&Normalizer::fit(&motion, &music));
    Ok(m)
}

/// The rollouts of one step as `r` sets them: from the token before the first full window,
/// towards a key pose due 12 frames or more later (or, with no key weight, with no key), the
/// draws made from `rng` in the order training has always made them.
fn stage_rollout(
    r: &RolloutSettings,
    stage: &DancerStage,
    window: usize,
    corpus: &Corpus,
    rng: &mut Rng,
) -> KeyRollout {
    // A full window of past before the announcement, as the live dancer has.
    let at = window - 1;
    let longest = r.horizon.min(stage.sequence.saturating_sub(at + 1));
    let horizon = KEY_HORIZON_MIN + rng.below(longest.saturating_sub(KEY_HORIZON_MIN) + 1);
    KeyRollout {
        batch: if r.key_weight > 0.0 {
            corpus.rollout_batch(rng, r.sequences, at, horizon, r.foreign)
        } else {
            corpus.free_rollout_batch(rng, r.sequences)
        },
        run: FreeRun {
            at,
            horizon,
            temperature: r.temperature,
            backprop_steps: r.backprop_steps,
            approach: r.approach,
        },
        weight: r.key_weight as f32,
        critic: r.critic.as_ref().map(|c| CriticTerm {
            weight: c.weight as f32,
            floor: c.floor.map_or(f32::MIN, |f| f as f32),
        }),
        noise_seed: rng.next_u64(),
        key_cm: r.key_cm.map(|c| c as f32),
        kinetic: r.kinetic as f32,
    }
}

/// The running figures of a stage's progress lines.
struct StageFigures {
    loss: f64,
    key_error: f64,
    key_error_cm: f64,
    keyless_nll: f64,
    kinetic_mismatch: f64,
    skipped_rollouts: u64,
    exploded_sequences: u64,
    gradient_skips: u64,
}

impl StageFigures {
    fn new() -> Self {
        Self {
            loss: f64::NAN,
            key_error: f64::NAN,
            key_error_cm: f64::NAN,
            keyless_nll: f64::NAN,
            kinetic_mismatch: f64::NAN,
            skipped_rollouts: 0,
            exploded_sequences: 0,
            gradient_skips: 0,
        }
    }

    /// Takes in one step's scores (`rollout`: whether the step ran rollouts).
    fn add(&mut self, scored: &StepLoss, rollout: bool) {
        self.skipped_rollouts += u64::from(rollout && scored.key_error.is_none());
        self.exploded_sequences += scored.exploded_sequences as u64;
        self.gradient_skips += u64::from(scored.gradient_not_finite);
        let smooth = |mean: &mut f64, x: Option<f32>| {
            if let Some(x) = x {
                *mean = running_mean(*mean, f64::from(x));
            }
        };
        smooth(&mut self.key_error, scored.key_error);
        smooth(&mut self.key_error_cm, scored.key_error_cm);
        smooth(&mut self.keyless_nll, scored.keyless_nll);
        smooth(&mut self.kinetic_mismatch, scored.kinetic_mismatch);
        let loss = f64::from(scored.nll);
        if loss.is_finite() {
            self.loss = running_mean(self.loss, loss);
        }
    }

    /// The rollouts' figures for an epoch line (`rollouts`: whether the stage runs any).
    fn rollout_line(&self, rollouts: bool) -> String {
        let mut line = String::new();
        if !self.key_error.is_nan() {
            line += &format!(
                ", key-pose rollout error {:.2} ({:.1} cm; {} rollouts broke or all exploded, not scored; {} exploded sequences left out of the others)",
                self.key_error, self.key_error_cm, self.skipped_rollouts, self.exploded_sequences
            );
        } else if rollouts {
            line += &format!(
                ", rollouts: {} broke or all exploded, not scored; {} exploded sequences left out of the others",
                self.skipped_rollouts, self.exploded_sequences
            );
        }
        if !self.keyless_nll.is_nan() {
            line += &format!(
                ", the rollouts' key-hidden NLL under the frozen start {:.2}",
                self.keyless_nll
            );
        }
        if !self.kinetic_mismatch.is_nan() {
            line += &format!(", their kinetic mismatch {:.3}", self.kinetic_mismatch);
        }
        if self.gradient_skips > 0 {
            line += &format!(
                ", {} updates skipped for a non-finite gradient",
                self.gradient_skips
            );
        }
        line
    }
}

/// One stage: the model the stage before left (None: a new network), trained `steps` steps
/// on `dances` and written to `--out`.
fn train_stage(
    args: &TrainArgs,
    stage: &DancerStage,
    steps: u64,
    dances: &[BuiltDance],
    start: Option<NeuralModel>,
    recipe_text: &str,
    data_hash: &str,
) -> Result<NeuralModel> {
    let train_pairs = pairs(dances, false);
    let train_names: Vec<String> = dances
        .iter()
        .filter(|d| !d.validation)
        .map(|d| d.name.clone())
        .collect();
    let val_pairs = pairs(dances, true);
    let fresh = start.is_none();
    let mut model = stage_model(stage, start, &train_pairs)?;
    let config = model.config;
    let norm = model.normalizer()?;
    let mut corpus = Corpus::new(&train_pairs, &norm, &config, stage.sequence);
    corpus.set_input_noise(stage.input_noise);
    corpus.set_music_drop(stage.music_drop);
    let val_corpus = Corpus::new(&val_pairs, &norm, &config, stage.sequence);
    if corpus.dances() == 0 {
        bail!(
            "no training dance is long enough for a {}-frame sequence",
            stage.sequence
        );
    }
    // The seed clip: the training data's most typical window (chosen afresh every stage, so
    // a model's seed always follows the current rule).
    let (seed_dance, seed_start) = corpus
        .typical_seed()
        .context("no training dance is longer than one window")?;
    let (motion, music) = corpus
        .seed_clip(&norm, seed_dance, seed_start)
        .context("no training dance is longer than one window")?;
    model.set_seed_clip(motion, music);
    let all_training_frames: Vec<_> = train_pairs
        .iter()
        .flat_map(|p| p.0.iter().copied())
        .collect();
    model.set_pose_range(&all_training_frames);
    eprintln!(
        "seed clip: training dance {} ({}), frames {seed_start}..{}",
        seed_dance,
        train_names.get(seed_dance).map_or("?", |s| s.as_str()),
        seed_start + config.window
    );
    let val: Vec<Batch> = val_corpus.all_sequences().into_iter().take(32).collect();
    eprintln!(
        "data: {} training dances ({} frames), {} validation dances ({} frames, {} sequences scored)",
        corpus.dances(),
        corpus.frames(),
        val_corpus.dances(),
        val_corpus.frames(),
        val.iter().map(|b| b.sequences).sum::<usize>(),
    );
    let previous = model.training.clone();
    model.training.dances = corpus.dances();
    model.training.frames = corpus.frames();
    model.training.seed = stage.seed;
    model.training.horizon_frames = model::horizon::data_horizon(model::tang2018::TANG_FPS);
    let retimed = if stage.beat_retime > 0.0 {
        format!(
            ", retimed within each beat (pace 1 − {}·cos(beat phase))",
            stage.beat_retime
        )
    } else {
        String::new()
    };
    model.training.data = format!(
        "tang2018 (Tang, Jia & Mao, Dance with Melody, ACM MM 2018; public research data), training split of danced dataset v{}, re-posed on the default rig{retimed}: {}",
        offline::dataset::DATASET_VERSION,
        train_names.join(" ")
    );
    model.training.recipe = recipe_text.to_string();
    model.training.data_hash = data_hash.to_string();
    let mut trainer = Trainer::new(model)?;
    if let Some(TrainOnly::Key) = stage.train_only {
        trainer = trainer.training_only(InputPath::Key);
    }
    let rollout_settings = stage.rollout.as_ref();
    if rollout_settings.is_some_and(|r| r.critic.is_some()) {
        trainer = trainer.with_critic()?;
    }
    let mut rng = Rng::new(stage.seed.wrapping_add(previous.steps));
    if fresh {
        trainer.data_init(&corpus.random_batch(&mut rng, 64, stage.key_drop));
    }
    let frames_per_step = stage.batch * stage.sequence;
    let steps_per_epoch = (corpus.frames() / frames_per_step).max(1) as u64;
    let pb = ProgressBar::new(steps);
    pb.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} steps {elapsed} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let started = Instant::now();
    let mut step: u64 = 0;
    let mut figures = StageFigures::new();
    let mut bad_steps = 0;
    let mut last_val = if val.is_empty() {
        None
    } else {
        Some(trainer.evaluate(&val)?)
    };
    eprintln!("validation NLL before the stage: {last_val:?} nats/frame");
    let validate = |trainer: &mut Trainer| -> Result<Option<f64>> {
        if val.is_empty() {
            return Ok(None);
        }
        Ok(Some(trainer.evaluate(&val)?))
    };
    let checkpoint = |trainer: &mut Trainer, step: u64, val: Option<f64>, elapsed: f64| {
        let m = trainer.model();
        m.training.steps = previous.steps + step;
        m.training.sequences = previous.sequences + step * stage.batch as u64;
        m.training.seconds = previous.seconds + elapsed;
        m.training.validation_nll = val;
        m.save(&args.out)
            .with_context(|| format!("writing {}", args.out.display()))
    };
    while step < steps {
        let progress = step as f64 / steps.max(1) as f64;
        let lr = learning_rate(stage.lr, step, progress);
        let batch = corpus.random_batch(&mut rng, stage.batch, stage.key_drop);
        let rollout =
            rollout_settings.map(|r| stage_rollout(r, stage, config.window, &corpus, &mut rng));
        let scored = trainer.step(&batch, rollout.as_ref(), lr);
        let loss = f64::from(scored.nll);
        figures.add(&scored, rollout.is_some());
        bad_steps = if loss.is_finite() { 0 } else { bad_steps + 1 };
        if bad_steps >= 20 {
            bail!(
                "training diverged at step {step} (20 non-finite losses in a row); the last checkpoint is {}",
                args.out.display()
            );
        }
        step += 1;
        pb.set_position(step);
        if !loss.is_finite() {
            continue;
        }
        let secs = started.elapsed().as_secs_f64();
        if step.is_multiple_of(steps_per_epoch) {
            last_val = validate(&mut trainer)?;
            checkpoint(&mut trainer, step, last_val, secs)?;
            let line = format!(
                "{}: epoch {} (step {step}): loss {:.2}, validation NLL {} nats/frame{}",
                stage.name,
                step / steps_per_epoch,
                figures.loss,
                last_val.map_or("-".into(), |v| format!("{v:.2}")),
                figures.rollout_line(rollout_settings.is_some()),
            );
            // A hidden bar (stderr not a terminal) swallows println: print the epoch anyway.
            if pb.is_hidden() {
                eprintln!("{line}");
            } else {
                pb.println(line);
            }
        }
        pb.set_message(format!(
            "loss {:.2} val {} lr {lr:.1e} {:.0} frames/s",
            figures.loss,
            last_val.map_or("-".into(), |v| format!("{v:.2}")),
            (step as f64 * frames_per_step as f64) / secs.max(1e-9)
        ));
    }
    pb.finish_and_clear();
    let secs = started.elapsed().as_secs_f64();
    last_val = validate(&mut trainer)?;
    checkpoint(&mut trainer, step, last_val, secs)?;
    println!(
        "{}: trained {step} steps in {secs:.0} s ({:.3} s/step, {:.2} epochs); validation NLL {} nats/frame; wrote {}",
        stage.name,
        secs / step.max(1) as f64,
        step as f64 / steps_per_epoch as f64,
        last_val.map_or("-".into(), |v| format!("{v:.3}")),
        args.out.display()
    );
    Ok(trainer.model().clone())
}
