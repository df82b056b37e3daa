//! Varispeed analysis (training's tempo augmentation): a song declared at `speed` times its
//! rate is heard that many times as fast, by the same streaming analysis live runs.

mod common;

use offline::analysis::{AnalyzeOptions, analyze_file_at_speed};

fn median_interval(times: &[f64]) -> f64 {
    let mut d: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

#[test]
fn a_song_played_faster_has_its_beats_closer_and_its_tempo_higher() {
    let rate = 44_100;
    let (samples, _) = common::click_track(24.0, 110.0, 0.5, rate);
    let dir = common::scratch("varispeed");
    let path = dir.join("110bpm.wav");
    common::write_wav(&path, &samples, rate, 2);
    let mut seen = Vec::new();
    for speed in [1.0, 1.25, 0.9] {
        let a = analyze_file_at_speed(
            &path,
            AnalyzeOptions::native(Some(25.0)),
            speed,
            &mut |_, _| {},
        )
        .unwrap();
        assert!(
            (a.duration_s * speed - 24.0).abs() < 0.05,
            "speed {speed}: {} s",
            a.duration_s
        );
        // Beats after the tracker has locked (the last half of the song).
        let late: Vec<f64> = a
            .beats
            .iter()
            .map(|b| b.time_s)
            .filter(|&t| t > a.duration_s / 2.0)
            .collect();
        let period = median_interval(&late);
        let want = 60.0 / 110.0 / speed;
        assert!(
            (period - want).abs() < 0.02,
            "speed {speed}: beats every {period:.3} s, want {want:.3}"
        );
        seen.push(a.features.len());
    }
    // 25 frames a second of the sped-up song.
    assert!(
        (seen[0] as f64 / seen[1] as f64 - 1.25).abs() < 0.02,
        "{seen:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
