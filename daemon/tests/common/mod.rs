//! Helpers shared by the binary's integration tests.
#![allow(dead_code)]

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

pub fn danced() -> Command {
    Command::new(env!("CARGO_BIN_EXE_danced"))
}

/// Runs `cmd`, asserts that it succeeded (its stderr in the message), and returns its stdout
/// and stderr.
pub fn succeed(cmd: &mut Command) -> (String, String) {
    let out = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "stderr: {stderr}");
    (String::from_utf8_lossy(&out.stdout).into_owned(), stderr)
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

/// Stereo clicks every beat from `first_s` (see [`daemon::demo_track::click_track`]).
pub fn click_track(seconds: f64, bpm: f64, first_s: f64, rate: u32) -> (Vec<f32>, Vec<f64>) {
    daemon::demo_track::click_track(seconds, bpm, first_s, rate)
}

/// Collects every datagram arriving on a socket until `until`, with its arrival time.
pub fn receive(
    socket: UdpSocket,
    until: Instant,
) -> std::thread::JoinHandle<Vec<(Instant, Vec<u8>)>> {
    receive_for(socket, move || Instant::now() < until)
}

/// Collects every datagram arriving on a socket while `listening` holds, with its arrival time.
pub fn receive_while(
    socket: UdpSocket,
    listening: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<Vec<(Instant, Vec<u8>)>> {
    receive_for(socket, move || {
        listening.load(std::sync::atomic::Ordering::Relaxed)
    })
}

fn receive_for(
    socket: UdpSocket,
    go_on: impl Fn() -> bool + Send + 'static,
) -> std::thread::JoinHandle<Vec<(Instant, Vec<u8>)>> {
    std::thread::spawn(move || {
        socket
            .set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        let mut got = Vec::new();
        let mut buf = vec![0u8; 65_536];
        while go_on() {
            if let Ok(n) = socket.recv(&mut buf) {
                got.push((Instant::now(), buf[..n].to_vec()));
            }
        }
        got
    })
}
