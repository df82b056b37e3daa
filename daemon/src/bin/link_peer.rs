//! `link-peer`: a bare Ableton Link peer for measurements, written against the Link SDK alone
//! (none of danced's code), so what it reports of a session is the SDK's view of it.
//!
//!     link-peer lead BPM SECONDS [AT_S NEW_BPM]   start a session at BPM (and change tempo)
//!     link-peer read QUANTUM SECONDS              print the session's beats as they pass
//!
//! `read` prints one line per beat: `beat N MONO_US TEMPO PEERS`, MONO_US on the
//! CLOCK_MONOTONIC clock in microseconds (what a process beside it can compare with).
//! Run it inside a network namespace of its own: Link talks to every interface.

use std::time::{Duration, Instant};

use rusty_link::{AblLink, SessionState};

fn monotonic_us() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime only writes the struct we pass.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as f64 * 1e6 + ts.tv_nsec as f64 * 1e-3
}

fn arg<T: std::str::FromStr>(args: &[String], i: usize, what: &str) -> T {
    args.get(i)
        .and_then(|a| a.parse().ok())
        .unwrap_or_else(|| usage(what))
}

fn usage(what: &str) -> ! {
    eprintln!(
        "link-peer: {what}\nusage: link-peer lead BPM SECONDS [AT_S NEW_BPM] | link-peer read QUANTUM SECONDS"
    );
    std::process::exit(2)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some("lead") => {
            let bpm: f64 = arg(&args, 2, "BPM");
            let seconds: f64 = arg(&args, 3, "SECONDS");
            let change = (args.len() >= 6).then(|| {
                (
                    arg::<f64>(&args, 4, "AT_S"),
                    arg::<f64>(&args, 5, "NEW_BPM"),
                )
            });
            lead(bpm, seconds, change);
        }
        Some("read") => {
            let quantum: f64 = arg(&args, 2, "QUANTUM");
            let seconds: f64 = arg(&args, 3, "SECONDS");
            read(quantum, seconds);
        }
        _ => usage("lead or read?"),
    }
}

fn lead(bpm: f64, seconds: f64, change: Option<(f64, f64)>) {
    let link = AblLink::new(bpm);
    link.enable(true);
    let start = Instant::now();
    let mut changed = false;
    while start.elapsed().as_secs_f64() < seconds {
        if let Some((at, to)) = change
            && !changed
            && start.elapsed().as_secs_f64() >= at
        {
            let mut state = SessionState::new();
            link.capture_app_session_state(&mut state);
            state.set_tempo(to, link.clock_micros());
            link.commit_app_session_state(&state);
            println!("tempo {to} at {:.0}", monotonic_us());
            changed = true;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    link.enable(false);
}

fn read(quantum: f64, seconds: f64) {
    let link = AblLink::new(120.0);
    link.enable(true);
    // Link's host clock against CLOCK_MONOTONIC, read together.
    let mono_minus_link = monotonic_us() - link.clock_micros() as f64;
    let mut state = SessionState::new();
    let start = Instant::now();
    let mut last_beat: Option<i64> = None;
    while start.elapsed().as_secs_f64() < seconds {
        link.capture_app_session_state(&mut state);
        let now = link.clock_micros();
        let beat = state.beat_at_time(now, quantum).floor() as i64;
        if last_beat.is_some_and(|b| beat > b) {
            let at = state.time_at_beat(beat as f64, quantum) as f64 + mono_minus_link;
            println!(
                "beat {beat} {at:.0} {:.3} {}",
                state.tempo(),
                link.num_peers()
            );
        }
        last_beat = Some(beat);
        std::thread::sleep(Duration::from_millis(1));
    }
    link.enable(false);
}
