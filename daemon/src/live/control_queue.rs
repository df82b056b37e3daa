//! The performer's controls on their way to the motion thread, kept off its real-time path:
//! each input (OSC receiver, MIDI, a test) owns a [`ControlSender`] that validates values
//! against the one range of each parameter, resolves key-pose names to indices, rate-limits
//! events per address, and hands the motion thread only `Copy` data through wait-free queues.
//!
//! Parameters (temperature, accent, transition length, tempo hint, seed) are coalesced: each
//! has one slot holding its newest value, so a fader or a flood of seeds can never fill a
//! queue or delay a key pose; a value replaced before the motion thread took it is counted.
//! Events (key pose, clear, pause, resume) go through one SPSC ring per input, each
//! rate-limited per address; a full ring or an exceeded limit is counted, never blocks.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use glam::Quat;
use model::rig::JOINT_COUNT;
use protocols::control::{
    BEAT_ACCENT_RANGE, NUDGE_MS_MAX, TEMPERATURE_RANGE, TEMPO_HINT_RANGE, valid_transition_beats,
};

use super::clock::{ClockDesk, ClockRefusal};
use super::sink::PoseBank;
use super::stats::Stats;
use super::wire::{ControlEvent, Quantize};
use model::source::{KeyPoseRoute, MovesSwitch, SourceControls};
use model::style::{DanceStyle, StyleRequest};

/// Events one input may queue before the motion thread takes them.
const QUEUE_CAPACITY: usize = 256;
/// Events per address an input may send in a burst, and per second after it.
const RATE_BURST: f64 = 32.0;
/// See [`RATE_BURST`].
const RATE_PER_S: f64 = 32.0;

/// A control the motion thread applies: plain data, names already resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MotionCommand {
    /// New temperature (within the parameter's range).
    Temperature(f32),
    /// New beat accent.
    BeatAccent(f32),
    /// New transition length for key poses reached "now", beats.
    TransitionBeats(f32),
    /// New tempo hint, BPM.
    TempoHint(f32),
    /// New style seed: the dance goes on, its randomness restarts.
    StyleSeed(u64),
    /// New dance style (or auto).
    DanceStyle(StyleRequest),
    /// New route for key poses.
    KeyPoseRoute(KeyPoseRoute),
    /// Dance the set of moves at this index, from the next beat or bar.
    Moves {
        /// Index in the order the dancer was given its sets.
        index: u16,
        /// When.
        at: MovesSwitch,
    },
    /// Reach the key pose at this index of the pose table.
    KeyPose {
        /// Index in [`ControlHub::table`]'s order.
        pose: u16,
        /// When.
        quantize: Quantize,
    },
    /// Drop the pending key pose.
    ClearKeyPose,
    /// Freeze.
    Pause,
    /// Unfreeze.
    Resume,
}

/// One parameter's newest value, written by any input, taken by the motion thread.
#[derive(Debug, Default)]
struct ParamSlot {
    bits: AtomicU64,
    pending: AtomicBool,
}

impl ParamSlot {
    /// Offers a value; returns true when it replaced one not yet taken.
    fn offer(&self, bits: u64) -> bool {
        self.bits.store(bits, Ordering::Release);
        self.pending.swap(true, Ordering::AcqRel)
    }

    fn take(&self) -> Option<u64> {
        self.pending
            .swap(false, Ordering::AcqRel)
            .then(|| self.bits.load(Ordering::Acquire))
    }
}

/// The coalescing slots, shared by every sender and the receiver.
#[derive(Debug, Default)]
struct Params {
    temperature: ParamSlot,
    accent: ParamSlot,
    transition: ParamSlot,
    tempo_hint: ParamSlot,
    seed: ParamSlot,
    /// 0 = auto, 1 + index = that [`DanceStyle`].
    style: ParamSlot,
    /// The [`KeyPoseRoute`]'s index.
    key_route: ParamSlot,
    /// The set of moves' index, plus 1 << 32 for a switch on the next bar.
    moves: ParamSlot,
}

