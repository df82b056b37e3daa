//! Online beat tracking: a beat-pointer hidden Markov model filtered forward in time
//! (the beat state space of Krebs, Böck & Widmer 2015, without look-ahead).
//!
//! Each state is (beat interval τ in frames, position φ within the beat). The position advances
//! one frame per frame; at the end of a beat the interval may change, with a probability that
//! falls off exponentially with the tempo ratio. Frames at the start of a beat expect onsets.
//! The tracker keeps only the forward probabilities, so every decision uses the past alone.

/// One beat state per this many positions of a beat expects an onset.
const OBSERVATION_LAMBDA: usize = 16;
/// Seconds of continuous evidence before beats are reported.
const LOCK_SECONDS: f64 = 1.0;
/// Once locked, the gates drop to this fraction of their values.
const UNLOCK_FACTOR: f32 = 0.75;
/// Added to the activation and its mean before their ratio, so near-silent stretches (where
/// both are ~0) give a ratio near 1 instead of amplifying noise.
const ACTIVATION_FLOOR: f32 = 0.02;
/// Share of a beat's offset from the predicted grid that moves the reported beat.
const BEAT_SMOOTHING_GAIN: f64 = 0.5;
/// Beats further than this share of an interval from the predicted grid restart the grid.
const BEAT_SMOOTHING_WINDOW: f64 = 0.1;
/// Mean onset strength below which the input counts as silence.
const SILENCE_FLUX: f32 = 0.05;

/// Tuning of the beat tracker. The defaults are what `danced bench beats` measured best on
/// songs outside the benchmark sets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BeatTrackerParams {
    /// Slowest tempo tracked, in beats per minute.
    pub min_bpm: f64,
    /// Fastest tempo tracked, in beats per minute.
    pub max_bpm: f64,
    /// How sharply the tempo may change between beats (Krebs et al. use 100).
    pub transition_lambda: f64,
    /// When above 0, the tempo at which `transition_lambda` applies as given; at other tempos it
    /// scales with the beat interval, so changing the interval by one frame costs the same at
    /// every tempo (0: the ratio cost of Krebs et al. at every tempo).
    pub transition_ref_bpm: f64,
    /// Slope of the log likelihood ratio of a beat against relative onset strength.
    pub observation_beta: f64,
    /// Onset strength relative to its mean above which a frame is no more beat-like.
    pub max_relative_strength: f32,
    /// Time constant of the onset-strength normaliser, seconds.
    pub norm_seconds: f64,
    /// Centre of the log-normal tempo prior, BPM.
    pub prior_bpm: f64,
    /// Width of the tempo prior in octaves (0 disables it).
    pub prior_octaves: f64,
    /// Minimum onset contrast (mean absolute deviation over mean) for beats to be reported;
    /// stationary noise stays well below it.
    pub contrast_gate: f32,
    /// Minimum mean relative onset strength on the tracked beats for beats to be reported: music
    /// puts its strongest onsets on the beat, noise does not.
    pub salience_gate: f32,
    /// Beats are reported this many frames before they are due (compensates analysis delay).
    pub lead_frames: usize,
    /// When above 0, the likelihood ratio is `((1 + z) / 2)^power` instead of `exp(beta (z − 1))`.
    pub observation_power: f64,
    /// Extra weight of bass-band onsets (kick drums, bass notes) in the beat observation.
    pub bass_weight: f32,
    /// Share of the learned beat activation in the observation (0: onset strength only,
    /// 1: activation only), as a weighted geometric mean of the two likelihood ratios.
    pub activation_weight: f64,
    /// Exponent on the activation's likelihood ratio (its activation over its recent mean).
    pub activation_power: f64,
}

impl Default for BeatTrackerParams {
    fn default() -> Self {
        Self {
            min_bpm: 65.0,
            max_bpm: 215.0,
            transition_lambda: 100.0,
            transition_ref_bpm: 150.0,
            observation_beta: 0.8,
            max_relative_strength: 30.0,
            norm_seconds: 3.0,
            prior_bpm: 120.0,
            prior_octaves: 1.0,
            contrast_gate: 0.32,
            salience_gate: 1.5,
            lead_frames: 0,
            bass_weight: 6.0,
            observation_power: 0.0,
            activation_weight: 0.35,
            activation_power: 1.0,
        }
    }
}

