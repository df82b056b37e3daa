//! Recipes of the analysis' networks: what `danced-train beats` and `danced-train downbeats`
//! train, on which songs, as a TOML file. The shipped networks' recipe
//! (`configs/analysis.recipe.toml`) is built in: it is what runs without one.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::error::TrainingError;
use crate::recipe::{parse_recipe, read_recipe_text};

/// The shipped analysis networks' recipe, verbatim.
pub const SHIPPED_ANALYSIS_RECIPE: &str = include_str!("../../configs/analysis.recipe.toml");

/// Where [`SHIPPED_ANALYSIS_RECIPE`] lives in the repository (for messages).
pub const SHIPPED_ANALYSIS_RECIPE_PATH: &str = "configs/analysis.recipe.toml";

/// The recipe of both analysis networks.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnalysisRecipe {
    /// The learned beat activation.
    pub beats: BeatRecipe,
    /// The downbeat network.
    pub downbeats: DownbeatRecipe,
}

/// Folders of songs a network trains on as one pool, and how.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SongFolder {
    /// The folders, their songs taken in this order: `NAME.flac|wav|mp3|ogg` beside
    /// `NAME.beats`; relative to where the command runs. Recordings of the held-out sources
    /// (`offline::real_music`) in them are skipped.
    pub folders: Vec<PathBuf>,
    /// Relative share of training batches drawn from this pool (shares are normalised).
    #[serde(default = "defaults::share")]
    pub share: f64,
    /// Copies of each song heard through a drawn recording condition (level, equalisation,
    /// band limit, compression, room, crowd), besides the song as it is.
    #[serde(default)]
    pub copies: usize,
}

/// How an ensemble is trained: members, seeds and validation.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnsembleSettings {
    /// Networks trained one after the other (seeds `seed`, `seed + 1`, ...) and averaged.
    pub members: usize,
    /// Seed of the first member's initial weights and batches, and of the recording conditions.
    pub seed: u64,
    /// Every this many songs of a pool, one is kept for validation (0: none).
    pub valid_every: usize,
}

impl EnsembleSettings {
    /// The seed of ensemble member `member` (counting from 0).
    pub fn member_seed(&self, member: usize) -> u64 {
        self.seed + member as u64
    }
}

/// The learned beat activation's recipe.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BeatRecipe {
    /// The songs.
    pub songs: Vec<SongFolder>,
    /// Members and seeds.
    pub ensemble: EnsembleSettings,
    /// Optimiser steps per network.
    pub steps: usize,
    /// Hidden channels.
    pub channels: usize,
    /// Kernel size of the dilated convolutions.
    pub kernel: usize,
    /// Dilation of each layer.
    pub dilations: Vec<usize>,
    /// Hops per training sequence.
    pub sequence: usize,
    /// Sequences per batch.
    pub batch: usize,
    /// Peak Adam learning rate (cosine decay to a tenth).
    pub learning_rate: f64,
}

/// The downbeat network's recipe.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DownbeatRecipe {
    /// The songs (their `.beats` files give each beat's position in the bar).
    pub songs: Vec<SongFolder>,
    /// Members and seeds.
    pub ensemble: EnsembleSettings,
    /// Optimiser steps per network.
    pub steps: usize,
    /// Width of each hidden layer.
    pub hidden: Vec<usize>,
    /// Rows per batch.
    pub batch: usize,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// Standard deviation of the noise added to the inputs.
    pub input_noise: f32,
}

mod defaults {
    pub fn share() -> f64 {
        1.0
    }
}

impl AnalysisRecipe {
    /// The shipped networks' recipe.
    pub fn shipped() -> Self {
        Self::parse(SHIPPED_ANALYSIS_RECIPE, SHIPPED_ANALYSIS_RECIPE_PATH)
            .expect("the shipped analysis recipe is valid (tested)")
    }

