//! How a recording reaches the microphone or the line input: the level, the equalisation and
//! band limit of a cheap file or a PA, a compressor, the room's reverb and a crowd's noise.
//! Training draws a condition per copy of a song, so networks that only heard clean renders
//! and studio masters learn what a show sounds like (augmentation).
//!
//! A condition changes the sound, never the timing: every effect is causal with at most a few
//! samples of delay (filters, the compressor's gain) or leaves the direct sound where it was
//! (the reverb adds a tail after it), so a song's beat times still hold.

use std::f32::consts::PI;

use biquad::{Biquad, Coefficients, DirectForm2Transposed, Q_BUTTERWORTH_F32, ToHertz, Type};
use model::neural::rng::Rng;
use rustfft::FftPlanner;
use rustfft::num_complex::Complex;

/// A shelf or peak of an equaliser.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EqBand {
    /// Corner or centre frequency, Hz.
    pub hz: f32,
    /// Gain, dB.
    pub db: f32,
}

/// A feed-forward compressor on the whole mix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Compressor {
    /// Threshold, dB below the mix's RMS level.
    pub threshold_db: f32,
    /// Input dB above the threshold per output dB.
    pub ratio: f32,
    /// Attack time constant, seconds.
    pub attack_s: f32,
    /// Release time constant, seconds.
    pub release_s: f32,
}

/// A room's reverb: exponentially decaying noise convolved with the mix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reverb {
    /// Time for the tail to fall 60 dB, seconds.
    pub rt60_s: f32,
    /// Level of the reverberant sound against the direct sound (0–1).
    pub wet: f32,
}

/// Noise of a crowd or a room under the music.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CrowdNoise {
    /// Music RMS over noise RMS, dB.
    pub snr_db: f32,
    /// How deeply the noise's level swells and falls (0 steady room noise, 1 a chattering crowd).
    pub swell: f32,
}

/// One drawn recording condition; [`RecordingCondition::default`] leaves a song as it is.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RecordingCondition {
    /// Overall gain, dB (loud gains clip softly, as an overdriven input does).
    pub gain_db: f32,
    /// Low shelf (bass boost or cut).
    pub low_shelf: Option<EqBand>,
    /// High shelf (treble boost or cut).
    pub high_shelf: Option<EqBand>,
    /// One peaking band anywhere in the midrange.
    pub peak: Option<EqBand>,
    /// High-pass corner of a small speaker or a phone, Hz.
    pub high_pass_hz: Option<f32>,
    /// Low-pass corner of a band-limited file or line (8 kHz: a 16 kHz file), Hz.
    pub band_limit_hz: Option<f32>,
    /// A compressor.
    pub compressor: Option<Compressor>,
    /// A room.
    pub reverb: Option<Reverb>,
    /// A crowd.
    pub noise: Option<CrowdNoise>,
    /// Seed of the reverb's and the noise's random signals.
    pub seed: u64,
}

/// Band limits drawn: a phone, a narrow line, a 16 kHz file, a 22 kHz file.
const BAND_LIMITS_HZ: [f32; 4] = [3_400.0, 5_500.0, 7_800.0, 10_500.0];

impl RecordingCondition {
    /// Draws a condition: each effect is present about half the time, so some copies are
    /// nearly clean and a few carry everything.
    pub fn draw(rng: &mut Rng) -> Self {
        let seed = rng.next_u64();
        let mut chance = |p: f64| rng.uniform() < p;
        let (a, b, c, d, e, f, g, h) = (
            chance(0.5),
            chance(0.5),
            chance(0.4),
            chance(0.3),
            chance(0.4),
            chance(0.5),
            chance(0.5),
            chance(0.5),
        );
        let mut span = |lo: f64, hi: f64| (lo + (hi - lo) * rng.uniform()) as f32;
        Self {
            gain_db: span(-24.0, 9.0),
            low_shelf: a.then(|| EqBand {
                hz: span(80.0, 300.0),
                db: span(-12.0, 9.0),
            }),
            high_shelf: b.then(|| EqBand {
                hz: span(2_500.0, 8_000.0),
                db: span(-15.0, 6.0),
            }),
            peak: c.then(|| EqBand {
                hz: span(300.0, 4_000.0),
                db: span(-9.0, 9.0),
            }),
            high_pass_hz: d.then(|| span(80.0, 400.0)),
            band_limit_hz: e.then(|| BAND_LIMITS_HZ[(span(0.0, 3.999)) as usize]),
            compressor: f.then(|| Compressor {
                threshold_db: span(0.0, 15.0),
                ratio: span(2.0, 10.0),
                attack_s: span(0.001, 0.02),
                release_s: span(0.05, 0.3),
            }),
            reverb: g.then(|| Reverb {
                rt60_s: span(0.3, 2.5),
                wet: span(0.1, 0.6),
            }),
            noise: h.then(|| CrowdNoise {
                snr_db: span(3.0, 30.0),
                swell: span(0.0, 1.0),
            }),
            seed,
        }
    }