/// Bit of the moves slot saying the switch waits for the next bar.
const MOVES_AT_BAR: u64 = 1 << 32;

fn style_bits(request: StyleRequest) -> u64 {
    match request {
        StyleRequest::Auto => 0,
        StyleRequest::Style(s) => 1 + s.index() as u64,
    }
}

fn style_of_bits(bits: u64) -> StyleRequest {
    match bits.checked_sub(1) {
        Some(i) => {
            DanceStyle::from_index(i as usize).map_or(StyleRequest::Auto, StyleRequest::Style)
        }
        None => StyleRequest::Auto,
    }
}

/// Builds the control path before a run: hands out one sender per input, then becomes the
/// motion thread's [`ControlReceiver`].
pub struct ControlHub {
    honoured: SourceControls,
    params: Arc<Params>,
    names: Arc<HashMap<String, u16>>,
    moves: Arc<Vec<String>>,
    clock: Option<ClockDesk>,
    table: Vec<[Quat; JOINT_COUNT]>,
    consumers: Vec<rtrb::Consumer<MotionCommand>>,
    stats: Arc<Stats>,
}

impl ControlHub {
    /// A hub resolving names in `poses` and counting into `stats`.
    pub fn new(poses: &dyn PoseBank, stats: Arc<Stats>) -> Self {
        let mut names = HashMap::new();
        let mut table = Vec::new();
        for name in poses.names() {
            if let Some(rotations) = poses.get(&name)
                && table.len() < usize::from(u16::MAX)
            {
                names.insert(name, table.len() as u16);
                table.push(rotations);
            }
        }
        Self {
            honoured: SourceControls::ALL,
            params: Arc::new(Params::default()),
            names: Arc::new(names),
            moves: Arc::new(Vec::new()),
            clock: None,
            table,
            consumers: Vec::new(),
            stats,
        }
    }

    /// Refuses the controls the source does not honour (style, key route, beat accent), each
    /// counted in `controls_unsupported`; a new hub passes them all on.
    pub fn honouring(mut self, controls: SourceControls) -> Self {
        self.honoured = controls;
        self
    }

    /// Resolves `/moves` names against `names` (the dancer's sets of moves, in order).
    pub fn with_moves(mut self, names: Vec<String>) -> Self {
        self.moves = Arc::new(names);
        self
    }

    /// Passes taps, nudges, "beat one" and clock choices to `desk` (without one they are
    /// refused as unsupported).
    pub fn with_clock(mut self, desk: ClockDesk) -> Self {
        self.clock = Some(desk);
        self
    }

    /// A sender for one more input (each input thread owns its own).
    pub fn sender(&mut self) -> ControlSender {
        let (producer, consumer) = rtrb::RingBuffer::new(QUEUE_CAPACITY);
        self.consumers.push(consumer);
        ControlSender {
            honoured: self.honoured,
            warned: [false; 5],
            producer,
            params: self.params.clone(),
            names: self.names.clone(),
            moves: self.moves.clone(),
            clock: self.clock.clone(),
            stats: self.stats.clone(),
            buckets: [TokenBucket::new(); 4],
        }
    }

    /// The key poses' names by index (what the browser view offers buttons for).
    pub fn pose_names(&self) -> Vec<String> {
        let mut names = vec![String::new(); self.table.len()];
        for (name, &i) in self.names.iter() {
            names[usize::from(i)] = name.clone();
        }
        names
    }

    /// The key poses by index, for the motion thread.
    pub fn table(&self) -> &[[Quat; JOINT_COUNT]] {
        &self.table
    }

    /// The motion thread's end, with the pose table.
    pub fn into_receiver(self) -> (ControlReceiver, Vec<[Quat; JOINT_COUNT]>) {
        (
            ControlReceiver {
                params: self.params,
                consumers: self.consumers,
            },
            self.table,
        )
    }
}

