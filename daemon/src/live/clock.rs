//! Which clock the beat grid comes from, and the performer's hand on it: the analysis of the
//! music heard, an incoming MIDI clock, an Ableton Link session or tapped beats; nudges and
//! "beat one is now" on top. The control inputs, the MIDI thread and the Link thread write here
//! (under a lock: none of them is real-time); the analysis thread reads the newest snapshot
//! through a triple buffer, never waiting.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use protocols::{ClockGrid, TapTempo};

/// Where the beat grid comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ClockSource {
    /// The beats the analysis hears in the music.
    #[default]
    Audio,
    /// The MIDI clock on the control port.
    Midi,
    /// An Ableton Link session.
    Link,
    /// Tapped beats.
    Tap,
}

impl ClockSource {
    /// Every source, in the order their numbers go (0 = audio).
    pub const ALL: [ClockSource; 4] = [
        ClockSource::Audio,
        ClockSource::Midi,
        ClockSource::Link,
        ClockSource::Tap,
    ];

    /// The names accepted by the configuration and `/danced/control/clock`.
    pub const NAMES: &'static str = "audio, midi, link, tap";

    /// From its name (case-insensitive).
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|s| s.name().eq_ignore_ascii_case(name.trim()))
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            ClockSource::Audio => "audio",
            ClockSource::Midi => "midi",
            ClockSource::Link => "link",
            ClockSource::Tap => "tap",
        }
    }

    /// Its number (for the stats' gauges).
    pub fn index(self) -> u32 {
        self as u32
    }
}

/// What the analysis thread needs of the clocks, copied whole through the triple buffer.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ClockSnapshot {
    /// The clock followed.
    pub source: ClockSource,
    /// Its grid on the run's clock (µs since the pipeline epoch); `None` for the audio, and
    /// while the chosen clock has no grid (the heard beats stand in, counted).
    pub grid: Option<ClockGrid>,
    /// Every beat moved later by this, ms (the nudges added up).
    pub nudge_ms: f32,
    /// Counts "beat one is now" requests; a new count asks for one.
    pub beat_one_requests: u32,
    /// When the newest request came, µs since the epoch.
    pub beat_one_at_us: f64,
    /// Pull an external clock's phase toward the beats heard.
    pub trim: bool,
    /// Link peers seen (0 without Link).
    pub peers: u32,
}

/// The analysis thread's ends of the clocks: the desk's snapshots in, the grid followed out
/// to every clock danced leads.
pub struct ClockWiring {
    /// The desk's newest snapshot.
    pub feed: triple_buffer::Output<ClockSnapshot>,
    /// The grid followed on the wall clock (µs since the epoch), one buffer per leader.
    pub led: Vec<triple_buffer::Input<Option<ClockGrid>>>,
}

impl std::fmt::Debug for ClockWiring {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClockWiring")
            .field("leaders", &self.led.len())
            .finish_non_exhaustive()
    }
}

/// Maps a MIDI driver's timestamps (µs on its own clock, e.g. since ALSA's queue started) onto
/// the run's: the smallest gap seen between a message's arrival and its stamp is the two
/// clocks' offset plus the least delivery delay, which is a fraction of a millisecond.
#[derive(Clone, Copy, Debug, Default)]
pub struct DriverClock {
    offset_us: Option<f64>,
}

impl DriverClock {
    /// A message stamped `stamp_us` arrived at `arrived_us` (run clock): the stamp on the run's
    /// clock.
    pub fn observe(&mut self, stamp_us: u64, arrived_us: f64) -> f64 {
        let gap = arrived_us - stamp_us as f64;
        let offset = self.offset_us.map_or(gap, |o| o.min(gap));
        self.offset_us = Some(offset);
        stamp_us as f64 + offset
    }

    /// Run clock minus driver clock, once a message has been seen.
    pub fn offset_us(&self) -> Option<f64> {
        self.offset_us
    }
}

/// The MIDI input thread's part in following an incoming MIDI clock: after each message the
/// map has read, the clock's grid goes to the desk on the run's clock.
#[derive(Clone, Copy, Debug)]
pub struct MidiClockInput {
    driver: DriverClock,
    beats_per_bar: u32,
}

impl MidiClockInput {
    /// For bars of `beats_per_bar`.
    pub fn new(beats_per_bar: u32) -> Self {
        Self {
            driver: DriverClock::default(),
            beats_per_bar,
        }
    }

