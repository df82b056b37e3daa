//! A built-in demo song, synthesised in code so danced runs with no files at all.
//!
//! 124 BPM, 4/4, C major (C – G – Am – F, one chord per bar): kick on every beat, snare on 2 and
//! 4, closed hi-hats on eighths, a bass on the roots and a soft pad. Deterministic.

use std::f64::consts::TAU;

/// Tempo of the demo song in beats per minute.
pub const DEMO_BPM: f64 = 124.0;
/// Sample rate of the demo song in Hz.
pub const DEMO_RATE: u32 = 44_100;
/// Time of the first beat (a downbeat), in seconds.
pub const DEMO_FIRST_BEAT_S: f64 = 0.5;

/// The demo song: interleaved stereo samples plus its exact beat grid.
#[derive(Clone, Debug)]
pub struct DemoTrack {
    /// Interleaved stereo samples at [`DEMO_RATE`].
    pub samples: Vec<f32>,
    /// Beat times in seconds.
    pub beats: Vec<f64>,
    /// Position of each beat in its bar (1 = downbeat).
    pub beat_in_bar: Vec<usize>,
}

/// Roots (MIDI) and triads of the progression, one chord per bar.
const CHORDS: [(u8, [u8; 3]); 4] = [
    (36, [60, 64, 67]),
    (43, [59, 62, 67]),
    (45, [57, 60, 64]),
    (41, [57, 60, 65]),
];

fn midi_hz(n: u8) -> f64 {
    440.0 * 2f64.powf((n as f64 - 69.0) / 12.0)
}

/// Renders `seconds` of the demo song.
pub fn demo_track(seconds: f64) -> DemoTrack {
    let rate = DEMO_RATE as f64;
    let n = (seconds * rate) as usize;
    let mut mono = vec![0.0f64; n];
    let beat = 60.0 / DEMO_BPM;
    let mut beats = Vec::new();
    let mut beat_in_bar = Vec::new();
    let mut seed = 0x5eed_u64;
    let mut noise = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut add = |start: f64, len: f64, f: &mut dyn FnMut(f64) -> f64| {
        let s = (start * rate) as usize;
        let e = ((start + len) * rate) as usize;
        for (i, v) in mono.iter_mut().enumerate().take(e.min(n)).skip(s) {
            *v += f(i as f64 / rate - start);
        }
    };
    let mut k = 0usize;
    loop {
        let t = DEMO_FIRST_BEAT_S + k as f64 * beat;
        if t > seconds - 0.05 {
            break;
        }
        let pos = k % 4;
        let (root, triad) = CHORDS[(k / 4) % 4];
        beats.push(t);
        beat_in_bar.push(pos + 1);
        // Kick: a falling sine with a click.
        add(t, 0.25, &mut |x| {
            let f = 50.0 + 90.0 * (-x / 0.03).exp();
            0.8 * (TAU * f * x).sin() * (-x / 0.12).exp()
        });
        if pos == 1 || pos == 3 {
            add(t, 0.2, &mut |x| {
                0.35 * noise() * (-x / 0.05).exp()
                    + 0.2 * (TAU * 190.0 * x).sin() * (-x / 0.04).exp()
            });
        }
        for half in [0.0, 0.5] {
            add(t + half * beat, 0.05, &mut |x| {
                0.08 * noise() * (-x / 0.01).exp()
            });
        }
        let bass = midi_hz(root);
        add(t, beat * 0.9, &mut |x| {
            0.25 * (TAU * bass * x).sin() * (-x / 0.3).exp()
        });
        if pos == 0 {
            let freqs = triad.map(midi_hz);
            add(t, 4.0 * beat, &mut |x| {
                let env = (x / 0.05).min(1.0) * (-x / 3.0).exp();
                freqs.iter().map(|f| (TAU * f * x).sin()).sum::<f64>() * 0.06 * env
            });
        }
        k += 1;
    }
    let peak = mono.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-9);
    let gain = 0.7 / peak;
    let samples = mono
        .iter()
        .flat_map(|&v| [(v * gain) as f32, (v * gain * 0.95) as f32])
        .collect();
    DemoTrack {
        samples,
        beats,
        beat_in_bar,
    }
}

/// Stereo clicks (decaying noise burst plus a low thump) every beat from `first_s`; returns the
/// samples at `rate` and the click times.
pub fn click_track(seconds: f64, bpm: f64, first_s: f64, rate: u32) -> (Vec<f32>, Vec<f64>) {
    let n = (seconds * f64::from(rate)) as usize;
    let mut samples = vec![0.0f32; n * 2];
    let mut seed = 12345u64;
    let mut beats = Vec::new();
    let mut t = first_s;
    while t < seconds {
        beats.push(t);
        let start = (t * f64::from(rate)) as usize;
        for i in 0..(0.05 * f64::from(rate)) as usize {
            let Some(frame) = samples.get_mut((start + i) * 2..(start + i) * 2 + 2) else {
                break;
            };
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let noise = ((seed >> 33) as f64 / (1u64 << 31) as f64) - 1.0;
            let x = i as f64 / f64::from(rate);
            let v = (0.6 * noise * (-x * 120.0).exp()
                + 0.8 * (std::f64::consts::TAU * 80.0 * x).sin() * (-x * 30.0).exp())
                as f32;
            frame[0] = v;
            frame[1] = v;
        }
        t += 60.0 / bpm;
    }
    (samples, beats)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demo_track_has_the_promised_grid_and_level() {
        let d = demo_track(10.0);
        assert_eq!(d.samples.len(), 2 * 441_000);
        assert_eq!(d.beats.len(), 20);
        assert!((d.beats[1] - d.beats[0] - 60.0 / DEMO_BPM).abs() < 1e-9);
        assert_eq!(&d.beat_in_bar[..5], &[1, 2, 3, 4, 1]);
        let peak = d.samples.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!((peak - 0.7).abs() < 1e-3);
    }
}