/// A token bucket: [`RATE_BURST`] events at once, [`RATE_PER_S`] a second after that.
#[derive(Clone, Copy, Debug)]
struct TokenBucket {
    tokens: f64,
    last: Option<Instant>,
}

impl TokenBucket {
    fn new() -> Self {
        Self {
            tokens: RATE_BURST,
            last: None,
        }
    }

    fn allow(&mut self, now: Instant) -> bool {
        if let Some(last) = self.last {
            let dt = now.saturating_duration_since(last).as_secs_f64();
            self.tokens = (self.tokens + dt * RATE_PER_S).min(RATE_BURST);
        }
        self.last = Some(now);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// Why a control was not passed on.
#[derive(Clone, Debug, PartialEq)]
pub enum ControlRefusal {
    /// No key pose of that name.
    UnknownPose(String),
    /// No set of moves of that name or number.
    UnknownMoves(String),
    /// No clock of that name.
    UnknownClock(String),
    /// A value outside its parameter's range, or not finite.
    OutOfRange,
    /// More events to this address than the rate limit allows.
    RateLimited,
    /// The queue to the motion thread is full.
    QueueFull,
    /// The dancer does not honour this control (e.g. a style for a model without a style
    /// input).
    Unsupported(UnsupportedControl),
}

/// A control some dancers do not honour.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UnsupportedControl {
    /// `/danced/control/style`.
    Style,
    /// `/danced/control/keypose/route`.
    KeyRoute,
    /// `/danced/control/accent`.
    BeatAccent,
    /// `/danced/control/moves`.
    Moves,
    /// `/danced/control/clock` (a clock this run does not have), tap, nudge and beat one
    /// (a run without a clock desk).
    Clock,
}

impl UnsupportedControl {
    /// What the performer is told, once per input and control.
    fn explanation(self) -> &'static str {
        match self {
            UnsupportedControl::Style => {
                "/danced/control/style refused: the loaded dancer has no style input"
            }
            UnsupportedControl::KeyRoute => {
                "/danced/control/keypose/route refused: the loaded dancer shows key poses over its dance and has no other route"
            }
            UnsupportedControl::BeatAccent => {
                "/danced/control/accent refused: the loaded dancer follows the beat by itself and has no beat accent"
            }
            UnsupportedControl::Moves => {
                "/danced/control/moves refused: the loaded dancer has one set of moves (give the retrieval dancer several --library files)"
            }
            UnsupportedControl::Clock => {
                "/danced/control/clock refused: that clock is not in this run (midi needs control.midi_port; link needs clock.link = true in a build with Link)"
            }
        }
    }
}

/// One input's end of the control path (not `Clone`: each input gets its own from the hub).
pub struct ControlSender {
    honoured: SourceControls,
    /// Whether each [`UnsupportedControl`] has been explained in the log yet.
    warned: [bool; 5],
    producer: rtrb::Producer<MotionCommand>,
    params: Arc<Params>,
    names: Arc<HashMap<String, u16>>,
    /// The dancer's sets of moves, by name, in order.
    moves: Arc<Vec<String>>,
    /// Where taps, nudges and clock choices go.
    clock: Option<ClockDesk>,
    stats: Arc<Stats>,
    /// Key pose, clear, pause/resume, the clock's controls.
    buckets: [TokenBucket; 4],
}

fn in_range(x: f32, (lo, hi): (f32, f32)) -> bool {
    x.is_finite() && (lo..=hi).contains(&x)
}

