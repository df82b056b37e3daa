//! Lock-free counters and histograms of the live pipeline, and the report they turn into.
//!
//! Definitions (all wall times on one monotonic clock, [`std::time::Instant`]):
//!
//! - **shown time** of a sent frame: the audio time heard at the send (`heard(now)`, from the
//!   audio clock) plus the output lead. Poses are made ahead of it from predicted music
//!   (`model::horizon`), so nothing is waited for.
//! - **added latency** of a sent frame: `send_wall − (ingest_wall(t_shown) − lead)`, where
//!   `t_shown` is the audio time the frame actually depicts (the shown time, or the newest
//!   pose's time when the motion was late and the pose was held) and `ingest_wall(t)` is the
//!   wall time the block holding the sample at `t` entered the audio ring: how much later than
//!   intended the frame left — the tick, the send, and any lateness of analysis or motion.
//! - **processing latency** of a model frame: `pose_ready_wall − ingest_wall(S)`, where `S` is
//!   the block that completed the newest feature frame the pose needed: how long analysis and
//!   motion actually took (what the delivery margin, `output.margin_ms`, must cover).
//! - **tick to sent** of a frame: `sent_wall − scheduled_wall`, where `sent_wall` is when the
//!   frame's last `send_to` returned and `scheduled_wall` its tick on the sender's fixed grid:
//!   the wake-up, the pose pick, forward kinematics, encoding and the system calls.
//! - **jitter** of a sent frame: `|(sent_wall − previous sent_wall) − period|`, how unevenly
//!   frames leave (what a receiver sees as uneven spacing), stamped when `send_to` returns.

use std::sync::Mutex;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

use serde::Serialize;

use crate::alloc_counter::RtThread;
use model::neural::safety::SafetyCounts;
use model::source::KeyPoseRoute;
use model::stage::StageCounts;

/// Allocations (and frees) counted per real-time thread since the process started.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq, Eq)]
pub struct ThreadAllocations {
    /// The capture callback (or the replay thread's writes).
    pub capture: u64,
    /// The analysis thread's loop.
    pub analysis: u64,
    /// The motion thread's loop.
    pub motion: u64,
    /// The sender thread's loop.
    pub sender: u64,
    /// The MIDI clock sender's loop.
    pub clock_out: u64,
}

impl ThreadAllocations {
    /// The counts so far.
    pub fn now() -> Self {
        use crate::alloc_counter::allocations;
        Self {
            capture: allocations(RtThread::Capture),
            analysis: allocations(RtThread::Analysis),
            motion: allocations(RtThread::Motion),
            sender: allocations(RtThread::Sender),
            clock_out: allocations(RtThread::ClockOut),
        }
    }

    /// All threads together.
    pub fn total(&self) -> u64 {
        self.capture + self.analysis + self.motion + self.sender + self.clock_out
    }
}

/// A fixed-range histogram of durations with atomic buckets: recording never allocates or locks.
pub struct Histogram {
    min_ns: i64,
    bucket_ns: i64,
    buckets: Box<[AtomicU32]>,
    count: AtomicU64,
    max_ns: AtomicU64,
    max_set: AtomicU32,
}

impl Histogram {
    /// Buckets of `bucket_us` from `min_ms` to `max_ms` (values outside go to the end buckets;
    /// the maximum is tracked exactly).
    pub fn new(min_ms: f64, max_ms: f64, bucket_us: f64) -> Self {
        let n = (((max_ms - min_ms) * 1000.0 / bucket_us).ceil() as usize).max(1);
        Self {
            min_ns: (min_ms * 1e6) as i64,
            bucket_ns: (bucket_us * 1e3).max(1.0) as i64,
            buckets: (0..n).map(|_| AtomicU32::new(0)).collect(),
            count: AtomicU64::new(0),
            max_ns: AtomicU64::new(0),
            max_set: AtomicU32::new(0),
        }
    }

    /// Records one value in seconds.
    pub fn record_s(&self, s: f64) {
        let ns = (s * 1e9) as i64;
        let i = ((ns - self.min_ns) / self.bucket_ns).clamp(0, self.buckets.len() as i64 - 1);
        self.buckets[i as usize].fetch_add(1, Ordering::Relaxed);
        self.count.fetch_add(1, Ordering::Relaxed);
        // Max stored with the sign bit flipped so unsigned comparison orders signed values.
        let key = (ns as u64) ^ (1 << 63);
        self.max_ns.fetch_max(key, Ordering::Relaxed);
        self.max_set.store(1, Ordering::Relaxed);
    }