    /// Applies the condition to mono samples at `rate` Hz, in place.
    pub fn apply(&self, samples: &mut [f32], rate: u32) {
        let fs = (rate as f32).hz();
        let filters = [
            self.low_shelf
                .map(|b| (Type::LowShelf(b.db), b.hz, Q_BUTTERWORTH_F32)),
            self.high_shelf
                .map(|b| (Type::HighShelf(b.db), b.hz, Q_BUTTERWORTH_F32)),
            self.peak.map(|b| (Type::PeakingEQ(b.db), b.hz, 1.0)),
            self.high_pass_hz
                .map(|hz| (Type::HighPass, hz, Q_BUTTERWORTH_F32)),
            // Two low-pass sections: a 4th-order band limit, as steep as a resampler's.
            self.band_limit_hz.map(|hz| (Type::LowPass, hz, 0.541)),
            self.band_limit_hz.map(|hz| (Type::LowPass, hz, 1.307)),
        ];
        let nyquist = rate as f32 / 2.0;
        for (kind, hz, q) in filters.into_iter().flatten() {
            if hz >= 0.95 * nyquist {
                continue;
            }
            let Ok(coefficients) = Coefficients::<f32>::from_params(kind, fs, hz.hz(), q) else {
                continue;
            };
            let mut filter = DirectForm2Transposed::<f32>::new(coefficients);
            samples.iter_mut().for_each(|x| *x = filter.run(*x));
        }
        let mut rng = Rng::new(self.seed);
        if let Some(r) = self.reverb {
            reverberate(samples, rate, r, &mut rng);
        }
        if let Some(n) = self.noise {
            add_noise(samples, rate, n, &mut rng);
        }
        if let Some(c) = self.compressor {
            compress(samples, rate, c);
        }
        let gain = 10f32.powf(self.gain_db / 20.0);
        for x in samples.iter_mut() {
            // Soft clip past full scale (tanh keeps small signals as they are).
            *x = (gain * *x).tanh();
        }
        samples
            .iter_mut()
            .filter(|x| !x.is_finite())
            .for_each(|x| *x = 0.0);
    }
}

fn rms(samples: &[f32]) -> f32 {
    let sum: f64 = samples.iter().map(|&x| f64::from(x) * f64::from(x)).sum();
    (sum / samples.len().max(1) as f64).sqrt() as f32
}

/// Convolves with an exponentially decaying noise tail (FFT convolution of the whole signal).
fn reverberate(samples: &mut [f32], rate: u32, r: Reverb, rng: &mut Rng) {
    let n = samples.len();
    if n == 0 {
        return;
    }
    let ir_len = ((r.rt60_s * rate as f32) as usize).clamp(1, n);
    // Amplitude falls 60 dB (a factor 1000) over rt60.
    let decay = (1000f32).ln() / (r.rt60_s * rate as f32);
    let mut ir: Vec<f32> = (0..ir_len)
        .map(|i| rng.normal() * (-decay * i as f32).exp())
        .collect();
    let energy = ir.iter().map(|x| x * x).sum::<f32>().sqrt().max(1e-9);
    ir.iter_mut().for_each(|x| *x /= energy);
    let size = (n + ir_len).next_power_of_two();
    let mut planner = FftPlanner::<f32>::new();
    let forward = planner.plan_fft_forward(size);
    let inverse = planner.plan_fft_inverse(size);
    let mut a: Vec<Complex<f32>> = samples.iter().map(|&x| Complex::new(x, 0.0)).collect();
    a.resize(size, Complex::default());
    let mut b: Vec<Complex<f32>> = ir.iter().map(|&x| Complex::new(x, 0.0)).collect();
    b.resize(size, Complex::default());
    forward.process(&mut a);
    forward.process(&mut b);
    a.iter_mut().zip(&b).for_each(|(x, y)| *x *= y);
    inverse.process(&mut a);
    let dry_rms = rms(samples);
    let wet: Vec<f32> = a[..n].iter().map(|c| c.re / size as f32).collect();
    let wet_scale = r.wet * dry_rms / rms(&wet).max(1e-9);
    for (x, w) in samples.iter_mut().zip(wet) {
        *x = (1.0 - r.wet) * *x + wet_scale * w;
    }
}