impl ControlSender {
    /// Validates, resolves and passes on one control; every outcome is counted in the stats
    /// (`controls_accepted`, `controls_rejected`, `controls_coalesced`,
    /// `controls_rate_limited`, `controls_dropped`, `controls_unsupported`); the first refusal
    /// of each unsupported control is also explained in the log.
    pub fn send(&mut self, event: ControlEvent) -> Result<(), ControlRefusal> {
        let r = self.pass_on(event);
        if let Err(ControlRefusal::Unsupported(c)) = &r
            && !std::mem::replace(&mut self.warned[*c as usize], true)
        {
            tracing::warn!("{} (counted as controls_unsupported)", c.explanation());
        }
        let s = &self.stats;
        let counter = match &r {
            Ok(()) => &s.controls_accepted,
            Err(
                ControlRefusal::UnknownPose(_)
                | ControlRefusal::UnknownMoves(_)
                | ControlRefusal::UnknownClock(_)
                | ControlRefusal::OutOfRange,
            ) => &s.controls_rejected,
            Err(ControlRefusal::RateLimited) => &s.controls_rate_limited,
            Err(ControlRefusal::QueueFull) => &s.controls_dropped,
            Err(ControlRefusal::Unsupported(_)) => &s.controls_unsupported,
        };
        counter.fetch_add(1, Ordering::Relaxed);
        r
    }

    fn offer(&self, slot: &ParamSlot, bits: u64) {
        if slot.offer(bits) {
            self.stats
                .controls_coalesced
                .fetch_add(1, Ordering::Relaxed);
        }
    }

    fn pass_on(&mut self, event: ControlEvent) -> Result<(), ControlRefusal> {
        let p = &self.params;
        let honoured = self.honoured;
        let supported = |yes: bool, control| {
            if yes {
                Ok(())
            } else {
                Err(ControlRefusal::Unsupported(control))
            }
        };
        let float = |x: f32, range| {
            in_range(x, range)
                .then_some(u64::from(x.to_bits()))
                .ok_or(ControlRefusal::OutOfRange)
        };
        let (bucket, command) = match event {
            ControlEvent::Temperature(t) => {
                self.offer(&p.temperature, float(t, TEMPERATURE_RANGE)?);
                return Ok(());
            }
            ControlEvent::BeatAccent(a) => {
                let bits = float(a, BEAT_ACCENT_RANGE)?;
                supported(honoured.beat_accent, UnsupportedControl::BeatAccent)?;
                self.offer(&p.accent, bits);
                return Ok(());
            }
            ControlEvent::TransitionBeats(b) => {
                if !valid_transition_beats(b) {
                    return Err(ControlRefusal::OutOfRange);
                }
                self.offer(&p.transition, u64::from(b.to_bits()));
                return Ok(());
            }
            ControlEvent::TempoHint(bpm) => {
                self.offer(&p.tempo_hint, float(bpm, TEMPO_HINT_RANGE)?);
                return Ok(());
            }
            ControlEvent::StyleSeed(seed) => {
                self.offer(&p.seed, seed);
                return Ok(());
            }
            ControlEvent::DanceStyle(name) => {
                let request = StyleRequest::parse(&name).ok_or(ControlRefusal::OutOfRange)?;
                supported(honoured.style, UnsupportedControl::Style)?;
                self.offer(&p.style, style_bits(request));
                return Ok(());
            }
            ControlEvent::KeyPoseRoute(name) => {
                let route = KeyPoseRoute::parse(&name).ok_or(ControlRefusal::OutOfRange)?;
                supported(honoured.key_route, UnsupportedControl::KeyRoute)?;
                self.offer(&p.key_route, route.index() as u64);
                return Ok(());
            }
            ControlEvent::Moves { choice, quantize } => {
                supported(honoured.moves, UnsupportedControl::Moves)?;
                let index = self
                    .moves
                    .iter()
                    .position(|n| n.eq_ignore_ascii_case(&choice))
                    .or_else(|| {
                        choice
                            .parse::<usize>()
                            .ok()
                            .filter(|&i| i < self.moves.len())
                    })
                    .ok_or(ControlRefusal::UnknownMoves(choice))?;
                let at = if quantize == Quantize::NextBeat {
                    0
                } else {
                    MOVES_AT_BAR
                };
                self.offer(&p.moves, index as u64 | at);
                return Ok(());
            }
            ControlEvent::KeyPose { name, quantize } => {
                let Some(&pose) = self.names.get(&name) else {
                    return Err(ControlRefusal::UnknownPose(name));
                };
                (0, MotionCommand::KeyPose { pose, quantize })
            }
            ControlEvent::Tap
            | ControlEvent::BeatOne
            | ControlEvent::Nudge(_)
            | ControlEvent::Clock(_) => {
                return self.pass_to_clock(event);
            }
            ControlEvent::ClearKeyPose => (1, MotionCommand::ClearKeyPose),
            ControlEvent::Pause => (2, MotionCommand::Pause),
            ControlEvent::Resume => (2, MotionCommand::Resume),
        };
        if !self.buckets[bucket].allow(Instant::now()) {
            return Err(ControlRefusal::RateLimited);
        }
        self.producer
            .push(command)
            .map_err(|_| ControlRefusal::QueueFull)
    }
}

