//! The `danced-train` binary as a user runs it, and the `danced` binary using what it wrote.

use std::path::{Path, PathBuf};
use std::process::Command;

fn danced_train() -> Command {
    Command::new(env!("CARGO_BIN_EXE_danced-train"))
}

/// The `danced` binary of the same build, beside `danced-train` (a workspace build makes both),
/// or `None` (with a message) when it was not built.
fn danced() -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_BIN_EXE_danced-train"))
        .with_file_name(format!("danced{}", std::env::consts::EXE_SUFFIX));
    if path.is_file() {
        Some(path)
    } else {
        eprintln!(
            "skipping: {} not built (cargo build -p daemon, or test the workspace)",
            path.display()
        );
        None
    }
}

/// Runs `cmd`, asserts that it succeeded (its stderr in the message), and returns its stdout
/// and stderr.
fn succeed(cmd: &mut Command) -> (String, String) {
    let out = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "stderr: {stderr}");
    (String::from_utf8_lossy(&out.stdout).into_owned(), stderr)
}

/// `../shared/data` beside the repository, or `None` (with a message) when `needed` is absent.
fn shared_data(needed: &str) -> Option<PathBuf> {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data");
    if data.join(needed).is_dir() {
        Some(data)
    } else {
        eprintln!("skipping: {} not found", data.join(needed).display());
        None
    }
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("danced-train-cli-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn train_writes_a_model_that_generate_and_bench_use() {
    let Some(data) = shared_data("tang2018") else {
        return;
    };
    let Some(danced) = danced() else {
        return;
    };
    let dir = scratch("train");
    let model = dir.join("tiny.dnn");
    let (stdout, stderr) = succeed(
        danced_train()
            .args([
                "dancer",
                "--tiny",
                "--max-steps",
                "3",
                "--sequence",
                "16",
                "--jobs",
                "2",
                "--beat-retime",
                "0.2",
                "--style-balance",
                "0.5",
                "--style-drop",
                "0.1",
                "--weight-average",
                "0.5",
            ])
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(&model),
    );
    assert!(stdout.contains("trained 3 steps"), "{stdout}");
    assert!(stderr.contains("seed clip: training dance"), "{stderr}");
    // Balanced: the 25 waltzes no longer take 80 % of the sequences.
    assert!(
        stderr.contains("style shares of sampled sequences: cha-cha"),
        "{stderr}"
    );
    let file = model::neural::file::NeuralModel::load(&model).unwrap();
    assert!(file.training.data.contains("retimed within each beat"));
    assert!(
        file.training
            .recipe
            .ends_with("--style-drop 0.1 --max-steps 3 --weight-average 0.5"),
        "{}",
        file.training.recipe
    );
    // The model is the weights' average; the last step's weights lie beside it.
    assert!(
        stdout.contains("averaged weights (decay 0.5) written"),
        "{stdout}"
    );
    let last = model::neural::file::NeuralModel::load(&dir.join("tiny.last.dnn")).unwrap();
    assert_eq!(last.training.steps, 3);
    let (a, l) = (&file.tensors.map, &last.tensors.map);
    assert_eq!(a.keys().collect::<Vec<_>>(), l.keys().collect::<Vec<_>>());
    assert!(a.iter().any(|(name, t)| t.data != l[name].data));
    assert_eq!(a["seed.motion"], l["seed.motion"]);
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
fn an_unknown_style_to_train_on_is_refused_by_name() {
    let out = danced_train()
        .args(["dancer", "--styles", "chacha,salsa", "--max-steps", "1"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("\"salsa\": a style is chacha, rumba, tango or waltz"),
        "{stderr}"
    );
}
