//! The whole streaming analysis chain behind one `process` call per audio block.

use crate::bar_features::BarHop;
use crate::bar_pointer::BarPointerParams;
use crate::beat::{BeatTracker, BeatTrackerParams};
use crate::beat_activation::{BEAT_INPUT_DIM, BeatActivation, BeatInput, BeatNetEnsemble};
use crate::beat_counter::BeatCounter;
use crate::chroma::ChromaFilterbank;
use crate::feature::{FeatureFrame, FeatureFramer};
use crate::hop::HopFrame;
use crate::mel::{MEL_BANDS, MEL_FMAX, MEL_FMIN, MelFilterbank};
use crate::meter::MeterTracker;
use crate::onset::{OnsetDetector, OnsetPeakPicker};
use crate::resample::StreamResampler;
use crate::stft::Stft;
use crate::tracker::{EVENT_TIME_OFFSET_S, TrackerOutput};
use crate::{ANALYSIS_RATE, DspError, HOP, LONG_WINDOW, SHORT_WINDOW, hop_rate};

/// Which beat and onset tracker drives the events and phases.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BeatTrackerKind {
    /// The built-in beat-pointer HMM over SuperFlux onset strength.
    #[default]
    Native,
    /// aubio's tempo and onset objects (GPL-3.0; needs the `aubio` feature).
    Aubio,
}

impl BeatTrackerKind {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Native => "native",
            Self::Aubio => "aubio",
        }
    }
}

/// How to build an [`Analyzer`].
#[derive(Clone, Copy, Debug)]
pub struct AnalyzerConfig {
    /// Input sample rate in Hz.
    pub sample_rate: u32,
    /// Interleaved input channels.
    pub channels: u16,
    /// Model frame rate in Hz for [`FeatureFrame`]s (`None`: no feature frames).
    pub model_rate: Option<f64>,
    /// Beat and onset tracker.
    pub tracker: BeatTrackerKind,
    /// Tuning of the native beat tracker.
    pub beat_params: BeatTrackerParams,
    /// Tuning of the bar pointer.
    pub bar_params: BarPointerParams,
    /// The learned networks (default: the shipped ones).
    pub networks: AnalysisNetworks,
}

/// The learned networks the analysis runs: the shipped ones, unless weights trained by
/// `danced-train` replace them (to measure them before they ship).
#[derive(Clone, Copy, Debug, Default)]
pub struct AnalysisNetworks {
    /// Beat activation weights (`None`: the shipped ones).
    pub beat: Option<&'static BeatNetEnsemble>,
    /// Downbeat network weights (`None`: the shipped ones).
    pub downbeat: Option<&'static crate::DownbeatNetEnsemble>,
}

/// An onset, reported by the causal peak picker.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OnsetEvent {
    /// When the onset happened, in seconds.
    pub time_s: f64,
    /// Its onset strength.
    pub strength: f32,
    /// Stream time at which it was reported, in seconds.
    pub decided_at_s: f64,
}

/// A beat, reported by the causal beat tracker.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BeatEvent {
    /// When the beat happened, in seconds.
    pub time_s: f64,
    /// Position in the bar (1 = downbeat).
    pub beat_in_bar: usize,
    /// Beats per bar (3 or 4).
    pub beats_per_bar: usize,
    /// Probability the bar tracker gives this count, in [0, 1].
    pub bar_confidence: f32,
    /// Tempo at this beat, in BPM.
    pub tempo_bpm: f64,
    /// Stream time at which the tracker committed to it, in seconds.
    pub decided_at_s: f64,
}

/// Receives the analysis as it happens. Every method has an empty default.
pub trait AnalysisSink {
    /// One analysis hop.
    fn hop(&mut self, _hop: &HopFrame) {}
    /// An onset.
    fn onset(&mut self, _onset: &OnsetEvent) {}
    /// A beat.
    fn beat(&mut self, _beat: &BeatEvent) {}
    /// A feature frame at the model rate.
    fn feature(&mut self, _frame: &FeatureFrame) {}
}

/// Native tracker: SuperFlux peak picking and the beat-pointer HMM.
struct NativeTracker {
    picker: OnsetPeakPicker,
    input: BeatInput,
    activation: BeatActivation,
    beats: BeatTracker,
}

enum Tracker {
    Native(Box<NativeTracker>),
    #[cfg(feature = "aubio")]
    Aubio(Box<crate::aubio_tracker::AubioTracker>),
}

/// The bar pointer's tuning for `config`. aubio's tracker computes none of the band-group
/// accents or the learned activation the downbeat network was trained with, so with it the
/// network may place beats in the bar but not overrule the tracked beat's level.
fn bar_params(config: AnalyzerConfig) -> BarPointerParams {
    match config.tracker {
        BeatTrackerKind::Native => config.bar_params,
        BeatTrackerKind::Aubio => BarPointerParams {
            half_time: 0.0,
            double_time: 0.0,
            ..config.bar_params
        },
    }
}

