//! Training data: a tang2018 dance becomes aligned motion and music features.

use std::path::PathBuf;

use dsp::feature::FeatureLayout;
use offline::dataset::{build_dance, is_validation, write_dataset};

#[test]
fn split_is_deterministic_and_stratified_by_style() {
    let names: Vec<String> = [
        "C_2", "C_4", "C_6", "C_7", "C_9", "T_5", "W_1", "W_10", "W_11",
    ]
    .iter()
    .map(|n| format!("DANCE_{n}"))
    .collect();
    let val: Vec<&String> = names.iter().filter(|n| is_validation(n, &names)).collect();
    assert_eq!(val, [&names[2], &names[8]]);
}

/// The shared data folder and its dance DANCE_W_22 (a waltz), or None when the data is absent
/// (the test skips, see `testkit`).
#[track_caller]
fn waltz_22() -> Option<(PathBuf, model::tang2018::TangDance)> {
    let data = testkit::require_shared("tang2018/DANCE_W_22")?;
    let dance = model::tang2018::load_dance(&data.join("tang2018/DANCE_W_22")).unwrap();
    Some((data, dance))
}

#[test]
fn a_dance_builds_into_aligned_finite_features() {
    let Some((data, dance)) = waltz_22() else {
        return;
    };
    let built = build_dance(&dance, &data, false).unwrap();
    assert_eq!(built.motion.len(), built.music.len());
    assert!(
        built.motion.len() + 5 >= dance.frames(),
        "{} of {} frames kept",
        built.motion.len(),
        dance.frames()
    );
    assert!(built.fit_error_cm < 2.5);
    let tempo: Vec<f32> = built
        .music
        .iter()
        .map(|f| f[FeatureLayout::TEMPO])
        .filter(|t| *t > 0.0)
        .collect();
    let median = {
        let mut t = tempo.clone();
        t.sort_by(f32::total_cmp);
        t[t.len() / 2]
    };
    assert!((median - 87.0).abs() < 3.0, "waltz tempo {median}");
    assert!(
        built
            .music
            .iter()
            .flatten()
            .chain(built.motion.iter().flatten())
            .all(|v| v.is_finite())
    );
    let out = std::env::temp_dir().join(format!("danced-ds-{}.npz", std::process::id()));
    write_dataset(&out, &[built]).unwrap();
    let manifest = std::fs::read_to_string(out.with_extension("json")).unwrap();
    assert!(manifest.contains("\"DANCE_W_22\"") && manifest.contains("\"dataset_version\": 2"));
    assert!(std::fs::metadata(&out).unwrap().len() > 100_000);
    std::fs::remove_file(&out).ok();
    std::fs::remove_file(out.with_extension("json")).ok();
}

/// The joint track of `motion` on the default rig, as the eval's speed measure reads it.
fn track(motion: &[model::motion::MotionFeatures]) -> Vec<glam::Vec3> {
    let mut poses = Vec::new();
    model::motion::decode(motion, model::motion::RootState::ORIGIN, &mut poses);
    model::rig::Skeleton::default_adult().trajectory(&poses)
}

#[test]
fn quiet_passages_turn_the_song_down_and_slow_the_dance_to_half_time() {
    let Some((data, dance)) = waltz_22() else {
        return;
    };
    let plain = build_dance(&dance, &data, false).unwrap();
    let quiet = offline::dataset::build_dance_augmented(&dance, &data, false, &[1.0], 2.0)
        .unwrap()
        .pop()
        .unwrap();
    assert_eq!(quiet.motion.len(), plain.motion.len());
    assert_eq!(quiet.music.len(), plain.music.len());
    assert!(plain.quiet.is_empty());
    assert!(!quiet.quiet.is_empty(), "no passage planned");
    let inside = |i: usize| quiet.quiet.iter().any(|&(a, b)| (a..b).contains(&i));
    let first = quiet.quiet[0].0;
    // Before the first passage, the dance is untouched (but for rounding: the motion went
    // through poses and back).
    let moved = quiet.motion[..first]
        .iter()
        .flatten()
        .zip(plain.motion[..first].iter().flatten())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(moved < 1e-3, "moved {moved} before the first passage");
    let energy = |d: &offline::dataset::BuiltDance, keep: &dyn Fn(usize) -> bool| {
        let v: Vec<f32> = (0..d.music.len())
            .filter(|&i| keep(i))
            .map(|i| d.music[i][FeatureLayout::ENERGY])
            .collect();
        v.iter().sum::<f32>() / v.len() as f32
    };
    let drop = energy(&plain, &inside) - energy(&quiet, &inside);
    assert!((6.0..20.0).contains(&drop), "passages {drop:.1} dB quieter");
    let far = |i: usize| quiet.quiet.iter().all(|&(a, b)| i + 25 < a || i > b + 50);
    let elsewhere = energy(&plain, &far) - energy(&quiet, &far);
    assert!(elsewhere.abs() < 0.3, "elsewhere {elsewhere:.2} dB quieter");
    // Half time inside (the edges glide), the same speed elsewhere.
    // The measure of the music table (`danced eval`): mean joint speed in the passages over
    // the rest.
    let spans: Vec<(f64, f64)> = quiet
        .quiet
        .iter()
        .map(|&(a, b)| (a as f64 / 25.0, b as f64 / 25.0))
        .collect();
    let ratio_of = |motion: &[model::motion::MotionFeatures]| {
        let (inside, rest) = daemon::eval::speed_inside_and_out(&track(motion), &spans);
        inside / rest
    };
    let (ratio, plain_ratio) = (ratio_of(&quiet.motion), ratio_of(&plain.motion));
    eprintln!(
        "{} passages: {drop:.1} dB quieter inside, {elsewhere:.2} dB elsewhere; joint speed inside / rest {ratio:.2} (as captured {plain_ratio:.2})",
        quiet.quiet.len()
    );
    assert!(
        ratio < 0.65 * plain_ratio,
        "inside / rest {ratio:.2}, as captured {plain_ratio:.2}"
    );
    assert!(quiet.motion.iter().flatten().all(|v| v.is_finite()));
}
