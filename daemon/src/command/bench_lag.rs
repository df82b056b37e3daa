//! `danced bench lag`: how far the dancer a receiver sees trails the music a listener hears,
//! measured from outside (`crate::bench::lag`), per song, dancer and output lead; and how long
//! the dancer's beat takes to come back after a sudden tempo change.

use std::path::PathBuf;

use anyhow::{Context, Result};
use offline::analysis::{AnalyzeOptions, analyze_samples};

use crate::bench::lag::{LagRun, measure_live_lag, offline_reference};
use crate::command::source::SourceArgs;
use crate::dancer::{SourceKind, SourceSettings, open_source};
use crate::live::config::Config;
use crate::live::replay::ReplayAudio;
use crate::offline_dance::dance_stream;

/// Options of `danced bench lag`.
#[derive(clap::Args, Debug)]
pub struct BenchLagArgs {
    /// Data folder: songs of `synth-beats` across 70–170 BPM (the built-in demo song without).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Audio files to measure instead of the data set's songs.
    #[arg(long)]
    pub input: Vec<PathBuf>,
    /// Songs taken from the data set (constant tempo, spread over the tempo range; 0: only the
    /// tempo jumps).
    #[arg(long, default_value_t = 5)]
    pub songs: usize,
    /// Seconds of each song replayed.
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Seconds at the start left out (the tracker locking on).
    #[arg(long, default_value_t = 6.0)]
    pub settle: f64,
    /// Output leads to measure, ms (comma-separated).
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        default_value = "0,50"
    )]
    pub lead_ms: Vec<f64>,
    /// Dancers to measure (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "neural,retrieval")]
    pub sources: Vec<String>,
    /// Tempo jumps measured: pairs of the data set's songs joined on a beat.
    #[arg(long, default_value_t = 4)]
    pub jumps: usize,
    /// The dancer measured.
    #[command(flatten)]
    pub dancer: SourceArgs,
}

/// One song to measure.
struct Song {
    name: String,
    bpm: Option<f64>,
    audio: ReplayAudio,
}

fn songs(args: &BenchLagArgs) -> Result<Vec<Song>> {
    if !args.input.is_empty() {
        return args
            .input
            .iter()
            .map(|p| {
                Ok(Song {
                    name: p.file_stem().unwrap_or_default().to_string_lossy().into(),
                    bpm: None,
                    audio: ReplayAudio::from_file(p)?,
                })
            })
            .collect();
    }
    let set = crate::bench::sets::synth_set(&args.data);
    if set.items.is_empty() {
        eprintln!(
            "no songs under {} — measuring the built-in demo song",
            args.data.join("synth-beats").display()
        );
        return Ok(vec![Song {
            name: "demo".into(),
            bpm: Some(crate::demo_track::DEMO_BPM),
            audio: ReplayAudio::demo(args.seconds + 1.0),
        }]);
    }
    let steady = crate::bench::sets::steady_songs(&set);
    let n = args.songs.max(1).min(steady.len());
    let picked: Vec<_> = (0..n)
        .map(|k| steady[k * (steady.len() - 1) / (n - 1).max(1)])
        .collect();
    picked
        .into_iter()
        .map(|(bpm, i)| {
            Ok(Song {
                name: i.name.clone(),
                bpm: Some(bpm),
                audio: ReplayAudio::from_file(&i.audio)?,
            })
        })
        .collect()
}

fn song_info(item: &crate::bench::sets::BenchItem) -> Option<crate::bench::sets::SynthSongInfo> {
    crate::bench::sets::SynthSongInfo::read(&item.audio)
}

/// A song that may be joined to another: tempo, name, audio, beats, quiet section.
type JoinCandidate = (f64, String, ReplayAudio, Vec<f64>, Option<(f64, f64)>);

/// Seconds into the first song the second one cuts in, and into the second where it resumes.
const CUT_NEAR_S: f64 = 16.0;
const RESUME_NEAR_S: f64 = 8.0;
/// A dancer's beat within this of the heard beat counts as back on it, seconds.
const ON_BEAT_S: f64 = 0.02;

