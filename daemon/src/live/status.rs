//! The live status line on stderr: rewritten in place about 4 times a second on a terminal,
//! a plain line every 5 s otherwise (logs stay readable).

use std::io::{IsTerminal, Write};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use super::stats::{KEY_POSE_PENDING, KEY_POSE_REACHED, Stats};

/// One status line from the current counters.
pub fn status_line(stats: &Stats) -> String {
    let key = match stats.key_pose_state.load(Ordering::Relaxed) {
        KEY_POSE_PENDING => format!(
            "pending ({} frames)",
            stats.key_pose_frames_to_go.load(Ordering::Relaxed)
        ),
        KEY_POSE_REACHED => "reached".to_string(),
        _ => "none".to_string(),
    };
    let accent = match stats.beat_accent.get() {
        a if a.is_finite() => format!("{a:.2}"),
        _ => "–".to_string(),
    };
    let paused = if stats.paused.load(Ordering::Relaxed) == 1 {
        " PAUSED"
    } else {
        ""
    };
    let style = match stats.style_danced() {
        Some(s) if stats.style_auto.load(Ordering::Relaxed) == 1 => format!("{} (auto)", s.name()),
        Some(s) => s.name().to_string(),
        None => "–".to_string(),
    };
    let route = stats.key_route().map_or("–", |r| r.name());
    let moves = stats
        .moves_danced()
        .map(|m| format!(" | moves {m}"))
        .unwrap_or_default();
    let c = &stats.clock;
    let clock = match c.source() {
        super::clock::ClockSource::Audio => String::new(),
        source => {
            let offset = c
                .offset()
                .map(|o| format!(", heard {o:+.0} ms"))
                .unwrap_or_default();
            let peers = match c.peers.load(Ordering::Relaxed) {
                0 => String::new(),
                n => format!(", {n} peers"),
            };
            format!(
                " | {} clock {:.1} BPM{offset}{peers}",
                source.name(),
                c.tempo_bpm.get()
            )
        }
    };
    let nudge = match c.nudge_ms.get() {
        n if n != 0.0 => format!(" | nudged {n:+.0} ms"),
        _ => String::new(),
    };
    format!(
        "tempo {:5.1} BPM{clock}{nudge} | beat {:.2} | latency p99 {:5.1} ms | temp {:.2} | accent {accent} | style {style}{moves} | key pose {key} ({route}) | drops {} | packets {}{paused}",
        stats.tempo_bpm.get(),
        stats.beat_phase.get(),
        stats.latency.quantile_ms(0.99),
        stats.temperature.get(),
        stats.dropped_frames(),
        stats.packets_sent.load(Ordering::Relaxed),
    )
}

/// Prints the status line at the right pace for where stderr goes.
#[derive(Debug)]
pub struct StatusPrinter {
    tty: bool,
    last: Option<Instant>,
    printed: bool,
}

impl Default for StatusPrinter {
    fn default() -> Self {
        Self::new()
    }
}

impl StatusPrinter {
    /// A printer for this process's stderr.
    pub fn new() -> Self {
        Self {
            tty: std::io::stderr().is_terminal(),
            last: None,
            printed: false,
        }
    }

    /// How often the caller should call [`StatusPrinter::tick`].
    pub fn interval(&self) -> Duration {
        Duration::from_millis(250)
    }

    /// Prints the line if it is due.
    pub fn tick(&mut self, stats: &Stats) {
        let every = if self.tty {
            Duration::from_millis(250)
        } else {
            Duration::from_secs(5)
        };
        if self.last.is_some_and(|l| l.elapsed() < every) {
            return;
        }
        self.last = Some(Instant::now());
        let line = status_line(stats);
        let mut err = std::io::stderr().lock();
        let _ = if self.tty {
            write!(err, "\r\x1b[2K{line}")
        } else {
            writeln!(err, "{line}")
        };
        let _ = err.flush();
        self.printed = true;
    }

    /// Ends the in-place line so later output starts on a fresh line.
    pub fn finish(&mut self) {
        if self.tty && self.printed {
            eprintln!();
        }
    }
}