    /// `map` has just read a packet stamped `stamp_us` (driver clock) whose first byte is
    /// `status`: clock and transport messages update the desk.
    pub fn packet(
        &mut self,
        map: &protocols::MidiMap,
        status: u8,
        stamp_us: u64,
        desk: &ClockDesk,
    ) {
        if !matches!(status, 0xf8 | 0xfa | 0xfb | 0xfc | 0xf2) {
            return;
        }
        let offset = self.driver.observe(stamp_us, desk.now_us()) - stamp_us as f64;
        let grid = map.clock().grid(stamp_us, self.beats_per_bar);
        desk.set_midi(grid.map(|g| g.delayed(offset)));
    }

    /// No message for a while: a clock that stopped ticking is let go of.
    pub fn idle(&mut self, map: &protocols::MidiMap, desk: &ClockDesk) {
        if let Some(offset) = self.driver.offset_us() {
            let now = (desk.now_us() - offset).max(0.0) as u64;
            let grid = map.clock().grid(now, self.beats_per_bar);
            desk.set_midi(grid.map(|g| g.delayed(offset)));
        }
    }
}

/// Nudges add up to at most this, ms either way.
pub const NUDGE_TOTAL_MS_MAX: f32 = 1000.0;

/// Why a clock control was refused.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ClockRefusal {
    /// No clock of that name.
    Unknown(String),
    /// This run has no such clock (no MIDI port, Link not joined).
    Unavailable(ClockSource),
}

struct DeskState {
    snapshot: ClockSnapshot,
    available: [bool; 4],
    beats_per_bar: u32,
    midi: Option<ClockGrid>,
    link: Option<ClockGrid>,
    taps: TapTempo,
    out: triple_buffer::Input<ClockSnapshot>,
}

impl DeskState {
    fn publish(&mut self) {
        self.snapshot.grid = match self.snapshot.source {
            ClockSource::Audio => None,
            ClockSource::Midi => self.midi,
            ClockSource::Link => self.link,
            ClockSource::Tap => self.taps.grid(),
        };
        self.out.write(self.snapshot);
    }
}

/// The clocks a run can follow and the performer's corrections; shared by every control input.
#[derive(Clone)]
pub struct ClockDesk {
    state: Arc<Mutex<DeskState>>,
    epoch: Instant,
}

/// Settings a desk starts from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockSettings {
    /// The clock followed at the start.
    pub source: ClockSource,
    /// Beats per bar of a MIDI clock or tapped beats (they do not say).
    pub beats_per_bar: u32,
    /// Pull an external clock's phase toward the beats heard.
    pub trim: bool,
    /// Whether a MIDI clock can arrive (a MIDI port is open).
    pub midi: bool,
    /// Whether a Link session is joined.
    pub link: bool,
}

impl Default for ClockSettings {
    fn default() -> Self {
        Self {
            source: ClockSource::Audio,
            beats_per_bar: 4,
            trim: false,
            midi: false,
            link: false,
        }
    }
}

impl ClockDesk {
    /// A desk for a run whose wall times count from `epoch`, and the analysis thread's end.
    pub fn new(
        settings: ClockSettings,
        epoch: Instant,
    ) -> (Self, triple_buffer::Output<ClockSnapshot>) {
        let snapshot = ClockSnapshot {
            source: settings.source,
            trim: settings.trim,
            ..ClockSnapshot::default()
        };
        let (out, feed) = triple_buffer::triple_buffer(&snapshot);
        let state = DeskState {
            snapshot,
            available: [true, settings.midi, settings.link, true],
            beats_per_bar: settings.beats_per_bar.max(1),
            midi: None,
            link: None,
            taps: TapTempo::new(),
            out,
        };
        let desk = ClockDesk {
            state: Arc::new(Mutex::new(state)),
            epoch,
        };
        (desk, feed)
    }

    /// Microseconds since the run's epoch, now.
    pub fn now_us(&self) -> f64 {
        self.epoch.elapsed().as_secs_f64() * 1e6
    }

    fn read<R>(&self, f: impl FnOnce(&DeskState) -> R) -> R {
        // A panic elsewhere while holding the lock leaves plain data: go on with it.
        let state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        f(&state)
    }

    /// Changes the state and publishes the new snapshot.
    fn with<R>(&self, f: impl FnOnce(&mut DeskState) -> R) -> R {
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let r = f(&mut state);
        state.publish();
        r
    }

    /// The clock followed.
    pub fn source(&self) -> ClockSource {
        self.read(|s| s.snapshot.source)
    }