impl ControlSender {
    /// Taps, nudges, "beat one" and clock choices: the clock desk's, on this (non-real-time)
    /// input thread.
    fn pass_to_clock(&mut self, event: ControlEvent) -> Result<(), ControlRefusal> {
        if let ControlEvent::Nudge(ms) = event
            && !(ms.is_finite() && ms.abs() <= NUDGE_MS_MAX)
        {
            return Err(ControlRefusal::OutOfRange);
        }
        let Some(desk) = &self.clock else {
            return Err(ControlRefusal::Unsupported(UnsupportedControl::Clock));
        };
        if !self.buckets[3].allow(Instant::now()) {
            return Err(ControlRefusal::RateLimited);
        }
        match event {
            ControlEvent::Tap => desk.tap(),
            ControlEvent::BeatOne => desk.beat_one(),
            ControlEvent::Nudge(ms) => desk.nudge(ms),
            ControlEvent::Clock(name) => {
                desk.choose(&name).map_err(|e| match e {
                    ClockRefusal::Unknown(n) => ControlRefusal::UnknownClock(n),
                    ClockRefusal::Unavailable(_) => {
                        ControlRefusal::Unsupported(UnsupportedControl::Clock)
                    }
                })?;
            }
            _ => {}
        }
        Ok(())
    }
}

/// The motion thread's end: takes coalesced parameters and queued events without waiting.
pub struct ControlReceiver {
    params: Arc<Params>,
    consumers: Vec<rtrb::Consumer<MotionCommand>>,
}

