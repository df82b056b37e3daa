//! `danced dataset audit` and `danced dataset build`: the tang2018 training data, checked and
//! turned into aligned motion and music features.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Subcommand;

use offline::progress::count_bar;

#[derive(Subcommand, Debug)]
/// `danced dataset` subcommands.
pub enum DatasetCommand {
    /// Every dance → motion features on the rig plus the streaming music features of its song,
    /// aligned, at 25 fps, split by dance into train/validation; one .npz + a .json manifest.
    Build {
        /// The shared data folder (holds tang2018/ and tang2018-beats/).
        #[arg(long, default_value = "../shared/data")]
        data: PathBuf,
        /// Output .npz file (a .json manifest is written beside it).
        #[arg(long)]
        out: PathBuf,
        /// Worker threads.
        #[arg(long, default_value_t = 2)]
        jobs: usize,
    },
    /// One row per dance: frames, seconds, rig fit error, bone-length spread, measured music
    /// offset, tempo, and the ground truth's BeatAlign and beat offset.
    Audit {
        /// The shared data folder (holds tang2018/ and tang2018-beats/).
        #[arg(long, default_value = "../shared/data")]
        data: PathBuf,
        /// Worker threads.
        #[arg(long, default_value_t = 2)]
        jobs: usize,
    },
}

/// Runs `danced dataset …`.
pub fn dataset(what: DatasetCommand) -> Result<()> {
    match what {
        DatasetCommand::Audit { data, jobs } => audit(&data, jobs),
        DatasetCommand::Build { data, out, jobs } => build(&data, &out, jobs),
    }
}

fn audit(data: &Path, jobs: usize) -> Result<()> {
    if !data.join("tang2018").is_dir() {
        bail!(
            "{} not found (pass --data DIR; see the README's Data section)",
            data.join("tang2018").display()
        );
    }
    let pb = count_bar(
        model::tang2018::dance_dirs(&data.join("tang2018")).map_or(0, |d| d.len() as u64),
    );
    let started = Instant::now();
    let rows = offline::dataset::audit(data, jobs, &|name| {
        pb.set_message(name.to_string());
        pb.inc(1);
    })
    .with_context(|| format!("reading {}", data.display()))?;
    pb.finish_and_clear();
    print!("{}", offline::dataset::audit_table(&rows));
    for r in rows.iter().filter(|r| r.problem.is_some() && r.frames > 0) {
        eprintln!("{}: {}", r.name, r.problem.as_deref().unwrap_or(""));
    }
    eprintln!(
        "audited {} dances in {:.1} s",
        rows.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

fn build(data: &Path, out: &Path, jobs: usize) -> Result<()> {
    let started = Instant::now();
    let results = offline::dataset::build_all(data, jobs, |_, _| true, true)?;
    let mut built = Vec::new();
    let mut skipped = Vec::new();
    for (name, r) in results {
        match r {
            Ok(d) => built.push(d),
            Err(e) => skipped.push(format!("{name}: {e}")),
        }
    }
    if built.is_empty() {
        bail!(
            "no dance could be built from {}",
            data.join("tang2018").display()
        );
    }
    offline::dataset::write_dataset(out, &built)?;
    let frames = |v: bool| {
        built
            .iter()
            .filter(|d| d.validation == v)
            .map(|d| d.motion.len())
            .sum::<usize>()
    };
    let with_music = built.iter().filter(|d| !d.music.is_empty()).count();
    println!(
        "wrote {} ({} dances, {} with music; train {} frames, validation {} frames: {}) in {:.1} s",
        out.display(),
        built.len(),
        with_music,
        frames(false),
        frames(true),
        built
            .iter()
            .filter(|d| d.validation)
            .map(|d| d.name.as_str())
            .collect::<Vec<_>>()
            .join(" "),
        started.elapsed().as_secs_f64()
    );
    for s in &skipped {
        eprintln!("skipped {s}");
    }
    Ok(())
}
