//! Ableton Link followed and led (builds with the `link` feature): `danced bench clock` runs the
//! pipeline in a network namespace of its own against `link-peer` processes (the Link SDK
//! alone), and its figures must meet the targets. Needs iproute2's `ip` and the right to make
//! a network namespace (root, or unprivileged user namespaces).
#![cfg(feature = "link")]

use std::process::Command;

#[test]
fn a_link_session_is_followed_within_5_ms_and_led_within_20_ms_of_the_music() {
    if !testkit::require_program("ip", "iproute2: apt-get install iproute2") {
        return;
    }
    let dir = std::env::temp_dir().join(format!("danced-link-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let json = dir.join("clock.json");
    let data = testkit::shared_data();
    let out = Command::new(env!("CARGO_BIN_EXE_danced"))
        .args(["bench", "clock", "--quick"])
        .args(["--part", "link-follow", "--part", "link-lead"])
        .arg("--peer")
        .arg(env!("CARGO_BIN_EXE_link-peer"))
        .arg("--data")
        .arg(&data)
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    if stderr.contains("cannot make a private network namespace") {
        testkit::skip(stderr.trim());
        return;
    }
    assert!(
        out.status.success(),
        "{stderr}\n{}",
        String::from_utf8_lossy(&out.stdout)
    );
    eprintln!("{}", String::from_utf8_lossy(&out.stdout));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let follow = &v["link_follow"][0];
    assert!(follow["beats"].as_u64().unwrap() >= 8, "{follow}");
    assert!(follow["offset_ms_p50"].as_f64().unwrap() <= 5.0, "{follow}");
    let lock = follow["lock_after_change_beats"]
        .as_f64()
        .expect("locked again");
    assert!(
        lock <= 1.0,
        "locked {lock} beats after the change: {follow}"
    );
    assert!(
        (follow["tempo_at_end"].as_f64().unwrap() - 140.0).abs() < 0.1,
        "{follow}"
    );
    assert!(follow["peers"].as_u64().unwrap() >= 1, "{follow}");
    assert_eq!(
        follow["beats_off_after_change"].as_u64(),
        Some(0),
        "{follow}"
    );
    assert_eq!(follow["rt_allocations"].as_u64(), Some(0), "{follow}");
    let lead = &v["link_lead"][0];
    assert!(lead["beats"].as_u64().unwrap() >= 8, "{lead}");
    assert!(lead["offset_ms_p50"].as_f64().unwrap() <= 20.0, "{lead}");
    assert!(lead["tempo_error_bpm"].as_f64().unwrap() <= 0.5, "{lead}");
    assert_eq!(lead["rt_allocations"].as_u64(), Some(0), "{lead}");
    let _ = std::fs::remove_dir_all(&dir);
}
