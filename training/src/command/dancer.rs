//! `danced-train dancer`: the neural dancer's training loop (data, progress, validation,
//! checkpoints).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};

use dsp::feature::FEATURE_DIM;
use model::motion::MOTION_FEATURE_DIM;
use model::neural::config::NetConfig;
use model::neural::file::{NeuralModel, TrainingSummary};
use model::neural::rng::Rng;
use model::neural::tensors::init_net;
use model::neural::token::{MUSIC_AT, Normalizer, TOKEN_DIM};
use offline::dataset::BuiltDance;

use crate::net::{FreeRun, InputPath};
use crate::train::{
    Batch, Corpus, CriticTerm, DanceInput, KEY_HORIZON_MIN, KeyRollout, Trainer, add_key_to_flow,
    add_level_to_flow, add_style_input,
};
use crate::weight_average::WeightAverage;

/// Options of `danced-train dancer`.
#[derive(clap::Args, Debug, Clone)]
pub struct TrainArgs {
    /// The shared data folder (tang2018 dances are built from it).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Where the model (and its checkpoints) are written.
    #[arg(long, default_value = "danced-model.dnn")]
    pub out: PathBuf,
    /// Training time budget, minutes (data loading not included).
    #[arg(long, default_value_t = 55.0)]
    pub minutes: f64,
    /// Continue from this model's weights (the optimiser state starts fresh).
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Seed of initialisation and batch sampling.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Sequences per batch.
    #[arg(long, default_value_t = 8)]
    pub batch: usize,
    /// Tokens per training sequence (longer than the 64-token attention window, so most
    /// positions train the full sliding window the live dancer always has).
    #[arg(long, default_value_t = 128)]
    pub sequence: usize,
    /// Peak learning rate.
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// Noise on the previous pose in training tokens, in standard deviations.
    #[arg(long, default_value_t = crate::train::INPUT_NOISE)]
    pub input_noise: f32,
    /// Fraction of sequences trained with the music hidden (so key poses carry information;
    /// 0.3 measured no better: the key input stayed unused and FID_k rose).
    #[arg(long, default_value_t = 0.0)]
    pub music_drop: f64,
    /// Also train on every training dance's mirror image (left and right swapped; the same
    /// music), doubling the data.
    #[arg(long)]
    pub mirror: bool,
    /// Fraction of sequences trained without a key pose.
    #[arg(long, default_value_t = 0.3)]
    pub key_drop: f64,
    /// Fraction of key-pose sequences whose key pose is spliced in from anywhere in the
    /// training data, the dance gliding onto it (so the key input carries what the past
    /// cannot: without splicing the key pose is the dance's own future, which the past already
    /// predicts).
    #[arg(long, default_value_t = 0.0)]
    pub key_splice: f64,
    /// Weight of the key-pose rollout loss (Yang et al.'s key-pose loss): every step also
    /// free-runs `--rollout-sequences` clean sequences from an announced key pose to its
    /// frame (0.5–2 s) and adds this times the distance (normalised rotations) from the
    /// pose reached to the key; 0 runs none.
    #[arg(long, default_value_t = 0.0)]
    pub key_rollout: f64,
    /// Sequences free-run per step for the key-pose loss.
    #[arg(long, default_value_t = 2)]
    pub rollout_sequences: usize,
    /// Longest key-pose rollout, frames (the horizon is drawn from 12 up to it; at most the
    /// sequence minus a window).
    #[arg(long, default_value_t = 50)]
    pub rollout_horizon: usize,
    /// Feed the rollouts' sampled poses back without a gradient, so only the step onto the
    /// key pose learns (back-propagated through every step, the key loss rose as it trained);
    /// the same as `--rollout-backprop 1`. Without styles or `--rollout-bounded` such a run is
    /// drawn by the live runtime and scored in one pass, about five times as fast a step.
    #[arg(long, conflicts_with = "rollout_backprop")]
    pub rollout_detach: bool,
    /// Back-propagate the key-pose loss through only the last K steps of each rollout (the
    /// poses fed back before them are constants), so the approach learns without the
    /// gradient of a whole chain of flow inverses; default: every step.
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    pub rollout_backprop: Option<u64>,
    /// Fraction of rollouts whose key pose is taken from anywhere in the training dances
    /// rather than the dance's own future (a performer calls poses the dance was not heading
    /// for: the bank `danced eval` scores is of those); 0 announces only their own.
    #[arg(long, default_value_t = 0.0)]
    pub rollout_foreign: f64,
    /// Score the key-pose distance on the last N frames of each rollout too, weighted
    /// 1 − g / N at g frames to go (with truncated back-propagation, the step onto the key
    /// alone learns to jump there; this teaches an approach); 0 scores the key frame alone.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub rollout_approach: usize,
    /// Weight of the key-pose rollouts' NLL under a frozen copy of the weights training
    /// resumed from, with the key hidden from that copy (nats per frame): the approach to a
    /// key must still look like dancing to a dancer that does not know where it is going;
    /// 0 keeps no copy. With `--key-rollout 0` the rollouts announce no key and this alone
    /// judges them: free dancing, as the shipped dancer (key poses shown over it) dances.
    #[arg(long, default_value_t = 0.0, requires = "resume")]
    pub rollout_keyless: f64,
    /// Frames of the rollouts the frozen copy finds at least this likely (NLL in nats per
    /// frame at or below it: e.g. the starting validation NLL, the data's own) cost nothing,
    /// so the free run is not rewarded for being likelier than dancing; default: no floor.
    #[arg(
        long,
        value_name = "NATS",
        requires = "rollout_keyless",
        allow_hyphen_values = true
    )]
    pub rollout_keyless_floor: Option<f64>,
    /// Fade the frozen copy's weight over the approach (`--rollout-approach` frames) to 0 on
    /// the key frame, so the dancing is judged on the way and the key distance alone judges
    /// the arrival.
    #[arg(long, requires = "rollout_keyless")]
    pub rollout_keyless_fade: bool,
    /// Hold each rollout's flow inverse finite (`net::ROLLOUT_INVERSE_BOUND`), so a sequence
    /// that explodes is left out instead of its infinities dropping the batch's whole rollout.
    /// Off by default: one run of the shipped recipe with it (K2G) danced worse than the two
    /// without it, more than a draw usually moves it.
    #[arg(long, requires = "key_rollout")]
    pub rollout_bounded: bool,
    /// Draw each foreign key pose (`--rollout-foreign`) as the farthest of N frames from the
    /// dance's own pose at the key frame: performers call poses that stand out, and a frame
    /// drawn at random is most often near the mean pose.
    #[arg(long, value_name = "N", default_value_t = 1, requires = "rollout_foreign", value_parser = clap::value_parser!(u64).range(1..=64))]
    pub rollout_foreign_draws: u64,
    /// Score the key-pose rollouts' distance as the body shape's mean joint distance (joint
    /// positions relative to the hips on the default rig, what `danced eval` scores), this
    /// many cm to one unit of `--key-rollout`; default: the distance in normalised rotations,
    /// which weighs a wrist's own turn (it moves no joint) as much as the hips' (they move all).
    #[arg(long, value_name = "CM", requires = "key_rollout", value_parser = positive_cm)]
    pub rollout_key_cm: Option<f64>,
    /// Weight of the key-pose rollouts' kinetic mismatch: how far each joint's mean squared
    /// horizontal and vertical speed and mean acceleration over the free run (what `danced
    /// eval`'s FID_k compares) stand from the training dance's over the same frames, as a
    /// squared log ratio; the approach to a key must move as the dance moved there. 0: off.
    #[arg(long, default_value_t = 0.0, requires = "key_rollout")]
    pub rollout_kinetic: f64,
    /// Train only the weights that read these inputs of the resumed model: `key` (the
    /// embedding's and the flow couplings' rows for the key pose, its count-down and flag:
    /// with no key pending the network dances exactly as the resumed model does, so the
    /// key-pose loss cannot cost the free dancing), `music` (the embedding's rows for the
    /// music features), `relative-level` (its embedding row, and the flow's with
    /// `--level-to-flow`) or `style` (the style embedding; see `--add-style`).
    #[arg(long, value_enum, value_name = "INPUTS", requires = "resume")]
    pub train_only: Option<InputPath>,
    /// Temperature of the key-pose rollouts' samples.
    #[arg(long, default_value_t = 0.5)]
    pub rollout_temperature: f32,
    /// Fraction of training tokens whose previous pose is hidden (past-context dropout, as
    /// MoGlow and Yang et al.'s key-pose flow train: 0.7 there), so the key pose and the
    /// music must carry what the past otherwise predicts; 0 hides none.
    #[arg(long, default_value_t = 0.0)]
    pub pose_drop: f64,
    /// Train the next-pose likelihood alone, without the auxiliary future-pose heads (the
    /// recipe before issue 21).
    #[arg(long)]
    pub no_aux: bool,
    /// Build a network without a style input (the architecture before issue 21).
    #[arg(long)]
    pub no_style: bool,
    /// Give a resumed network built without a style input one, its rows at zero: the same
    /// dancer, with or without a style, until trained (e.g. `--train-only style`).
    #[arg(long, requires = "resume", conflicts_with = "no_style")]
    pub add_style: bool,
    /// Build a network whose flow also reads the key pose's distance from the previous pose
    /// and the count-down directly (beside the transformer's context), so a key pose can
    /// steer the next pose without passing through attention. With `--resume` of a network
    /// built without it, the flow's new inputs start at zero weight (the same dancer).
    #[arg(long)]
    pub key_to_flow: bool,
    /// Build a network whose flow also reads the relative level (the music heard below its
    /// recent peak) directly, so a quieter passage can scale the next pose's distribution
    /// without passing through attention. With `--resume` of a network built without it, the
    /// flow's new input starts at zero weight (the same dancer).
    #[arg(long)]
    pub level_to_flow: bool,
    /// Balance the styles in the sampled sequences: a style's share goes as its frames to the
    /// power 1 − this (0: by frames, 25 waltzes to 4 cha-chas; 1: every style equally often).
    #[arg(long, default_value_t = 0.0)]
    pub style_balance: f64,
    /// Retime every training dance within each beat before training (time runs at
    /// 1 − depth·cos(beat phase), as the live beat accent does), so the network learns to slow
    /// into the beat from its own beat input; 0 trains on the dances as captured.
    #[arg(long, default_value_t = 0.0, value_parser = parse_depth)]
    pub beat_retime: f64,
    /// Write about this many quiet passages a minute into every training dance: 2 or 4 bars
    /// of its song turned down 6–14 dB and low-passed (before the streaming analysis hears
    /// it), the motion slowed to half time there (tang2018 has no breakdowns to learn calm
    /// from); 0 trains on the songs as they are.
    #[arg(long, default_value_t = 0.0, value_parser = parse_quiet)]
    pub quiet_passages: f64,
    /// Fraction of training sequences with the style input hidden.
    #[arg(long, default_value_t = 0.0)]
    pub style_drop: f64,
    /// Also train on every training dance played at these speeds with its song (varispeed,
    /// e.g. `0.8,1.25,1.5`: a dance of 87 BPM at 70, 109 and 130 BPM), comma-separated.
    #[arg(long, value_delimiter = ',', value_parser = parse_speed)]
    pub speeds: Vec<f64>,
    /// Train and validate on the dances of these styles only (e.g. `chacha`; comma-separated);
    /// default: every style.
    #[arg(long, value_delimiter = ',', value_parser = parse_style)]
    pub styles: Vec<model::style::DanceStyle>,
    /// Threads building the dances.
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// Stop after this many steps; the learning rate's cosine then runs over the steps (or
    /// the time budget, whichever ends first), so a run's schedule does not depend on how
    /// loaded the machine was.
    #[arg(long)]
    pub max_steps: Option<u64>,
    /// Write an exponential moving average of the weights (Polyak averaging, this decay per
    /// step: about `1 / (1 − D)` steps carry most of its weight) as the model, so one update's
    /// noise is averaged out of the dancer; the last step's weights go beside it as
    /// `OUT.last.dnn`. Default: the last step's weights are the model.
    #[arg(long, value_parser = parse_decay)]
    pub weight_average: Option<f64>,
    /// Use the tiny test network instead of the default size.
    #[arg(long, hide = true)]
    pub tiny: bool,
}

