//! The pipeline's network and controller edges: OSC out to every configured target (native,
//! VMC, VRChat), and the OSC and MIDI control inputs feeding the motion thread's channel.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{Context, Result};
use glam::Quat;
use model::rig::JOINT_COUNT;
use protocols::{
    ControlParser, ControlReceiver, MidiInputs, MidiMap, MidiParser, NativeEncoder, OscOutput,
    OscTarget, TargetKind, VmcEncoder, VrchatEncoder, VrchatTrackerMap, parse_target,
};

use super::clock::{ClockDesk, MidiClockInput};
use super::config::Config;
use super::control_queue::ControlHub;
use super::sink::{FrameSink, PoseBank, SinkLosses};
use super::wire::{AnalysisEvent, BodyFrame};

/// Sends frames and events to every configured OSC target.
pub struct OscSink {
    out: OscOutput,
}

impl OscSink {
    /// The targets `config` asks for (native `output.osc`, `output.vmc`, `output.vrchat`).
    pub fn from_config(config: &Config) -> Result<Self> {
        let mut targets = Vec::new();
        for t in &config.output.osc {
            targets.push(parse_target(TargetKind::Native, t).context("output.osc")?);
        }
        if config.output.vmc.enabled {
            targets.push(
                parse_target(TargetKind::Vmc, &config.output.vmc.target)
                    .context("output.vmc.target")?,
            );
        }
        if config.output.vrchat.enabled {
            targets.push(
                parse_target(TargetKind::Vrchat, &config.output.vrchat.target)
                    .context("output.vrchat.target")?,
            );
        }
        Self::new(targets, config)
    }

    /// An output to `targets` with `config`'s encoder settings.
    pub fn new(targets: Vec<OscTarget>, config: &Config) -> Result<Self> {
        let map = VrchatTrackerMap::from_numbered(&config.output.vrchat.trackers)
            .context("output.vrchat.trackers")?;
        let out = OscOutput::with_encoders(
            targets,
            NativeEncoder::default(),
            VmcEncoder::new(config.output.vmc.split_bundles),
            VrchatEncoder::new(map),
        )
        .context("opening the OSC output socket")?;
        Ok(Self { out })
    }

    /// Where it sends, for the start-up message.
    pub fn describe(&self) -> String {
        let names: Vec<String> = self
            .out
            .targets()
            .iter()
            .map(|t| format!("{:?} {}", t.kind, t.addr).to_lowercase())
            .collect();
        if names.is_empty() {
            "no OSC targets".into()
        } else {
            names.join(", ")
        }
    }
}

impl FrameSink for OscSink {
    fn send_frame(&mut self, frame: &BodyFrame) {
        self.out.send_frame(frame);
    }
    fn send_event(&mut self, event: &AnalysisEvent) {
        self.out.send_event(event);
    }
    fn packets_sent(&self) -> u64 {
        self.out.packets_sent()
    }
    fn prepare(&mut self, frame: &BodyFrame) {
        self.out.prepare(frame);
    }
    fn losses(&self) -> SinkLosses {
        let c = self.out.counters();
        SinkLosses {
            send_errors: c.send_errors,
            non_finite_replaced: c.non_finite_replaced + c.clamped_values,
            vrchat_missing_bones: c.vrchat_missing_bones,
        }
    }
}

impl PoseBank for crate::pose_bank::PoseBank {
    fn get(&self, name: &str) -> Option<[Quat; JOINT_COUNT]> {
        crate::pose_bank::PoseBank::get(self, name).map(|p| p.rotations)
    }
    fn names(&self) -> Vec<String> {
        self.poses().iter().map(|p| p.name.clone()).collect()
    }
}

/// Counters of the control inputs, shared with the stats.
#[derive(Debug, Default)]
pub struct ControlCounters {
    /// OSC control events accepted.
    pub osc_accepted: AtomicU64,
    /// OSC packets or messages ignored (malformed, unknown address, bad arguments).
    pub osc_ignored: AtomicU64,
    /// OSC datagrams from sources outside `control.allow`, dropped unread.
    pub osc_refused_sources: AtomicU64,
    /// MIDI messages turned into control events.
    pub midi_events: AtomicU64,
    /// MIDI bytes dropped by the parser (running status gone wrong, truncated messages).
    pub midi_dropped: AtomicU64,
    /// MIDI messages midir delivered that were too long to read (system exclusive).
    pub midi_skipped: AtomicU64,
    /// MIDI messages lost because the queue from midir's thread was full.
    pub midi_queue_full: AtomicU64,
}

/// The running control inputs; dropping them does not stop them, [`ControlInputs::join`] does.
pub struct ControlInputs {
    threads: Vec<JoinHandle<()>>,
    /// Their counters.
    pub counters: Arc<ControlCounters>,
    /// Address the OSC control receiver listens on, if any.
    pub osc_addr: Option<SocketAddr>,
    /// The MIDI port connected, if any.
    pub midi_port: Option<String>,
}

