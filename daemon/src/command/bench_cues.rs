//! `danced bench cues`: key poses cued "on the next bar" during real-time replays of rendered
//! songs or real recordings, measured from outside (`crate::bench::cues`): where each lands
//! against the true (or reference) downbeats.

use std::path::PathBuf;

use anyhow::{Result, bail};

use crate::bench::cues::{CueLanding, HIT_TOLERANCE_S, measure_bar_cues};
use crate::bench::lag::LagRun;
use crate::live::replay::ReplayAudio;

/// Options of `danced bench cues`.
#[derive(clap::Args, Debug)]
pub struct BenchCuesArgs {
    /// Data folder (its `synth-beats` songs are used unless `--songs` is given).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// A folder of songs rendered by `synth_beats.py` to use instead.
    #[arg(long)]
    pub songs: Option<PathBuf>,
    /// Which songs: rendered ones (exact downbeats) or the held-out real recordings (against
    /// their offline-tracker downbeats).
    #[arg(long, value_enum, default_value_t = CueSet::Rendered)]
    pub set: CueSet,
    /// Songs replayed (constant tempo, spread over the tempo range).
    #[arg(long, default_value_t = 5)]
    pub count: usize,
    /// Cues per song.
    #[arg(long, default_value_t = 4)]
    pub cues: usize,
    /// Heard time of the first cue, seconds (the tracker has locked on by then).
    #[arg(long, default_value_t = 8.0)]
    pub first_cue: f64,
    /// Seconds between cues (not a whole number of bars, so cues fall anywhere in the bar).
    #[arg(long, default_value_t = 4.7)]
    pub spacing: f64,
    /// Output lead, ms.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub lead_ms: f64,
}

/// The songs `danced bench cues` replays.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CueSet {
    /// Constant-tempo rendered songs (`synth-beats`, or `--songs`).
    Rendered,
    /// The real recordings no network trains on (`real-music`).
    RealMusic,
}

/// Runs `danced bench cues`.
pub fn bench_cues(args: BenchCuesArgs) -> Result<()> {
    let set = match (&args.songs, args.set) {
        (Some(dir), _) => crate::bench::sets::rendered_set("songs", dir),
        (None, CueSet::Rendered) => crate::bench::sets::synth_set(&args.data),
        (None, CueSet::RealMusic) => {
            let [held_out, _] = crate::bench::sets::real_music_sets(&args.data);
            held_out
        }
    };
    let steady = match args.set {
        CueSet::Rendered => crate::bench::sets::steady_songs(&set),
        CueSet::RealMusic => crate::bench::sets::by_reference_tempo(&set),
    };
    if steady.is_empty() {
        bail!("no constant-tempo annotated songs found (pass --data or --songs)");
    }
    let n = args.count.max(1).min(steady.len());
    let cue_times: Vec<f64> = (0..args.cues)
        .map(|k| args.first_cue + k as f64 * args.spacing)
        .collect();
    let seconds = cue_times.last().copied().unwrap_or(args.first_cue) + 4.0;
    println!(
        "| song | BPM | meter | cues | on a downbeat (±{:.0} ms) | on the next bar | landing − downbeat, ms |",
        HIT_TOLERANCE_S * 1000.0
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    let mut all: Vec<CueLanding> = Vec::new();
    for k in 0..n {
        let (bpm, item) = steady[k * (steady.len() - 1) / (n - 1).max(1)];
        let Some(downbeats) = item.downbeats.as_ref() else {
            continue;
        };
        let audio = ReplayAudio::from_file(&item.audio)?;
        let run = LagRun {
            audio: &audio,
            seconds: seconds.min(audio.duration_s()),
            settle_s: 0.0,
            lead_ms: args.lead_ms,
            rate_hz: 60.0,
        };
        let landings = measure_bar_cues(&run, &cue_times, downbeats, 0.1)?;
        let errors: Vec<String> = landings
            .iter()
            .map(|l| {
                l.error_s
                    .map_or("never".into(), |e| format!("{:+.0}", e * 1000.0))
            })
            .collect();
        println!(
            "| {} | {bpm:.0} | {} | {} | {} | {} | {} |",
            item.name,
            item.meter.map_or("–".into(), |m| format!("{m}/4")),
            landings.len(),
            landings.iter().filter(|l| l.hit()).count(),
            landings.iter().filter(|l| l.hit() && l.next_bar).count(),
            errors.join(", ")
        );
        all.extend(landings);
    }
    let hits = all.iter().filter(|l| l.hit()).count();
    let next = all.iter().filter(|l| l.hit() && l.next_bar).count();
    let mut abs: Vec<f64> = all.iter().filter_map(|l| l.error_s.map(f64::abs)).collect();
    abs.sort_by(f64::total_cmp);
    println!(
        "\n{hits} of {} cues landed within {:.0} ms of a true downbeat ({next} on the first bar line at least 100 ms after the cue); median |error| {:.0} ms.",
        all.len(),
        HIT_TOLERANCE_S * 1000.0,
        abs.get(abs.len() / 2).copied().unwrap_or(f64::NAN) * 1000.0
    );
    Ok(())
}