/// Per-hop analysis state; split from the resampler so its callback can borrow it.
struct Core {
    history: Vec<f32>,
    pending: usize,
    samples_in: u64,
    delay: usize,
    hop_index: u64,
    short: Stft,
    long: Stft,
    short_mag: Vec<f32>,
    long_mag: Vec<f32>,
    power: Vec<f32>,
    mel_fb: MelFilterbank,
    mel_db: Vec<f32>,
    chroma_fb: ChromaFilterbank,
    chroma: [f32; 12],
    onsets: OnsetDetector,
    beat_input: [f32; BEAT_INPUT_DIM],
    beat_activation: f32,
    tracker: Tracker,
    meter: MeterTracker,
    counter: BeatCounter,
    framer: Option<FeatureFramer>,
}

/// The streaming analysis: feed it interleaved PCM blocks of any size; it calls the sink for
/// every hop, onset, beat and feature frame. Allocates only in [`Analyzer::new`].
pub struct Analyzer {
    resampler: StreamResampler,
    core: Core,
}

impl Analyzer {
    /// Builds the chain for the given input format.
    pub fn new(config: AnalyzerConfig) -> Result<Self, DspError> {
        let resampler = StreamResampler::new(config.sample_rate, config.channels)?;
        if let Some(r) = config.model_rate
            && !(r.is_finite() && (1.0..=hop_rate()).contains(&r))
        {
            return Err(DspError::FrameRate(r));
        }
        let fps = hop_rate();
        let tracker = match config.tracker {
            BeatTrackerKind::Native => Tracker::Native(Box::new(NativeTracker {
                picker: OnsetPeakPicker::new(fps),
                input: BeatInput::new(fps),
                activation: BeatActivation::new(
                    config
                        .networks
                        .beat
                        .cloned()
                        .unwrap_or_else(BeatNetEnsemble::builtin),
                ),
                beats: BeatTracker::with_params(fps, config.beat_params),
            })),
            #[cfg(feature = "aubio")]
            BeatTrackerKind::Aubio => {
                Tracker::Aubio(Box::new(crate::aubio_tracker::AubioTracker::new()?))
            }
            #[cfg(not(feature = "aubio"))]
            BeatTrackerKind::Aubio => return Err(DspError::TrackerUnavailable("aubio")),
        };
        let short = Stft::new(SHORT_WINDOW);
        let long = Stft::new(LONG_WINDOW);
        let core = Core {
            history: vec![0.0; LONG_WINDOW],
            pending: 0,
            samples_in: 0,
            delay: resampler.delay_samples(),
            hop_index: 0,
            short_mag: vec![0.0; short.bins()],
            long_mag: vec![0.0; long.bins()],
            power: vec![0.0; short.bins()],
            mel_fb: MelFilterbank::new(MEL_BANDS, MEL_FMIN, MEL_FMAX, SHORT_WINDOW, ANALYSIS_RATE),
            mel_db: vec![-120.0; MEL_BANDS],
            chroma_fb: ChromaFilterbank::new(LONG_WINDOW, ANALYSIS_RATE),
            chroma: [0.0; 12],
            onsets: OnsetDetector::new(SHORT_WINDOW, ANALYSIS_RATE),
            beat_input: [0.0; BEAT_INPUT_DIM],
            beat_activation: 0.0,
            tracker,
            meter: MeterTracker::with_network(
                fps,
                bar_params(config),
                config
                    .networks
                    .downbeat
                    .cloned()
                    .unwrap_or_else(crate::DownbeatNetEnsemble::builtin),
            ),
            counter: BeatCounter::default(),
            framer: config.model_rate.map(FeatureFramer::new),
            short,
            long,
        };
        Ok(Self { resampler, core })
    }

    /// Feeds one block of interleaved samples; the sink hears everything it completes.
    pub fn process(&mut self, interleaved: &[f32], sink: &mut impl AnalysisSink) {
        let core = &mut self.core;
        self.resampler
            .push(interleaved, &mut |mono, now| core.samples(mono, now, sink));
    }

    /// Latency of the short-window features: half the window plus the resampler delay, seconds.
    pub fn short_latency_s(&self) -> f64 {
        (SHORT_WINDOW / 2 + self.core.delay) as f64 / ANALYSIS_RATE as f64
    }

    /// Latency of chroma: half the long window plus the resampler delay, in seconds.
    pub fn long_latency_s(&self) -> f64 {
        (LONG_WINDOW / 2 + self.core.delay) as f64 / ANALYSIS_RATE as f64
    }

    /// Input time consumed so far, in seconds.
    pub fn stream_time_s(&self) -> f64 {
        self.resampler.consumed_frames() as f64 / self.resampler.input_rate() as f64
    }
}

