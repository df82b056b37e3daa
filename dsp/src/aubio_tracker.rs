//! aubio's tempo and onset objects as a second, selectable tracker (GPL-3.0, feature `aubio`).
//!
//! Time convention: every position below is a sample index in the mono [`ANALYSIS_RATE`] stream
//! fed to [`AubioTracker::process`] (sample 0 = first sample fed). The analyzer turns a
//! `frames_ago` into a time as `hop_time - frames_ago / hop_rate + EVENT_TIME_OFFSET_S`, where
//! `hop_time` is the centre of the short window, `SHORT_WINDOW / 2` samples before the end of the
//! current hop. So `frames_ago = (reference - event) / HOP` with
//! `reference = hop_end - SHORT_WINDOW / 2 + EVENT_TIME_OFFSET_S · rate`; counting from the hop's
//! end alone would put every aubio event ~35 ms late. aubio stamps beats within the hop that
//! reports them, after that reference, so a beat's `frames_ago` is about −1…−3 (negative);
//! onsets come out ~+2.5 because aubio reports them 4–5 hops after the attack.

use aubio::{Onset, OnsetMode, Tempo};

use crate::analyzer::{EVENT_TIME_OFFSET_S, TrackerOutput};
use crate::{ANALYSIS_RATE, DspError, HOP, SHORT_WINDOW};

/// FFT size of both aubio objects: the native short window, so both trackers see 46 ms frames.
const BUF_SIZE: usize = 1024;
/// Mean square below which a hop counts as silent: aubio's own −90 dB tempo silence gate.
const SILENCE_POWER: f32 = 1e-9;
/// Input clamp: far above any real signal, low enough that aubio's f32 sums of squares stay finite.
const MAX_SAMPLE: f32 = 16.0;
/// A beat keeps the tracker locked (and audio keeps beats valid) for this many periods.
const LOCK_PERIODS: f64 = 2.0;
/// Added to aubio's beat period, in hops. aubio's comb filterbank sums `acf[a·i .. a·i + 2a − 2]`
/// for lag `i`, a window centred one lag too late, so its period comes out 0.54–0.66 hops short
/// at every tempo measured (70–175 BPM click tracks): 1.7 % fast at 120 BPM.
const PERIOD_BIAS_HOPS: f64 = 0.6;
/// Share of the gap between aubio's beat and the predicted one that a beat moves the grid by.
/// aubio re-estimates its phase every 1.5 s and jumps by up to ±60 ms doing so (raw spacing off
/// by up to 10 % at 128–140 BPM); 0.2 keeps the spacing within ~1 % yet follows a phase change
/// in a few beats.
const PHASE_GAIN: f64 = 0.2;
/// Where a beat really lies after the sample aubio stamps it with, in seconds (measured on click
/// tracks in the tests, 70–140 BPM; aubio anticipates beats slightly).
const BEAT_LAG_S: f64 = 0.010;
/// Same for onsets, after aubio has already removed its own 4.3-hop onset delay.
const ONSET_LAG_S: f64 = 0.0;

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

        let tempo_ok = self.tempo.do_result(&self.buf).is_ok();
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

        let onset = match self.onset.do_result(&self.buf) {
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

    /// 5 ms noise bursts at `bpm`, the first at `first_s`.
    fn click_track(bpm: f64, secs: f64, first_s: f64) -> (Vec<f32>, Vec<f64>) {
        let len = (secs * RATE) as usize;
        let mut x = vec![0.0f32; len];
        let mut clicks = Vec::new();
        let mut seed = 0x2545_f491_u32;
        let mut t = first_s;
        while t < secs {
            let start = (t * RATE).round() as usize;
            clicks.push(start as f64 / RATE);
            for s in x.iter_mut().skip(start).take((0.005 * RATE) as usize) {
                seed ^= seed << 13;
                seed ^= seed >> 17;
                seed ^= seed << 5;
                *s = 0.5 * (seed as f32 / u32::MAX as f32 * 2.0 - 1.0);
            }
            t += 60.0 / bpm;
        }
        (x, clicks)
    }

    struct Run {
        beats: Vec<f64>,
        onsets: Vec<f64>,
        last: TrackerOutput,
        finite: bool,
        conf_max: f64,
    }

    /// Feeds `x` hop by hop and converts events to times exactly as the analyzer does.
    fn run(x: &[f32]) -> Run {
        let mut tr = AubioTracker::new().unwrap();
        let mut r = Run {
            beats: Vec::new(),
            onsets: Vec::new(),
            last: TrackerOutput::default(),
            finite: true,
            conf_max: 0.0,
        };
        let mut raw_conf = Vec::new();
        for (i, hop) in x.chunks_exact(HOP).enumerate() {
            let out = tr.process(hop);
            let hop_time = (((i + 1) * HOP) as f64 - (SHORT_WINDOW / 2) as f64) / RATE;
            let at = |ago: f64| hop_time - ago / hop_rate() + EVENT_TIME_OFFSET_S;
            r.beats.extend(out.beat.map(at));
            r.onsets.extend(out.onset.map(at));
            r.finite &= [
                out.tempo_bpm,
                out.tempo_confidence,
                out.beat_phase,
                out.frames_to_next_beat,
            ]
            .iter()
            .chain(out.beat.iter())
            .chain(out.onset.iter())
            .all(|v| v.is_finite());
            r.last = out;
            raw_conf.push(tr.tempo.get_confidence() as f64);
            r.conf_max = raw_conf.iter().fold(0.0f64, |m, &c| m.max(c));
        }
        r
    }

    pub(super) fn click_track_pub(bpm: f64, secs: f64, first_s: f64) -> (Vec<f32>, Vec<f64>) {
        click_track(bpm, secs, first_s)
    }

    pub(super) fn run_pub(x: &[f32]) -> (Vec<f64>, Vec<f64>, TrackerOutput, f64) {
        let r = run(x);
        (r.beats, r.onsets, r.last, r.conf_max)
    }

    fn nearest(t: f64, clicks: &[f64]) -> f64 {
        clicks
            .iter()
            .map(|c| t - c)
            .min_by(|a, b| a.abs().total_cmp(&b.abs()))
            .unwrap_or(f64::NAN)
    }

    #[test]
    fn aubio_diag() {
        let (x, clicks) = click_track(120.0, 20.0, 0.25);
        let r = run(&x);
        for b in &r.beats {
            eprintln!("beat {b:.4} err {:+.4}", nearest(*b, &clicks));
        }
        for o in &r.onsets {
            eprintln!("onset {o:.4} err {:+.4}", nearest(*o, &clicks));
        }
        eprintln!("{:?}", r.last);
    }
}

