//! `danced`: the command line. It parses and dispatches; each command lives in
//! `daemon::command`.

use anyhow::Result;
use clap::{Parser, Subcommand};
use tracing_subscriber::EnvFilter;

use daemon::command::analyze::{AnalyzeArgs, analyze};
use daemon::command::bench_beats::{BenchBeatsArgs, bench_beats};
use daemon::command::bench_clock::{BenchClockArgs, bench_clock};
use daemon::command::bench_cues::{BenchCuesArgs, bench_cues};
use daemon::command::bench_lag::{BenchLagArgs, bench_lag};
use daemon::command::bench_live::{BenchLiveArgs, bench_live};
use daemon::command::bench_model::{BenchModelArgs, bench_model};
use daemon::command::bench_motion_beats::{BenchMotionBeatsArgs, bench_motion_beats};
use daemon::command::bench_moves::{BenchMovesArgs, bench_moves};
use daemon::command::bench_stage::{BenchStageArgs, bench_stage};
use daemon::command::bvh_export::{BvhArgs, bvh_export};
use daemon::command::dataset::{DatasetCommand, dataset};
use daemon::command::demo::{DemoArgs, demo};
use daemon::command::devices::devices;
use daemon::command::eval::{EvalArgs, eval};
use daemon::command::generate::{GenerateArgs, generate};
use daemon::command::library::{LibraryCommand, library};
use daemon::command::metrics::{MetricsArgs, metrics};
use daemon::command::moved::{MovedArgs, moved};
use daemon::command::run::{RunArgs, run};
use daemon::command::view::{ViewArgs, view};

// Counts allocations in the audio callback path (see `daemon::alloc_counter`).
#[global_allocator]
static ALLOCATOR: daemon::alloc_counter::CountingAllocator =
    daemon::alloc_counter::CountingAllocator;

/// Listens to music and makes a 3D character dance to it, live.
#[derive(Parser, Debug)]
#[command(name = "danced", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Moved: `danced-train dancer` trains the neural dancer.
    #[command(hide = true, disable_help_flag = true)]
    Train(MovedArgs),
    /// Moved: `danced-train beats` trains the learned beat activation.
    #[command(hide = true, disable_help_flag = true)]
    TrainBeats(MovedArgs),
    /// Analyse an audio file with the streaming analysis (beats, onsets, tempo, features).
    Analyze(AnalyzeArgs),
    /// Measure the analysis on the annotated data sets.
    Bench {
        #[command(subcommand)]
        what: BenchCommand,
    },
    /// Dance to a song offline through the streaming analysis and write the motion as BVH.
    Generate(GenerateArgs),
    /// Play a dance file in the browser view, with its song in sync when given.
    View(ViewArgs),
    /// Export a tang2018 dance, fitted to the rig, as BVH.
    Bvh(BvhArgs),
    /// Dance metrics of a BVH motion against a song's beats (BeatAlign, beat offset, kinetic
    /// features, freezes, foot skating).
    Metrics(MetricsArgs),
    /// Dance live to the sound card (or a replayed file) and send the motion.
    Run(Box<RunArgs>),
    /// Dance live to the built-in demo song (no sound card, no files needed).
    Demo(DemoArgs),
    /// List the audio inputs.
    Devices,
    /// The tang2018 training data: audit it.
    Dataset {
        #[command(subcommand)]
        what: DatasetCommand,
    },
    /// Score the motion sources on the validation dances' music: BeatAlign, beat offset, FPD,
    /// FMD, FID_k, Dist_k, freezes, foot skating, next to the ground truth.
    Eval(EvalArgs),
    /// The retrieval dancer's clip library.
    Library {
        #[command(subcommand)]
        what: LibraryCommand,
    },
}

#[derive(Subcommand, Debug)]
enum BenchCommand {
    /// Beat tracking accuracy and speed: native and aubio on synth-beats, tang2018, real-music, madmom-tests.
    Beats(BenchBeatsArgs),
    /// The live pipeline at 1× on a replayed file: latency, jitter, CPU, memory, drops.
    Live(BenchLiveArgs),
    /// How far the dancer a receiver sees trails the heard music, measured over UDP.
    Lag(BenchLagArgs),
    /// Key poses cued on the next bar during real-time replays: how many land on a downbeat.
    Cues(BenchCuesArgs),
    /// Per-frame sampling time of the neural dancer on one thread (p50, p99).
    Model(BenchModelArgs),
    /// How far each dancer wanders on each stage mode, and what keeping it on the stage costs.
    Stage(BenchStageArgs),
    /// A clip library cut from your own dances (and the built-in one) danced to annotated
    /// songs: beat by tempo band, freezes, foot skating, and whether its moves show.
    Moves(BenchMovesArgs),
    /// The beat grid found from each tang2018 dance's motion alone against its music's beats.
    MotionBeats(BenchMotionBeatsArgs),
    /// The show's clock: MIDI clock followed and sent; Link followed and led (builds with
    /// Link, in a network namespace of its own).
    Clock(BenchClockArgs),
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    daemon::alloc_counter::mark_installed();
    match Cli::parse().command {
        Command::Train(args) => moved("train", "dancer", &args),
        Command::TrainBeats(args) => moved("train-beats", "beats", &args),
        Command::Analyze(args) => analyze(args),
        Command::Bench { what } => match what {
            BenchCommand::Beats(args) => bench_beats(args),
            BenchCommand::Live(args) => bench_live(args),
            BenchCommand::Lag(args) => bench_lag(args),
            BenchCommand::Cues(args) => bench_cues(args),
            BenchCommand::Model(args) => bench_model(&args),
            BenchCommand::Stage(args) => bench_stage(args),
            BenchCommand::Moves(args) => bench_moves(args),
            BenchCommand::MotionBeats(args) => bench_motion_beats(args),
            BenchCommand::Clock(args) => bench_clock(args),
        },
        Command::Generate(args) => generate(&args),
        Command::View(args) => view(&args),
        Command::Bvh(args) => bvh_export(&args),
        Command::Metrics(args) => metrics(&args),
        Command::Run(args) => run(*args),
        Command::Demo(args) => demo(args),
        Command::Devices => devices(),
        Command::Dataset { what } => dataset(what),
        Command::Eval(args) => eval(&args),
        Command::Library { what } => library(what),
    }
}
