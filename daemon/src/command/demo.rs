//! `danced demo`: dance live to the built-in demo song (no sound card, no files).

use std::path::PathBuf;

use anyhow::Result;

use crate::command::clock_args::ClockArgs;
use crate::command::source::SourceArgs;
use crate::command::view_flag::ViewFlag;
use crate::live::config::Config;
use crate::live::run::{AudioSource, RunMode, run_live, summary};

/// Options of `danced demo`.
#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Stop after this many seconds (runs until Ctrl-C otherwise).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Frames sent per second.
    #[arg(long)]
    pub rate: Option<f64>,
    /// Write the run's stats as JSON here.
    #[arg(long)]
    pub stats_json: Option<PathBuf>,
    /// The dancer.
    #[command(flatten)]
    pub dancer: SourceArgs,
    /// Where the browser view is served, if anywhere.
    #[command(flatten)]
    pub view: ViewFlag,
    /// Where the beat grid comes from (tap, link), and the clocks danced leads.
    #[command(flatten)]
    pub clock: ClockArgs,
}

/// Runs `danced demo`.
pub fn demo(args: DemoArgs) -> Result<()> {
    let DemoArgs {
        duration,
        rate,
        stats_json,
        dancer,
        view,
        clock,
    } = args;
    let mut config = Config::default();
    dancer.apply(&mut config);
    view.apply(&mut config);
    clock.apply(&mut config);
    config.audio.duration = duration;
    config.stats_json = stats_json;
    if let Some(r) = rate {
        config.output.rate_hz = r;
    }
    config.validate("command line")?;
    let report = run_live(&config, AudioSource::Demo, RunMode::Interactive)?;
    println!("{}", summary(&report));
    Ok(())
}
