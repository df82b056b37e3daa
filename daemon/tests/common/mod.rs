//! Helpers shared by the binary's integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

pub fn danced() -> Command {
    Command::new(env!("CARGO_BIN_EXE_danced"))
}

/// `../shared/data` beside the repository, or `None` (with a message) when `needed` is absent.
pub fn shared_data(needed: &str) -> Option<PathBuf> {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data");
    if data.join(needed).is_dir() {
        Some(data)
    } else {
        eprintln!("skipping: {} not found", data.join(needed).display());
        None
    }
}

pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("danced-cli-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// 16-bit PCM WAV writer, enough for tests.
pub fn write_wav(path: &Path, samples: &[f32], rate: u32, channels: u16) {
    let data_len = (samples.len() * 2) as u32;
    let mut b = Vec::with_capacity(44 + data_len as usize);
    b.extend_from_slice(b"RIFF");
    b.extend_from_slice(&(36 + data_len).to_le_bytes());
    b.extend_from_slice(b"WAVEfmt ");
    b.extend_from_slice(&16u32.to_le_bytes());
    b.extend_from_slice(&1u16.to_le_bytes());
    b.extend_from_slice(&channels.to_le_bytes());
    b.extend_from_slice(&rate.to_le_bytes());
    b.extend_from_slice(&(rate * channels as u32 * 2).to_le_bytes());
    b.extend_from_slice(&(channels * 2).to_le_bytes());
    b.extend_from_slice(&16u16.to_le_bytes());
    b.extend_from_slice(b"data");
    b.extend_from_slice(&data_len.to_le_bytes());
    for s in samples {
        b.extend_from_slice(&((s.clamp(-1.0, 1.0) * 32767.0) as i16).to_le_bytes());
    }
    std::fs::write(path, b).unwrap();
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