fn parse_speed(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.25..=4.0).contains(&v) => Ok(v),
        _ => Err(format!("{s:?}: a speed is a number in 0.25..=4")),
    }
}

fn parse_style(s: &str) -> Result<model::style::DanceStyle, String> {
    model::style::DanceStyle::from_name(s)
        .ok_or_else(|| format!("{s:?}: a style is chacha, rumba, tango or waltz"))
}

fn parse_quiet(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..=4.0).contains(&v) => Ok(v),
        _ => Err(format!(
            "{s:?}: quiet passages a minute is a number in 0..=4"
        )),
    }
}

fn parse_decay(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..1.0).contains(&v) => Ok(v),
        _ => Err(format!("{s:?}: a decay is a number in 0..1 (e.g. 0.99)")),
    }
}

/// Where the last step's weights go beside an averaged model: `X.dnn` → `X.last.dnn`.
pub fn last_step_path(out: &Path) -> PathBuf {
    out.with_extension("last.dnn")
}

fn positive_cm(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("{s:?}: centimetres to a unit is a number above 0")),
    }
}

fn parse_depth(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..0.9).contains(&v) => Ok(v),
        _ => Err(format!("{s:?}: a retime depth is a number in 0..0.9")),
    }
}

/// ` NAME VALUE` for the recipe when `value` is not the option's default of 0, else nothing.
fn option_if_set(name: &str, value: f64) -> String {
    if value > 0.0 {
        format!(" {name} {value}")
    } else {
        String::new()
    }
}

