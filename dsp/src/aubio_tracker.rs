//! aubio's tempo and onset objects as a second, selectable tracker (GPL-3.0, feature `aubio`).
//!
//! Time convention: every position below is a sample index in the mono [`ANALYSIS_RATE`] stream
//! fed to [`AubioTracker::process`] (sample 0 = first sample fed). The analyzer turns a
//! `frames_ago` into a time as `hop_time - frames_ago / hop_rate + EVENT_TIME_OFFSET_S`, where
//! `hop_time` is the centre of the short window, `SHORT_WINDOW / 2` samples before the end of the
//! current hop. So `frames_ago = (reference - event) / HOP` with
//! `reference = hop_end - SHORT_WINDOW / 2 + EVENT_TIME_OFFSET_S · rate`; counting from the hop's
//! end alone would put every aubio event ~35 ms late. aubio stamps beats within the hop that
//! reports them, mostly after that reference, so a beat's `frames_ago` is about −3…+1 (usually
//! negative); an onset's is about +3…+4 because aubio reports it 4–5 hops after the attack.

use aubio::{Onset, OnsetMode, Tempo};

use crate::tracker::{EVENT_TIME_OFFSET_S, TrackerOutput};
use crate::{ANALYSIS_RATE, DspError, HOP, SHORT_WINDOW};

/// FFT size of both aubio objects: the native short window, so both trackers see 46 ms frames.
const BUF_SIZE: usize = 1024;
/// Mean square below which a hop counts as silent: aubio's own −90 dB tempo silence gate.
const SILENCE_POWER: f32 = 1e-9;
/// Input clamp: far above any real signal, low enough that aubio's f32 sums of squares stay finite.
const MAX_SAMPLE: f32 = 16.0;
/// A beat keeps the tracker locked (and audio keeps beats valid) for this many periods.
const LOCK_PERIODS: f64 = 2.0;
/// Added to aubio's beat period, in hops. For lag `i` aubio's comb filterbank sums
/// `acf[a·i ..= a·i + 2a − 2]`, windows centred `a − 1` lags past the harmonic `a·i`, which pulls
/// the peak to shorter lags: the period comes out 0.54–0.66 hops short at every tempo measured
/// (70–175 BPM click tracks), 1.7 % fast at 120 BPM.
const PERIOD_BIAS_HOPS: f64 = 0.6;
/// Share of the gap between aubio's beat and the predicted one that a beat moves the grid by.
/// aubio re-estimates its phase every 1.5 s and jumps by up to ±60 ms doing so (raw spacing off
/// by up to 10 % at 128–140 BPM); 0.2 keeps the spacing within ~1 % yet follows a phase change
/// in a few beats.
const PHASE_GAIN: f64 = 0.2;
/// Where a beat really lies after the sample aubio stamps it with, in seconds (measured on click
/// tracks in the tests, 70–140 BPM; aubio anticipates beats slightly).
const BEAT_LAG_S: f64 = 0.010;
/// Same for onsets (HFC), after aubio has removed its own 4.3-hop onset delay.
const ONSET_LAG_S: f64 = 0.004;

/// aubio's beat tracker and onset detector, stepped one analysis hop at a time.
pub struct AubioTracker {
    tempo: Tempo,
    onset: Onset,
    /// The current hop, sanitised: aubio reads exactly `HOP` samples and keeps a NaN forever.
    buf: [f32; HOP],
    /// Samples fed so far, including the current hop.
    samples: u64,
    /// aubio's last beat stamp as last seen; a change is how beats are detected (see `process`).
    last_stamp: u32,
    /// Position of the last beat passed on (on the smoothed grid).
    last_beat: Option<f64>,
    /// End of the last hop above the silence gate.
    last_audible: Option<u64>,
}

// SAFETY: the aubio objects exclusively own their heap state (no globals, no thread-locals, no
// shared references; the builtin library uses the Ooura FFT with per-object tables), so moving
// them to another thread is sound. They are not `Sync`, and this type does not claim to be.
unsafe impl Send for AubioTracker {}