/// The tempo-jump table: songs of contrasting tempo joined on a beat, each dancer offline
/// (the live path hears exactly the same, see the lag table).
fn tempo_jumps(args: &BenchLagArgs, config: &Config) -> Result<()> {
    use crate::bench::beat_recovery::{dancer_beat_errors, largest_step_m, recovery_s};
    let set = crate::bench::sets::synth_set(&args.data);
    let mut cases: Vec<(String, crate::bench::beat_recovery::Splice)> = Vec::new();
    // Songs rendered with a tempo jump of their own.
    for item in &set.items {
        let Some(info) = song_info(item) else {
            continue;
        };
        if let Some(cut_s) = info.tempo_change_s
            && let Ok(a) = ReplayAudio::from_file(&item.audio)
        {
            let end_bpm = 60.0
                / item
                    .beats
                    .windows(2)
                    .last()
                    .map_or(f64::NAN, |w| w[1] - w[0]);
            cases.push((
                format!("{:.0} → {end_bpm:.0} BPM (in {})", info.bpm, item.name),
                crate::bench::beat_recovery::Splice {
                    samples: offline::decode::mono_mix(&a.samples, a.channels),
                    sample_rate: a.sample_rate,
                    beats: item.beats.clone(),
                    cut_s,
                },
            ));
        }
    }
    // Pairs of songs joined on a beat: the same sample rate, tempos a fifth or more apart, no
    // quiet section where it is measured (a break is another test).
    let decoded: Vec<JoinCandidate> = set
        .items
        .iter()
        .filter_map(|i| {
            let info = song_info(i)?;
            if !info.constant || !(70.0..=170.0).contains(&info.bpm) {
                return None;
            }
            let a = ReplayAudio::from_file(&i.audio).ok()?;
            Some((info.bpm, i.name.clone(), a, i.beats.clone(), info.quiet))
        })
        .collect();
    let clear_before = |q: Option<(f64, f64)>| q.is_none_or(|(s, _)| s >= CUT_NEAR_S + 1.0);
    let clear_after = |q: Option<(f64, f64)>| q.is_none_or(|(_, e)| e <= RESUME_NEAR_S - 1.0);
    let mut joined = 0;
    for (x, a) in decoded.iter().enumerate() {
        for b in decoded.iter().skip(x + 1) {
            // Alternate slower → faster and faster → slower.
            let (a, b) = if joined % 2 == 0 { (a, b) } else { (b, a) };
            let ratio = a.0.max(b.0) / a.0.min(b.0);
            if joined >= args.jumps
                || a.2.sample_rate != b.2.sample_rate
                || ratio < 1.2
                || !clear_before(a.4)
                || !clear_after(b.4)
            {
                continue;
            }
            let Some(s) = crate::bench::beat_recovery::splice(
                (&a.2.samples, a.2.channels, &a.3),
                (&b.2.samples, b.2.channels, &b.3),
                a.2.sample_rate,
                CUT_NEAR_S,
                RESUME_NEAR_S,
            ) else {
                continue;
            };
            cases.push((
                format!("{:.0} → {:.0} BPM ({} → {})", a.0, b.0, a.1, b.1),
                s,
            ));
            joined += 1;
            break;
        }
    }
    if cases.is_empty() {
        eprintln!("no songs for the tempo-jump table");
        return Ok(());
    }
    println!();
    println!(
        "| tempo jump | dancer | beat back within {:.0} ms after | beats on time from 8 s after | tempo heard at the end | largest joint step, 4 s after / elsewhere |",
        ON_BEAT_S * 1e3
    );
    println!("| --- | --- | --- | --- | --- | --- |");
    for (title, s) in &cases {
        let rate = s.sample_rate;
        let fa = analyze_samples(
            "tempo jump",
            &s.samples,
            rate,
            1,
            AnalyzeOptions::native(Some(model::retrieval::RETRIEVAL_FPS)),
        )?;
        for name in &args.sources {
            let kind = SourceKind::parse(name).with_context(|| format!("unknown dancer {name}"))?;
            let mut source = open_source(kind, &source_settings(kind, config), config.dancer.seed)?;
            let fps = source.frame_rate();
            let horizon = model::horizon::offline_horizon(&*source);
            let errors = dancer_beat_errors(&fa.features, horizon, fps, &s.beats);
            let back = recovery_s(&errors, s.cut_s, ON_BEAT_S);
            // How the rest of the song goes: beats on time from 8 s after the jump.
            let late: Vec<Option<f64>> = errors
                .iter()
                .filter(|(t, _)| *t >= s.cut_s + 8.0)
                .map(|(_, e)| *e)
                .collect();
            let on_time = late
                .iter()
                .filter(|e| e.is_some_and(|e| e.abs() <= ON_BEAT_S))
                .count() as f64
                / late.len().max(1) as f64;
            let end_tempo = fa.features.last().map_or(0.0, |f| f.grid.tempo_bpm());
            let music = dsp::predicted_stream(&fa.features, horizon);
            let poses = dance_stream(&mut *source, &music, horizon, music.len(), |_| {
                model::source::Controls {
                    temperature: config.dancer.temperature,
                    ..Default::default()
                }
            });
            let end = poses.len() as f64 / fps;
            let near = largest_step_m(&poses, fps, s.cut_s, s.cut_s + 4.0);
            let before = largest_step_m(&poses, fps, 4.0, s.cut_s);
            let after = largest_step_m(&poses, fps, s.cut_s + 4.0, end);
            println!(
                "| {title} | {} | {} | {:.0} % | {end_tempo:.0} BPM | {:.1} cm / {:.1} cm |",
                kind.name(),
                back.map_or("not within the song".into(), |t| format!("{t:.1} s")),
                on_time * 100.0,
                near * 100.0,
                before.max(after) * 100.0
            );
        }
    }
    Ok(())
}