    /// Values recorded.
    pub fn count(&self) -> u64 {
        self.count.load(Ordering::Relaxed)
    }

    /// The `q` quantile (0..=1) in milliseconds (upper edge of its bucket); 0 when empty.
    pub fn quantile_ms(&self, q: f64) -> f64 {
        let total = self.count();
        if total == 0 {
            return 0.0;
        }
        let target = ((q * total as f64).ceil() as u64).clamp(1, total);
        let mut seen = 0u64;
        for (i, b) in self.buckets.iter().enumerate() {
            seen += u64::from(b.load(Ordering::Relaxed));
            if seen >= target {
                let upper = self.min_ns + (i as i64 + 1) * self.bucket_ns;
                return (upper as f64 / 1e6).min(self.max_ms());
            }
        }
        self.max_ms()
    }

    /// The largest value recorded, ms (0 when empty).
    pub fn max_ms(&self) -> f64 {
        if self.max_set.load(Ordering::Relaxed) == 0 {
            return 0.0;
        }
        let ns = (self.max_ns.load(Ordering::Relaxed) ^ (1 << 63)) as i64;
        ns as f64 / 1e6
    }
}

/// An `f32` in an atomic, for live values shown on the status line.
#[derive(Debug, Default)]
pub struct AtomicF32(AtomicU32);

impl AtomicF32 {
    /// Stores a value.
    pub fn set(&self, v: f32) {
        self.0.store(v.to_bits(), Ordering::Relaxed);
    }
    /// Loads the value.
    pub fn get(&self) -> f32 {
        f32::from_bits(self.0.load(Ordering::Relaxed))
    }
}

/// Key pose state for the status line: 0 none, 1 pending, 2 reached.
pub const KEY_POSE_NONE: u32 = 0;
/// A key pose is pending (frames to go in `key_pose_frames_to_go`).
pub const KEY_POSE_PENDING: u32 = 1;
/// The last key pose was reached.
pub const KEY_POSE_REACHED: u32 = 2;

