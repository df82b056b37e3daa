//! Training data: a tang2018 dance becomes aligned motion and music features.

use std::path::Path;

use daemon::dataset::{build_dance, is_validation, write_dataset};
use dsp::feature::FeatureLayout;

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

#[test]
fn a_dance_builds_into_aligned_finite_features() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data");
    let dir = data.join("tang2018/DANCE_W_22");
    if !dir.is_dir() {
        eprintln!("skipping: {} not found", dir.display());
        return;
    }
    let dance = model::tang2018::load_dance(&dir).unwrap();
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
