//! `danced library build` and `danced library poses`: the retrieval dancer's clip library and
//! the key-pose bank picked from it.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Subcommand;

use offline::files::write_atomic;

#[derive(Subcommand, Debug)]
/// `danced library` subcommands.
pub enum LibraryCommand {
    /// Pick the key-pose bank from the shipped clip library: the poses farthest apart, written
    /// as a BVH plus a TOML naming its frames (the shipped one is configs/poses/).
    Poses {
        /// Output folder (bank.bvh and bank.toml are written there).
        #[arg(long)]
        out: PathBuf,
        /// How many poses.
        #[arg(long, default_value_t = 16)]
        count: usize,
    },
    /// Cut the clip library from the tang2018 training split and write it (the shipped one is
    /// configs/clips/tang2018-train.danclips).
    Build {
        /// The shared data folder (holds tang2018/ and tang2018-beats/).
        #[arg(long, default_value = "../shared/data")]
        data: PathBuf,
        /// Output file.
        #[arg(long)]
        out: PathBuf,
        /// Keep at most this many poses, in runs of clips spread over the library.
        #[arg(long, default_value_t = crate::dancer::DEFAULT_MAX_POSES)]
        max_poses: usize,
        /// Worker threads.
        #[arg(long, default_value_t = 2)]
        jobs: usize,
    },
}

/// Runs `danced library …`.
pub fn library(what: LibraryCommand) -> Result<()> {
    match what {
        LibraryCommand::Build {
            data,
            out,
            max_poses,
            jobs,
        } => build(&data, &out, max_poses, jobs),
        LibraryCommand::Poses { out, count } => poses(&out, count),
    }
}

fn poses(out: &Path, count: usize) -> Result<()> {
    use crate::pose_bank::{bank_toml, pick_diverse_poses};
    let (library, _) = crate::dancer::load_library(None)?;
    let poses = pick_diverse_poses(&library, count);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let skeleton = model::rig::Skeleton::default_adult();
    let bvh = out.join("bank.bvh");
    model::bvh::export(&skeleton, &poses, 1.0)
        .write(&bvh)
        .with_context(|| format!("writing {}", bvh.display()))?;
    let toml = out.join("bank.toml");
    write_atomic(&toml, bank_toml(&poses, "bank.bvh").as_bytes())
        .with_context(|| format!("writing {}", toml.display()))?;
    for (i, p) in poses.iter().enumerate() {
        println!("pose-{}: {}", i + 1, crate::pose_bank::describe(p));
    }
    Ok(())
}

fn build(data: &Path, out: &Path, max_poses: usize, jobs: usize) -> Result<()> {
    let started = Instant::now();
    let (full, names) = crate::dancer::training_library(data, jobs)?;
    let library = full.subset(max_poses);
    let meta = crate::dancer::library_metadata(&library, &names, full.poses.len());
    let bytes = library.to_bytes(&meta);
    write_atomic(out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    println!(
        "{}: {} clips, {} poses ({:.2} MB) from {} training dances (full library {} clips, {} poses) in {:.1} s",
        out.display(),
        library.clips.len(),
        library.poses.len(),
        bytes.len() as f64 / 1e6,
        names.len(),
        full.clips.len(),
        full.poses.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
