//! End-to-end analysis: audio in (synthesised, or recorded from `../shared/data` when present),
//! beats, onsets and feature frames out, scored against known answers.

use std::path::PathBuf;

use daemon::demo_track::{DEMO_RATE, demo_track};
use dsp::feature::{FEATURE_DIM, FeatureLayout};
use dsp::metrics;
use offline::analysis::{AnalyzeOptions, analyze_file, analyze_samples};

fn options(model_rate: Option<f64>) -> AnalyzeOptions {
    AnalyzeOptions {
        tracker: dsp::BeatTrackerKind::Native,
        model_rate,
        ..AnalyzeOptions::default()
    }
}

/// `shared/data` beside the repository when `needed` is in it; else the test skips (see
/// `testkit`).
#[track_caller]
fn shared_data(needed: &str) -> Option<PathBuf> {
    testkit::require_shared(needed)
}

#[test]
fn demo_song_beats_bars_and_features() {
    let demo = demo_track(30.0);
    let a = analyze_samples("demo", &demo.samples, DEMO_RATE, 2, options(Some(30.0))).unwrap();
    let est: Vec<f64> = a.beats.iter().map(|b| b.time_s).collect();
    let scores = metrics::evaluate_beats(&demo.beats, &est);
    assert!(scores.f_measure > 0.95, "F {}", scores.f_measure);
    assert!(
        (a.median_tempo() - 124.0).abs() < 1.5,
        "tempo {}",
        a.median_tempo()
    );
    // Every beat is decided at most 50 ms after it happens.
    assert!(a.beats.iter().all(|b| b.decided_at_s - b.time_s <= 0.05));
    // After the first bars the bar count matches the song's.
    let late: Vec<_> = a.beats.iter().filter(|b| b.time_s > 12.0).collect();
    let mut right = 0;
    for b in &late {
        let k = ((b.time_s - demo.beats[0]) / (60.0 / 124.0)).round() as usize;
        if b.beats_per_bar == 4
            && b.beat_in_bar == demo.beat_in_bar[k.min(demo.beat_in_bar.len() - 1)]
        {
            right += 1;
        }
    }
    assert!(
        right as f64 >= 0.9 * late.len() as f64,
        "bar position right on {right} of {} beats",
        late.len()
    );
    // Feature frames: one per 1/30 s, finite, documented layout.
    assert!(
        (a.features.len() as i64 - 900).abs() <= 2,
        "{} frames",
        a.features.len()
    );
    for (i, f) in a.features.iter().enumerate() {
        assert_eq!(f.index, i as u64);
        assert!(f.values.iter().all(|v| v.is_finite()));
        let s = f.values[FeatureLayout::BEAT_SIN];
        let c = f.values[FeatureLayout::BEAT_COS];
        assert!((s * s + c * c - 1.0).abs() < 1e-3);
    }
    assert_eq!(FeatureLayout::names().len(), FEATURE_DIM);
    // The song is in C major: C, E, G and A dominate the mean chroma (C G Am F).
    let mut chroma = [0.0f32; 12];
    for f in &a.features {
        for (k, c) in chroma.iter_mut().enumerate() {
            *c += f.values[FeatureLayout::CHROMA + k];
        }
    }
    let mut order: Vec<usize> = (0..12).collect();
    order.sort_by(|&x, &y| chroma[y].total_cmp(&chroma[x]));
    for pc in &order[..4] {
        assert!(
            [0, 4, 5, 7, 9, 11, 2].contains(pc),
            "pitch class {pc} is among the strongest: {chroma:?}"
        );
    }
}

/// Mean of feature `k` over the frames from `a_s` to `b_s` (stream seconds).
fn mean_between(frames: &[dsp::FeatureFrame], k: usize, a_s: f64, b_s: f64) -> f32 {
    let inside: Vec<f32> = frames
        .iter()
        .filter(|f| (a_s..b_s).contains(&f.time_s))
        .map(|f| f.values[k])
        .collect();
    inside.iter().sum::<f32>() / inside.len().max(1) as f32
}