/// The dancer's settings from the command line's configuration.
fn source_settings(kind: SourceKind, config: &Config) -> SourceSettings<'_> {
    SourceSettings {
        network_only: false,
        model: if kind == SourceKind::Neural {
            config.dancer.model.as_deref()
        } else {
            None
        },
        libraries: if kind == SourceKind::Retrieval {
            &config.dancer.libraries
        } else {
            &[]
        },
        beat_accent: Some(config.dancer.beat_accent),
        foot_plant: Some(config.dancer.foot_plant),
        key_route: Some(config.dancer.key_pose_route()),
        stage: config.stage.settings(),
    }
}

/// Runs `danced bench lag`.
pub fn bench_lag(args: BenchLagArgs) -> Result<()> {
    let mut config = Config::default();
    args.dancer.apply(&mut config);
    let songs = if args.songs == 0 && args.input.is_empty() {
        Vec::new()
    } else {
        songs(&args)?
    };
    println!(
        "| song | BPM | dancer | lead ms | lag ms | correlation | frames | late frames | /danced/beat after the dancer's beat, median / max ms |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for song in &songs {
        let a = analyze_samples(
            &song.name,
            &song.audio.samples,
            song.audio.sample_rate,
            song.audio.channels,
            AnalyzeOptions::native(Some(model::retrieval::RETRIEVAL_FPS)),
        )
        .with_context(|| format!("analysing {}", song.name))?;
        for name in &args.sources {
            let kind = SourceKind::parse(name).with_context(|| format!("unknown dancer {name}"))?;
            let settings = source_settings(kind, &config);
            for &lead_ms in &args.lead_ms {
                let seed = config.dancer.seed;
                // The reference: the same song danced offline at the horizon the run uses.
                let mut offline = open_source(kind, &settings, seed)?;
                let rate = offline.frame_rate();
                let frames = ((args.seconds + 1.0) * rate) as usize;
                let reference = offline_reference(&mut *offline, &a.features, lead_ms, frames);
                let run = LagRun {
                    audio: &song.audio,
                    seconds: args.seconds,
                    settle_s: args.settle,
                    lead_ms,
                    rate_hz: config.output.rate_hz,
                };
                let live =
                    measure_live_lag(&run, open_source(kind, &settings, seed)?, &reference, rate)
                        .with_context(|| format!("{} with the {name} dancer", song.name))?;
                let e = live.estimate;
                let mut d = live.beat_message_delays_s.clone();
                d.sort_by(f64::total_cmp);
                let beat_delay = match (d.get(d.len() / 2), d.last()) {
                    (Some(m), Some(x)) => format!("{:.1} / {:.1}", m * 1e3, x * 1e3),
                    _ => "no beats".into(),
                };
                println!(
                    "| {} | {} | {} | {lead_ms:.0} | {:+.1} | {:.3} | {} | {}{} | {beat_delay} |",
                    song.name,
                    song.bpm.map_or("?".into(), |b| format!("{b:.0}")),
                    kind.name(),
                    e.lag_s * 1e3,
                    e.correlation,
                    e.frames,
                    live.late_frames,
                    if live.replay_rebases > 0 {
                        format!(" (replay fell behind {} times)", live.replay_rebases)
                    } else {
                        String::new()
                    }
                );
            }
        }
    }
    tempo_jumps(&args, &config)
}
