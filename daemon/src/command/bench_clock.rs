//! `danced bench clock`: the show's clock measured. An incoming MIDI clock followed from
//! timestamps with a millisecond of jitter; the MIDI clock danced sends (tick spacing on this
//! machine); and in builds with Link, a Link session followed and led against peers that are
//! the SDK alone, inside a network namespace the bench makes for itself.

use std::path::PathBuf;

use anyhow::{Context, Result};
use serde::Serialize;

use crate::bench::clock::{MidiInRow, MidiOutRow, midi_clock_in, midi_clock_out};

/// Options of `danced bench clock`.
#[derive(clap::Args, Debug, Clone)]
pub struct BenchClockArgs {
    /// Only these parts (midi-in, midi-out, link-follow, link-lead); all by default (the Link
    /// parts in builds with Link).
    #[arg(long)]
    pub part: Vec<String>,
    /// Shorter runs (a check, not a measurement to quote).
    #[arg(long)]
    pub quick: bool,
    /// The shared data folder (rendered songs with exact beats for the Link lead; the built-in
    /// demo song without).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// The `link-peer` program (default: beside this executable).
    #[arg(long)]
    pub peer: Option<PathBuf>,
    /// Also write the results as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Everything measured.
#[derive(Debug, Default, Serialize)]
pub struct ClockBench {
    /// MIDI clock in.
    pub midi_in: Vec<MidiInRow>,
    /// MIDI clock out.
    pub midi_out: Vec<MidiOutRow>,
    /// Link followed.
    #[cfg(feature = "link")]
    pub link_follow: Vec<crate::bench::link::LinkFollow>,
    /// Link led.
    #[cfg(feature = "link")]
    pub link_lead: Vec<crate::bench::link::LinkLead>,
}

/// Runs `danced bench clock`.
pub fn bench_clock(args: BenchClockArgs) -> Result<()> {
    let wants = |p: &str| args.part.is_empty() || args.part.iter().any(|x| x == p);
    let link_parts = wants("link-follow") || wants("link-lead");
    if link_parts && !crate::live::link::AVAILABLE && !args.part.is_empty() {
        anyhow::bail!("this build has no Ableton Link (build with --features link)");
    }
    #[cfg(feature = "link")]
    if link_parts {
        // First, before any thread: Link must not reach the machine's network.
        crate::bench::private_network::enter()?;
        anyhow::ensure!(
            crate::bench::private_network::only_loopback(),
            "the private network namespace shows other interfaces"
        );
        eprintln!("in a private network namespace (loopback only) for Link");
    }
    let mut out = ClockBench::default();
    let seconds = if args.quick { 10.0 } else { 60.0 };
    if wants("midi-in") {
        for (i, bpm) in [90.0, 128.0, 174.0].into_iter().enumerate() {
            out.midi_in
                .push(midi_clock_in(bpm, 1_000.0, seconds, 1 + i as u64));
        }
        println!(
            "MIDI clock in: timestamps ±1 ms (uniform), from two beats after Continue at bar 3"
        );
        println!(
            "| BPM | tempo error p50 / max (BPM) | next-beat error p50 / p95 (ms) | bar right |"
        );
        println!("| --- | --- | --- | --- |");
        for r in &out.midi_in {
            println!(
                "| {:.0} | {:.3} / {:.3} | {:.2} / {:.2} | {:.0} % |",
                r.bpm,
                r.tempo_error_p50,
                r.tempo_error_max,
                r.phase_error_ms_p50,
                r.phase_error_ms_p95,
                100.0 * r.bar_right
            );
        }
        println!();
    }
    if wants("midi-out") {
        for bpm in [128.0, 174.0] {
            out.midi_out
                .push(midi_clock_out(bpm, seconds / 2.0, true).context("MIDI clock out")?);
        }
        println!("MIDI clock out: when each message was handed to the port, this machine");
        println!(
            "| BPM | ticks | spacing jitter p50 / p99 / max (ms) | lateness p99 (ms) | receiver's tempo error p50 / max (BPM) | restarts | Start on a bar |"
        );
        println!("| --- | --- | --- | --- | --- | --- | --- |");
        for r in &out.midi_out {
            println!(
                "| {:.0} | {} | {:.3} / {:.3} / {:.3} | {:.3} | {:.3} / {:.3} | {} | {} |",
                r.bpm,
                r.ticks,
                r.spacing_jitter_ms_p50,
                r.spacing_jitter_ms_p99,
                r.spacing_jitter_ms_max,
                r.lateness_ms_p99,
                r.receiver_tempo_error_p50,
                r.receiver_tempo_error_max,
                r.restarts,
                if r.started_on_a_bar { "yes" } else { "no" }
            );
        }
        println!();
    }
    #[cfg(feature = "link")]
    if link_parts {
        link(&args, &mut out)?;
    }
    if let Some(path) = &args.json {
        let json = serde_json::to_string_pretty(&out).context("encoding the results")?;
        offline::files::write_atomic(path, json.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

#[cfg(feature = "link")]
fn link(args: &BenchClockArgs, out: &mut ClockBench) -> Result<()> {
    use crate::bench::link::{follow, lead};
    use crate::live::replay::ReplayAudio;
    let peer = match &args.peer {
        Some(p) => p.clone(),
        None => std::env::current_exe()
            .context("finding this executable")?
            .with_file_name("link-peer"),
    };
    anyhow::ensure!(
        peer.exists(),
        "no Link peer at {} (cargo build --release --features link builds it beside danced)",
        peer.display()
    );
    let wants = |p: &str| args.part.is_empty() || args.part.iter().any(|x| x == p);
    let seconds = if args.quick { 16.0 } else { 40.0 };
    if wants("link-follow") {
        out.link_follow.push(follow(&peer, seconds, 128.0, 140.0)?);
        println!(
            "Link followed: a peer leads at 128 BPM, then 140 from halfway; /danced/beat received over OSC against the session's beats (read by another peer)"
        );
        println!(
            "| BPM | beats | offset p50 / p95 (ms) | after the change: locked from (beats), beats off | tempo at the end | peers | real-time allocations |"
        );
        println!("| --- | --- | --- | --- | --- | --- | --- |");
        for r in &out.link_follow {
            println!(
                "| {:.0} → {:.0} | {} | {:.2} / {:.2} | {}, {} | {:.2} | {} | {} |",
                r.bpm.0,
                r.bpm.1,
                r.beats,
                r.offset_ms_p50,
                r.offset_ms_p95,
                r.lock_after_change_beats
                    .map_or("never".into(), |b| format!("{b:.2}")),
                r.beats_off_after_change,
                r.tempo_at_end,
                r.peers,
                r.rt_allocations
            );
        }
        println!();
    }
    if wants("link-lead") {
        let set = crate::bench::sets::synth_set(&args.data);
        let steady = crate::bench::sets::steady_songs(&set);
        let mut songs: Vec<(String, ReplayAudio, Vec<f64>)> = Vec::new();
        let picks: Vec<usize> = match steady.len() {
            0 => Vec::new(),
            n if args.quick => vec![n / 2],
            n => vec![0, n / 2, n - 1],
        };
        for i in picks {
            let item = steady[i].1;
            let audio = ReplayAudio::from_file(&item.audio)?;
            songs.push((item.name.clone(), audio, item.beats.clone()));
        }
        if songs.is_empty() {
            eprintln!(
                "no rendered songs in {}: leading from the built-in demo song",
                args.data.display()
            );
            let demo = crate::demo_track::demo_track(seconds + 1.0);
            songs.push((
                "demo song".into(),
                ReplayAudio::demo(seconds + 1.0),
                demo.beats,
            ));
        }
        for (name, audio, beats) in &songs {
            out.link_lead
                .push(lead(&peer, name, audio, beats, seconds, 8.0)?);
        }
        println!(
            "Link led from the music heard: the session's beats (read by a peer) against the song's annotated beats as heard, from 8 s in"
        );
        println!(
            "| song | BPM | beats | offset p50 / p95 (ms) | bias (ms) | tempo error (BPM) | real-time allocations |"
        );
        println!("| --- | --- | --- | --- | --- | --- | --- |");
        for r in &out.link_lead {
            println!(
                "| {} | {:.1} | {} | {:.1} / {:.1} | {:+.1} | {:.2} | {} |",
                r.song,
                r.bpm,
                r.beats,
                r.offset_ms_p50,
                r.offset_ms_p95,
                r.bias_ms,
                r.tempo_error_bpm,
                r.rt_allocations
            );
        }
        println!();
    }
    Ok(())
}