impl AubioTracker {
    /// Builds aubio's tempo ("default" = spectral flux) and onset ("default" = HFC) objects.
    pub fn new() -> Result<Self, DspError> {
        // The Rust binding has no "default" mode; these are what aubio maps "default" to.
        let tempo = Tempo::new(OnsetMode::SpecFlux, BUF_SIZE, HOP, ANALYSIS_RATE)
            .map_err(|e| DspError::Aubio(format!("tempo object: {e}")))?;
        let mut onset = Onset::new(OnsetMode::Hfc, BUF_SIZE, HOP, ANALYSIS_RATE)
            .map_err(|e| DspError::Aubio(format!("onset object: {e}")))?;
        // aubio drops an onset when the hop that reports it (4–5 hops after the attack) is below
        // −70 dB, which loses every hit followed by digital silence; `process` gates instead on
        // audio after the onset's own time. −∞: aubio's level of a silent hop is −∞, and −∞ < −∞
        // is false.
        onset.set_silence(f32::NEG_INFINITY);
        Ok(Self {
            tempo,
            onset,
            buf: [0.0; HOP],
            samples: 0,
            last_stamp: 0,
            last_beat: None,
            last_audible: None,
        })
    }

    /// Feeds one hop of [`HOP`] mono samples at [`ANALYSIS_RATE`]; other lengths are zero-padded
    /// or truncated so the stream's clock stays one hop per call.
    pub(crate) fn process(&mut self, hop: &[f32]) -> TrackerOutput {
        let n = hop.len().min(HOP);
        for (d, &s) in self.buf.iter_mut().zip(&hop[..n]) {
            *d = if s.is_finite() {
                s.clamp(-MAX_SAMPLE, MAX_SAMPLE)
            } else {
                0.0
            };
        }
        self.buf[n..].fill(0.0);
        let hop_start = self.samples;
        self.samples += HOP as u64;
        let power = self.buf.iter().map(|x| x * x).sum::<f32>() / HOP as f32;
        if power > SILENCE_POWER {
            self.last_audible = Some(self.samples);
        }
        let rate = f64::from(ANALYSIS_RATE);
        let reference =
            self.samples as f64 - (SHORT_WINDOW / 2) as f64 + EVENT_TIME_OFFSET_S * rate;
        // aubio keeps its clock in a u32 of samples that wraps (after 54 h); so does this cast.
        let hop_start32 = hop_start as u32;

        // A slice, never the array by value: the binding's `From<T: AsRef<[f32]>>` takes `T` by
        // value and keeps a pointer into it, which would dangle for an owned array.
        let tempo_ok = self.tempo.do_result(self.buf.as_slice()).is_ok();
        let aubio_period = f64::from(self.tempo.get_period_s()) * rate;
        let period = if aubio_period.is_finite() && aubio_period > 0.0 {
            aubio_period + PERIOD_BIAS_HOPS * HOP as f64
        } else {
            0.0
        };

        // `do_result` is useless for beats: aubio zeroes it on hops below −90 dB (the hop a
        // predicted beat falls on is often silent between clicks), and when it does report one
        // the value is only the fractional hop. `get_last` is set on every predicted beat, with
        // the beat's sample position, so a change in it is the reliable signal.
        let mut beat = None;
        let stamp = self.tempo.get_last() as u32;
        if tempo_ok && stamp != self.last_stamp {
            self.last_stamp = stamp;
            // aubio stamps a beat within the hop that predicts it: 0..=HOP samples past its start.
            let within = stamp.wrapping_sub(hop_start32);
            // aubio keeps predicting beats from its 6 s window after the music stops.
            let audible = self
                .last_audible
                .is_some_and(|a| (self.samples - a) as f64 <= LOCK_PERIODS * period);
            if period > 0.0 && within as usize <= HOP && audible {
                let heard = hop_start as f64 + f64::from(within) + BEAT_LAG_S * rate;
                let pos = match self.last_beat {
                    Some(prev) if heard - prev < LOCK_PERIODS * period => {
                        let beats = ((heard - prev) / period).round();
                        // Within half a period of the last beat: aubio moved its phase back, not
                        // a new beat.
                        (beats >= 1.0).then(|| {
                            let predicted = prev + beats * period;
                            predicted + PHASE_GAIN * (heard - predicted)
                        })
                    }
                    _ => Some(heard),
                };
                if let Some(pos) = pos {
                    self.last_beat = Some(pos);
                    beat = Some((reference - pos) / HOP as f64);
                }
            }
        }

        let onset = match self.onset.do_result(self.buf.as_slice()) {
            Ok(v) if v > 0.0 => {
                // Signed: aubio's onset stamp has its 4.3-hop delay removed, so it lies before
                // this hop's start.
                let rel = (self.onset.get_last() as u32).wrapping_sub(hop_start32) as i32;
                let pos = hop_start as f64 + f64::from(rel) + ONSET_LAG_S * rate;
                // Replaces aubio's silence gate (see `new`): something must be heard after it.
                self.last_audible
                    .is_some_and(|a| a as f64 > pos)
                    .then(|| (reference - pos) / HOP as f64)
            }
            _ => None,
        };

        let since = self.last_beat.map(|b| reference - b);
        let locked = period > 0.0 && since.is_some_and(|s| s <= LOCK_PERIODS * period);
        let (beat_phase, frames_to_next_beat) = match since {
            Some(s) if period > 0.0 => {
                let into = s.rem_euclid(period);
                (into / period, (period - into) / HOP as f64)
            }
            _ => (0.0, 0.0),
        };
        // A peak-to-sum ratio of aubio's comb output, not a probability: ~0.1 on white noise,
        // 3–200 on click tracks. Clamped, it reads as "no evidence" … "clear beat".
        let confidence = f64::from(self.tempo.get_confidence());
        TrackerOutput {
            onset,
            beat,
            tempo_bpm: if locked { 60.0 * rate / period } else { 0.0 },
            tempo_confidence: if locked && confidence.is_finite() {
                confidence.clamp(0.0, 1.0)
            } else {
                0.0
            },
            beat_phase,
            frames_to_next_beat,
            locked,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hop_rate;

    const RATE: f64 = ANALYSIS_RATE as f64;

    /// Click shapes: one 5 ms white-noise burst, or a 1 kHz blip decaying with τ = 5 ms.
    #[derive(Clone, Copy, Debug)]
    enum Click {
        Noise,
        Blip,
    }

    /// Clicks at `bpm` from `first_s` on, at `rate`; returns the signal and the click times.
    fn click_track(
        rate: f64,
        shape: Click,
        bpm: f64,
        secs: f64,
        first_s: f64,
    ) -> (Vec<f32>, Vec<f64>) {
        let mut x = vec![0.0f32; (secs * rate) as usize];
        let mut clicks = Vec::new();
        let mut seed = 0x2545_f491_u32;
        let mut t = first_s;
        while t < secs - 0.05 {
            let start = (t * rate).round() as usize;
            clicks.push(start as f64 / rate);
            let len = match shape {
                Click::Noise => 0.005 * rate,
                Click::Blip => 0.03 * rate,
            } as usize;
            for (k, s) in x[start..start + len].iter_mut().enumerate() {
                let tt = k as f64 / rate;
                *s = match shape {
                    Click::Noise => {
                        seed ^= seed << 13;
                        seed ^= seed >> 17;
                        seed ^= seed << 5;
                        0.5 * (seed as f32 / u32::MAX as f32 * 2.0 - 1.0)
                    }
                    Click::Blip => {
                        (0.8 * (std::f64::consts::TAU * 1000.0 * tt).sin() * (-tt / 0.005).exp())
                            as f32
                    }
                };
            }
            t += 60.0 / bpm;
        }
        (x, clicks)
    }

    /// Events and the last output of a hop-by-hop run.
    struct Run {
        beats: Vec<f64>,
        onsets: Vec<f64>,
        outputs: Vec<TrackerOutput>,
    }

    /// Feeds `x` hop by hop and turns events into times exactly as the analyzer does.
    fn run(tr: &mut AubioTracker, x: &[f32]) -> Run {
        let mut r = Run {
            beats: Vec::new(),
            onsets: Vec::new(),
            outputs: Vec::new(),
        };
        let fed_before = tr.samples;
        for (i, hop) in x.chunks_exact(HOP).enumerate() {
            let out = tr.process(hop);
            let end = fed_before + ((i + 1) * HOP) as u64;
            let hop_time = (end as f64 - (SHORT_WINDOW / 2) as f64) / RATE;
            let at = |ago: f64| hop_time - ago / hop_rate() + EVENT_TIME_OFFSET_S;
            r.beats.extend(out.beat.map(at));
            r.onsets.extend(out.onset.map(at));
            r.outputs.push(out);
        }
        r
    }

    fn all_finite(outs: &[TrackerOutput]) -> bool {
        outs.iter().all(|o| {
            [
                o.tempo_bpm,
                o.tempo_confidence,
                o.beat_phase,
                o.frames_to_next_beat,
            ]
            .into_iter()
            .chain(o.beat)
            .chain(o.onset)
            .all(f64::is_finite)
        })
    }

    fn nearest(t: f64, clicks: &[f64]) -> f64 {
        clicks
            .iter()
            .map(|c| t - c)
            .min_by(|a, b| a.abs().total_cmp(&b.abs()))
            .unwrap_or(f64::NAN)
    }

    #[test]
    fn aubio_click_track_gives_steady_beats_at_120_bpm() {
        for shape in [Click::Noise, Click::Blip] {
            let (x, clicks) = click_track(RATE, shape, 120.0, 20.0, 0.25);
            let r = run(&mut AubioTracker::new().unwrap(), &x);
            assert!(all_finite(&r.outputs), "{shape:?}");

            let late: Vec<f64> = r.beats.iter().copied().filter(|&t| t > 5.0).collect();
            assert!(
                late.len() >= 28,
                "{shape:?}: only {} beats after 5 s",
                late.len()
            );
            for w in late.windows(2) {
                let gap = w[1] - w[0];
                assert!(
                    (gap / 0.5 - 1.0).abs() < 0.03,
                    "{shape:?}: beats {:.3} → {:.3} s",
                    w[0],
                    w[1]
                );
            }
            // The time convention: beats land on the clicks, not a window or a hop away.
            let errs: Vec<f64> = late.iter().map(|&t| nearest(t, &clicks)).collect();
            let mean_abs = errs.iter().map(|e| e.abs()).sum::<f64>() / errs.len() as f64;
            assert!(
                mean_abs < 0.02,
                "{shape:?}: beats {mean_abs:.4} s off the clicks on average"
            );

            let hops_5s = (5.0 * hop_rate()) as usize;
            for o in &r.outputs[hops_5s..] {
                assert!(o.locked, "{shape:?}: lost the beat");
                assert!(
                    (o.tempo_bpm / 120.0 - 1.0).abs() < 0.03,
                    "{shape:?}: {} BPM",
                    o.tempo_bpm
                );
                assert!(
                    (0.0..1.0).contains(&o.beat_phase) && (0.0..=1.0).contains(&o.tempo_confidence)
                );
                assert!(
                    o.frames_to_next_beat > 0.0
                        && o.frames_to_next_beat <= 0.5 * hop_rate() * 1.03 + 1e-9
                );
            }

            let heard = clicks
                .iter()
                .filter(|&&c| r.onsets.iter().any(|&o| (o - c).abs() < 0.015))
                .count();
            assert!(
                heard * 10 >= clicks.len() * 9,
                "{shape:?}: onsets at {heard} of {} clicks",
                clicks.len()
            );
            assert!(
                r.onsets.len() <= clicks.len() + 1,
                "{shape:?}: {} onsets",
                r.onsets.len()
            );
        }
    }

    #[test]
    fn aubio_digital_silence_gives_no_beats_and_no_nan() {
        let r = run(
            &mut AubioTracker::new().unwrap(),
            &vec![0.0; 20 * ANALYSIS_RATE as usize],
        );
        assert!(
            r.beats.is_empty(),
            "beats in silence: {:?}",
            &r.beats[..r.beats.len().min(5)]
        );
        assert!(r.onsets.is_empty(), "onsets in silence: {:?}", r.onsets);
        assert!(all_finite(&r.outputs));
        assert!(r.outputs.iter().all(|o| !o.locked && o.tempo_bpm == 0.0));
    }

    #[test]
    fn aubio_stops_beating_when_the_music_stops() {
        let (mut x, _) = click_track(RATE, Click::Noise, 120.0, 10.0, 0.25);
        x.resize(20 * ANALYSIS_RATE as usize, 0.0);
        let r = run(&mut AubioTracker::new().unwrap(), &x);
        assert!(
            r.beats.iter().all(|&t| t < 11.5),
            "beats long after the music: {:?}",
            r.beats
        );
        assert!(!r.outputs.last().unwrap().locked);
        assert!(all_finite(&r.outputs));
    }

    #[test]
    fn aubio_survives_garbage_hops() {
        let mut tr = AubioTracker::new().unwrap();
        let garbage: [&[f32]; 6] = [
            &[f32::NAN; HOP],
            &[f32::INFINITY; HOP],
            &[1e30; HOP],
            &[0.5; 10],
            &[],
            &[0.1; 3 * HOP],
        ];
        let outs: Vec<TrackerOutput> = garbage.iter().map(|h| tr.process(h)).collect();
        assert!(all_finite(&outs));
        // The garbage must not poison aubio's state: a click track afterwards still locks.
        let (x, _) = click_track(RATE, Click::Noise, 120.0, 12.0, 0.25);
        let r = run(&mut tr, &x);
        assert!(all_finite(&r.outputs));
        assert!(r.outputs.last().unwrap().locked);
        assert!((r.outputs.last().unwrap().tempo_bpm / 120.0 - 1.0).abs() < 0.03);
    }

    /// The convention end to end: the analyzer's beat times equal this module's own reading
    /// of `frames_ago`, and with a resampler in the way they still land on the clicks.
    #[test]
    fn aubio_beats_through_the_analyzer_land_on_the_clicks() {
        use crate::{AnalysisSink, Analyzer, AnalyzerConfig, BeatEvent, BeatTrackerKind};
        struct Beats(Vec<f64>);
        impl AnalysisSink for Beats {
            fn beat(&mut self, b: &BeatEvent) {
                self.0.push(b.time_s);
            }
        }
        let analyse = |rate: u32, x: &[f32]| {
            let mut a = Analyzer::new(AnalyzerConfig {
                sample_rate: rate,
                channels: 1,
                model_rate: None,
                tracker: BeatTrackerKind::Aubio,
                beat_params: Default::default(),
                bar_params: Default::default(),
                networks: Default::default(),
            })
            .unwrap();
            let mut beats = Beats(Vec::new());
            for block in x.chunks(1000) {
                a.process(block, &mut beats);
            }
            beats.0
        };

        let (x, _) = click_track(RATE, Click::Blip, 120.0, 15.0, 0.4);
        let direct = run(&mut AubioTracker::new().unwrap(), &x).beats;
        let via = analyse(ANALYSIS_RATE, &x);
        assert_eq!(direct.len(), via.len());
        assert!(
            direct.iter().zip(&via).all(|(d, v)| (d - v).abs() < 1e-9),
            "{direct:?} vs {via:?}"
        );

        let (x, clicks) = click_track(44_100.0, Click::Blip, 120.0, 15.0, 0.4);
        let errs: Vec<f64> = analyse(44_100, &x)
            .iter()
            .filter(|&&t| t > 5.0)
            .map(|&t| nearest(t, &clicks))
            .collect();
        assert!(errs.len() >= 18, "{} beats", errs.len());
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        assert!(mean.abs() < 0.02, "beats {mean:+.4} s off the clicks");
    }
}
