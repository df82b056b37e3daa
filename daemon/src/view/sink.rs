//! The sender thread's end of the browser view: the newest frame goes into a triple buffer and
//! events into a wait-free queue, so a slow browser can never hold up the OSC stream.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::thread::Thread;

use crate::live::sink::FrameSink;
use crate::live::wire::{AnalysisEvent, BodyFrame};

use super::counters::ViewCounters;

/// Analysis events the sender → view queue holds (a second of beats, onsets and energy).
pub const VIEW_EVENT_QUEUE: usize = 512;

/// Copies `src` into `dst` reusing `dst`'s bone storage (no allocation once it has grown).
pub fn copy_frame(dst: &mut BodyFrame, src: &BodyFrame) {
    dst.frame_index = src.frame_index;
    dst.audio_time_s = src.audio_time_s;
    dst.timetag = src.timetag;
    dst.root_position = src.root_position;
    dst.root_rotation = src.root_rotation;
    dst.bones.clear();
    dst.bones.extend_from_slice(&src.bones);
}

/// A [`FrameSink`] feeding the view thread: it never blocks and allocates nothing per frame
/// (the triple buffer is created from a full frame, so each of its three frames already holds
/// every bone).
pub struct ViewSink {
    frames: triple_buffer::Input<BodyFrame>,
    events: rtrb::Producer<AnalysisEvent>,
    view_thread: Thread,
    counters: Arc<ViewCounters>,
    handed: u64,
}

impl ViewSink {
    /// A sink handing frames to `frames` and events to `events`, waking `view_thread`.
    pub fn new(
        frames: triple_buffer::Input<BodyFrame>,
        events: rtrb::Producer<AnalysisEvent>,
        view_thread: Thread,
        counters: Arc<ViewCounters>,
    ) -> Self {
        Self {
            frames,
            events,
            view_thread,
            counters,
            handed: 0,
        }
    }
}

impl FrameSink for ViewSink {
    fn send_frame(&mut self, frame: &BodyFrame) {
        copy_frame(self.frames.input_buffer_mut(), frame);
        if self.frames.publish() {
            // The view thread had not taken the previous one (it forwards at most 60 a second).
            self.counters
                .frames_replaced
                .fetch_add(1, Ordering::Relaxed);
        }
        self.handed += 1;
        self.view_thread.unpark();
    }

    fn send_event(&mut self, event: &AnalysisEvent) {
        if self.events.push(*event).is_err() {
            self.counters.events_dropped.fetch_add(1, Ordering::Relaxed);
        }
        self.handed += 1;
    }

    fn packets_sent(&self) -> u64 {
        // What reached the view's queues; what reached each browser is in the view counters.
        self.handed
    }
}

/// Two sinks side by side (the OSC targets and the view); the first one's count and losses are
/// the packets on the network, the view keeps its own counters.
pub struct SinkPair {
    first: Box<dyn FrameSink>,
    second: Box<dyn FrameSink>,
}

impl SinkPair {
    /// Sends everything to `first`, then to `second`.
    pub fn new(first: Box<dyn FrameSink>, second: Box<dyn FrameSink>) -> Self {
        Self { first, second }
    }
}

impl FrameSink for SinkPair {
    fn send_frame(&mut self, frame: &BodyFrame) {
        self.first.send_frame(frame);
        self.second.send_frame(frame);
    }
    fn send_event(&mut self, event: &AnalysisEvent) {
        self.first.send_event(event);
        self.second.send_event(event);
    }
    fn packets_sent(&self) -> u64 {
        self.first.packets_sent()
    }
    fn prepare(&mut self, frame: &BodyFrame) {
        self.first.prepare(frame);
        self.second.prepare(frame);
    }
    fn losses(&self) -> crate::live::sink::SinkLosses {
        self.first.losses()
    }
}