#[cfg(test)]
mod diag2 {
    #[test]
    fn aubio_diag2() {
        use super::tests::*;
        let mut all = Vec::new();
        for bpm in [70.0, 85.0, 100.0, 110.0, 120.0, 128.0, 140.0, 160.0, 175.0] {
            for first in [0.25, 0.61] {
                let (x, clicks) = click_track_pub(bpm, 30.0, first);
                let r = run_pub(&x);
                let near = |t: f64| {
                    clicks
                        .iter()
                        .map(|c| t - c)
                        .min_by(|a, b| a.abs().total_cmp(&b.abs()))
                        .unwrap()
                };
                let errs: Vec<f64> =
                    r.0.iter()
                        .filter(|&&t| t > 10.0)
                        .map(|&t| near(t))
                        .collect();
                let oerrs: Vec<f64> = r.1.iter().map(|&t| near(t)).collect();
                let stats = |e: &[f64]| {
                    (
                        e.iter().sum::<f64>() / e.len() as f64,
                        e.iter().fold(0.0f64, |m, e| m.max(e.abs())),
                    )
                };
                let times: Vec<f64> = r.0.iter().copied().filter(|&t| t > 5.0).collect();
                let sp = times
                    .windows(2)
                    .map(|w| (w[1] - w[0]) * bpm / 60.0 - 1.0)
                    .fold(0.0f64, |m, e| m.max(e.abs()));
                let (m, mx) = stats(&errs);
                if bpm <= 140.0 {
                    all.push(m);
                }
                eprintln!(
                    "bpm {bpm} first {first}: beat err mean {m:+.4} max {mx:.4} spacing {sp:.4} n {} | onsets {} of {} err {:?} | bpm {:.2} conf {:.3}",
                    errs.len(),
                    r.1.len(),
                    clicks.len(),
                    stats(&oerrs),
                    r.2.tempo_bpm,
                    r.3
                );
            }
        }
        eprintln!(
            "mean of means 70-140: {:+.4}",
            all.iter().sum::<f64>() / all.len() as f64
        );
    }
}
