//! Bar position and meter (3/4 or 4/4), causally, one tracked beat at a time: beat-synchronous
//! features ([`crate::bar_features`]) → the downbeat network ([`crate::downbeat_net`]) → the
//! bar pointer ([`crate::bar_pointer`]), whose committed count is what every beat reports.

use crate::bar_class::{BarClass, CLASSES};
use crate::bar_features::{BarFeatures, BarHop, BeatSpanFeatures};
use crate::bar_pointer::{BarPointer, BarPointerParams};
use crate::downbeat_net::{DownbeatClassifier, DownbeatNetEnsemble};

/// Causal bar tracker driven by analysis hops and beat events. Allocates only when built.
#[derive(Clone, Debug)]
pub struct MeterTracker {
    features: BeatSpanFeatures,
    classifier: DownbeatClassifier,
    pointer: BarPointer,
    last_features: Option<BarFeatures>,
    confidence: f32,
}

impl MeterTracker {
    /// A tracker with the shipped downbeat network, for hops at `hop_rate` per second.
    pub fn new(hop_rate: f64, params: BarPointerParams) -> Self {
        Self::with_network(hop_rate, params, DownbeatNetEnsemble::builtin())
    }

    /// A tracker with these downbeat network weights.
    pub fn with_network(
        hop_rate: f64,
        params: BarPointerParams,
        ensemble: DownbeatNetEnsemble,
    ) -> Self {
        Self {
            features: BeatSpanFeatures::new(hop_rate),
            classifier: DownbeatClassifier::new(ensemble, params.tempo_jump),
            pointer: BarPointer::new(params),
            last_features: None,
            confidence: 0.0,
        }
    }

    /// Feeds one analysis hop.
    pub fn hop(&mut self, hop: &BarHop) {
        self.features.hop(hop);
    }

    /// Registers a tracked beat at `beat_time_s`, reported on the hop just fed with the tracker
    /// at `tempo_bpm`; returns its committed bar class.
    pub fn beat(&mut self, beat_time_s: f64, tempo_bpm: f64) -> BarClass {
        self.last_features = self.features.beat(beat_time_s, tempo_bpm).copied();
        let prior = *self.classifier.class_prior();
        let observation = self
            .last_features
            .as_ref()
            .map(|f| *self.classifier.push(&f.values));
        // A jump to another metrical level restarted the network's window, as at the start of
        // a song (which the network was trained on): the count's evidence goes with it.
        if observation.is_some() && self.classifier.restarted() {
            self.pointer.forget();
        }
        let (class, confidence) = self.pointer.beat(observation.as_ref().map(|q| (q, &prior)));
        self.confidence = confidence;
        CLASSES[class]
    }

    /// The features of the beat before the last reported one, completed at that report.
    pub fn last_features(&self) -> Option<&BarFeatures> {
        self.last_features.as_ref()
    }

    /// Probability the bar pointer gives the current count, in [0, 1].
    pub fn confidence(&self) -> f32 {
        self.confidence
    }
}