impl BeatTrackerParams {
    /// Applies `name=value` overrides separated by commas (for tuning runs); unknown names or
    /// unparsable values are reported back.
    pub fn with_overrides(mut self, spec: &str) -> Result<Self, crate::DspError> {
        for (k, x) in crate::tuning::overrides(spec)? {
            match k {
                "min_bpm" => self.min_bpm = x.clamp(20.0, 300.0),
                "max_bpm" => self.max_bpm = x.clamp(20.0, 400.0),
                "transition_lambda" => self.transition_lambda = x,
                "transition_ref_bpm" => self.transition_ref_bpm = x,
                "observation_beta" => self.observation_beta = x,
                "max_relative_strength" => self.max_relative_strength = x as f32,
                "norm_seconds" => self.norm_seconds = x,
                "prior_bpm" => self.prior_bpm = x,
                "prior_octaves" => self.prior_octaves = x,
                "contrast_gate" => self.contrast_gate = x as f32,
                "salience_gate" => self.salience_gate = x as f32,
                "lead_frames" => self.lead_frames = x as usize,
                "bass_weight" => self.bass_weight = x as f32,
                "observation_power" => self.observation_power = x,
                "activation_weight" => self.activation_weight = x.clamp(0.0, 1.0),
                "activation_power" => self.activation_power = x,
                other => {
                    return Err(crate::DspError::Tuning(format!(
                        "unknown beat tracker parameter {other:?}"
                    )));
                }
            }
        }
        Ok(self)
    }
}

/// What the tracker knows after a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BeatState {
    /// Tempo in beats per minute (0 until the tracker has locked on).
    pub tempo_bpm: f64,
    /// Confidence in [0, 1]: the tempo posterior's share within ±4 % of `tempo_bpm`, scaled by
    /// how salient the onsets on the tracked beats are; 0 while no beat is heard.
    pub tempo_confidence: f64,
    /// Position in the current beat, in [0, 1): 0 on the beat.
    pub beat_phase: f64,
    /// Frames until the next predicted beat.
    pub frames_to_next_beat: f64,
    /// Frames since the beat reported on this frame, when one is (`Some(0.3)`: the beat was 0.3
    /// frames before this frame's time; negative when the tempo grid puts it a little after).
    pub beat_frames_ago: Option<f64>,
    /// Whether the tracker currently hears a beat at all (periodic evidence over silence/noise).
    pub locked: bool,
}

/// Causal beat tracker over an onset-strength signal.
pub struct BeatTracker {
    frame_rate: f64,
    intervals: Vec<usize>,
    offsets: Vec<usize>,
    beat_positions: Vec<usize>,
    transition: Vec<f64>,
    fwd: Vec<f64>,
    next: Vec<f64>,
    tempo_mass: Vec<f64>,
    norm_mean: f32,
    full_mean: f32,
    contrast: f32,
    recent_z: [f32; 3],
    salience: f32,
    activation_mean: f32,
    salience_pending: bool,
    locked: bool,
    evident_frames: u32,
    params: BeatTrackerParams,
    norm_alpha: f32,
    last_phase: f64,
    interval: f64,
    frames_since_beat: f64,
    on_grid: bool,
    state: BeatState,
}

impl BeatTracker {
    /// Builds a tracker for onset strengths arriving at `frame_rate` frames per second.
    pub fn new(frame_rate: f64) -> Self {
        Self::with_params(frame_rate, BeatTrackerParams::default())
    }