impl ControlInputs {
    /// Starts the OSC control receiver (`control.osc_port`, 0 = off) and the MIDI input
    /// (`control.midi_port`), each with its own sender from `hub`, until `stop` is set.
    /// MIDI clock and transport go to `desk` as well.
    pub fn start(
        config: &Config,
        hub: &mut ControlHub,
        desk: &ClockDesk,
        stop: Arc<AtomicBool>,
    ) -> Result<Self> {
        let counters = Arc::new(ControlCounters::default());
        let mut inputs = ControlInputs {
            threads: Vec::new(),
            counters: counters.clone(),
            osc_addr: None,
            midi_port: None,
        };
        if config.control.osc_port != 0 {
            let addr: SocketAddr = format!("{}:{}", config.control.bind, config.control.osc_port)
                .parse()
                .with_context(|| {
                    format!(
                        "control.bind {:?} with port {} is not a socket address",
                        config.control.bind, config.control.osc_port
                    )
                })?;
            let mut receiver = ControlReceiver::bind(addr, ControlParser::default())
                .with_context(|| format!("listening for OSC control on {addr}"))?;
            inputs.osc_addr = receiver.local_addr().ok();
            receiver.set_allowed_sources(config.control.allow.clone());
            if !addr.ip().is_loopback() {
                if config.control.allow.is_empty() {
                    tracing::warn!(
                        "OSC control listens on {addr}, beyond this machine: anyone on the \
                         network can steer the dancer (control.allow lists the controllers)"
                    );
                } else {
                    tracing::warn!(
                        "OSC control listens on {addr}, beyond this machine, for {:?} only",
                        config.control.allow
                    );
                }
            }
            let (mut tx, stop, counters) = (hub.sender(), stop.clone(), counters.clone());
            inputs.threads.push(
                std::thread::Builder::new()
                    .name("osc-control".into())
                    .spawn(move || {
                        let mut events = Vec::with_capacity(64);
                        while !stop.load(Ordering::Relaxed) {
                            events.clear();
                            if receiver.poll(&mut events) == 0 {
                                // Non-blocking socket: 1 ms naps keep control latency ≤ 1 ms at
                                // ~0 CPU.
                                std::thread::sleep(Duration::from_millis(1));
                            }
                            for e in events.drain(..) {
                                // Refusals are counted by the sender.
                                let _ = tx.send(e);
                            }
                            let p = receiver.parser();
                            counters.osc_accepted.store(p.accepted(), Ordering::Relaxed);
                            counters.osc_ignored.store(p.ignored(), Ordering::Relaxed);
                            counters
                                .osc_refused_sources
                                .store(receiver.refused_sources(), Ordering::Relaxed);
                        }
                    })?,
            );
        }
        if let Some(port) = &config.control.midi_port {
            let map = match &config.control.midi_map {
                Some(p) => {
                    MidiMap::load(p).with_context(|| format!("control.midi_map {}", p.display()))?
                }
                None => {
                    MidiMap::from_toml_str(GENERIC_MIDI_MAP).context("the built-in MIDI map")?
                }
            };
            let (raw_tx, raw_rx) = crossbeam_channel::bounded(1024);
            let connection = MidiInputs::connect(port, raw_tx)
                .with_context(|| format!("opening MIDI input {port:?}"))?;
            inputs.midi_port = Some(connection.port_name().to_string());
            let (mut tx, stop, counters) = (hub.sender(), stop, counters);
            let desk = desk.clone();
            let beats_per_bar = config.clock.beats_per_bar;
            inputs.threads.push(
                std::thread::Builder::new()
                    .name("midi-control".into())
                    .spawn(move || {
                        // The connection lives as long as this thread: dropping it closes the port.
                        let connection = connection;
                        let mut map = map;
                        let mut parser = MidiParser::default();
                        let mut events = Vec::with_capacity(16);
                        let mut clock = MidiClockInput::new(beats_per_bar);
                        while !stop.load(Ordering::Relaxed) {
                            let Ok(packet) = raw_rx.recv_timeout(Duration::from_millis(50)) else {
                                clock.idle(&map, &desk);
                                continue;
                            };
                            events.clear();
                            map.map_packet(&mut parser, &packet, &mut events);
                            clock.packet(&map, packet.1[0], packet.0, &desk);
                            counters
                                .midi_events
                                .fetch_add(events.len() as u64, Ordering::Relaxed);
                            counters
                                .midi_dropped
                                .store(parser.dropped(), Ordering::Relaxed);
                            counters
                                .midi_skipped
                                .store(connection.skipped(), Ordering::Relaxed);
                            counters
                                .midi_queue_full
                                .store(connection.dropped(), Ordering::Relaxed);
                            for e in events.drain(..) {
                                let _ = tx.send(e);
                            }
                        }
                    })?,
            );
        }
        Ok(inputs)
    }

    /// Waits for the input threads (after the stop flag is set).
    pub fn join(self) {
        for t in self.threads {
            let _ = t.join();
        }
    }
}

/// The generic MIDI map, used when `control.midi_port` is set without `control.midi_map`.
pub const GENERIC_MIDI_MAP: &str = include_str!("../../../configs/midi/generic.toml");
