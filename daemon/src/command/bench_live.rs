//! `danced bench live`: the live pipeline at 1× on a replayed file (latency, jitter, CPU,
//! memory, drops).

use std::path::PathBuf;

use anyhow::Result;

use crate::command::source::SourceArgs;
use crate::live::config::Config;
use crate::live::run::{AudioSource, RunMode, run_live, summary};

/// Options of `danced bench live`.
#[derive(clap::Args, Debug)]
pub struct BenchLiveArgs {
    /// Audio file (the built-in demo song, looped, without one).
    #[arg(long)]
    pub input: Option<PathBuf>,
    /// Seconds to run.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
    /// Frames sent per second.
    #[arg(long, default_value_t = 60.0)]
    pub rate: f64,
    /// Write the stats as JSON here.
    #[arg(long)]
    pub stats_json: Option<PathBuf>,
    /// The dancer measured.
    #[command(flatten)]
    pub dancer: SourceArgs,
}

/// Runs `danced bench live`.
pub fn bench_live(args: BenchLiveArgs) -> Result<()> {
    let BenchLiveArgs {
        input,
        seconds,
        rate,
        stats_json,
        dancer,
    } = args;
    let mut config = Config::default();
    dancer.apply(&mut config);
    config.audio.duration = Some(seconds);
    config.audio.looped = true;
    config.output.rate_hz = rate;
    config.stats_json = stats_json;
    // A benchmark takes no control and must not hold the performer's control port.
    config.control.osc_port = 0;
    config.validate("command line")?;
    let audio = input.map_or(AudioSource::Demo, AudioSource::File);
    eprintln!("running the live pipeline at 1× for {seconds} s...");
    let report = run_live(&config, audio, RunMode::Quiet)?;
    println!("{}", summary(&report));
    Ok(())
}
