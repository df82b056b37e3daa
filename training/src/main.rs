//! `danced-train`: the command line of training (burn). The live binary, `danced`, reads what
//! it writes.

use anyhow::Result;
use clap::{Parser, Subcommand};
use tracing_subscriber::EnvFilter;

use training::command::{beats, dancer, downbeats};

/// Trains danced's networks: the neural dancer, the learned beat activation and the
/// downbeat network.
#[derive(Parser, Debug)]
#[command(name = "danced-train", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Train the neural dancer by a recipe (default: the shipped dancer's) on the tang2018 dances.
    Dancer(Box<dancer::TrainArgs>),
    /// Train the learned beat activation on songs with exact beats (e.g. rendered ones).
    Beats(beats::TrainBeatsArgs),
    /// Train the downbeat network on songs whose beats carry their position in the bar.
    Downbeats(downbeats::TrainDownbeatsArgs),
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::Dancer(args) => dancer::train(&args),
        Command::Beats(args) => beats::train_beats(&args),
        Command::Downbeats(args) => downbeats::train_downbeats(&args),
    }
}
