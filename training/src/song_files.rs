//! Finding songs with beat annotations in folders (as `../shared/tools/synth_beats.py` writes
//! them: `NAME.flac|wav|mp3|ogg` beside `NAME.beats`), and the options every command that
//! trains an ensemble on such songs shares.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;

/// How a song-trained ensemble is split, seeded and loaded.
#[derive(Args, Debug, Clone)]
pub struct EnsembleArgs {
    /// Every this many songs, one is held out for validation.
    #[arg(long, default_value_t = 10)]
    pub valid_every: usize,
    /// Seed of batches and initial weights (member i of the ensemble uses seed + i).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Networks trained (one after the other, each with its own seed) and averaged.
    #[arg(long, default_value_t = 3)]
    pub ensemble: usize,
    /// Songs analysed in parallel.
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
}

impl EnsembleArgs {
    /// Whether song `i` (in the order found) is held out for validation.
    pub fn held_out(&self, i: usize) -> bool {
        self.valid_every > 1 && i % self.valid_every == self.valid_every - 1
    }

    /// The seed of ensemble member `member`.
    pub fn member_seed(&self, member: usize) -> u64 {
        self.seed + member as u64
    }

    /// Members to train (at least one).
    pub fn members(&self) -> usize {
        self.ensemble.max(1)
    }
}

/// Every audio file with a `.beats` file beside it in `folders`, sorted within each folder.
pub fn annotated_songs(folders: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut songs = Vec::new();
    for folder in folders {
        let dir = std::fs::read_dir(folder)
            .with_context(|| format!("reading song folder {}", folder.display()))?;
        let mut found = Vec::new();
        for entry in dir {
            let p = entry?.path();
            if is_audio(&p) && p.with_extension("beats").exists() {
                found.push(p);
            }
        }
        found.sort();
        songs.extend(found);
    }
    if songs.len() < 2 {
        bail!(
            "need at least two songs with .beats files in the song folders, found {}",
            songs.len()
        );
    }
    Ok(songs)
}

fn is_audio(p: &Path) -> bool {
    p.extension()
        .is_some_and(|e| ["flac", "wav", "mp3", "ogg"].iter().any(|x| e == *x))
}
