//! The page's head-up display data: what the run is (once per client) and how it is doing (ten
//! times a second), as JSON text messages beside the binary OSC.

use std::sync::atomic::Ordering;

use serde::Serialize;

use crate::live::stats::{KEY_POSE_PENDING, KEY_POSE_REACHED, Stats};

/// What a page is told when it connects.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct ViewHello {
    /// `"live"` (frames over the socket) or `"playback"` (a dance file, fetched whole).
    pub mode: &'static str,
    /// The dancer's name.
    pub dancer: String,
    /// The key poses the page offers buttons for, in the control path's order.
    pub poses: Vec<String>,
    /// Frames per second the run sends (or the dance file holds).
    pub rate_hz: f64,
    /// Model frames per second (key-pose countdowns are in these).
    pub model_rate_hz: f64,
    /// The output lead, ms.
    pub lead_ms: f64,
    /// Whether `/audio` holds the song (playback).
    pub audio: bool,
    /// Frames in `/dance.vmc` (playback).
    pub frames: usize,
    /// The controls the dancer honours beyond those every dancer takes; the page hides the
    /// others (the daemon refuses them).
    pub controls: model::source::SourceControls,
    /// The stage the dancer is kept on (`None`: a dance file, shown wherever it goes).
    pub stage: Option<model::stage::StageSettings>,
    /// The dancer's sets of moves the page offers a selector for (empty: it has one).
    pub moves: Vec<String>,
    /// The clocks the run can follow (`audio` and `tap` always; `midi` with a MIDI port,
    /// `link` with Link joined); empty for playback.
    pub clocks: Vec<&'static str>,
}

/// The run as the HUD shows it.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct ViewStatus {
    /// Tempo, BPM (0 before the tracker locks).
    pub tempo_bpm: f32,
    /// Beat phase of the newest analysed frame, 0..1.
    pub beat_phase: f32,
    /// Temperature now.
    pub temperature: f32,
    /// Beat accent now (None: the dancer's own).
    pub accent: Option<f32>,
    /// The style danced (None: a dancer without a style input).
    pub style: Option<&'static str>,
    /// Whether the music chose the style (`auto`) rather than the performer.
    pub style_auto: bool,
    /// Where key poses go: `"overlay"` or `"network"` (None: a dancer without a route).
    pub key_route: Option<&'static str>,
    /// `"none"`, `"pending"` or `"reached"`.
    pub key_pose: &'static str,
    /// The pending (or last reached) key pose's name.
    pub key_pose_name: Option<String>,
    /// Model frames until the pending key pose.
    pub key_pose_frames_to_go: u32,
    /// The set of moves danced (None: a dancer with one).
    pub moves: Option<String>,
    /// The clock followed: `audio`, `midi`, `link` or `tap`.
    pub clock: &'static str,
    /// Tempo of the grid followed, BPM (0 while none is).
    pub clock_tempo_bpm: f32,
    /// How far the music is heard from an external clock, ms (None: not measured).
    pub clock_offset_ms: Option<f32>,
    /// The nudges added up, ms.
    pub nudge_ms: f32,
    /// Link peers.
    pub peers: u32,
    /// Whether the dancer is paused.
    pub paused: bool,
    /// Added latency p99 of the sender, ms.
    pub latency_p99_ms: f64,
    /// Frames sent and, of them, late.
    pub frames_sent: u64,
    /// Frames whose pose was held because the motion was late.
    pub late_frames: u64,
    /// Controls applied and refused by the control path (all inputs).
    pub controls_applied: u64,
    /// See above.
    pub controls_rejected: u64,
}

impl ViewStatus {
    /// The status now; `poses` names key-pose indices.
    pub fn read(stats: &Stats, poses: &[String]) -> Self {
        let key = stats.key_pose_state.load(Ordering::Relaxed);
        let accent = stats.beat_accent.get();
        let key_index = stats.key_pose_index.load(Ordering::Relaxed) as usize;
        Self {
            tempo_bpm: stats.tempo_bpm.get(),
            beat_phase: stats.beat_phase.get(),
            temperature: stats.temperature.get(),
            accent: accent.is_finite().then_some(accent),
            style: stats.style_danced().map(|s| s.name()),
            style_auto: stats.style_auto.load(Ordering::Relaxed) == 1,
            key_route: stats.key_route().map(|r| r.name()),
            key_pose: match key {
                KEY_POSE_PENDING => "pending",
                KEY_POSE_REACHED => "reached",
                _ => "none",
            },
            key_pose_name: (key == KEY_POSE_PENDING || key == KEY_POSE_REACHED)
                .then(|| poses.get(key_index).cloned())
                .flatten(),
            key_pose_frames_to_go: stats.key_pose_frames_to_go.load(Ordering::Relaxed),
            moves: stats.moves_danced().map(str::to_owned),
            clock: stats.clock.source().name(),
            clock_tempo_bpm: stats.clock.tempo_bpm.get(),
            clock_offset_ms: stats.clock.offset(),
            nudge_ms: stats.clock.nudge_ms.get(),
            peers: stats.clock.peers.load(Ordering::Relaxed),
            paused: stats.paused.load(Ordering::Relaxed) == 1,
            latency_p99_ms: stats.latency.quantile_ms(0.99),
            frames_sent: stats.frames_sent.load(Ordering::Relaxed),
            late_frames: stats.late_frames.load(Ordering::Relaxed),
            controls_applied: stats.controls_accepted.load(Ordering::Relaxed),
            controls_rejected: stats.controls_rejected.load(Ordering::Relaxed),
        }
    }
}

/// A JSON text message `{"type": kind, ...value}`.
pub fn message<T: Serialize>(kind: &str, value: &T) -> String {
    let mut v = serde_json::to_value(value).unwrap_or_default();
    if let Some(o) = v.as_object_mut() {
        o.insert("type".into(), kind.into());
    }
    v.to_string()
}
