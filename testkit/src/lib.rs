//! Helpers for the workspace's tests: skips that say so, and waits with a deadline.
//!
//! A test that needs something outside the repository (the shared data sets in
//! `../shared/data`, liblo's `oscdump`, headless Chromium, a PulseAudio server) and finds it
//! missing calls [`skip`] (or [`require_path`], [`require_shared`], [`require_program`]) and
//! returns. The skip is visible: a line `SKIP <test>: <reason>` goes straight to the process's
//! stderr, past libtest's capture (which only intercepts the `print!`/`eprint!` macros), so it
//! shows in `cargo test`'s output even though the test passes. With `DANCED_REQUIRE_ALL` set (to
//! anything but empty or `0`, as CI does) a skip panics instead, so nothing CI means to test can
//! silently not run.
//!
//! A test that waits for something to happen polls for it with [`wait_until`] and a generous
//! deadline instead of sleeping a fixed time and hoping.
//!
//! ```no_run
//! #[test]
//! fn reads_a_dance() {
//!     let Some(data) = testkit::require_shared("tang2018") else {
//!         return;
//!     };
//!     // ... use data.join("tang2018") ...
//! }
//! ```

#![warn(missing_docs)]

use std::fmt::Display;
use std::io::Write;
use std::panic::Location;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The environment variable that turns every skip into a failure.
pub const REQUIRE_ALL: &str = "DANCED_REQUIRE_ALL";

/// Whether [`REQUIRE_ALL`] is set to something other than empty or `0`.
pub fn require_all() -> bool {
    std::env::var_os(REQUIRE_ALL).is_some_and(|v| !v.is_empty() && v != "0")
}

/// The running test's name (libtest names each test's thread after it), else the caller's
/// source location.
fn test_name(caller: &Location<'_>) -> String {
    match std::thread::current().name() {
        Some(name) if name != "main" => name.to_string(),
        _ => format!("{}:{}", caller.file(), caller.line()),
    }
}

/// Skips the running test for `reason`; the caller then returns.
///
/// Writes `SKIP <test>: <reason>` to stderr directly (not through `eprintln!`, which libtest
/// captures and throws away for a passing test). Panics instead when [`REQUIRE_ALL`] is set.
#[track_caller]
pub fn skip(reason: impl Display) {
    let test = test_name(Location::caller());
    if require_all() {
        panic!("{REQUIRE_ALL} is set and {test} would skip: {reason}");
    }
    let line = format!("SKIP {test}: {reason}\n");
    let _ = std::io::stderr().lock().write_all(line.as_bytes());
}

/// `true` when `path` exists; otherwise skips (see [`skip`]) with "`path` not found (`what`)"
/// and returns `false`.
#[track_caller]
pub fn require_path(path: &Path, what: impl Display) -> bool {
    if path.exists() {
        return true;
    }
    skip(format_args!("{} not found ({what})", path.display()));
    false
}

/// The shared data folder, `shared/data` beside the repository (read-only input for tests and
/// benchmarks; a fresh clone has none).
pub fn shared_data() -> PathBuf {
    // This crate sits one level below the repository root, like every crate of the workspace.
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest
        .parent()
        .and_then(Path::parent)
        .unwrap_or(manifest)
        .join("shared/data")
}

/// The shared data folder when `needed` (a path inside it) exists; otherwise skips (see
/// [`skip`]) and returns `None`.
#[track_caller]
pub fn require_shared(needed: &str) -> Option<PathBuf> {
    let data = shared_data();
    require_path(
        &data.join(needed),
        "the shared data sets, read from shared/data beside the repository",
    )
    .then_some(data)
}

/// The executable `name` found on `PATH`, if any.
pub fn find_program(name: &str) -> Option<PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join(name))
        .find(|p| {
            p.metadata()
                .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
        })
}

/// `true` when the program `name` is on `PATH`; otherwise skips (see [`skip`]) with "`name` is
/// not installed (`install`)" and returns `false`.
#[track_caller]
pub fn require_program(name: &str, install: impl Display) -> bool {
    if find_program(name).is_some() {
        return true;
    }
    skip(format_args!("{name} is not installed ({install})"));
    false
}

/// Polls `condition` every 10 ms until it holds or `timeout` has passed; returns whether it
/// held (checked once more at the deadline). The caller asserts on the result, so a timeout
/// only bounds how long a failing test takes: make it generous (CI is a loaded 2-core machine).
pub fn wait_until(timeout: Duration, mut condition: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + timeout;
    loop {
        if condition() {
            return true;
        }
        if Instant::now() >= deadline {
            return false;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wait_until_returns_when_the_condition_holds() {
        let start = Instant::now();
        let mut n = 0;
        assert!(wait_until(Duration::from_secs(10), || {
            n += 1;
            n == 3
        }));
        assert!(start.elapsed() < Duration::from_secs(5));
        assert!(!wait_until(Duration::from_millis(30), || false));
    }

    #[test]
    fn present_things_are_found() {
        assert!(require_path(
            Path::new(env!("CARGO_MANIFEST_DIR")),
            "this crate"
        ));
        assert!(find_program("sh").is_some());
        assert!(find_program("surely-no-such-program-danced").is_none());
    }
}
