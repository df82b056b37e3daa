//! The songs a recipe of the analysis networks names: found in their folders (as
//! `../shared/tools/synth_beats.py` writes them: `NAME.flac|wav|mp3|ogg` beside `NAME.beats`),
//! split into training and validation, and analysed as they are and through drawn recording
//! conditions.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use model::neural::rng::Rng;
use offline::analysis::{AnalyzeOptions, FileAnalysis, analyze_file, analyze_samples};
use offline::recording_condition::RecordingCondition;

use crate::analysis_recipe::{EnsembleSettings, SongFolder};

/// One analysis to run: a song, heard as it is or through a recording condition.
#[derive(Clone, Debug)]
pub struct SongHearing {
    /// The audio file (its `.beats` file lies beside it).
    pub audio: PathBuf,
    /// The condition it is heard through (`None`: as it is).
    pub condition: Option<RecordingCondition>,
    /// Index of the song pool in the recipe.
    pub pool: usize,
    /// Whether it validates rather than trains.
    pub validation: bool,
}

/// Songs per folder a quick check of a recipe analyses.
const CHECK_SONGS_PER_FOLDER: usize = 3;

/// Every hearing of every song of `folders`: each training song as it is and through
/// `copies` drawn conditions, each validation song as it is. Recordings of held-out sources
/// are left out; a quick `check` keeps the first [`CHECK_SONGS_PER_FOLDER`] of each folder.
/// Validation songs are every `valid_every`-th of a pool, counting across its folders.
pub fn hearings(
    folders: &[SongFolder],
    ensemble: &EnsembleSettings,
    check: bool,
) -> Result<Vec<SongHearing>> {
    let mut rng = Rng::new(ensemble.seed ^ 0x5eed_c0de);
    let mut out = Vec::new();
    for (f, folder) in folders.iter().enumerate() {
        let mut songs = Vec::new();
        for dir in &folder.folders {
            let mut found = annotated_songs(dir)?;
            if check {
                found.truncate(CHECK_SONGS_PER_FOLDER);
            }
            songs.extend(found);
        }
        for (i, audio) in songs.into_iter().enumerate() {
            let every = ensemble.valid_every;
            let validation = every > 1 && i % every == every - 1;
            out.push(SongHearing {
                audio: audio.clone(),
                condition: None,
                pool: f,
                validation,
            });
            if validation {
                continue;
            }
            for _ in 0..folder.copies {
                out.push(SongHearing {
                    audio: audio.clone(),
                    condition: Some(RecordingCondition::draw(&mut rng)),
                    pool: f,
                    validation: false,
                });
            }
        }
    }
    if out.iter().filter(|h| !h.validation).count() < 1 {
        bail!("no training songs in the recipe's folders");
    }
    Ok(out)
}

/// Every audio file with a `.beats` file beside it in `folder`, sorted, held-out sources left
/// out.
pub fn annotated_songs(folder: &Path) -> Result<Vec<PathBuf>> {
    let dir = std::fs::read_dir(folder).with_context(|| {
        format!(
            "reading song folder {} (see the recipe's comments for how to make it)",
            folder.display()
        )
    })?;
    let mut found = Vec::new();
    for entry in dir {
        let p = entry?.path();
        if offline::decode::is_audio_file(&p)
            && p.with_extension("beats").exists()
            && !offline::real_music::is_held_out(&p)
        {
            found.push(p);
        }
    }
    found.sort();
    if found.is_empty() {
        bail!("no songs with .beats files in {}", folder.display());
    }
    Ok(found)
}

/// Analyses a hearing with the analysis that runs live.
pub fn analyse(hearing: &SongHearing, options: AnalyzeOptions) -> Result<FileAnalysis> {
    let audio = &hearing.audio;
    let analysis = match &hearing.condition {
        None => analyze_file(audio, options, &mut |_, _| {}),
        Some(condition) => {
            let decoded = offline::decode::decode_file(audio)
                .with_context(|| format!("decoding {}", audio.display()))?;
            let mut mono = offline::decode::mono_mix(&decoded.samples, decoded.channels);
            condition.apply(&mut mono, decoded.sample_rate);
            analyze_samples(
                &audio.display().to_string(),
                &mono,
                decoded.sample_rate,
                1,
                options,
            )
        }
    };
    analysis.with_context(|| format!("analysing {}", audio.display()))
}
