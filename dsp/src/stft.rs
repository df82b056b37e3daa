//! Windowed FFT magnitude of the newest samples, without allocation per frame.

use std::sync::Arc;

use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};

/// Magnitude spectrum of a Hann-windowed frame, scaled so a full-scale sine peaks near 1.
pub struct Stft {
    fft: Arc<dyn Fft<f32>>,
    window: Vec<f32>,
    buf: Vec<Complex32>,
    scratch: Vec<Complex32>,
    scale: f32,
}

impl Stft {
    /// Plans an FFT of `window_len` samples (a power of two is fastest).
    pub fn new(window_len: usize) -> Self {
        let fft = FftPlanner::new().plan_fft_forward(window_len);
        let window: Vec<f32> = (0..window_len)
            .map(|i| {
                let x = std::f32::consts::PI * i as f32 / window_len as f32;
                x.sin() * x.sin()
            })
            .collect();
        let sum: f32 = window.iter().sum();
        let scratch = vec![Complex32::default(); fft.get_inplace_scratch_len()];
        Self {
            fft,
            scale: 2.0 / sum,
            window,
            buf: vec![Complex32::default(); window_len],
            scratch,
        }
    }

    /// Window length in samples.
    pub fn window_len(&self) -> usize {
        self.window.len()
    }

    /// Number of magnitude bins (`window_len / 2 + 1`).
    pub fn bins(&self) -> usize {
        self.window.len() / 2 + 1
    }

    /// Writes the magnitude spectrum of `frame` (exactly `window_len` samples) into `out`
    /// (`bins()` values).
    pub fn magnitude(&mut self, frame: &[f32], out: &mut [f32]) {
        debug_assert_eq!(frame.len(), self.window.len());
        for ((b, &x), &w) in self.buf.iter_mut().zip(frame).zip(&self.window) {
            *b = Complex32::new(x * w, 0.0);
        }
        self.fft
            .process_with_scratch(&mut self.buf, &mut self.scratch);
        for (o, c) in out.iter_mut().zip(&self.buf) {
            *o = c.norm() * self.scale;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_scale_sine_peaks_near_one_at_its_bin() {
        let n = 1024;
        let mut stft = Stft::new(n);
        let bin = 37.0;
        let frame: Vec<f32> = (0..n)
            .map(|i| (2.0 * std::f32::consts::PI * bin * i as f32 / n as f32).sin())
            .collect();
        let mut mag = vec![0.0; stft.bins()];
        stft.magnitude(&frame, &mut mag);
        let (argmax, peak) =
            mag.iter().enumerate().fold(
                (0, 0.0f32),
                |(bi, bm), (i, &m)| if m > bm { (i, m) } else { (bi, bm) },
            );
        assert_eq!(argmax, 37);
        assert!((peak - 1.0).abs() < 0.01, "peak {peak}");
        assert!(mag[60] < 1e-3);
    }
}