impl Core {
    fn samples(&mut self, mono: &[f32], now: f64, sink: &mut impl AnalysisSink) {
        let base = LONG_WINDOW - HOP;
        for &x in mono {
            self.history[base + self.pending] = x;
            self.pending += 1;
            self.samples_in += 1;
            if self.pending == HOP {
                self.hop(now, sink);
                self.history.copy_within(HOP.., 0);
                self.pending = 0;
            }
        }
    }

    fn hop(&mut self, now: f64, sink: &mut impl AnalysisSink) {
        let sr = ANALYSIS_RATE as f64;
        let end = self.samples_in as f64 - self.delay as f64;
        let time_s = (end - (SHORT_WINDOW / 2) as f64) / sr;
        let short_frame = &self.history[LONG_WINDOW - SHORT_WINDOW..];
        self.short.magnitude(short_frame, &mut self.short_mag);
        let energy = short_frame.iter().map(|x| x * x).sum::<f32>() / SHORT_WINDOW as f32;
        let energy_db = (10.0 * (energy + 1e-12).log10()).max(-120.0);
        for (p, m) in self.power.iter_mut().zip(&self.short_mag) {
            *p = m * m;
        }
        self.mel_fb.apply(&self.power, &mut self.mel_db);
        for v in self.mel_db.iter_mut() {
            *v = (10.0 * (*v + 1e-12).log10()).max(-120.0);
        }
        if self.hop_index.is_multiple_of(2) {
            self.long.magnitude(&self.history, &mut self.long_mag);
            self.chroma_fb.apply(&self.long_mag, &mut self.chroma);
        }
        let strength = self.onsets.process(&self.short_mag);
        let bass = self.onsets.low_flux();

        let out = match &mut self.tracker {
            Tracker::Native(n) => {
                let onset = n.picker.process(strength).then_some(0.0);
                n.input.process(&self.onsets, &mut self.beat_input);
                self.beat_activation = n.activation.process(&self.beat_input);
                let st = n.beats.process(strength, bass, self.beat_activation);
                TrackerOutput {
                    onset,
                    beat: st.beat_frames_ago,
                    tempo_bpm: st.tempo_bpm,
                    tempo_confidence: st.tempo_confidence,
                    beat_phase: st.beat_phase,
                    frames_to_next_beat: st.frames_to_next_beat,
                    locked: st.locked,
                }
            }
            #[cfg(feature = "aubio")]
            Tracker::Aubio(a) => a.process(&self.history[LONG_WINDOW - HOP..]),
        };

        self.meter.hop(&BarHop {
            chroma: &self.chroma,
            bass_flux: bass,
            group_flux: &self.beat_input,
            beat_activation: self.beat_activation,
            energy_db,
        });
        let fps = hop_rate();
        if let Some(ago) = out.onset {
            let e = OnsetEvent {
                time_s: time_s - ago / fps + EVENT_TIME_OFFSET_S,
                strength,
                decided_at_s: now,
            };
            sink.onset(&e);
        }
        let tracked = out.beat.map(|ago| {
            let beat_time_s = time_s - ago / fps + EVENT_TIME_OFFSET_S;
            (beat_time_s, self.meter.beat(beat_time_s, out.tempo_bpm))
        });
        let bar_features = tracked.and(self.meter.last_features());
        let counted = self.counter.hop(
            time_s + EVENT_TIME_OFFSET_S,
            tracked,
            out.tempo_bpm,
            out.beat_phase,
            out.frames_to_next_beat,
            fps,
        );
        if let Some((beat_time_s, beat_in_bar)) = counted.beat {
            let e = BeatEvent {
                time_s: beat_time_s,
                beat_in_bar,
                beats_per_bar: counted.beats_per_bar,
                bar_confidence: self.meter.confidence(),
                tempo_bpm: counted.tempo_bpm,
                decided_at_s: now,
            };
            sink.beat(&e);
        }
        let hop = HopFrame {
            index: self.hop_index,
            time_s,
            decided_at_s: now,
            mel_db: &self.mel_db,
            energy_db,
            onset_strength: strength,
            bass_onset_strength: bass,
            beat_input: &self.beat_input,
            beat_activation: self.beat_activation,
            chroma: &self.chroma,
            tempo_bpm: counted.tempo_bpm,
            tempo_confidence: out.tempo_confidence,
            beat_phase: counted.beat_phase,
            next_beat_s: time_s + EVENT_TIME_OFFSET_S + counted.frames_to_next_beat / fps,
            bar_phase: ((counted.beat_in_bar - 1) as f64 + counted.beat_phase)
                / counted.beats_per_bar as f64,
            beat_in_bar: counted.beat_in_bar,
            beats_per_bar: counted.beats_per_bar,
            bar_confidence: self.meter.confidence(),
            bar_features,
            locked: out.locked,
        };
        sink.hop(&hop);
        if let Some(framer) = self.framer.as_mut()
            && let Some(frame) = framer.push(&hop)
        {
            sink.feature(&frame);
        }
        self.hop_index += 1;
    }
}
