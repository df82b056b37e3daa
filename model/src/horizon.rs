//! The prediction horizon: how many model frames past the newest analysed frame a dancer
//! generates, so that the pose for the music heard *now* (plus the output lead) already exists
//! when the sender shows it. The dancer is handed the newest frame predicted to the pose's time
//! (`dsp::FeatureFrame::predicted_at`); offline generation and the training data use the same
//! horizon at lead 0 (`dsp::predicted_stream`), so a model learns exactly what it hears live.

use crate::source::MotionSource;

/// Resampler delay allowed for (rubato's sinc filter at 44.1/48 kHz input; 0 at 22 050 Hz).
const RESAMPLER_ALLOWANCE_S: f64 = 0.006;

/// Audio time from a frame's own time to the moment the analysis has it: half a short window
/// (the features describe its centre), one hop (a frame completes on the first hop at or past
/// its time) and the resampler.
pub const ANALYSIS_DELAY_S: f64 =
    (dsp::SHORT_WINDOW / 2 + dsp::HOP) as f64 / dsp::ANALYSIS_RATE as f64 + RESAMPLER_ALLOWANCE_S;

/// Default delivery margin, seconds: a 512-frame capture period at 48 kHz (10.7 ms), the thread
/// hand-offs and one dancer step.
pub const DEFAULT_MARGIN_S: f64 = 0.015;

/// Frames ahead of the analysis a source stepping at `rate` with `lookahead` frames must
/// generate so that, with poses shown `lead_s` (audio seconds) ahead of the heard audio and
/// `margin_s` for delivery, the pose after the shown time exists until the next frame arrives.
///
/// Pose `k + H` is made when frame `k` is analysed, at about `k / rate + ANALYSIS_DELAY_S`, and
/// must cover shown times until frame `k + 1` is: `H − 1 ≥ rate · (delay + margin + lead)`.
pub fn horizon_frames(rate: f64, lead_s: f64, margin_s: f64, lookahead: usize) -> usize {
    let frames = 1.0 + rate * (ANALYSIS_DELAY_S + margin_s + lead_s);
    let frames = if frames.is_finite() {
        frames.ceil().max(1.0)
    } else {
        1.0
    };
    frames.min(250.0) as usize + lookahead
}

/// The horizon `source` runs at: what the timing needs, and at least what its music was
/// predicted by in training (a longer horizon costs no delay, only older spectra).
pub fn source_horizon(source: &dyn MotionSource, lead_s: f64, margin_s: f64) -> usize {
    horizon_frames(
        source.frame_rate(),
        lead_s,
        margin_s,
        source.lookahead_frames(),
    )
    .max(source.horizon_frames())
}

/// The horizon of offline generation: the live one at lead 0 and the default margin.
pub fn offline_horizon(source: &dyn MotionSource) -> usize {
    source_horizon(source, 0.0, DEFAULT_MARGIN_S)
}

/// The horizon of training data and evaluation sets at `rate` for a source without look-ahead:
/// the live one at lead 0 and the default margin.
pub fn data_horizon(rate: f64) -> usize {
    horizon_frames(rate, 0.0, DEFAULT_MARGIN_S, 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn horizon_covers_delay_margin_and_lead() {
        // 25 fps: 34.8 + 6 ms analysis, 15 ms margin → 1 + 1.4 frames → 3.
        assert_eq!(data_horizon(25.0), 3);
        assert_eq!(horizon_frames(25.0, 0.05, DEFAULT_MARGIN_S, 0), 4);
        assert_eq!(horizon_frames(25.0, -0.2, DEFAULT_MARGIN_S, 0), 1);
        assert_eq!(horizon_frames(25.0, 0.0, DEFAULT_MARGIN_S, 4), 7);
        assert_eq!(horizon_frames(25.0, f64::NAN, 0.0, 0), 1);
        // Every horizon leaves the pose ahead of the shown time until the next frame arrives.
        for lead_ms in [-40, 0, 20, 50, 100] {
            let lead = f64::from(lead_ms) * 1e-3;
            let h = horizon_frames(25.0, lead, DEFAULT_MARGIN_S, 0) as f64;
            let newest_pose = h / 25.0;
            let shown_before_next = 1.0 / 25.0 + ANALYSIS_DELAY_S + DEFAULT_MARGIN_S + lead;
            assert!(newest_pose >= shown_before_next, "lead {lead_ms} ms");
        }
    }
}