/// Everything the pipeline counts, shared by all its threads.
pub struct Stats {
    /// Added latency of sent frames (see the module docs).
    pub latency: Histogram,
    /// Processing latency of model frames.
    pub processing: Histogram,
    /// Send-time jitter of sent frames: |`send_to` returned − scheduled tick|.
    pub jitter: Histogram,
    /// Tick to sent: scheduled tick → the frame's last datagram handed to the OS.
    pub tick_to_sent: Histogram,
    dropped_frames: AtomicU64,
    /// Stream errors reported by the audio backend.
    pub stream_errors: AtomicU64,
    /// Times the capture stream was rebuilt.
    pub reconnects: AtomicU64,
    /// Attempts to reopen a lost capture device that failed (it was still gone).
    pub reconnect_failures: AtomicU64,
    /// Times a capture stream stopped calling back and was rebuilt.
    pub capture_stalls: AtomicU64,
    /// Capture blocks dropped because an old and a new stream's callbacks overlapped.
    pub capture_contended: AtomicU64,
    /// Replaced capture streams whose teardown has not returned (stuck in their driver).
    pub capture_streams_stuck: AtomicU64,
    /// Feature frames lost because the analysis → motion queue was full.
    pub features_dropped: AtomicU64,
    /// Audio-clock anchors lost because the analysis → sender queue was full.
    pub anchors_dropped: AtomicU64,
    /// Poses lost because the motion → sender queue was full.
    pub poses_dropped: AtomicU64,
    /// Control events lost because the queue to the motion thread was full.
    pub controls_dropped: AtomicU64,
    /// Parameter values (temperature, accent, seed, …) replaced by a newer one before the
    /// motion thread applied them.
    pub controls_coalesced: AtomicU64,
    /// Control events refused by the per-address rate limit.
    pub controls_rate_limited: AtomicU64,
    /// Control events refused because the dancer does not honour them (a style for a model
    /// without a style input, …).
    pub controls_unsupported: AtomicU64,
    /// Datagrams the operating system refused to send.
    pub send_errors: AtomicU64,
    /// Non-finite values the encoders replaced before sending.
    pub non_finite_replaced: AtomicU64,
    /// VRChat trackers skipped because their bone was missing from a frame.
    pub vrchat_missing_bones: AtomicU64,
    /// Frames handed to the sink.
    pub frames_sent: AtomicU64,
    /// Frames whose pose was not ready at send time (the newest pose was held).
    pub late_frames: AtomicU64,
    /// Times the sender fell more than a tick behind and skipped ticks to rejoin its grid.
    pub sender_stalls: AtomicU64,
    /// The replay's clock: the wall time (ns since the epoch) at which its audio time 0 is
    /// heard; audio time `a` is heard at `origin + a / speed` (u64::MAX before a replay runs).
    pub replay_origin_ns: AtomicU64,
    /// Times the replay fell behind by more than 200 ms and restarted its clock from then.
    pub replay_rebases: AtomicU64,
    /// Packets the sink reports.
    pub packets_sent: AtomicU64,
    /// Model frames stepped.
    pub model_frames: AtomicU64,
    /// Frames of silence the analysis inserted while no audio arrived.
    pub silence_frames: AtomicU64,
    /// Analysis events dropped because the sender thread was behind.
    pub events_dropped: AtomicU64,
    /// Control events applied.
    pub controls_accepted: AtomicU64,
    /// Control events refused (unknown pose name, invalid value).
    pub controls_rejected: AtomicU64,
    /// Pipeline threads running at real-time priority.
    pub realtime_threads: AtomicU64,
    /// Current tempo, BPM.
    pub tempo_bpm: AtomicF32,
    /// Current beat phase in [0, 1).
    pub beat_phase: AtomicF32,
    /// Current temperature.
    pub temperature: AtomicF32,
    /// Current beat accent (NaN: the source's own).
    pub beat_accent: AtomicF32,
    /// Key pose state (`KEY_POSE_*`).
    pub key_pose_state: AtomicU32,
    /// Frames left to a pending key pose.
    pub key_pose_frames_to_go: AtomicU32,
    /// Bank index of the pending (or last reached) key pose.
    pub key_pose_index: AtomicU32,
    /// 1 while paused.
    pub paused: AtomicU32,
    /// The style danced: 0 = none (a source without a style input), 1 + its index.
    pub style: AtomicU32,
    /// 1 while the style is `auto` (chosen from the music), 0 while one is requested.
    pub style_auto: AtomicU32,
    /// Where key poses go: 0 = the source has no route, 1 + the [`KeyPoseRoute`]'s index.
    pub key_route: AtomicU32,
    /// What the dancer's safety nets did (neural dancer only).
    pub safety: SafetyGauges,
    /// What the stage did.
    pub stage: StageGauges,
    /// The names of the dancer's sets of moves, set once before the run (empty: it has one).
    pub moves_names: std::sync::OnceLock<Vec<String>>,
    /// The set of moves danced: 0 = the source has one, 1 + its index.
    pub moves: AtomicU32,
    /// Switches of the set of moves made.
    pub moves_switches: AtomicU64,
    /// The clock the beat grid follows.
    pub clock: ClockGauges,
    rss: Mutex<Vec<(f64, u64)>>,
}

impl Default for Stats {
    fn default() -> Self {
        Self::new()
    }
}