/// Adds pinkish noise whose level swells and falls over seconds, as a crowd's does.
fn add_noise(samples: &mut [f32], rate: u32, noise: CrowdNoise, rng: &mut Rng) {
    let music = rms(samples);
    if music <= 0.0 {
        return;
    }
    let dt = 1.0 / rate as f32;
    // Three one-pole sections give a roughly 1/f spectrum across the band that matters.
    let poles = [60.0f32, 600.0, 4_000.0].map(|hz| 1.0 - (-2.0 * PI * hz * dt).exp());
    let mut state = [0.0f32; 3];
    let mut swell = 0.0f32;
    let swell_alpha = 1.0 - (-dt / 0.7).exp();
    let mut raw: Vec<f32> = samples
        .iter()
        .map(|_| {
            let w = rng.normal();
            let mut y = 0.0;
            for (s, p) in state.iter_mut().zip(poles) {
                *s += p * (w - *s);
                y += *s;
            }
            swell += swell_alpha * (rng.normal() * 3.0 - swell);
            y * (1.0 + noise.swell * swell.tanh())
        })
        .collect();
    let scale = music / rms(&raw).max(1e-9) * 10f32.powf(-noise.snr_db / 20.0);
    raw.iter_mut().for_each(|x| *x *= scale);
    samples.iter_mut().zip(raw).for_each(|(x, n)| *x += n);
}

/// A feed-forward compressor with an attack/release envelope on the level in dB.
fn compress(samples: &mut [f32], rate: u32, c: Compressor) {
    let level = 20.0 * rms(samples).max(1e-9).log10();
    let threshold = level - c.threshold_db;
    let coeff = |t: f32| 1.0 - (-1.0 / (t * rate as f32)).exp();
    let (attack, release) = (coeff(c.attack_s), coeff(c.release_s));
    let mut envelope = level;
    // Make-up gain puts the compressed mix back near its level.
    let makeup = c.threshold_db * (1.0 - 1.0 / c.ratio) * 0.5;
    for x in samples.iter_mut() {
        let db = 20.0 * x.abs().max(1e-6).log10();
        let a = if db > envelope { attack } else { release };
        envelope += a * (db - envelope);
        let over = (envelope - threshold).max(0.0);
        let reduction = over * (1.0 - 1.0 / c.ratio);
        *x *= 10f32.powf((makeup - reduction) / 20.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tone(rate: u32, hz: f32, seconds: f32) -> Vec<f32> {
        (0..(rate as f32 * seconds) as usize)
            .map(|i| 0.3 * (2.0 * PI * hz * i as f32 / rate as f32).sin())
            .collect()
    }

    #[test]
    fn the_default_condition_leaves_a_quiet_song_as_it_is() {
        let mut s = tone(22_050, 440.0, 0.5);
        let before = s.clone();
        RecordingCondition::default().apply(&mut s, 22_050);
        for (a, b) in s.iter().zip(&before) {
            assert!((a - b.tanh()).abs() < 1e-6);
        }
    }

    #[test]
    fn a_band_limit_removes_what_lies_above_it() {
        let rate = 22_050;
        let condition = RecordingCondition {
            band_limit_hz: Some(3_400.0),
            ..Default::default()
        };
        let mut high = tone(rate, 8_000.0, 1.0);
        let mut low = tone(rate, 500.0, 1.0);
        condition.apply(&mut high, rate);
        condition.apply(&mut low, rate);
        assert!(rms(&high[2_000..]) < 0.01 * 0.3, "{}", rms(&high[2_000..]));
        assert!(rms(&low[2_000..]) > 0.9 * 0.3 / 2f32.sqrt());
    }

    #[test]
    fn reverb_and_noise_keep_the_onset_where_it_was() {
        // A click at 0.5 s: after the room and the crowd, the loudest sample is still there.
        let rate = 22_050;
        let mut s = vec![0.0f32; rate as usize];
        s[rate as usize / 2] = 1.0;
        let condition = RecordingCondition {
            reverb: Some(Reverb {
                rt60_s: 1.5,
                wet: 0.5,
            }),
            noise: Some(CrowdNoise {
                snr_db: 10.0,
                swell: 1.0,
            }),
            seed: 3,
            ..Default::default()
        };
        condition.apply(&mut s, rate);
        let peak = s
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .unwrap()
            .0;
        assert_eq!(peak, rate as usize / 2);
        assert!(s.iter().all(|x| x.is_finite()));
        assert!(
            s[..rate as usize / 2].iter().any(|&x| x != 0.0),
            "noise before the click"
        );
    }

    #[test]
    fn drawn_conditions_vary_and_stay_finite() {
        let mut rng = Rng::new(7);
        let drawn: Vec<RecordingCondition> = (0..40)
            .map(|_| RecordingCondition::draw(&mut rng))
            .collect();
        assert!(drawn.iter().any(|c| c.reverb.is_some()));
        assert!(drawn.iter().any(|c| c.reverb.is_none()));
        assert!(drawn.iter().any(|c| c.band_limit_hz == Some(7_800.0)));
        for c in drawn.iter().take(6) {
            let mut s = tone(16_000, 220.0, 2.0);
            c.apply(&mut s, 16_000);
            assert!(s.iter().all(|x| x.is_finite() && x.abs() <= 1.0), "{c:?}");
        }
    }
}