    /// Builds a tracker with explicit tuning.
    pub fn with_params(frame_rate: f64, params: BeatTrackerParams) -> Self {
        let min_iv = (60.0 * frame_rate / params.max_bpm).floor().max(2.0) as usize;
        let max_iv = ((60.0 * frame_rate / params.min_bpm).ceil() as usize).max(min_iv + 1);
        let intervals: Vec<usize> = (min_iv..=max_iv).collect();
        let mut offsets = Vec::with_capacity(intervals.len());
        let mut total = 0;
        for &iv in &intervals {
            offsets.push(total);
            total += iv;
        }
        let beat_positions: Vec<usize> = intervals
            .iter()
            .map(|&iv| (iv / OBSERVATION_LAMBDA).max(1))
            .collect();
        let n = intervals.len();
        let mut transition = vec![0.0; n * n];
        for (j, &from) in intervals.iter().enumerate() {
            let row = &mut transition[j * n..(j + 1) * n];
            // Intervals are whole frames, so a tempo between two of them is held by alternating
            // neighbours, and the phase is corrected by one-frame steps. Under a pure ratio
            // cost those steps are dearer at fast tempos (short intervals) than at slow ones.
            let lambda = if params.transition_ref_bpm > 0.0 {
                let ref_interval = 60.0 * frame_rate / params.transition_ref_bpm;
                params.transition_lambda * from as f64 / ref_interval
            } else {
                params.transition_lambda
            };
            for (i, &to) in intervals.iter().enumerate() {
                let ratio = to as f64 / from as f64;
                let bpm = 60.0 * frame_rate / to as f64;
                let prior = if params.prior_octaves > 0.0 {
                    let o = (bpm / params.prior_bpm).log2() / params.prior_octaves;
                    (-0.5 * o * o).exp()
                } else {
                    1.0
                };
                row[i] = prior * (-lambda * (ratio - 1.0).abs()).exp();
            }
            let sum: f64 = row.iter().sum();
            row.iter_mut().for_each(|v| *v /= sum);
        }
        let fwd = vec![1.0 / total as f64; total];
        Self {
            frame_rate,
            intervals,
            offsets,
            beat_positions,
            transition,
            next: vec![0.0; total],
            fwd,
            tempo_mass: vec![0.0; n],
            norm_mean: 0.0,
            full_mean: 0.0,
            contrast: 0.0,
            recent_z: [0.0; 3],
            salience: 0.0,
            activation_mean: 0.0,
            salience_pending: false,
            locked: false,
            evident_frames: 0,
            params,
            norm_alpha: (1.0 / (params.norm_seconds * frame_rate)) as f32,
            last_phase: 0.0,
            interval: 1.0,
            frames_since_beat: 1e9,
            on_grid: false,
            state: BeatState::default(),
        }
    }

    /// Number of states in the model (its per-frame cost).
    pub fn num_states(&self) -> usize {
        self.fwd.len()
    }

    /// The state after the last frame.
    pub fn state(&self) -> BeatState {
        self.state
    }