impl Stats {
    /// Empty counters; histograms cover −20…180 ms latency and 0…50 ms jitter.
    pub fn new() -> Self {
        Self {
            latency: Histogram::new(-20.0, 180.0, 20.0),
            processing: Histogram::new(0.0, 200.0, 20.0),
            jitter: Histogram::new(0.0, 50.0, 5.0),
            tick_to_sent: Histogram::new(0.0, 50.0, 5.0),
            dropped_frames: AtomicU64::new(0),
            stream_errors: AtomicU64::new(0),
            reconnects: AtomicU64::new(0),
            reconnect_failures: AtomicU64::new(0),
            capture_stalls: AtomicU64::new(0),
            capture_contended: AtomicU64::new(0),
            capture_streams_stuck: AtomicU64::new(0),
            features_dropped: AtomicU64::new(0),
            anchors_dropped: AtomicU64::new(0),
            poses_dropped: AtomicU64::new(0),
            controls_dropped: AtomicU64::new(0),
            controls_coalesced: AtomicU64::new(0),
            controls_rate_limited: AtomicU64::new(0),
            controls_unsupported: AtomicU64::new(0),
            send_errors: AtomicU64::new(0),
            non_finite_replaced: AtomicU64::new(0),
            vrchat_missing_bones: AtomicU64::new(0),
            frames_sent: AtomicU64::new(0),
            late_frames: AtomicU64::new(0),
            sender_stalls: AtomicU64::new(0),
            replay_origin_ns: AtomicU64::new(u64::MAX),
            replay_rebases: AtomicU64::new(0),
            packets_sent: AtomicU64::new(0),
            model_frames: AtomicU64::new(0),
            silence_frames: AtomicU64::new(0),
            events_dropped: AtomicU64::new(0),
            controls_accepted: AtomicU64::new(0),
            controls_rejected: AtomicU64::new(0),
            realtime_threads: AtomicU64::new(0),
            tempo_bpm: AtomicF32::default(),
            beat_phase: AtomicF32::default(),
            temperature: AtomicF32::default(),
            beat_accent: AtomicF32::default(),
            key_pose_state: AtomicU32::new(KEY_POSE_NONE),
            key_pose_frames_to_go: AtomicU32::new(0),
            key_pose_index: AtomicU32::new(0),
            safety: SafetyGauges::default(),
            stage: StageGauges::default(),
            moves_names: std::sync::OnceLock::new(),
            moves: AtomicU32::new(0),
            moves_switches: AtomicU64::new(0),
            clock: ClockGauges::default(),
            paused: AtomicU32::new(0),
            style: AtomicU32::new(0),
            style_auto: AtomicU32::new(1),
            key_route: AtomicU32::new(0),
            // One sample a second: two hours before this ever grows.
            rss: Mutex::new(Vec::with_capacity(7200)),
        }
    }

    /// Counts frames dropped at the ring (reader behind).
    pub fn add_dropped_frames(&self, frames: u64) {
        self.dropped_frames.fetch_add(frames, Ordering::Relaxed);
    }

    /// Audio frames dropped at the ring so far.
    pub fn dropped_frames(&self) -> u64 {
        self.dropped_frames.load(Ordering::Relaxed)
    }

    /// Records the process's resident set size at `elapsed_s` (called about once a second).
    pub fn sample_rss(&self, elapsed_s: f64) {
        if let Some(rss) = rss_bytes()
            && let Ok(mut v) = self.rss.lock()
        {
            v.push((elapsed_s, rss));
        }
    }

    /// Records the style danced (None: the source has no style input) and whether the music
    /// chose it (`auto`).
    pub fn set_style_danced(&self, style: Option<model::style::DanceStyle>, auto: bool) {
        let v = style.map_or(0, |s| 1 + s.index() as u32);
        self.style.store(v, Ordering::Relaxed);
        self.style_auto.store(u32::from(auto), Ordering::Relaxed);
    }

    /// Records where key poses go (None: the source has no route to choose).
    pub fn set_key_route(&self, route: Option<KeyPoseRoute>) {
        let v = route.map_or(0, |r| 1 + r.index() as u32);
        self.key_route.store(v, Ordering::Relaxed);
    }

    /// Where key poses go, as last recorded.
    pub fn key_route(&self) -> Option<KeyPoseRoute> {
        let v = self.key_route.load(Ordering::Relaxed);
        v.checked_sub(1)
            .and_then(|i| KeyPoseRoute::from_index(i as usize))
    }

    /// The style danced, as last recorded.
    pub fn style_danced(&self) -> Option<model::style::DanceStyle> {
        let v = self.style.load(Ordering::Relaxed);
        v.checked_sub(1)
            .and_then(|i| model::style::DanceStyle::from_index(i as usize))
    }

    /// The name of the set of moves danced, if the dancer holds several.
    pub fn moves_danced(&self) -> Option<&str> {
        let i = self.moves.load(Ordering::Relaxed).checked_sub(1)?;
        self.moves_names
            .get()
            .and_then(|n| n.get(i as usize))
            .map(String::as_str)
    }