/// Whether each step also free-runs rollouts: towards key poses (`--key-rollout`), or with no
/// key for the frozen critic alone (`--rollout-keyless` with `--key-rollout 0`).
fn runs_rollouts(args: &TrainArgs) -> bool {
    args.key_rollout > 0.0 || args.rollout_keyless > 0.0
}

/// How many rollout steps the key-pose loss reaches back through (None: every step).
fn rollout_backprop(args: &TrainArgs) -> Option<usize> {
    if args.rollout_detach {
        Some(1)
    } else {
        args.rollout_backprop.map(|k| k as usize)
    }
}

/// The tang2018 dances of `styles` (every style if empty) built with their music (training
/// and validation; the split is the whole data set's).
pub(crate) fn load_dances(
    data: &Path,
    jobs: usize,
    speeds: &[f64],
    quiet_per_minute: f64,
    styles: &[model::style::DanceStyle],
) -> Result<Vec<BuiltDance>> {
    let built: Vec<BuiltDance> = offline::dataset::build_all_augmented(
        data,
        jobs,
        speeds,
        quiet_per_minute,
        |d, _| {
            styles.is_empty()
                || model::style::DanceStyle::of_tang_dance(&d.name)
                    .is_some_and(|s| styles.contains(&s))
        },
        true,
    )?
    .into_iter()
    .filter_map(|(_, r)| r.ok())
    .filter(|d| !d.music.is_empty())
    .collect();
    if built.is_empty() {
        bail!("no dance with music could be built from {}", data.display());
    }
    Ok(built)
}