    /// Likelihood ratio of "this frame is on a beat" over "it is not", from the onset strength
    /// relative to its recent mean: above-average frames favour beat states, quiet ones count
    /// against them, and the ratio is bounded so one huge attack cannot override the tempo.
    fn beat_likelihood_ratio(&mut self, strength: f32, bass_strength: f32, activation: f32) -> f64 {
        let flux = self.flux_likelihood_ratio(strength, bass_strength);
        let w = self.params.activation_weight;
        if w <= 0.0 {
            return flux;
        }
        let a = if activation.is_finite() {
            activation.clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.activation_mean += self.norm_alpha * (a - self.activation_mean);
        let ratio = ((a + ACTIVATION_FLOOR) / (self.activation_mean + ACTIVATION_FLOOR)) as f64;
        flux.powf(1.0 - w) * ratio.powf(w * self.params.activation_power)
    }

    /// The onset-strength part of [`Self::beat_likelihood_ratio`].
    fn flux_likelihood_ratio(&mut self, strength: f32, bass_strength: f32) -> f64 {
        let clean = |x: f32| if x.is_finite() { x.max(0.0) } else { 0.0 };
        let (full, bass) = (clean(strength), clean(bass_strength));
        // The gate looks at the full-band flux alone: summed over many bands it is nearly
        // constant for stationary noise, while the few bass bins fluctuate even then.
        // The mean rises fast so that sound arriving after silence is not one long "attack".
        let rise = if full > self.full_mean { 12.0 } else { 1.0 };
        self.full_mean += (rise * self.norm_alpha).min(1.0) * (full - self.full_mean);
        let zf = full / (self.full_mean + 1e-3);
        self.contrast += self.norm_alpha * ((zf - 1.0).abs().min(4.0) - self.contrast);
        let s = full + self.params.bass_weight * bass;
        self.norm_mean += self.norm_alpha * (s - self.norm_mean);
        let z = (s / (self.norm_mean + 1e-3)).min(self.params.max_relative_strength);
        self.recent_z = [self.recent_z[1], self.recent_z[2], z];
        if self.params.observation_power > 0.0 {
            ((1.0 + z as f64) / 2.0).powf(self.params.observation_power)
        } else {
            (self.params.observation_beta * (z as f64 - 1.0)).exp()
        }
    }

    /// Consumes one frame's onset strength (all bands and bass bands) and learned beat
    /// activation; returns the updated state.
    pub fn process(&mut self, strength: f32, bass_strength: f32, activation: f32) -> BeatState {
        let p_beat = self.beat_likelihood_ratio(strength, bass_strength, activation);
        let p_other = 1.0;
        let n = self.intervals.len();

        // Beat boundaries: the last position of every interval feeds position 0 of every interval.
        for (i, (&iv, &off)) in self.intervals.iter().zip(&self.offsets).enumerate() {
            self.tempo_mass[i] = self.fwd[off + iv - 1];
        }
        for i in 0..n {
            let mut into = 0.0;
            for j in 0..n {
                into += self.tempo_mass[j] * self.transition[j * n + i];
            }
            self.next[self.offsets[i]] = into;
        }
        for (&iv, &off) in self.intervals.iter().zip(&self.offsets) {
            self.next[off + 1..off + iv].copy_from_slice(&self.fwd[off..off + iv - 1]);
        }

        // Observation and normalisation.
        let mut sum = 0.0;
        for ((&iv, &off), &bp) in self
            .intervals
            .iter()
            .zip(&self.offsets)
            .zip(&self.beat_positions)
        {
            for (k, v) in self.next[off..off + iv].iter_mut().enumerate() {
                *v *= if k < bp { p_beat } else { p_other };
                sum += *v;
            }
        }
        if sum > 0.0 && sum.is_finite() {
            let inv = 1.0 / sum;
            for (f, v) in self.fwd.iter_mut().zip(&self.next) {
                *f = v * inv;
            }
        } else {
            let u = 1.0 / self.fwd.len() as f64;
            self.fwd.iter_mut().for_each(|f| *f = u);
        }

        self.decide()
    }

    fn decide(&mut self) -> BeatState {
        let (mut best, mut best_p) = (0, f64::MIN);
        for (s, &p) in self.fwd.iter().enumerate() {
            if p > best_p {
                best_p = p;
                best = s;
            }
        }
        let ti = match self.offsets.binary_search(&best) {
            Ok(i) => i,
            Err(i) => i - 1,
        };
        let iv = self.intervals[ti];
        let pos = best - self.offsets[ti];

        // Tempo: posterior-weighted interval around the best one, for sub-frame resolution.
        for (i, (&iv_i, &off)) in self.intervals.iter().zip(&self.offsets).enumerate() {
            self.tempo_mass[i] = self.fwd[off..off + iv_i].iter().sum();
        }
        let (mut wsum, mut ivsum, mut near) = (0.0, 0.0, 0.0);
        for (i, &iv_i) in self.intervals.iter().enumerate() {
            let ratio = iv_i as f64 / iv as f64;
            if (ratio - 1.0).abs() <= 0.04 {
                near += self.tempo_mass[i];
                wsum += self.tempo_mass[i];
                ivsum += self.tempo_mass[i] * iv_i as f64;
            }
        }
        let interval = if wsum > 0.0 { ivsum / wsum } else { iv as f64 };
        // Integer intervals alternate around a fractional tempo; smooth over about a second so the
        // reported tempo sits between them. A jump larger than the window resets the average.
        if (self.interval / interval - 1.0).abs() > 0.08 {
            self.interval = interval;
        } else {
            self.interval += (interval - self.interval) / self.frame_rate;
        }
        let interval = self.interval;
        let phase = pos as f64 / iv as f64;

        self.frames_since_beat += 1.0;
        // The beat is reported `lead_frames` before it is due: the position counter is exact
        // between tempo changes, and reporting early cancels part of the analysis delay.
        let lead = self.params.lead_frames.min(iv / 4);
        let shifted = ((pos + lead) % iv) as f64 / iv as f64;
        let wrapped = shifted < self.last_phase - 0.5;
        let mut beat_frames_ago = None;
        let beat_due = wrapped && self.frames_since_beat >= 0.6 * interval;
        // The beat's salience is read one frame after it, so the frames on both sides count.
        if self.salience_pending {
            let z = self.recent_z.iter().fold(0.0f32, |m, &v| m.max(v));
            self.salience += 0.25 * (z - self.salience);
        }
        self.salience_pending = beat_due;
        // Hysteresis: locking needs clear evidence, a brief dip (a break, a soft bar) keeps it.
        let hold = if self.locked { UNLOCK_FACTOR } else { 1.0 };
        let evident = self.contrast > hold * self.params.contrast_gate
            && self.salience > hold * self.params.salience_gate
            && self.full_mean > SILENCE_FLUX;
        // Evidence must last before a lock, so a transient (sound after silence) is not a beat.
        self.evident_frames = if evident { self.evident_frames + 1 } else { 0 };
        let locked = evident
            && (self.locked || self.evident_frames as f64 >= LOCK_SECONDS * self.frame_rate);
        self.locked = locked;
        if beat_due && !locked {
            self.frames_since_beat = 0.0;
        }
        if beat_due && locked {
            let ago = pos as f64 - if pos + lead >= iv { iv as f64 } else { 0.0 };
            let ago = self.smooth_beat(ago, interval);
            beat_frames_ago = Some(ago);
            self.frames_since_beat = ago;
        } else if !locked {
            self.on_grid = false;
        }
        self.last_phase = shifted;
        self.state = BeatState {
            tempo_bpm: if locked {
                60.0 * self.frame_rate / interval
            } else {
                0.0
            },
            // The tempo posterior alone is nearly always peaked (tempo changes are expensive), so
            // the confidence also says how clearly the onsets mark the beats: 0 while unlocked,
            // 1 once the beat onsets stand at twice the salience gate.
            tempo_confidence: if locked {
                near.clamp(0.0, 1.0)
                    * (self.salience / (2.0 * self.params.salience_gate)).clamp(0.0, 1.0) as f64
            } else {
                0.0
            },
            beat_phase: phase,
            frames_to_next_beat: (iv - pos) as f64,
            beat_frames_ago,
            locked,
        };
        self.state
    }

    /// Moves a beat found `ago` frames back towards where the previous beat and the fractional
    /// interval put it. The state space holds whole-frame intervals only, so a tempo between two
    /// of them is followed by alternating neighbours and beats land up to a few frames either
    /// side of the true grid; the fractional interval knows better.
    fn smooth_beat(&mut self, ago: f64, interval: f64) -> f64 {
        // The previous reported beat is `frames_since_beat` back; the found beat, `gap` after it.
        let gap = self.frames_since_beat - ago;
        let off_grid = gap - interval;
        let on_grid = self.on_grid && off_grid.abs() <= BEAT_SMOOTHING_WINDOW * interval;
        self.on_grid = true;
        if on_grid {
            self.frames_since_beat - interval - BEAT_SMOOTHING_GAIN * off_grid
        } else {
            ago
        }
    }

    /// Onset contrast: mean absolute deviation of the onset strength over its mean (the gate).
    pub fn contrast(&self) -> f32 {
        self.contrast
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn click_strengths(bpm: f64, fps: f64, seconds: f64) -> Vec<f32> {
        let n = (seconds * fps) as usize;
        let period = 60.0 * fps / bpm;
        (0..n)
            .map(|t| {
                let ph = (t as f64 / period).fract();
                if ph * period < 1.0 { 5.0 } else { 0.1 }
            })
            .collect()
    }

    #[test]
    fn locks_onto_a_click_train_tempo_and_phase() {
        let fps = crate::hop_rate();
        for bpm in [70.0, 100.0, 128.0, 174.0] {
            let mut bt = BeatTracker::new(fps);
            let mut beats = Vec::new();
            let strengths = click_strengths(bpm, fps, 20.0);
            for (t, &s) in strengths.iter().enumerate() {
                let st = bt.process(s, 0.0, 0.0);
                if let Some(ago) = st.beat_frames_ago {
                    beats.push(t as f64 - ago);
                }
            }
            let st = bt.state();
            assert!(
                st.tempo_confidence > 0.5,
                "bpm {bpm}: confidence {}",
                st.tempo_confidence
            );
            assert!(
                (st.tempo_bpm - bpm).abs() / bpm < 0.02,
                "bpm {bpm}: got {}",
                st.tempo_bpm
            );
            let period = 60.0 * fps / bpm;
            let late: Vec<f64> = beats.iter().filter(|&&b| b > 8.0 * fps).copied().collect();
            assert!(
                late.len() as f64 >= 11.0 * bpm / 60.0,
                "bpm {bpm}: {} beats",
                late.len()
            );
            for b in late {
                let off = (b / period).fract().min(1.0 - (b / period).fract()) * period;
                assert!(
                    off <= 1.5,
                    "bpm {bpm}: beat {b} is {off} frames off the grid"
                );
            }
        }
    }

    #[test]
    fn a_one_frame_tempo_step_costs_the_same_at_every_tempo() {
        let fps = crate::hop_rate();
        let params = BeatTrackerParams {
            prior_octaves: 0.0,
            ..BeatTrackerParams::default()
        };
        let step_ratio = |params: BeatTrackerParams, bpm: f64| {
            let bt = BeatTracker::with_params(fps, params);
            let n = bt.intervals.len();
            let j = bt
                .intervals
                .iter()
                .position(|&iv| iv as f64 >= 60.0 * fps / bpm)
                .unwrap();
            (
                bt.transition[j * n + j + 1] / bt.transition[j * n + j],
                bt.intervals[j],
            )
        };
        let ref_interval = 60.0 * fps / params.transition_ref_bpm;
        let expected = (-params.transition_lambda / ref_interval).exp();
        for bpm in [70.0, 87.0, 150.0, 200.0] {
            let (r, _) = step_ratio(params, bpm);
            assert!(
                (r / expected - 1.0).abs() < 1e-9,
                "{bpm} BPM: {r} vs {expected}"
            );
        }
        // Without the reference tempo the cost is the ratio's (Krebs et al.): a one-frame step
        // is dearer at fast tempos.
        let ratio_cost = BeatTrackerParams {
            transition_ref_bpm: 0.0,
            ..params
        };
        for bpm in [70.0, 200.0] {
            let (r, iv) = step_ratio(ratio_cost, bpm);
            let expected = (-ratio_cost.transition_lambda / iv as f64).exp();
            assert!(
                (r / expected - 1.0).abs() < 1e-9,
                "{bpm} BPM: {r} vs {expected}"
            );
        }
    }

    #[test]
    fn beats_found_on_whole_frames_are_pulled_onto_the_fractional_grid() {
        let mut bt = BeatTracker::new(crate::hop_rate());
        let interval = 50.4;
        let mut worst_found: f64 = 0.0;
        let mut worst_reported: f64 = 0.0;
        let mut last_reported = 0.0;
        for k in 0..40 {
            let truth = 100.0 + k as f64 * interval;
            // The state space finds each beat on a whole frame, alternately early and late.
            let found = (truth + if k % 2 == 0 { 1.0 } else { -1.0 }).round();
            bt.frames_since_beat = found - last_reported;
            let ago = bt.smooth_beat(0.0, interval);
            let reported = found - ago;
            last_reported = reported;
            if k >= 10 {
                worst_found = worst_found.max((found - truth).abs());
                worst_reported = worst_reported.max((reported - truth).abs());
            }
        }
        assert!(worst_found >= 1.0, "the constructed beats are off the grid");
        assert!(
            worst_reported <= 0.5,
            "reported beats stray {worst_reported} frames from the grid (found: {worst_found})"
        );
        // A beat far off the prediction (a tempo or phase jump) is taken as found.
        bt.frames_since_beat = 70.0;
        assert_eq!(bt.smooth_beat(0.0, interval), 0.0);
    }

    #[test]
    fn silence_and_noise_give_no_beats() {
        let fps = crate::hop_rate();
        let mut bt = BeatTracker::new(fps);
        for _ in 0..(20.0 * fps) as usize {
            let st = bt.process(0.0, 0.0, 0.0);
            assert!(st.beat_frames_ago.is_none() && st.tempo_confidence == 0.0);
        }
        // Stationary noise: the full-band flux is steady (many bands averaged), the few bass
        // bins fluctuate wildly.
        let mut bt = BeatTracker::new(fps);
        let mut seed = 12345u64;
        let mut beats = 0;
        let mut uniform = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as f32 / (1u64 << 31) as f32
        };
        for _ in 0..(30.0 * fps) as usize {
            let full = 3.0 * (1.0 + 0.3 * (uniform() - 0.5));
            let bass = 2.0 * uniform();
            if bt.process(full, bass, 0.0).beat_frames_ago.is_some() {
                beats += 1;
            }
        }
        assert!(beats < 5, "{beats} beats invented from noise");
    }
}