    /// The summary of a run lasting `wall_s` that used `cpu_s` of process CPU time.
    pub fn report(&self, wall_s: f64, cpu_s: f64) -> StatsReport {
        let rss = self.rss.lock().map(|v| v.clone()).unwrap_or_default();
        let end_t = rss.last().map_or(0.0, |r| r.0);
        let max_in = |from: f64, to: f64| {
            rss.iter()
                .filter(|r| r.0 >= from && r.0 <= to)
                .map(|r| r.1)
                .max()
                .unwrap_or(0)
        };
        let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
        StatsReport {
            wall_s,
            latency_ms_p50: self.latency.quantile_ms(0.5),
            latency_ms_p99: self.latency.quantile_ms(0.99),
            latency_ms_max: self.latency.max_ms(),
            processing_ms_p50: self.processing.quantile_ms(0.5),
            processing_ms_p99: self.processing.quantile_ms(0.99),
            processing_ms_max: self.processing.max_ms(),
            jitter_ms_p50: self.jitter.quantile_ms(0.5),
            jitter_ms_p99: self.jitter.quantile_ms(0.99),
            jitter_ms_max: self.jitter.max_ms(),
            tick_to_sent_ms_p50: self.tick_to_sent.quantile_ms(0.5),
            tick_to_sent_ms_p99: self.tick_to_sent.quantile_ms(0.99),
            tick_to_sent_ms_max: self.tick_to_sent.max_ms(),
            cpu_percent: if wall_s > 0.0 {
                100.0 * cpu_s / wall_s
            } else {
                0.0
            },
            rss_start: rss.first().map_or(0, |r| r.1),
            rss_end: rss.last().map_or(0, |r| r.1),
            rss_max: rss.iter().map(|r| r.1).max().unwrap_or(0),
            rss_first_minute_max: max_in(0.0, 60.0),
            rss_last_minute_max: max_in(end_t - 60.0, end_t),
            drops: self.dropped_frames(),
            stream_errors: load(&self.stream_errors),
            reconnects: load(&self.reconnects),
            reconnect_failures: load(&self.reconnect_failures),
            capture_stalls: load(&self.capture_stalls),
            capture_contended: load(&self.capture_contended),
            capture_streams_stuck: load(&self.capture_streams_stuck),
            features_dropped: load(&self.features_dropped),
            anchors_dropped: load(&self.anchors_dropped),
            poses_dropped: load(&self.poses_dropped),
            controls_dropped: load(&self.controls_dropped),
            controls_coalesced: load(&self.controls_coalesced),
            controls_rate_limited: load(&self.controls_rate_limited),
            controls_unsupported: load(&self.controls_unsupported),
            send_errors: load(&self.send_errors),
            non_finite_replaced: load(&self.non_finite_replaced),
            vrchat_missing_bones: load(&self.vrchat_missing_bones),
            frames_sent: load(&self.frames_sent),
            late_frames: load(&self.late_frames),
            sender_stalls: load(&self.sender_stalls),
            horizon_frames: 0,
            model_frames: load(&self.model_frames),
            silence_frames: load(&self.silence_frames),
            packets_sent: load(&self.packets_sent),
            events_dropped: load(&self.events_dropped),
            callback_allocations: crate::alloc_counter::allocations(RtThread::Capture),
            allocations: ThreadAllocations::now(),
            allocation_counting: crate::alloc_counter::is_installed(),
            controls_accepted: load(&self.controls_accepted),
            controls_rejected: load(&self.controls_rejected),
            realtime_threads: load(&self.realtime_threads),
            osc_control_accepted: 0,
            osc_control_ignored: 0,
            osc_control_refused_sources: 0,
            midi_events: 0,
            midi_bytes_dropped: 0,
            midi_skipped: 0,
            midi_queue_full: 0,
            safety_nets: self.safety.load(),
            stage: self.stage.load(),
            moves: self.moves_danced().map(str::to_owned),
            moves_switches: load(&self.moves_switches),
            clock: self.clock.report(),
            style: self.style_danced().map(|s| s.name()),
            key_route: self.key_route().map(|r| r.name()),
            view: None,
        }
    }
}