/// A training dance's mirror image (owned motion) with the dance's music and style.
type MirroredDance<'a> = (
    Vec<[f32; MOTION_FEATURE_DIM]>,
    &'a [[f32; FEATURE_DIM]],
    Option<usize>,
);

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

/// The dances with their motion re-posed on the default rig (see
/// [`BuiltDance::motion_on_default_rig`]).
pub(crate) fn on_default_rig(mut dances: Vec<BuiltDance>) -> Vec<BuiltDance> {
    for d in &mut dances {
        d.motion = d.motion_on_default_rig();
    }
    dances
}

/// Fits the normalisation of the music features whose embedding rows are all zero (a model
/// widened to a newer feature layout: `model::neural::music_layout::upgrade` gives them mean 0,
/// std 1) to `music`, and returns their indices. No weight reads such a feature, so its
/// statistics change nothing the model does until it learns to read it, and then it reads it
/// on the scale of the other inputs rather than in raw units (dB for the relative level).
fn refit_unread_music(model: &mut NeuralModel, music: &[[f32; FEATURE_DIM]]) -> Result<Vec<usize>> {
    let embed = model
        .tensors
        .get("embed.w", &[TOKEN_DIM, model.config.d_model])?;
    let width = model.config.d_model;
    let unread: Vec<usize> = (0..FEATURE_DIM)
        .filter(|&i| {
            let row = (MUSIC_AT + i) * width;
            embed[row..row + width].iter().all(|&w| w == 0.0)
        })
        .collect();
    if unread.is_empty() || music.is_empty() {
        return Ok(Vec::new());
    }
    let mut norm = model.normalizer()?;
    let fitted = Normalizer::fit(&[], music);
    for &i in &unread {
        norm.music_mean[i] = fitted.music_mean[i];
        norm.music_std[i] = fitted.music_std[i];
    }
    model.set_normalizer(&norm);
    Ok(unread)
}