impl ControlReceiver {
    /// Calls `apply` for every parameter changed and every event queued since the last poll
    /// (parameters first, so a key pose uses the newest transition length); never allocates.
    pub fn poll(&mut self, mut apply: impl FnMut(MotionCommand)) {
        let p = &self.params;
        let f = |bits: u64| f32::from_bits(bits as u32);
        if let Some(b) = p.temperature.take() {
            apply(MotionCommand::Temperature(f(b)));
        }
        if let Some(b) = p.accent.take() {
            apply(MotionCommand::BeatAccent(f(b)));
        }
        if let Some(b) = p.transition.take() {
            apply(MotionCommand::TransitionBeats(f(b)));
        }
        if let Some(b) = p.tempo_hint.take() {
            apply(MotionCommand::TempoHint(f(b)));
        }
        if let Some(seed) = p.seed.take() {
            apply(MotionCommand::StyleSeed(seed));
        }
        if let Some(bits) = p.style.take() {
            apply(MotionCommand::DanceStyle(style_of_bits(bits)));
        }
        if let Some(bits) = p.key_route.take() {
            let route = KeyPoseRoute::from_index(bits as usize).unwrap_or(KeyPoseRoute::Overlay);
            apply(MotionCommand::KeyPoseRoute(route));
        }
        if let Some(bits) = p.moves.take() {
            apply(MotionCommand::Moves {
                index: (bits & 0xffff) as u16,
                at: if bits & MOVES_AT_BAR != 0 {
                    MovesSwitch::NextBar
                } else {
                    MovesSwitch::NextBeat
                },
            });
        }
        for c in &mut self.consumers {
            while let Ok(command) = c.pop() {
                apply(command);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::live::sink::MemoryPoseBank;

    fn hub() -> (ControlHub, Arc<Stats>) {
        let stats = Arc::new(Stats::new());
        (
            ControlHub::new(&MemoryPoseBank::builtin(), stats.clone()),
            stats,
        )
    }

    fn drain(rx: &mut ControlReceiver) -> Vec<MotionCommand> {
        let mut got = Vec::new();
        rx.poll(|c| got.push(c));
        got
    }

    #[test]
    fn names_resolve_to_indices_and_unknown_names_are_counted() {
        let (mut hub, stats) = hub();
        let mut tx = hub.sender();
        let arms_up = hub.names["arms_up"];
        let (mut rx, table) = hub.into_receiver();
        assert_eq!(table.len(), 2);
        let key = |name: &str| ControlEvent::KeyPose {
            name: name.into(),
            quantize: Quantize::NextBar,
        };
        assert_eq!(tx.send(key("arms_up")), Ok(()));
        assert_eq!(
            tx.send(key("nope")),
            Err(ControlRefusal::UnknownPose("nope".into()))
        );
        assert_eq!(
            drain(&mut rx),
            vec![MotionCommand::KeyPose {
                pose: arms_up,
                quantize: Quantize::NextBar
            }]
        );
        assert_eq!(stats.controls_accepted.load(Ordering::Relaxed), 1);
        assert_eq!(stats.controls_rejected.load(Ordering::Relaxed), 1);
    }

    #[test]
    fn a_flood_of_parameters_coalesces_to_the_newest_value() {
        let (mut hub, stats) = hub();
        let mut tx = hub.sender();
        let (mut rx, _) = hub.into_receiver();
        for i in 0..10_000u64 {
            tx.send(ControlEvent::StyleSeed(i)).unwrap();
            tx.send(ControlEvent::Temperature((i % 200) as f32 / 100.0))
                .unwrap();
        }
        tx.send(ControlEvent::Pause).unwrap();
        assert_eq!(
            drain(&mut rx),
            vec![
                MotionCommand::Temperature(1.99),
                MotionCommand::StyleSeed(9_999),
                MotionCommand::Pause
            ]
        );
        assert_eq!(stats.controls_coalesced.load(Ordering::Relaxed), 19_998);
        assert!(drain(&mut rx).is_empty());
    }

    #[test]
    fn events_are_rate_limited_per_address_and_out_of_range_values_refused() {
        let (mut hub, stats) = hub();
        let mut tx = hub.sender();
        let (mut rx, _) = hub.into_receiver();
        let mut limited = 0;
        for _ in 0..100 {
            if tx.send(ControlEvent::ClearKeyPose) == Err(ControlRefusal::RateLimited) {
                limited += 1;
            }
        }
        // A burst of 32 passes (plus whatever refilled in the microseconds the loop took).
        assert!((60..=68).contains(&limited), "{limited}");
        // Another address has its own budget.
        assert_eq!(tx.send(ControlEvent::Pause), Ok(()));
        assert_eq!(
            stats.controls_rate_limited.load(Ordering::Relaxed),
            limited as u64
        );
        assert!(drain(&mut rx).len() >= 33);
        for bad in [
            ControlEvent::Temperature(f32::NAN),
            ControlEvent::Temperature(2.5),
            ControlEvent::BeatAccent(0.95),
            ControlEvent::TransitionBeats(0.0),
            ControlEvent::TransitionBeats(65.0),
            ControlEvent::TempoHint(20.0),
            ControlEvent::DanceStyle("polka".into()),
            ControlEvent::KeyPoseRoute("both".into()),
        ] {
            assert_eq!(
                tx.send(bad.clone()),
                Err(ControlRefusal::OutOfRange),
                "{bad:?}"
            );
        }
        assert_eq!(stats.controls_rejected.load(Ordering::Relaxed), 8);
    }

    #[test]
    fn a_set_of_moves_by_name_or_number_reaches_the_motion_thread_newest_first() {
        let stats = Arc::new(Stats::new());
        let mut three = ControlHub::new(&MemoryPoseBank::builtin(), stats.clone())
            .with_moves(vec!["tang2018".into(), "Salsa".into(), "breaking".into()]);
        let mut tx = three.sender();
        let (mut rx, _) = three.into_receiver();
        let moves = |choice: &str, quantize| ControlEvent::Moves {
            choice: choice.into(),
            quantize,
        };
        tx.send(moves("salsa", Quantize::NextBar)).unwrap();
        assert_eq!(
            drain(&mut rx),
            vec![MotionCommand::Moves {
                index: 1,
                at: MovesSwitch::NextBar
            }]
        );
        // The newest choice wins; the one it replaced is counted.
        tx.send(moves("1", Quantize::NextBar)).unwrap();
        tx.send(moves("2", Quantize::NextBeat)).unwrap();
        assert_eq!(
            drain(&mut rx),
            vec![MotionCommand::Moves {
                index: 2,
                at: MovesSwitch::NextBeat
            }]
        );
        assert_eq!(stats.controls_coalesced.load(Ordering::Relaxed), 1);
        for unknown in ["3", "polka"] {
            assert_eq!(
                tx.send(moves(unknown, Quantize::NextBar)),
                Err(ControlRefusal::UnknownMoves(unknown.into()))
            );
        }
        assert_eq!(stats.controls_rejected.load(Ordering::Relaxed), 2);
        assert!(drain(&mut rx).is_empty());

        // A dancer with one set of moves refuses the control, counted.
        let (one, stats) = hub();
        let mut one = one.honouring(SourceControls::default());
        let mut tx = one.sender();
        assert_eq!(
            tx.send(moves("0", Quantize::NextBar)),
            Err(ControlRefusal::Unsupported(UnsupportedControl::Moves))
        );
        assert_eq!(stats.controls_unsupported.load(Ordering::Relaxed), 1);
    }

    #[test]
    fn a_key_route_by_name_reaches_the_motion_thread_newest_first() {
        let (mut hub, stats) = hub();
        let mut tx = hub.sender();
        let (mut rx, _) = hub.into_receiver();
        tx.send(ControlEvent::KeyPoseRoute("network".into()))
            .unwrap();
        assert_eq!(
            drain(&mut rx),
            vec![MotionCommand::KeyPoseRoute(KeyPoseRoute::Network)]
        );
        tx.send(ControlEvent::KeyPoseRoute("network".into()))
            .unwrap();
        tx.send(ControlEvent::KeyPoseRoute("overlay".into()))
            .unwrap();
        assert_eq!(
            drain(&mut rx),
            vec![MotionCommand::KeyPoseRoute(KeyPoseRoute::Overlay)]
        );
        assert_eq!(stats.controls_coalesced.load(Ordering::Relaxed), 1);
        assert!(drain(&mut rx).is_empty());
        // `/keypose/route N` and the slot number routes alike.
        for (i, name) in protocols::control::KEY_ROUTE_NUMBERS.iter().enumerate() {
            let route = KeyPoseRoute::parse(name).unwrap();
            assert_eq!(route.index(), i);
            assert_eq!(KeyPoseRoute::from_index(i), Some(route));
        }
    }

    #[test]
    fn controls_the_dancer_does_not_honour_are_refused_and_counted() {
        let stats = Arc::new(Stats::new());
        // A dancer without a style input that routes key poses and takes an accent.
        let honoured = SourceControls {
            style: false,
            ..SourceControls::ALL
        };
        let mut hub =
            ControlHub::new(&MemoryPoseBank::builtin(), stats.clone()).honouring(honoured);
        let mut tx = hub.sender();
        let (mut rx, _) = hub.into_receiver();
        for name in ["rumba", "auto"] {
            assert_eq!(
                tx.send(ControlEvent::DanceStyle(name.into())),
                Err(ControlRefusal::Unsupported(UnsupportedControl::Style))
            );
        }
        // A name that is no style is still a bad argument, not an unsupported control.
        assert_eq!(
            tx.send(ControlEvent::DanceStyle("polka".into())),
            Err(ControlRefusal::OutOfRange)
        );
        tx.send(ControlEvent::KeyPoseRoute("network".into()))
            .unwrap();
        tx.send(ControlEvent::BeatAccent(0.2)).unwrap();
        assert_eq!(
            drain(&mut rx),
            vec![
                MotionCommand::BeatAccent(0.2),
                MotionCommand::KeyPoseRoute(KeyPoseRoute::Network)
            ]
        );
        assert_eq!(stats.controls_unsupported.load(Ordering::Relaxed), 2);
        assert_eq!(stats.controls_rejected.load(Ordering::Relaxed), 1);
        assert_eq!(stats.controls_accepted.load(Ordering::Relaxed), 2);
        // A dancer that honours none of the three (the retrieval dancer).
        let stats = Arc::new(Stats::new());
        let mut hub = ControlHub::new(&MemoryPoseBank::builtin(), stats.clone())
            .honouring(SourceControls::default());
        let mut tx = hub.sender();
        for event in [
            ControlEvent::DanceStyle("waltz".into()),
            ControlEvent::KeyPoseRoute("overlay".into()),
            ControlEvent::BeatAccent(0.5),
        ] {
            assert!(matches!(
                tx.send(event),
                Err(ControlRefusal::Unsupported(_))
            ));
        }
        assert_eq!(stats.controls_unsupported.load(Ordering::Relaxed), 3);
        // Temperature and key poses every dancer takes.
        tx.send(ControlEvent::Temperature(0.7)).unwrap();
    }

    #[test]
    fn a_style_by_name_reaches_the_motion_thread_newest_first() {
        let (mut hub, stats) = hub();
        let mut tx = hub.sender();
        let (mut rx, _) = hub.into_receiver();
        tx.send(ControlEvent::DanceStyle("rumba".into())).unwrap();
        assert_eq!(
            drain(&mut rx),
            vec![MotionCommand::DanceStyle(StyleRequest::Style(
                DanceStyle::Rumba
            ))]
        );
        tx.send(ControlEvent::DanceStyle("waltz".into())).unwrap();
        tx.send(ControlEvent::DanceStyle("auto".into())).unwrap();
        assert_eq!(
            drain(&mut rx),
            vec![MotionCommand::DanceStyle(StyleRequest::Auto)]
        );
        assert_eq!(stats.controls_coalesced.load(Ordering::Relaxed), 1);
        for s in DanceStyle::ALL {
            let r = StyleRequest::Style(s);
            assert_eq!(style_of_bits(style_bits(r)), r);
        }
    }

    #[test]
    fn a_full_queue_is_counted_not_waited_on() {
        let (mut hub, stats) = hub();
        let mut tx = hub.sender();
        let _rx = hub.into_receiver();
        let mut full = 0;
        // Spread over time so the rate limit is not what refuses them.
        for i in 0..QUEUE_CAPACITY + 10 {
            tx.buckets[2] = TokenBucket::new();
            let e = if i % 2 == 0 {
                ControlEvent::Pause
            } else {
                ControlEvent::Resume
            };
            if tx.send(e) == Err(ControlRefusal::QueueFull) {
                full += 1;
            }
        }
        assert_eq!(full, 10);
        assert_eq!(stats.controls_dropped.load(Ordering::Relaxed), 10);
    }
}