/// The clock the beat grid follows, as the analysis thread last chose it, and what the MIDI
/// clock leader sent.
#[derive(Debug)]
pub struct ClockGauges {
    /// The [`ClockSource`](super::clock::ClockSource)'s number.
    pub source: AtomicU32,
    /// Tempo of the grid followed, BPM (0 while none is).
    pub tempo_bpm: AtomicF32,
    /// Median offset of the heard beats from an external clock's, ms (NaN: not measured).
    pub offset_ms: AtomicF32,
    /// How far the external clock's phase is trimmed toward the heard beats, ms.
    pub trim_ms: AtomicF32,
    /// The nudges added up, ms.
    pub nudge_ms: AtomicF32,
    /// Feature frames on which the chosen external clock had no grid (the heard beats stood in).
    pub fallback_frames: AtomicU64,
    /// Link peers.
    pub peers: AtomicU32,
    /// MIDI clock ticks sent.
    pub midi_ticks_sent: AtomicU64,
    /// Times the MIDI clock sent restarted its transport after the grid jumped.
    pub midi_restarts: AtomicU64,
    /// MIDI clock messages the output port refused.
    pub midi_send_errors: AtomicU64,
}

impl Default for ClockGauges {
    fn default() -> Self {
        let nan = AtomicF32::default();
        nan.set(f32::NAN);
        Self {
            source: AtomicU32::new(0),
            tempo_bpm: AtomicF32::default(),
            offset_ms: nan,
            trim_ms: AtomicF32::default(),
            nudge_ms: AtomicF32::default(),
            fallback_frames: AtomicU64::new(0),
            peers: AtomicU32::new(0),
            midi_ticks_sent: AtomicU64::new(0),
            midi_restarts: AtomicU64::new(0),
            midi_send_errors: AtomicU64::new(0),
        }
    }
}

impl ClockGauges {
    /// The clock followed, by name.
    pub fn source(&self) -> super::clock::ClockSource {
        let i = self.source.load(Ordering::Relaxed) as usize;
        super::clock::ClockSource::ALL
            .get(i)
            .copied()
            .unwrap_or_default()
    }

    /// The offset, when measured.
    pub fn offset(&self) -> Option<f32> {
        Some(self.offset_ms.get()).filter(|x| x.is_finite())
    }

    /// What the run's summary says of the clock.
    pub fn report(&self) -> ClockReport {
        let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
        ClockReport {
            source: self.source().name(),
            tempo_bpm: self.tempo_bpm.get(),
            offset_ms: self.offset(),
            trim_ms: self.trim_ms.get(),
            nudge_ms: self.nudge_ms.get(),
            fallback_frames: load(&self.fallback_frames),
            peers: self.peers.load(Ordering::Relaxed),
            midi_ticks_sent: load(&self.midi_ticks_sent),
            midi_restarts: load(&self.midi_restarts),
            midi_send_errors: load(&self.midi_send_errors),
        }
    }
}

/// The clock in a run's summary ([`ClockGauges`] at the end).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ClockReport {
    /// `audio`, `midi`, `link` or `tap`.
    pub source: &'static str,
    /// Tempo of the grid followed, BPM.
    pub tempo_bpm: f32,
    /// Median offset of the heard beats from an external clock's, ms.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub offset_ms: Option<f32>,
    /// Trim of the external clock's phase, ms.
    pub trim_ms: f32,
    /// The nudges added up, ms.
    pub nudge_ms: f32,
    /// Feature frames the chosen external clock had no grid for.
    pub fallback_frames: u64,
    /// Link peers.
    pub peers: u32,
    /// MIDI clock ticks sent.
    pub midi_ticks_sent: u64,
    /// Times the MIDI clock sent restarted (Stop, Start) after the grid jumped.
    pub midi_restarts: u64,
    /// MIDI clock messages the output port refused.
    pub midi_send_errors: u64,
}

/// The dancer's [`SafetyCounts`], published by the motion thread after each step.
#[derive(Debug, Default)]
pub struct SafetyGauges {
    /// Whether the dancer has safety nets at all.
    pub present: AtomicU32,
    values: [AtomicU64; 9],
}

impl SafetyGauges {
    /// Publishes `c` (a few relaxed stores; no allocation).
    pub fn store(&self, c: &SafetyCounts) {
        self.present.store(1, Ordering::Relaxed);
        let v = [
            c.frames,
            c.held,
            c.range_clamped,
            c.range_clamped_values,
            c.speed_limited,
            c.restarts,
            c.accented,
            c.key_blended,
            c.foot_locked,
        ];
        for (a, x) in self.values.iter().zip(v) {
            a.store(x, Ordering::Relaxed);
        }
    }