/// Prints how much of the training data the quiet passages cover and what they changed: the
/// energy heard (absolute and below the recent peak) and the joint speed inside them against the
/// rest of their dances.
fn report_quiet_passages(dances: &[BuiltDance]) {
    use dsp::feature::FeatureLayout;
    let (mut passages, mut quiet_frames, mut frames) = (0, 0, 0);
    let mut energy = [0.0f64; 2];
    let mut relative = [0.0f64; 2];
    let mut speed = [0.0f64; 2];
    let mut counts = [0usize; 2];
    let skeleton = model::rig::Skeleton::default_adult();
    for d in dances.iter().filter(|d| !d.validation) {
        frames += d.motion.len();
        if d.quiet.is_empty() {
            continue;
        }
        passages += d.quiet.len();
        let mut poses = Vec::new();
        model::motion::decode(&d.motion, model::motion::RootState::ORIGIN, &mut poses);
        let positions = skeleton.trajectory(&poses);
        for i in 1..d.music.len().min(poses.len()) {
            let inside = usize::from(d.quiet.iter().any(|&(a, b)| (a..b).contains(&i)));
            quiet_frames += inside;
            energy[inside] += f64::from(d.music[i][FeatureLayout::ENERGY]);
            relative[inside] += f64::from(d.music[i][FeatureLayout::RELATIVE_LEVEL]);
            speed[inside] += model::rig::Skeleton::mean_joint_step(&positions, i);
            counts[inside] += 1;
        }
    }
    let mean = |v: [f64; 2], k: usize| v[k] / counts[k].max(1) as f64;
    eprintln!(
        "quiet passages: {passages} over {:.1} % of {frames} training frames; energy heard {:.1} dB inside, {:.1} dB in the rest of their dances (below the recent peak {:.1} and {:.1} dB); joint speed inside / rest {:.2}",
        100.0 * quiet_frames as f64 / frames.max(1) as f64,
        mean(energy, 1),
        mean(energy, 0),
        mean(relative, 1),
        mean(relative, 0),
        mean(speed, 1) / mean(speed, 0).max(1e-9)
    );
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

/// Runs `danced-train dancer`.
pub fn train(args: &TrainArgs) -> Result<()> {
    let started_loading = Instant::now();
    let mut dances = on_default_rig(load_dances(
        &args.data,
        args.jobs,
        &args.speeds,
        args.quiet_passages,
        &args.styles,
    )?);
    if args.beat_retime > 0.0 {
        for d in dances.iter_mut().filter(|d| !d.validation) {
            *d = d.beat_retimed(args.beat_retime);
        }
    }
    if args.quiet_passages > 0.0 {
        report_quiet_passages(&dances);
    }
    let mut train_pairs = pairs(&dances, false);
    let mirrored: Vec<MirroredDance> = if args.mirror {
        train_pairs
            .iter()
            .map(|(m, a, style)| {
                (
                    m.iter().map(model::motion::mirror_features).collect(),
                    *a,
                    *style,
                )
            })
            .collect()
    } else {
        Vec::new()
    };
    train_pairs.extend(mirrored.iter().map(|(m, a, style)| (&m[..], *a, *style)));
    let train_names: Vec<String> = dances
        .iter()
        .filter(|d| !d.validation)
        .map(|d| d.name.clone())
        .collect();
    let val_pairs = pairs(&dances, true);
    let (mut model, fresh) = match &args.resume {
        Some(path) => {
            let mut model =
                NeuralModel::load(path).with_context(|| format!("loading {}", path.display()))?;
            if args.key_to_flow && !model.config.key_to_flow {
                add_key_to_flow(&mut model)
                    .with_context(|| format!("giving {}'s flow the key pose", path.display()))?;
                eprintln!(
                    "{}: its flow now also reads the key pose (new weights zero: the same dancer until trained)",
                    path.display()
                );
            }
            if args.add_style && model.config.styles == 0 {
                add_style_input(&mut model);
                eprintln!(
                    "{}: it now has a style input (rows zero: the same dancer until trained)",
                    path.display()
                );
            }
            if args.level_to_flow && !model.config.level_to_flow {
                add_level_to_flow(&mut model).with_context(|| {
                    format!("giving {}'s flow the relative level", path.display())
                })?;
                eprintln!(
                    "{}: its flow now also reads the relative level (new weights zero: the same dancer until trained)",
                    path.display()
                );
            }
            let music: Vec<_> = train_pairs
                .iter()
                .flat_map(|p| p.1.iter().copied())
                .collect();
            let refit = refit_unread_music(&mut model, &music)
                .with_context(|| format!("renormalising {}'s music", path.display()))?;
            if !refit.is_empty() {
                eprintln!(
                    "{}: music features {refit:?} are read by no weight yet; their normalisation is fitted to the training data",
                    path.display()
                );
            }
            (model, false)
        }
        None => {
            let mut config = if args.tiny {
                NetConfig::tiny()
            } else {
                NetConfig::default()
            };
            if args.no_style {
                config.styles = 0;
            }
            config.key_to_flow = args.key_to_flow;
            config.level_to_flow = args.level_to_flow;
            let mut m = NeuralModel {
                config,
                tensors: init_net(&config, args.seed),
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
            (m, true)
        }
    };
    let config = model.config;
    let norm = model.normalizer()?;
    let mut corpus = Corpus::new(&train_pairs, &norm, &config, args.sequence);
    corpus.set_input_noise(args.input_noise);
    corpus.set_music_drop(args.music_drop);
    corpus.set_style_drop(args.style_drop);
    corpus.set_style_balance(args.style_balance);
    corpus.set_key_splice(args.key_splice);
    corpus.set_pose_drop(args.pose_drop);
    if config.styles > 0 {
        let shares: Vec<String> = corpus
            .style_shares()
            .iter()
            .map(|(s, w)| {
                let name = s
                    .and_then(model::style::DanceStyle::from_index)
                    .map_or("none", |s| s.name());
                format!("{name} {:.0} %", 100.0 * w)
            })
            .collect();
        eprintln!("style shares of sampled sequences: {}", shares.join(", "));
    }
    let val_corpus = Corpus::new(&val_pairs, &norm, &config, args.sequence);
    if corpus.dances() == 0 {
        bail!(
            "no training dance is long enough for a {}-frame sequence",
            args.sequence
        );
    }
    // The seed clip: the training data's most typical window (chosen afresh when resuming,
    // so a model's seed always follows the current rule).
    let (seed_dance, seed_start) = corpus
        .typical_seed()
        .context("no training dance is longer than one window")?;
    let (motion, music) = corpus
        .seed_clip(&norm, seed_dance, seed_start)
        .context("no training dance is longer than one window")?;
    model.set_seed_clip(motion, music);
    // One seed clip per style, so a dance of that style starts (and restarts) from its own
    // motion: a cha-cha asked for over a waltz's context is a combination training never saw.
    for style in 0..config.styles {
        if let Some((dance, start)) = corpus.typical_seed_of(Some(style))
            && let Some((motion, music)) = corpus.seed_clip(&norm, dance, start)
        {
            eprintln!(
                "seed clip of style {style}: {}, frames {start}..{}",
                train_names.get(dance).map_or("?", |s| s.as_str()),
                start + config.window
            );
            model.set_style_seed_clip(style, motion, music);
        }
    }
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
        "data: {} training dances ({} frames), {} validation dances ({} frames, {} sequences scored), loaded in {:.0} s",
        corpus.dances(),
        corpus.frames(),
        val_corpus.dances(),
        val_corpus.frames(),
        val.iter().map(|b| b.sequences).sum::<usize>(),
        started_loading.elapsed().as_secs_f64()
    );
    let previous = model.training.clone();
    model.training.dances = corpus.dances();
    model.training.frames = corpus.frames();
    model.training.seed = args.seed;
    model.training.horizon_frames = model::horizon::data_horizon(model::tang2018::TANG_FPS);
    let mut variants = String::new();
    if args.mirror {
        variants += ", with their mirror images";
    }
    if args.beat_retime > 0.0 {
        variants += &format!(
            ", retimed within each beat (pace 1 − {}·cos(beat phase))",
            args.beat_retime
        );
    }
    if args.quiet_passages > 0.0 {
        variants += &format!(
            ", with about {} quiet passages a minute (2 or 4 bars of the song 6–14 dB down and low-passed, the motion at half time there)",
            args.quiet_passages
        );
    }
    if args.key_splice > 0.0 {
        variants += &format!(
            ", {} of the key-pose sequences with a key pose spliced in from elsewhere in the data (the dance gliding onto it)",
            args.key_splice
        );
    }
    if args.pose_drop > 0.0 {
        variants += &format!(
            ", {} of the training tokens with the previous pose hidden",
            args.pose_drop
        );
    }
    model.training.data = format!(
        "tang2018 (Tang, Jia & Mao, Dance with Melody, ACM MM 2018; public research data), training split of danced dataset v{}, re-posed on the default rig{variants}: {}",
        offline::dataset::DATASET_VERSION,
        train_names.join(" ")
    );
    let recipe = format!(
        "danced-train dancer --minutes {} --seed {} --batch {} --sequence {} --lr {} --key-drop {} --input-noise {} --music-drop {}",
        args.minutes,
        args.seed,
        args.batch,
        args.sequence,
        args.lr,
        args.key_drop,
        args.input_noise,
        args.music_drop
    ) + if args.mirror { " --mirror" } else { "" }
        + if args.no_aux { " --no-aux" } else { "" }
        + if args.no_style { " --no-style" } else { "" }
        + if args.key_to_flow {
            " --key-to-flow"
        } else {
            ""
        }
        + if args.add_style { " --add-style" } else { "" }
        + if args.level_to_flow {
            " --level-to-flow"
        } else {
            ""
        }
        + &option_if_set("--beat-retime", args.beat_retime)
        + &option_if_set("--style-balance", args.style_balance)
        + &option_if_set("--style-drop", args.style_drop)
        + &option_if_set("--quiet-passages", args.quiet_passages)
        + &option_if_set("--key-splice", args.key_splice)
        + &option_if_set("--pose-drop", args.pose_drop)
        + &if runs_rollouts(args) {
            format!(
                " --key-rollout {} --rollout-sequences {} --rollout-horizon {} --rollout-temperature {}{}",
                args.key_rollout,
                args.rollout_sequences,
                args.rollout_horizon,
                args.rollout_temperature,
                match rollout_backprop(args) {
                    Some(k) => format!(" --rollout-backprop {k}"),
                    None => String::new(),
                }
            ) + &option_if_set("--rollout-foreign", args.rollout_foreign)
                + &option_if_set("--rollout-kinetic", args.rollout_kinetic)
                + &option_if_set("--rollout-approach", args.rollout_approach as f64)
                + &if args.rollout_foreign_draws > 1 {
                    format!(" --rollout-foreign-draws {}", args.rollout_foreign_draws)
                } else {
                    String::new()
                }
                + &args
                    .rollout_key_cm
                    .map_or(String::new(), |c| format!(" --rollout-key-cm {c}"))
                + &option_if_set("--rollout-keyless", args.rollout_keyless)
                + &args
                    .rollout_keyless_floor
                    .map_or(String::new(), |f| format!(" --rollout-keyless-floor {f}"))
                + if args.rollout_keyless_fade {
                    " --rollout-keyless-fade"
                } else {
                    ""
                }
                + if args.rollout_bounded {
                    " --rollout-bounded"
                } else {
                    ""
                }
        } else {
            String::new()
        }
        + &args
            .max_steps
            .map_or(String::new(), |m| format!(" --max-steps {m}"))
        + &args
            .weight_average
            .map_or(String::new(), |d| format!(" --weight-average {d}"))
        + &args
            .train_only
            .and_then(|p| clap::ValueEnum::to_possible_value(&p))
            .map_or(String::new(), |v| format!(" --train-only {}", v.get_name()))
        + &if args.speeds.is_empty() {
            String::new()
        } else {
            let list: Vec<String> = args.speeds.iter().map(f64::to_string).collect();
            format!(" --speeds {}", list.join(","))
        }
        + &if args.styles.is_empty() {
            String::new()
        } else {
            let list: Vec<&str> = args.styles.iter().map(|s| s.name()).collect();
            format!(" --styles {}", list.join(","))
        };
    model.training.recipe = if previous.recipe.is_empty() {
        recipe
    } else {
        format!("{}; then --resume: {recipe}", previous.recipe)
    };
    let mut trainer = Trainer::new(model)?;
    if let Some(path) = args.train_only {
        trainer = trainer.training_only(path);
    }
    if args.rollout_keyless > 0.0 {
        trainer = trainer.with_critic()?;
    }
    let mut rng = Rng::new(args.seed.wrapping_add(previous.steps));
    if fresh {
        trainer.data_init(&corpus.random_batch(&mut rng, 64, args.key_drop));
    }
    let frames_per_step = args.batch * args.sequence;
    let steps_per_epoch = (corpus.frames() / frames_per_step).max(1) as u64;
    let budget = Duration::from_secs_f64(args.minutes.max(0.0) * 60.0);
    let pb = ProgressBar::new(budget.as_secs());
    pb.set_style(
        ProgressStyle::with_template("{bar:30} {elapsed}/{len}s {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let started = Instant::now();
    let mut step: u64 = 0;
    let mut smoothed = f64::NAN;
    let mut key_error = f64::NAN;
    let mut key_error_cm = f64::NAN;
    let mut keyless_nll = f64::NAN;
    let mut kinetic_mismatch = f64::NAN;
    let mut skipped_rollouts = 0u64;
    let mut exploded_sequences = 0u64;
    let mut gradient_skips = 0u64;
    let mut bad_steps = 0;
    let mut last_val = if val.is_empty() {
        None
    } else {
        Some(trainer.evaluate(&val)?)
    };
    eprintln!("validation NLL before training: {:?} nats/frame", last_val);
    let mut average = args
        .weight_average
        .map(|decay| WeightAverage::new(decay, &trainer.weights()));
    // The validation NLL of what goes to `--out`: the averaged weights when averaging.
    let validate =
        |trainer: &mut Trainer, average: Option<&WeightAverage>| -> Result<Option<f64>> {
            if val.is_empty() {
                return Ok(None);
            }
            Ok(Some(match average {
                Some(avg) => trainer.evaluate_weights(avg.weights(), &val)?,
                None => trainer.evaluate(&val)?,
            }))
        };
    let checkpoint = |trainer: &mut Trainer,
                      average: Option<&WeightAverage>,
                      step: u64,
                      val: Option<f64>,
                      elapsed: f64|
     -> Result<()> {
        let m = trainer.model();
        m.training.steps = previous.steps + step;
        m.training.sequences = previous.sequences + step * args.batch as u64;
        m.training.seconds = previous.seconds + elapsed;
        m.training.validation_nll = val;
        let Some(avg) = average else {
            return m
                .save(&args.out)
                .with_context(|| format!("writing {}", args.out.display()));
        };
        let last = last_step_path(&args.out);
        let mut averaged = m.clone();
        avg.apply_to(&mut averaged.tensors);
        // The validation NLL measured is the average's; the last step's is not measured here.
        m.training.validation_nll = None;
        m.save(&last)
            .with_context(|| format!("writing {}", last.display()))?;
        averaged
            .save(&args.out)
            .with_context(|| format!("writing {}", args.out.display()))
    };
    while started.elapsed() < budget && args.max_steps.is_none_or(|m| step < m) {
        let by_time = started.elapsed().as_secs_f64() / budget.as_secs_f64().max(1e-9);
        let by_steps = args
            .max_steps
            .map_or(0.0, |m| step as f64 / m.max(1) as f64);
        let progress = by_time.max(by_steps);
        let lr = learning_rate(args.lr, step, progress);
        let batch = corpus.random_batch(&mut rng, args.batch, args.key_drop);
        let rollout = runs_rollouts(args).then(|| {
            // A full window of past before the announcement, as the live dancer has.
            let at = config.window - 1;
            let longest = args
                .rollout_horizon
                .min(args.sequence.saturating_sub(at + 1));
            let horizon = KEY_HORIZON_MIN + rng.below(longest.saturating_sub(KEY_HORIZON_MIN) + 1);
            KeyRollout {
                batch: if args.key_rollout > 0.0 {
                    corpus.rollout_batch(
                        &mut rng,
                        args.rollout_sequences,
                        at,
                        horizon,
                        args.rollout_foreign,
                        args.rollout_foreign_draws as usize,
                    )
                } else {
                    corpus.free_rollout_batch(&mut rng, args.rollout_sequences)
                },
                run: FreeRun {
                    at,
                    horizon,
                    temperature: args.rollout_temperature,
                    backprop_steps: rollout_backprop(args),
                    approach: args.rollout_approach,
                    bounded: args.rollout_bounded,
                },
                weight: args.key_rollout as f32,
                critic: (args.rollout_keyless > 0.0).then(|| CriticTerm {
                    weight: args.rollout_keyless as f32,
                    floor: args.rollout_keyless_floor.map_or(f32::MIN, |f| f as f32),
                    fade: args.rollout_keyless_fade,
                }),
                noise_seed: rng.next_u64(),
                key_cm: args.rollout_key_cm.map(|c| c as f32),
                kinetic: args.rollout_kinetic as f32,
            }
        });
        let scored = trainer.step(&batch, rollout.as_ref(), lr, !args.no_aux);
        let loss = f64::from(scored.nll);
        if let Some(avg) = average.as_mut()
            && loss.is_finite()
        {
            avg.update(&trainer.weights());
        }
        skipped_rollouts += u64::from(rollout.is_some() && scored.key_error.is_none());
        exploded_sequences += scored.exploded_sequences as u64;
        gradient_skips += u64::from(scored.gradient_not_finite);
        if let Some(e) = scored.key_error {
            key_error = running_mean(key_error, f64::from(e));
        }
        if let Some(e) = scored.key_error_cm {
            key_error_cm = running_mean(key_error_cm, f64::from(e));
        }
        if let Some(e) = scored.keyless_nll {
            keyless_nll = running_mean(keyless_nll, f64::from(e));
        }
        if let Some(e) = scored.kinetic_mismatch {
            kinetic_mismatch = running_mean(kinetic_mismatch, f64::from(e));
        }
        bad_steps = if loss.is_finite() { 0 } else { bad_steps + 1 };
        if bad_steps >= 20 {
            bail!(
                "training diverged at step {step} (20 non-finite losses in a row); the last checkpoint is {}",
                args.out.display()
            );
        }
        if !loss.is_finite() {
            step += 1;
            continue;
        }
        smoothed = running_mean(smoothed, loss);
        step += 1;
        let secs = started.elapsed().as_secs_f64();
        if step.is_multiple_of(steps_per_epoch) {
            last_val = validate(&mut trainer, average.as_ref())?;
            checkpoint(&mut trainer, average.as_ref(), step, last_val, secs)?;
            // A hidden bar (stderr not a terminal) swallows println: print the epoch anyway.
            let line = format!(
                "epoch {} (step {step}): loss {smoothed:.2}, validation NLL {} nats/frame{}{}{}{}",
                step / steps_per_epoch,
                last_val.map_or("-".into(), |v| format!("{v:.2}")),
                if key_error.is_nan() {
                    String::new()
                } else if args.key_rollout == 0.0 {
                    format!(
                        ", free rollouts: {skipped_rollouts} broke or all exploded, not scored; {exploded_sequences} exploded sequences left out of the others"
                    )
                } else {
                    format!(
                        ", key-pose rollout error {key_error:.2} ({key_error_cm:.1} cm; {skipped_rollouts} rollouts broke or all exploded, not scored; {exploded_sequences} exploded sequences left out of the others)"
                    )
                },
                if keyless_nll.is_nan() {
                    String::new()
                } else {
                    format!(
                        ", the rollouts' key-hidden NLL under the frozen start {keyless_nll:.2}"
                    )
                },
                if kinetic_mismatch.is_nan() {
                    String::new()
                } else {
                    format!(", their kinetic mismatch {kinetic_mismatch:.3}")
                },
                if gradient_skips == 0 {
                    String::new()
                } else {
                    format!(", {gradient_skips} updates skipped for a non-finite gradient")
                }
            );
            if pb.is_hidden() {
                eprintln!("{line}");
            } else {
                pb.println(line);
            }
        }
        pb.set_position(secs as u64);
        pb.set_message(format!(
            "step {step} loss {smoothed:.2} val {} lr {lr:.1e} {:.0} frames/s",
            last_val.map_or("-".into(), |v| format!("{v:.2}")),
            (step as f64 * frames_per_step as f64) / secs
        ));
    }
    pb.finish_and_clear();
    let secs = started.elapsed().as_secs_f64();
    last_val = validate(&mut trainer, average.as_ref())?;
    checkpoint(&mut trainer, average.as_ref(), step, last_val, secs)?;
    if average.is_some() && !val.is_empty() {
        println!(
            "averaged weights (decay {}) written; the last step's weights ({}): validation NLL {:.3} nats/frame",
            args.weight_average.unwrap_or_default(),
            last_step_path(&args.out).display(),
            trainer.evaluate(&val)?
        );
    }
    println!(
        "trained {step} steps in {secs:.0} s ({:.3} s/step, {:.0} frames/s, {:.2} epochs); validation NLL {} nats/frame; wrote {}",
        secs / step.max(1) as f64,
        (step as f64 * frames_per_step as f64) / secs.max(1e-9),
        step as f64 / steps_per_epoch as f64,
        last_val.map_or("-".into(), |v| format!("{v:.3}")),
        args.out.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use dsp::feature::FeatureLayout;

    #[test]
    fn a_widened_models_unread_music_is_normalised_to_the_data_and_nothing_else() {
        let config = NetConfig::tiny();
        let mut model = NeuralModel {
            config,
            tensors: init_net(&config, 1),
            training: TrainingSummary::default(),
        };
        model.set_normalizer(&Normalizer::identity());
        let unread = FeatureLayout::RELATIVE_LEVEL;
        let width = config.d_model;
        let embed = model.tensors.map.get_mut("embed.w").unwrap();
        embed.data[(MUSIC_AT + unread) * width..][..width].fill(0.0);
        // Half the frames at −3 dB, half at −9: mean −6, std 3.
        let music: Vec<[f32; FEATURE_DIM]> = (0..100)
            .map(|i| {
                let mut row = [10.0; FEATURE_DIM];
                row[unread] = if i % 2 == 0 { -3.0 } else { -9.0 };
                row
            })
            .collect();
        assert_eq!(
            refit_unread_music(&mut model, &music).unwrap(),
            vec![unread]
        );
        let norm = model.normalizer().unwrap();
        assert!((norm.music_mean[unread] + 6.0).abs() < 1e-4, "{norm:?}");
        assert!((norm.music_std[unread] - 3.0).abs() < 1e-4, "{norm:?}");
        // Every feature a weight reads keeps the statistics it was trained with.
        for i in (0..FEATURE_DIM).filter(|&i| i != unread) {
            assert_eq!(
                (norm.music_mean[i], norm.music_std[i]),
                (0.0, 1.0),
                "feature {i}"
            );
        }
    }
}