#[test]
fn the_relative_level_tells_a_breakdown_from_a_quietly_mastered_song() {
    let demo = demo_track(30.0);
    let gain = |db: f32| 10f32.powf(db / 20.0);
    let quiet_song: Vec<f32> = demo.samples.iter().map(|x| x * gain(-12.0)).collect();
    let mut breakdown = demo.samples.clone();
    let channels = 2;
    for (i, x) in breakdown.iter_mut().enumerate() {
        let t = (i / channels) as f64 / f64::from(DEMO_RATE);
        if (14.0..20.0).contains(&t) {
            *x *= gain(-12.0);
        }
    }
    let run = |samples: &[f32]| {
        analyze_samples(
            "demo",
            samples,
            DEMO_RATE,
            channels as u16,
            options(Some(25.0)),
        )
        .unwrap()
        .features
    };
    let (loud, quiet, broken) = (run(&demo.samples), run(&quiet_song), run(&breakdown));
    let level = FeatureLayout::RELATIVE_LEVEL;
    let energy = FeatureLayout::ENERGY;
    // The quietly mastered song and the breakdown sit at one absolute level...
    let quiet_energy = mean_between(&quiet, energy, 15.0, 20.0);
    let breakdown_energy = mean_between(&broken, energy, 15.0, 20.0);
    assert!(
        (quiet_energy - breakdown_energy).abs() < 1.0,
        "{quiet_energy} against {breakdown_energy} dBFS"
    );
    // ...but only the breakdown is quieter than before.
    let steady = mean_between(&quiet, level, 15.0, 20.0);
    let dropped = mean_between(&broken, level, 15.0, 20.0);
    assert!(steady > -4.0, "steady song {steady} dB below its peak");
    let loud_steady = mean_between(&loud, level, 15.0, 20.0);
    assert!(
        (steady - loud_steady).abs() < 0.5,
        "the mastering moves it: {steady} against {loud_steady} dB"
    );
    assert!(
        dropped < steady - 8.0,
        "breakdown {dropped} dB, steady {steady} dB"
    );
    // A second after the music returns, it reads as loud as the unbroken song.
    let back = mean_between(&broken, level, 21.0, 26.0);
    let unbroken = mean_between(&loud, level, 21.0, 26.0);
    assert!(
        (back - unbroken).abs() < 0.5,
        "{back} against {unbroken} dB"
    );
}

#[test]
fn hand_annotated_onsets_are_found() {
    let Some(data) = shared_data("madmom-tests") else {
        return;
    };
    let dir = data.join("madmom-tests");
    let a = analyze_file(&dir.join("sample.wav"), options(None), &mut |_, _| {}).unwrap();
    let reference = offline::files::read_times(&dir.join("sample.onsets")).unwrap();
    let est: Vec<f64> = a.onsets.iter().map(|o| o.time_s).collect();
    let s = metrics::onset_f_measure(&reference, &est, metrics::ONSET_TOLERANCE_S);
    assert!(s.f_measure > 0.9, "onset F {}", s.f_measure);
    // The same signal at 22 050 Hz gives the same onsets.
    let b = analyze_file(&dir.join("sample_22050.wav"), options(None), &mut |_, _| {}).unwrap();
    let est_b: Vec<f64> = b.onsets.iter().map(|o| o.time_s).collect();
    assert!(metrics::onset_f_measure(&est, &est_b, 0.02).f_measure > 0.9);
}

#[test]
fn synthetic_songs_with_exact_beats_are_tracked() {
    let Some(data) = shared_data("synth-beats") else {
        return;
    };
    // A spread of styles: a regression guard, not the benchmark (`danced bench beats` is).
    let songs = [
        "synth_004_115bpm_4-4_chacha",
        "synth_005_94bpm_3-4_folk34",
        "synth_012_162bpm_3-4_jazzwaltz",
        "synth_017_123bpm_4-4_bossa",
    ];
    let mut total = 0.0;
    for song in songs {
        let audio = data.join("synth-beats").join(format!("{song}.flac"));
        let reference = offline::files::read_times(&audio.with_extension("beats")).unwrap();
        let a = analyze_file(&audio, options(None), &mut |_, _| {}).unwrap();
        let est: Vec<f64> = a
            .beats
            .iter()
            .filter(|b| b.decided_at_s - b.time_s <= 0.05)
            .map(|b| b.time_s)
            .collect();
        let f = metrics::evaluate_beats(&reference, &est).f_measure;
        eprintln!("{song}: F {f:.3}");
        total += f;
    }
    assert!(
        total / songs.len() as f64 > 0.9,
        "mean F {}",
        total / songs.len() as f64
    );
}

#[test]
fn unreadable_files_give_errors_that_name_them() {
    let dir = std::env::temp_dir().join(format!("danced-analysis-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let empty = dir.join("empty.wav");
    std::fs::write(&empty, b"").unwrap();
    let text = dir.join("notes.mp3");
    std::fs::write(&text, "this is not audio\n".repeat(100)).unwrap();
    for p in [dir.join("missing.flac"), empty, text] {
        let e = analyze_file(&p, options(None), &mut |_, _| {})
            .unwrap_err()
            .to_string();
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        assert!(e.contains(&name), "error {e:?} does not name {name}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