    /// The counts last published, if the dancer has nets.
    pub fn load(&self) -> Option<SafetyCounts> {
        if self.present.load(Ordering::Relaxed) == 0 {
            return None;
        }
        let v = self.values.each_ref().map(|a| a.load(Ordering::Relaxed));
        Some(SafetyCounts {
            frames: v[0],
            held: v[1],
            range_clamped: v[2],
            range_clamped_values: v[3],
            speed_limited: v[4],
            restarts: v[5],
            accented: v[6],
            key_blended: v[7],
            foot_locked: v[8],
        })
    }
}

/// What the stage did ([`StageCounts`]), published by the motion thread after each step.
#[derive(Debug, Default)]
pub struct StageGauges {
    /// Whether the dancer is on a stage at all.
    present: AtomicU32,
    frames: AtomicU64,
    steered: AtomicU64,
    glided: AtomicU64,
    clamped: AtomicU64,
    /// f32 bits of the largest turn, degrees per second.
    max_turn: AtomicU32,
}

impl StageGauges {
    /// Publishes `c` (a few relaxed stores; no allocation).
    pub fn store(&self, c: &StageCounts) {
        self.present.store(1, Ordering::Relaxed);
        self.frames.store(c.frames, Ordering::Relaxed);
        self.steered.store(c.steered, Ordering::Relaxed);
        self.glided.store(c.glided, Ordering::Relaxed);
        self.clamped.store(c.clamped, Ordering::Relaxed);
        self.max_turn
            .store(c.max_turn_deg_per_s.to_bits(), Ordering::Relaxed);
    }

    /// The counts last published, if the dancer is on a stage.
    pub fn load(&self) -> Option<StageCounts> {
        (self.present.load(Ordering::Relaxed) != 0).then(|| StageCounts {
            frames: self.frames.load(Ordering::Relaxed),
            steered: self.steered.load(Ordering::Relaxed),
            glided: self.glided.load(Ordering::Relaxed),
            clamped: self.clamped.load(Ordering::Relaxed),
            max_turn_deg_per_s: f32::from_bits(self.max_turn.load(Ordering::Relaxed)),
        })
    }
}

