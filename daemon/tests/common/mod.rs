//! Helpers shared by the binary's integration tests.
#![allow(dead_code)]

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
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

/// `shared/data` beside the repository, or `None` when `needed` is absent: the test skips (a
/// `SKIP` line, or a failure under `DANCED_REQUIRE_ALL`; see `testkit`).
#[track_caller]
pub fn shared_data(needed: &str) -> Option<PathBuf> {
    testkit::require_shared(needed)
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

/// Datagrams with their arrival times.
pub type Packets = Vec<(Instant, Vec<u8>)>;

/// Datagrams received so far, as the receiving thread collects them (for a test that waits for
/// one to come); the thread takes them back when it ends.
pub type Inbox = Arc<Mutex<Packets>>;

/// Collects every datagram arriving on a socket until `until`, with its arrival time.
pub fn receive(socket: UdpSocket, until: Instant) -> std::thread::JoinHandle<Packets> {
    receive_for(socket, move || Instant::now() < until, Inbox::default())
}

/// Collects every datagram arriving on a socket while `listening` holds, with its arrival time.
pub fn receive_while(
    socket: UdpSocket,
    listening: Arc<AtomicBool>,
) -> std::thread::JoinHandle<Packets> {
    receive_for(
        socket,
        move || listening.load(Ordering::Relaxed),
        Inbox::default(),
    )
}

/// [`receive_while`], also sharing the datagrams as they arrive.
pub fn receive_watched(
    socket: UdpSocket,
    listening: Arc<AtomicBool>,
) -> (Inbox, std::thread::JoinHandle<Packets>) {
    let inbox = Inbox::default();
    let handle = receive_for(
        socket,
        move || listening.load(Ordering::Relaxed),
        inbox.clone(),
    );
    (inbox, handle)
}

fn receive_for(
    socket: UdpSocket,
    go_on: impl Fn() -> bool + Send + 'static,
    inbox: Inbox,
) -> std::thread::JoinHandle<Packets> {
    std::thread::spawn(move || {
        socket
            .set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        let mut buf = vec![0u8; 65_536];
        while go_on() {
            if let Ok(n) = socket.recv(&mut buf) {
                inbox
                    .lock()
                    .unwrap()
                    .push((Instant::now(), buf[..n].to_vec()));
            }
        }
        std::mem::take(&mut *inbox.lock().unwrap())
    })
}
