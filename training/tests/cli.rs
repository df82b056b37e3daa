//! The `danced-train` binary as a user runs it, and the `danced` binary using what it wrote.

use std::path::{Path, PathBuf};
use std::process::Command;

fn danced_train() -> Command {
    Command::new(env!("CARGO_BIN_EXE_danced-train"))
}

/// The `danced` binary of the same build, beside `danced-train` (a workspace build makes both),
/// or `None` when it was not built (the test skips, see `testkit`).
#[track_caller]
fn danced() -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_BIN_EXE_danced-train"))
        .with_file_name(format!("danced{}", std::env::consts::EXE_SUFFIX));
    testkit::require_path(&path, "cargo build -p daemon, or test the workspace").then_some(path)
}

/// Runs `cmd`, asserts that it succeeded (its stderr in the message), and returns its stdout
/// and stderr.
fn succeed(cmd: &mut Command) -> (String, String) {
    let out = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "stderr: {stderr}");
    (String::from_utf8_lossy(&out.stdout).into_owned(), stderr)
}

/// `shared/data` beside the repository, or `None` when `needed` is absent (the test skips, see
/// `testkit`).
#[track_caller]
fn shared_data(needed: &str) -> Option<PathBuf> {
    testkit::require_shared(needed)
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("danced-train-cli-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn the_shipped_recipe_trains_a_model_that_generate_and_bench_use() {
    let Some(data) = shared_data("tang2018") else {
        return;
    };
    let Some(danced) = danced() else {
        return;
    };
    let dir = scratch("train");
    let recipe =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/models/default.recipe.toml");
    // The shipped recipe, every stage cut to 2 steps on a slice of the data; by default and
    // named, the same model.
    let model = dir.join("check.dnn");
    let named = dir.join("named.dnn");
    let (stdout, stderr) = succeed(
        danced_train()
            .args(["dancer", "--check", "2", "--jobs", "2"])
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(&model),
    );
    for stage in ["dance", "keys", "key-weights"] {
        assert!(
            stdout.contains(&format!("{stage}: trained 2 steps")),
            "{stdout}"
        );
    }
    assert!(
        stderr.contains("training by the shipped recipe"),
        "{stderr}"
    );
    assert!(stderr.contains("seed clip: training dance"), "{stderr}");
    succeed(
        danced_train()
            .args(["dancer", "--check", "2", "--jobs", "2", "--recipe"])
            .arg(&recipe)
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(&named),
    );
    let file = model::neural::file::NeuralModel::load(&model).unwrap();
    let again = model::neural::file::NeuralModel::load(&named).unwrap();
    assert_eq!(
        file.tensors, again.tensors,
        "the default is not the shipped recipe"
    );
    assert_eq!(file.training.steps, 6);
    assert!(file.config.key_to_flow && file.config.styles == 0);
    assert!(file.training.data.contains("retimed within each beat"));
    // The recipe is recorded verbatim (after the line that says this was a check), and the
    // data by its hash.
    let text = std::fs::read_to_string(&recipe).unwrap();
    assert!(file.training.recipe.starts_with("# A check of this recipe"));
    assert!(file.training.recipe.ends_with(&text));
    assert!(file.training.data_hash.starts_with("sha256:"));
    assert_eq!(file.training.data_hash.len(), "sha256:".len() + 64);
    assert_eq!(file.training.data_hash, again.training.data_hash);
    // The model file drives generate (through the streaming sampler) and the bench.
    let out = dir.join("gen.bvh");
    let (stdout, _) = succeed(
        Command::new(&danced)
            .arg("generate")
            .arg("--audio")
            .arg(data.join("tang2018/DANCE_W_16/audio.mp3"))
            .args(["--seconds", "4", "--keypose", "pose-2@3"])
            .arg("--model")
            .arg(&model)
            .arg("--out")
            .arg(&out),
    );
    assert!(stdout.contains("by the neural dancer"), "{stdout}");
    assert!(stdout.contains("key pose pose-2 at 3.00 s"), "{stdout}");
    let bvh = model::bvh::Bvh::read(&out).unwrap();
    assert_eq!(bvh.frames.len(), 100);
    assert!(bvh.frames.iter().flatten().all(|v| v.is_finite()));
    let (stdout, _) = succeed(
        Command::new(&danced)
            .args(["bench", "model", "--frames", "50", "--model"])
            .arg(&model),
    );
    assert!(stdout.contains("p99"), "{stdout}");
    // A model file is for the neural source only.
    let run = Command::new(&danced)
        .arg("generate")
        .arg("--audio")
        .arg(data.join("tang2018/DANCE_W_16/audio.mp3"))
        .args(["--source", "retrieval", "--model"])
        .arg(&model)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("neural source"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_recipe_with_an_unknown_setting_is_refused_by_name() {
    let dir = scratch("recipe");
    let recipe = dir.join("r.toml");
    std::fs::write(
        &recipe,
        "[[stage]]\nname = \"a\"\nsteps = 5\nmirror = true\n",
    )
    .unwrap();
    let out = danced_train()
        .args(["dancer", "--recipe"])
        .arg(&recipe)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("unknown field `mirror`"), "{stderr}");
    assert!(stderr.contains("r.toml"), "{stderr}");
    // A flag of the experiments is no option any more.
    let out = danced_train()
        .args(["dancer", "--mirror"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_analysis_networks_train_by_a_recipe_and_the_analysis_reads_them() {
    let Some(data) = shared_data("real-music") else {
        return;
    };
    let dir = scratch("analysis");
    // The shipped recipe's settings on folders every checkout of the shared data has: rendered
    // songs and the real recordings (whose held-out sources must be skipped).
    let shipped = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/analysis.recipe.toml"),
    )
    .unwrap();
    let synth = data.join("synth-beats").display().to_string();
    let real = data.join("real-music").display().to_string();
    let recipe = shipped
        .replace("beat-data/synth-1000", &synth)
        .replace("beat-data/synth-5000", &synth)
        .replace("beat-data/synth-8000", &synth)
        .replace("beat-data/real-extra", &real)
        .replace("../shared/data/real-music", &real);
    let recipe_file = dir.join("analysis.recipe.toml");
    std::fs::write(&recipe_file, recipe).unwrap();
    let beats = dir.join("beats.dnba");
    let (_, stderr) = succeed(
        danced_train()
            .args(["beats", "--check", "3", "--recipe"])
            .arg(&recipe_file)
            .arg("--out")
            .arg(&beats),
    );
    assert!(stderr.contains("analysed"), "{stderr}");
    let ensemble = dsp::BeatNetEnsemble::from_bytes(&std::fs::read(&beats).unwrap()).unwrap();
    assert_eq!(ensemble.nets.len(), 3);
    let downbeats = dir.join("downbeats.dndb");
    succeed(
        danced_train()
            .args(["downbeats", "--check", "3", "--recipe"])
            .arg(&recipe_file)
            .arg("--out")
            .arg(&downbeats),
    );
    let ensemble =
        dsp::DownbeatNetEnsemble::from_bytes(&std::fs::read(&downbeats).unwrap()).unwrap();
    assert_eq!(ensemble.nets.len(), 3);
    // A folder that is missing is named, with where to look for how to make it.
    let missing = std::fs::read_to_string(&recipe_file).unwrap().replacen(
        &format!("folders = [{synth:?}"),
        "folders = [\"no-such-folder\"",
        1,
    );
    std::fs::write(&recipe_file, missing).unwrap();
    let out = danced_train()
        .args(["beats", "--check", "1", "--recipe"])
        .arg(&recipe_file)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("no-such-folder") && stderr.contains("recipe"),
        "{stderr}"
    );
}