    /// Follows the clock named `name`.
    pub fn choose(&self, name: &str) -> Result<ClockSource, ClockRefusal> {
        let source = ClockSource::parse(name).ok_or_else(|| ClockRefusal::Unknown(name.into()))?;
        self.with(|s| {
            if !s.available[source as usize] {
                return Err(ClockRefusal::Unavailable(source));
            }
            s.snapshot.source = source;
            Ok(source)
        })
    }

    /// A tap of tap tempo, now.
    pub fn tap(&self) {
        let now = self.now_us().max(0.0) as u64;
        self.with(|s| {
            let bpb = s.beats_per_bar;
            s.taps.tap(now, bpb);
        });
    }

    /// Moves every beat `ms` later (earlier when negative); the total stays within
    /// ±[`NUDGE_TOTAL_MS_MAX`].
    pub fn nudge(&self, ms: f32) {
        if !ms.is_finite() {
            return;
        }
        self.with(|s| {
            s.snapshot.nudge_ms =
                (s.snapshot.nudge_ms + ms).clamp(-NUDGE_TOTAL_MS_MAX, NUDGE_TOTAL_MS_MAX);
        });
    }

    /// The beat heard nearest now is the first of its bar.
    pub fn beat_one(&self) {
        let now = self.now_us();
        self.with(|s| {
            s.snapshot.beat_one_requests = s.snapshot.beat_one_requests.wrapping_add(1);
            s.snapshot.beat_one_at_us = now;
        });
    }

    /// The MIDI clock's newest grid (µs since the epoch), or `None` when it stopped.
    pub fn set_midi(&self, grid: Option<ClockGrid>) {
        self.with(|s| s.midi = grid);
    }

    /// Beats per bar of a MIDI clock or tapped beats.
    pub fn beats_per_bar(&self) -> u32 {
        self.read(|s| s.beats_per_bar)
    }

    /// The Link session's newest grid (µs since the epoch) and its peers.
    pub fn set_link(&self, grid: Option<ClockGrid>, peers: u32) {
        self.with(|s| {
            s.link = grid;
            s.snapshot.peers = peers;
        });
    }
}

impl std::fmt::Debug for ClockDesk {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClockDesk").finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn driver_stamps_map_onto_the_run_clock_by_the_least_delay() {
        let mut c = DriverClock::default();
        assert_eq!(c.offset_us(), None);
        // Driver clock = run clock − 5 s; deliveries take 0.3 to 2 ms.
        assert_eq!(c.observe(1_000_000, 6_002_000.0), 6_002_000.0);
        assert_eq!(c.observe(1_100_000, 6_100_300.0), 6_100_300.0);
        assert_eq!(c.observe(1_200_000, 6_201_500.0), 6_200_300.0);
        assert_eq!(c.offset_us(), Some(5_000_300.0));
    }

    #[test]
    fn names_round_trip() {
        for s in ClockSource::ALL {
            assert_eq!(ClockSource::parse(s.name()), Some(s));
            assert!(ClockSource::NAMES.contains(s.name()));
        }
        assert_eq!(ClockSource::parse(" MIDI "), Some(ClockSource::Midi));
        assert_eq!(ClockSource::parse("vinyl"), None);
    }

    #[test]
    fn the_snapshot_carries_the_chosen_clocks_grid_and_the_corrections() {
        let settings = ClockSettings {
            midi: true,
            ..ClockSettings::default()
        };
        let (desk, mut feed) = ClockDesk::new(settings, Instant::now());
        let g = ClockGrid::new(1e6, 0.0, 128.0, 4).unwrap();
        desk.set_midi(Some(g));
        assert_eq!(feed.read().grid, None, "the audio is followed");
        assert_eq!(desk.choose("midi"), Ok(ClockSource::Midi));
        assert_eq!(feed.read().grid, Some(g));
        assert_eq!(
            desk.choose("link"),
            Err(ClockRefusal::Unavailable(ClockSource::Link))
        );
        assert_eq!(
            desk.choose("vinyl"),
            Err(ClockRefusal::Unknown("vinyl".into()))
        );
        desk.nudge(12.0);
        desk.nudge(-2.0);
        desk.nudge(f32::NAN);
        assert_eq!(feed.read().nudge_ms, 10.0);
        desk.nudge(5000.0);
        assert_eq!(feed.read().nudge_ms, NUDGE_TOTAL_MS_MAX);
        desk.beat_one();
        let s = *feed.read();
        assert_eq!(s.beat_one_requests, 1);
        assert!(s.beat_one_at_us > 0.0);
        desk.set_midi(None);
        assert_eq!(feed.read().grid, None, "the MIDI clock stopped");
    }
}