/// What `--stats-json` writes and `danced bench live` prints.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct StatsReport {
    /// Wall time of the run, seconds.
    pub wall_s: f64,
    /// Added latency, median, ms.
    pub latency_ms_p50: f64,
    /// Added latency, 99th percentile, ms.
    pub latency_ms_p99: f64,
    /// Added latency, maximum, ms.
    pub latency_ms_max: f64,
    /// Processing latency, median, ms.
    pub processing_ms_p50: f64,
    /// Processing latency, 99th percentile, ms.
    pub processing_ms_p99: f64,
    /// Processing latency, maximum, ms.
    pub processing_ms_max: f64,
    /// Send jitter, median, ms.
    pub jitter_ms_p50: f64,
    /// Send jitter, 99th percentile, ms.
    pub jitter_ms_p99: f64,
    /// Send jitter, maximum, ms.
    pub jitter_ms_max: f64,
    /// Scheduled tick → frame sent, median, ms.
    pub tick_to_sent_ms_p50: f64,
    /// Scheduled tick → frame sent, 99th percentile, ms.
    pub tick_to_sent_ms_p99: f64,
    /// Scheduled tick → frame sent, maximum, ms.
    pub tick_to_sent_ms_max: f64,
    /// Process CPU time over wall time, percent of one core.
    pub cpu_percent: f64,
    /// Resident set size at the first sample, bytes.
    pub rss_start: u64,
    /// Resident set size at the last sample, bytes.
    pub rss_end: u64,
    /// Largest resident set size sampled, bytes.
    pub rss_max: u64,
    /// Largest RSS in the first minute, bytes.
    pub rss_first_minute_max: u64,
    /// Largest RSS in the last minute, bytes.
    pub rss_last_minute_max: u64,
    /// Audio frames dropped at the ring.
    pub drops: u64,
    /// Audio backend stream errors.
    pub stream_errors: u64,
    /// Capture stream rebuilds.
    pub reconnects: u64,
    /// Failed attempts to reopen a lost capture device.
    pub reconnect_failures: u64,
    /// Capture streams that stopped calling back and were rebuilt.
    pub capture_stalls: u64,
    /// Capture blocks dropped while an old and a new stream's callbacks overlapped.
    pub capture_contended: u64,
    /// Replaced capture streams whose teardown had not returned at the end (stuck in their
    /// driver; their threads are abandoned, not waited for).
    pub capture_streams_stuck: u64,
    /// Feature frames lost on the way to the motion thread (queue full).
    pub features_dropped: u64,
    /// Audio-clock anchors lost on the way to the sender (queue full).
    pub anchors_dropped: u64,
    /// Poses lost on the way to the sender (queue full).
    pub poses_dropped: u64,
    /// Control events lost on the way to the motion thread (queue full).
    pub controls_dropped: u64,
    /// Parameter values replaced by a newer one before they were applied.
    pub controls_coalesced: u64,
    /// Control events refused by the per-address rate limit.
    pub controls_rate_limited: u64,
    /// Control events refused because the dancer does not honour them.
    pub controls_unsupported: u64,
    /// Datagrams the operating system refused to send.
    pub send_errors: u64,
    /// Non-finite values the encoders replaced.
    pub non_finite_replaced: u64,
    /// VRChat trackers skipped because their bone was missing.
    pub vrchat_missing_bones: u64,
    /// Pose frames sent.
    pub frames_sent: u64,
    /// Sent frames whose pose was late (held).
    pub late_frames: u64,
    /// Times the sender skipped ticks after falling behind.
    pub sender_stalls: u64,
    /// Model frames past the newest analysed frame each pose was made for (set by the pipeline).
    pub horizon_frames: u64,
    /// Model frames stepped.
    pub model_frames: u64,
    /// Frames of silence inserted while no audio arrived.
    pub silence_frames: u64,
    /// Packets the sink sent.
    pub packets_sent: u64,
    /// Analysis events dropped on the way to the sink.
    pub events_dropped: u64,
    /// Allocations in the audio callback path (the capture thread of `allocations`).
    pub callback_allocations: u64,
    /// Allocations and frees counted in each real-time thread's steady-state loop.
    pub allocations: ThreadAllocations,
    /// Whether allocations were counted at all (the counting allocator is installed).
    pub allocation_counting: bool,
    /// Control events applied.
    pub controls_accepted: u64,
    /// Control events refused.
    pub controls_rejected: u64,
    /// Pipeline threads that got real-time priority (3 when the system allows it, else 0).
    pub realtime_threads: u64,
    /// OSC control events parsed from the control port.
    pub osc_control_accepted: u64,
    /// OSC control packets or messages ignored (malformed, unknown address, wrong arguments).
    pub osc_control_ignored: u64,
    /// OSC control datagrams from sources outside `control.allow`.
    pub osc_control_refused_sources: u64,
    /// Control events made from MIDI input.
    pub midi_events: u64,
    /// MIDI bytes the parser dropped (garbage, truncated messages).
    pub midi_bytes_dropped: u64,
    /// MIDI messages too long to read (system exclusive), skipped.
    pub midi_skipped: u64,
    /// MIDI messages lost because the queue from the MIDI driver's thread was full.
    pub midi_queue_full: u64,
    /// What the dancer's safety nets did (neural dancer only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safety_nets: Option<SafetyCounts>,
    /// What the stage did: frames steered back from the edge and clamped at it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stage: Option<StageCounts>,
    /// The set of moves danced at the end (a dancer holding several only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub moves: Option<String>,
    /// Switches of the set of moves made.
    pub moves_switches: u64,
    /// The clock the beat grid followed.
    pub clock: ClockReport,
    /// The style danced at the end (sources with a style input only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub style: Option<&'static str>,
    /// Where key poses went at the end (sources with a route only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub key_route: Option<&'static str>,
    /// The browser view's counters, when it ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub view: Option<crate::view::ViewReport>,
}

/// Resident set size of this process, bytes (Linux `/proc/self/statm`; `None` elsewhere).
pub fn rss_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = s.split_whitespace().nth(1)?.parse().ok()?;
    // SAFETY: sysconf has no preconditions.
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    Some(pages * if page > 0 { page as u64 } else { 4096 })
}

/// User plus system CPU time of the whole process so far, seconds.
pub fn process_cpu_s() -> f64 {
    // SAFETY: getrusage only writes the struct we pass.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) } != 0 {
        return 0.0;
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(usage.ru_utime) + tv(usage.ru_stime)
}
