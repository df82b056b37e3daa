//! Beat-synchronous evidence of where a bar begins (after Krebs, Böck, Dorfer & Widmer 2016,
//! "Downbeat tracking using beat-synchronous features"): per tracked beat, the accent on the
//! beat in each band group (a kick on 1, a snare on 2 and 4), the bass attack, the learned beat
//! activation, how much the harmony changed against the one and two beats before (chords move
//! on bar lines), the beat's loudness, and the tracked tempo.
//!
//! A beat's features are complete when the next beat is reported: the harmony of its span is
//! known only then. So [`BeatSpanFeatures::beat`] returns the features of the beat before the
//! one just reported.

use crate::onset::FLUX_GROUPS;

/// Values per beat.
pub const BAR_FEATURE_DIM: usize = FLUX_GROUPS + 6;
/// Index of the bass attack among a beat's features.
const BASS: usize = FLUX_GROUPS;
/// Index of the learned beat activation's peak.
const ACTIVATION: usize = FLUX_GROUPS + 1;
/// Index of the harmonic change against the previous beat.
const CHANGE_1: usize = FLUX_GROUPS + 2;
/// Index of the harmonic change against the beat two back.
const CHANGE_2: usize = FLUX_GROUPS + 3;
/// Index of the beat's mean level.
const LEVEL: usize = FLUX_GROUPS + 4;
/// Index of the tracked tempo, in octaves from 120 BPM: the one feature whose absolute value
/// matters (a 300 BPM count is implausible), so the network reads it as it is.
pub const TEMPO_FEATURE: usize = FLUX_GROUPS + 5;
/// Tempo octaves are clamped to ± this.
const TEMPO_OCTAVES_MAX: f32 = 2.0;
/// Hops up to and including the report that count towards a beat's accent: the beat is
/// reported a hop or two after it happens.
const ACCENT_HOPS_BEFORE: usize = 5;
/// Hops after the report that still count: a bass note's flux can peak just after it.
const ACCENT_HOPS_AFTER: u32 = 3;
/// Time constant of the bass flux average the bass attack is taken against, seconds.
const BASS_MEAN_SECONDS: f64 = 3.0;
/// Floor of that average, so silence does not turn faint noise into strong attacks.
const BASS_MEAN_FLOOR: f32 = 1e-2;
/// Level is given in units of this many dB, so one unit is an audible step.
const LEVEL_UNIT_DB: f32 = 3.0;

/// What one analysis hop contributes to the beat it belongs to.
#[derive(Clone, Copy, Debug)]
pub struct BarHop<'a> {
    /// Chroma, index 0 = C.
    pub chroma: &'a [f32; 12],
    /// Onset flux in the bass bands.
    pub bass_flux: f32,
    /// Relative onset flux per band group (the beat activation's inputs).
    pub group_flux: &'a [f32; FLUX_GROUPS],
    /// Learned beat activation in [0, 1].
    pub beat_activation: f32,
    /// RMS level, dBFS.
    pub energy_db: f32,
}

/// One tracked beat's features.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BarFeatures {
    /// When the beat happened, stream seconds.
    pub beat_time_s: f64,
    /// Its [`BAR_FEATURE_DIM`] values.
    pub values: [f32; BAR_FEATURE_DIM],
}

/// Accumulates hops into per-beat features. Allocates nothing.
#[derive(Clone, Debug)]
pub struct BeatSpanFeatures {
    /// Accent inputs of the last hops, a ring.
    recent: [[f32; ACTIVATION + 1]; ACCENT_HOPS_BEFORE],
    recent_pos: usize,
    bass_mean: f32,
    bass_alpha: f32,
    /// The beat being described: its accent so far, its time, and hops left to extend it.
    pending: [f32; BAR_FEATURE_DIM],
    pending_time_s: Option<f64>,
    hops_after: u32,
    chroma_sum: [f32; 12],
    level_sum: f32,
    span_hops: u32,
    /// Mean chroma of the spans of the last two described beats (newest first).
    previous_chroma: [[f32; 12]; 2],
    out: BarFeatures,
}

impl BeatSpanFeatures {
    /// An accumulator for hops at `hop_rate` per second.
    pub fn new(hop_rate: f64) -> Self {
        Self {
            recent: [[0.0; ACTIVATION + 1]; ACCENT_HOPS_BEFORE],
            recent_pos: 0,
            bass_mean: 0.0,
            bass_alpha: (1.0 / (BASS_MEAN_SECONDS * hop_rate)) as f32,
            pending: [0.0; BAR_FEATURE_DIM],
            pending_time_s: None,
            hops_after: 0,
            chroma_sum: [0.0; 12],
            level_sum: 0.0,
            span_hops: 0,
            previous_chroma: [[0.0; 12]; 2],
            out: BarFeatures {
                beat_time_s: 0.0,
                values: [0.0; BAR_FEATURE_DIM],
            },
        }
    }

    /// Feeds one hop.
    pub fn hop(&mut self, h: &BarHop) {
        let clean = |x: f32| if x.is_finite() { x.max(0.0) } else { 0.0 };
        let bass = clean(h.bass_flux);
        self.bass_mean += self.bass_alpha * (bass - self.bass_mean);
        let slot = &mut self.recent[self.recent_pos];
        for (s, &g) in slot.iter_mut().zip(h.group_flux) {
            *s = clean(g);
        }
        slot[BASS] = (bass / (self.bass_mean + BASS_MEAN_FLOOR)).ln_1p();
        slot[ACTIVATION] = clean(h.beat_activation);
        let accent = *slot;
        self.recent_pos = (self.recent_pos + 1) % ACCENT_HOPS_BEFORE;
        if self.hops_after > 0 {
            self.hops_after -= 1;
            for (p, a) in self.pending.iter_mut().zip(accent) {
                *p = p.max(a);
            }
        }
        for (s, &c) in self.chroma_sum.iter_mut().zip(h.chroma) {
            *s += clean(c);
        }
        self.level_sum += if h.energy_db.is_finite() {
            h.energy_db.max(-120.0)
        } else {
            -120.0
        };
        self.span_hops += 1;
    }