    /// The recipe in `path`, or the shipped one when there is none.
    pub fn read_or_shipped(path: Option<&Path>) -> Result<Self, TrainingError> {
        match path {
            Some(p) => Self::parse(&read_recipe_text(p)?, &p.display().to_string()),
            None => Ok(Self::shipped()),
        }
    }

    /// Parses and checks a recipe's text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, TrainingError> {
        parse_recipe(text, origin, Self::check)
    }

    fn check(&self) -> Result<(), String> {
        check_songs("beats", &self.beats.songs)?;
        check_songs("downbeats", &self.downbeats.songs)?;
        for (name, e) in [
            ("beats", &self.beats.ensemble),
            ("downbeats", &self.downbeats.ensemble),
        ] {
            if !(1..=16).contains(&e.members) {
                return Err(format!("{name}.ensemble.members must be in 1..=16"));
            }
        }
        let b = &self.beats;
        if b.steps == 0 || b.batch == 0 || b.sequence < 16 {
            return Err("beats: steps and batch must be at least 1, sequence at least 16".into());
        }
        if !(1..=256).contains(&b.channels) || !(1..=16).contains(&b.kernel) {
            return Err("beats: channels must be in 1..=256 and kernel in 1..=16".into());
        }
        if b.dilations.len() > 32 || b.dilations.iter().any(|&d| !(1..=1024).contains(&d)) {
            return Err("beats: at most 32 dilations, each in 1..=1024".into());
        }
        let d = &self.downbeats;
        if d.steps == 0 || d.batch == 0 || d.hidden.is_empty() || d.hidden.contains(&0) {
            return Err(
                "downbeats: steps and batch must be at least 1, hidden a list of widths ≥ 1".into(),
            );
        }
        if !(d.input_noise.is_finite() && d.input_noise >= 0.0) {
            return Err("downbeats: input_noise must be ≥ 0".into());
        }
        for (name, lr) in [("beats", b.learning_rate), ("downbeats", d.learning_rate)] {
            if !(lr.is_finite() && lr > 0.0 && lr < 1.0) {
                return Err(format!("{name}.learning_rate must be in (0, 1)"));
            }
        }
        Ok(())
    }
}

fn check_songs(name: &str, songs: &[SongFolder]) -> Result<(), String> {
    if songs.is_empty() {
        return Err(format!(
            "{name}: a recipe needs at least one [[{name}.songs]] pool"
        ));
    }
    for s in songs {
        if s.folders.is_empty() {
            return Err(format!("{name}: every [[{name}.songs]] pool needs folders"));
        }
        if !(s.share.is_finite() && s.share > 0.0) {
            return Err(format!(
                "{name}: share of {} must be > 0",
                s.folders[0].display()
            ));
        }
        if s.copies > 16 {
            return Err(format!(
                "{name}: copies of {} must be at most 16",
                s.folders[0].display()
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_recipe_parses() {
        let r = AnalysisRecipe::shipped();
        assert!(!r.beats.songs.is_empty() && !r.downbeats.songs.is_empty());
    }

    #[test]
    fn unknown_and_out_of_range_settings_are_refused_by_name() {
        let bad = SHIPPED_ANALYSIS_RECIPE.replacen("[beats]", "[beats]\nmirror = true", 1);
        let e = AnalysisRecipe::parse(&bad, "x.toml").unwrap_err();
        assert!(e.message.contains("mirror"), "{}", e.message);
        let bad = SHIPPED_ANALYSIS_RECIPE.replacen("copies = 3", "copies = 30", 1);
        let e = AnalysisRecipe::parse(&bad, "x.toml").unwrap_err();
        assert!(e.message.contains("copies"), "{}", e.message);
        let bad = SHIPPED_ANALYSIS_RECIPE.replacen("copies = 3", "copies = 3\nshare = -1", 1);
        let e = AnalysisRecipe::parse(&bad, "x.toml").unwrap_err();
        assert!(e.message.contains("share"), "{}", e.message);
    }
}
