//! Where the pipeline's output goes: a [`FrameSink`] (OSC senders at merge; a channel in tests).

use std::collections::HashMap;

use crossbeam_channel::Sender;
use glam::Quat;
use model::rig::JOINT_COUNT;

use super::wire::{AnalysisEvent, BodyFrame};

/// Receives every pose frame and analysis event the pipeline produces, on the sending thread.
pub trait FrameSink: Send {
    /// Sends one pose frame.
    fn send_frame(&mut self, frame: &BodyFrame);
    /// Sends one analysis event.
    fn send_event(&mut self, event: &AnalysisEvent);
    /// Packets put on the wire so far.
    fn packets_sent(&self) -> u64;
    /// Grows the sink's buffers to their working size with a representative frame, sending
    /// nothing (called at set-up, so the real-time loop never allocates).
    fn prepare(&mut self, _frame: &BodyFrame) {}
    /// What the sink lost or repaired so far (all zero for sinks that cannot lose anything).
    fn losses(&self) -> SinkLosses {
        SinkLosses::default()
    }
}

/// What a sink lost or repaired, as counted by its encoders and sockets.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SinkLosses {
    /// Datagrams the operating system refused.
    pub send_errors: u64,
    /// Non-finite values replaced (and out-of-range integers clamped) before sending.
    pub non_finite_replaced: u64,
    /// VRChat trackers skipped because their bone was missing from the frame.
    pub vrchat_missing_bones: u64,
}

/// Discards everything but counts what it was given (one "packet" per frame or event).
#[derive(Debug, Default)]
pub struct NullSink {
    packets: u64,
}

impl FrameSink for NullSink {
    fn send_frame(&mut self, _frame: &BodyFrame) {
        self.packets += 1;
    }
    fn send_event(&mut self, _event: &AnalysisEvent) {
        self.packets += 1;
    }
    fn packets_sent(&self) -> u64 {
        self.packets
    }
}

/// What a [`ChannelSink`] forwards.
#[derive(Clone, Debug, PartialEq)]
pub enum SinkItem {
    /// A pose frame, with the wall instant it was handed to the sink.
    Frame(BodyFrame, std::time::Instant),
    /// An analysis event.
    Event(AnalysisEvent),
}

/// Forwards clones of everything into a crossbeam channel (in-process consumers and tests).
#[derive(Debug)]
pub struct ChannelSink {
    tx: Sender<SinkItem>,
    packets: u64,
}

impl ChannelSink {
    /// A sink sending into `tx`; a disconnected receiver is ignored.
    pub fn new(tx: Sender<SinkItem>) -> Self {
        Self { tx, packets: 0 }
    }
}

impl FrameSink for ChannelSink {
    fn send_frame(&mut self, frame: &BodyFrame) {
        if self
            .tx
            .try_send(SinkItem::Frame(frame.clone(), std::time::Instant::now()))
            .is_ok()
        {
            self.packets += 1;
        }
    }
    fn send_event(&mut self, event: &AnalysisEvent) {
        if self.tx.try_send(SinkItem::Event(*event)).is_ok() {
            self.packets += 1;
        }
    }
    fn packets_sent(&self) -> u64 {
        self.packets
    }
}

/// Key poses by name (a file or a performer's library at merge).
pub trait PoseBank {
    /// The local rotation of every joint of the pose called `name`, if known.
    fn get(&self, name: &str) -> Option<[Quat; JOINT_COUNT]>;
    /// Every pose name (read once, when a run is set up).
    fn names(&self) -> Vec<String>;
}

/// A pose bank held in memory (tests, built-in poses).
#[derive(Clone, Debug, Default)]
pub struct MemoryPoseBank {
    poses: HashMap<String, [Quat; JOINT_COUNT]>,
}

impl MemoryPoseBank {
    /// An empty bank.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds (or replaces) a pose.
    pub fn insert(&mut self, name: impl Into<String>, rotations: [Quat; JOINT_COUNT]) {
        self.poses.insert(name.into(), rotations);
    }

    /// A bank with the built-in poses: `tpose` (every joint at rest) and `arms_up`.
    pub fn builtin() -> Self {
        let mut bank = Self::new();
        bank.insert("tpose", [Quat::IDENTITY; JOINT_COUNT]);
        let mut up = [Quat::IDENTITY; JOINT_COUNT];
        up[model::rig::Joint::LeftUpperArm.index()] = Quat::from_rotation_z(1.2);
        up[model::rig::Joint::RightUpperArm.index()] = Quat::from_rotation_z(-1.2);
        bank.insert("arms_up", up);
        bank
    }
}

impl PoseBank for MemoryPoseBank {
    fn get(&self, name: &str) -> Option<[Quat; JOINT_COUNT]> {
        self.poses.get(name).copied()
    }
    fn names(&self) -> Vec<String> {
        let mut names: Vec<String> = self.poses.keys().cloned().collect();
        names.sort();
        names
    }
}