    /// Registers a beat at `beat_time_s`, reported on the hop just fed with the tracker at
    /// `tempo_bpm`; returns the features of the beat before it (none for the first beat of the
    /// stream).
    pub fn beat(&mut self, beat_time_s: f64, tempo_bpm: f64) -> Option<&BarFeatures> {
        let finished = self.pending_time_s.map(|time| {
            let n = self.span_hops.max(1) as f32;
            let mut chroma = [0.0f32; 12];
            for (c, s) in chroma.iter_mut().zip(&self.chroma_sum) {
                *c = s / n;
            }
            let mut v = self.pending;
            v[CHANGE_1] = cosine_distance(&chroma, &self.previous_chroma[0]);
            v[CHANGE_2] = cosine_distance(&chroma, &self.previous_chroma[1]);
            v[LEVEL] = self.level_sum / n / LEVEL_UNIT_DB;
            let octaves = (tempo_bpm.max(1.0) / 120.0).log2() as f32;
            v[TEMPO_FEATURE] = if octaves.is_finite() {
                octaves.clamp(-TEMPO_OCTAVES_MAX, TEMPO_OCTAVES_MAX)
            } else {
                0.0
            };
            self.previous_chroma[1] = self.previous_chroma[0];
            self.previous_chroma[0] = chroma;
            (time, v)
        });
        self.pending = [0.0; BAR_FEATURE_DIM];
        for hop in &self.recent {
            for (p, &a) in self.pending.iter_mut().zip(hop) {
                *p = p.max(a);
            }
        }
        self.pending_time_s = Some(beat_time_s);
        self.hops_after = ACCENT_HOPS_AFTER;
        self.chroma_sum = [0.0; 12];
        self.level_sum = 0.0;
        self.span_hops = 0;
        let (beat_time_s, values) = finished?;
        self.out = BarFeatures {
            beat_time_s,
            values,
        };
        Some(&self.out)
    }
}

/// 1 − cosine similarity; 0 when either vector is silent.
fn cosine_distance(a: &[f32; 12], b: &[f32; 12]) -> f32 {
    let dot: f32 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let na: f32 = a.iter().map(|x| x * x).sum::<f32>().sqrt();
    let nb: f32 = b.iter().map(|x| x * x).sum::<f32>().sqrt();
    if na < 1e-6 || nb < 1e-6 {
        0.0
    } else {
        1.0 - dot / (na * nb)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed(f: &mut BeatSpanFeatures, chroma: &[f32; 12], bass: f32, group0: f32) {
        let mut groups = [0.1; FLUX_GROUPS];
        groups[0] = group0;
        f.hop(&BarHop {
            chroma,
            bass_flux: bass,
            group_flux: &groups,
            beat_activation: 0.2,
            energy_db: -12.0,
        });
    }

    #[test]
    fn a_beat_is_described_when_the_next_is_reported() {
        let c = [1.0, 0., 0., 0., 1., 0., 0., 1., 0., 0., 0., 0.];
        let g = [0., 0., 1., 0., 0., 1., 0., 0., 0., 1., 0., 0.];
        let mut f = BeatSpanFeatures::new(86.0);
        for _ in 0..40 {
            feed(&mut f, &c, 0.1, 0.1);
        }
        assert!(
            f.beat(0.5, 120.0).is_none(),
            "the first beat has no predecessor"
        );
        // Beat at 0.5 s: a group-0 hit two hops after its report, then its span holds chord c.
        for i in 0..40 {
            feed(&mut f, &c, 0.1, if i == 1 { 3.0 } else { 0.1 });
        }
        let first = *f.beat(1.0, 240.0).unwrap();
        assert_eq!(first.beat_time_s, 0.5);
        assert_eq!(first.values[0], 3.0, "the hit after the report counts");
        assert_eq!(
            first.values[CHANGE_1], 0.0,
            "same chord as before: no change"
        );
        assert!((first.values[LEVEL] - -4.0).abs() < 1e-5);
        // The beat at 1.0 s brings chord g: a full change against both earlier spans.
        for i in 0..40 {
            feed(&mut f, &g, 0.1, if i == 20 { 3.0 } else { 0.1 });
        }
        let second = *f.beat(1.5, 120.0).unwrap();
        assert_eq!(second.beat_time_s, 1.0);
        assert!(
            second.values[0] < 0.2,
            "a hit mid-span is no accent on the beat"
        );
        assert!((second.values[CHANGE_1] - 1.0).abs() < 1e-5);
        assert!(second.values.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn non_finite_input_gives_finite_features() {
        let mut f = BeatSpanFeatures::new(86.0);
        let bad = [f32::NAN; 12];
        let groups = [f32::INFINITY; FLUX_GROUPS];
        for k in 0..3 {
            for _ in 0..30 {
                f.hop(&BarHop {
                    chroma: &bad,
                    bass_flux: f32::NAN,
                    group_flux: &groups,
                    beat_activation: f32::NAN,
                    energy_db: f32::NEG_INFINITY,
                });
            }
            if let Some(out) = f.beat(k as f64, f64::NAN) {
                assert!(out.values.iter().all(|v| v.is_finite()), "{out:?}");
            }
        }
    }
}
