//! The shipped dancer: the retrieval dancer playing the clip library that is built into the
//! binary, and the builder that cuts that library from the tang2018 training split.

use std::path::Path;

use anyhow::{Context, Result};
use model::retrieval::{ClipLibrary, RetrievalDancer};
use model::source::MotionSource;

/// The clip library shipped in the repository (`configs/clips/tang2018-train.danclips`).
pub const SHIPPED_CLIPS: &[u8] = include_bytes!("../../configs/clips/tang2018-train.danclips");

/// Path of the shipped library relative to the repository root (for messages and rebuilds).
pub const SHIPPED_CLIPS_PATH: &str = "configs/clips/tang2018-train.danclips";

/// Largest library `danced library build` writes by default, in poses: the whole training split
/// (51 193 poses, 2.6 MB compressed) fits; a smaller library dances measurably worse
/// (`danced eval`: FID_k 181 at 24 000 poses against 34 with all of them).
pub const DEFAULT_MAX_POSES: usize = 80_000;

/// Reads the clip library from `path`, or the shipped one when `path` is `None`.
pub fn load_library(path: Option<&Path>) -> Result<(ClipLibrary, String)> {
    match path {
        None => ClipLibrary::from_bytes(SHIPPED_CLIPS)
            .with_context(|| format!("reading the built-in clip library ({SHIPPED_CLIPS_PATH})")),
        Some(p) => {
            let bytes = std::fs::read(p).with_context(|| format!("reading {}", p.display()))?;
            ClipLibrary::from_bytes(&bytes).with_context(|| format!("reading {}", p.display()))
        }
    }
}

/// The default motion source: the retrieval dancer on the shipped clip library.
pub fn default_source(seed: u64) -> Result<Box<dyn MotionSource + Send>> {
    let (library, _) = load_library(None)?;
    Ok(Box::new(
        RetrievalDancer::new(library, seed).context("starting the retrieval dancer")?,
    ))
}

/// Cuts the full clip library from the training split of `data/tang2018` (fitted, aligned and
/// featurised exactly as `danced dataset build` does); returns it with the dances used.
pub fn training_library(data: &Path, jobs: usize) -> Result<(ClipLibrary, Vec<String>)> {
    let dances = crate::dataset::dances_with_split(data)
        .with_context(|| format!("reading {}", data.join("tang2018").display()))?;
    let built = crate::dataset::build_dances(
        data,
        &dances,
        jobs,
        |dance, validation| !validation && dance.audio.is_some(),
        |_| {},
    );
    let (names, pairs): (Vec<String>, Vec<_>) = built
        .into_iter()
        .filter_map(|(name, r)| {
            let b = r.ok()?;
            Some((name, (b.poses_on_default_rig(), b.music)))
        })
        .unzip();
    anyhow::ensure!(
        !pairs.is_empty(),
        "no training dance with music under {}",
        data.join("tang2018").display()
    );
    Ok((ClipLibrary::from_dances(&pairs), names))
}

/// Metadata stored in a library file: what it was cut from and under which terms.
pub fn library_metadata(library: &ClipLibrary, dances: &[String], full_poses: usize) -> String {
    let names: Vec<String> = dances.iter().map(|n| format!("\"{n}\"")).collect();
    format!(
        "{{\"kind\": \"danced retrieval clip library\", \"fps\": {}, \"clips\": {}, \"poses\": {}, \"poses_before_subsetting\": {full_poses}, \"source\": \"tang2018 (Tang, Jia & Mao, Dance with Melody, ACM MM 2018; public research data), training split of danced dataset v{}\", \"dances\": [{}]}}",
        model::retrieval::RETRIEVAL_FPS,
        library.clips.len(),
        library.poses.len(),
        crate::dataset::DATASET_VERSION,
        names.join(", ")
    )
}
