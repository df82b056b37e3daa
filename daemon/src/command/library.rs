//! `danced library build`, `danced library poses` and `danced library accompany`: the
//! retrieval dancer's clip library, the key-pose bank picked from it, and rhythm tracks for
//! dances without music.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
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
    /// Cut a clip library and write it: from a folder of your own dances (`--bvh DIR`, any BVH
    /// rig, no music needed: the beat is found from the motion), or from the tang2018 training
    /// split (the shipped one is configs/clips/tang2018-train.danclips).
    Build {
        /// A folder of BVH dances to cut the library from (every .bvh file directly in it).
        #[arg(long, value_name = "DIR")]
        bvh: Option<PathBuf>,
        /// The library's name, as the dancer and the view show it (default: the folder's name).
        #[arg(long)]
        name: Option<String>,
        /// How the dance files' joints and axes are read.
        #[command(flatten)]
        import: super::import_args::ImportArgs,
        /// The shared data folder (holds tang2018/ and tang2018-beats/), without `--bvh`.
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
    /// Render a rhythm track for each dance of a folder, on the beat found from its motion (a
    /// kick on every beat, a backbeat, hats, a bass changing on the bars; louder where the dance
    /// moves harder): `NAME.wav` and `NAME.beats` (time and place in the bar) in `--out`. Play
    /// one with its dance (`danced view DANCE.bvh --audio NAME.wav`) to hear the beat found.
    Accompany {
        /// A folder of BVH dances (every .bvh file directly in it).
        #[arg(long, value_name = "DIR")]
        bvh: PathBuf,
        /// How the dance files' joints and axes are read.
        #[command(flatten)]
        import: super::import_args::ImportArgs,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Draws each track's sounds and chords (the same seed, the same tracks).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Worker threads.
        #[arg(long, default_value_t = 2)]
        jobs: usize,
    },
}

/// Runs `danced library …`.
pub fn library(what: LibraryCommand) -> Result<()> {
    match what {
        LibraryCommand::Build {
            bvh: Some(dir),
            name,
            import,
            out,
            max_poses,
            jobs,
            ..
        } => build_from_moves(&dir, name, &import, &out, max_poses, jobs),
        LibraryCommand::Build {
            bvh: None,
            data,
            out,
            max_poses,
            jobs,
            ..
        } => build(&data, &out, max_poses, jobs),
        LibraryCommand::Poses { out, count } => poses(&out, count),
        LibraryCommand::Accompany {
            bvh,
            import,
            out,
            seed,
            jobs,
        } => accompany(&bvh, &import, &out, seed, jobs),
    }
}

/// `library accompany`: a rhythm track for each dance of a folder.
fn accompany(
    dir: &Path,
    import: &super::import_args::ImportArgs,
    out: &Path,
    seed: u64,
    jobs: usize,
) -> Result<()> {
    use model::metrics::{JointTrack, summed_joint_speed};
    use model::retrieval::RETRIEVAL_FPS;
    use offline::accompaniment::{ACCOMPANIMENT_RATE, accompany, beat_intensity};
    let settings = import.settings()?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let skeleton = model::rig::Skeleton::default_adult();
    println!("| dance | seconds | tempo (BPM) | confidence | bar | beats | track |");
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    let mut written = 0;
    for (i, (path, result)) in offline::moves::read_moves_folder(dir, &settings, jobs)?
        .into_iter()
        .enumerate()
    {
        let dance = match result {
            Ok(d) => d,
            Err(e) => {
                println!("| {} | – | – | – | – | – | not read: {e} |", path.display());
                continue;
            }
        };
        let positions = skeleton.trajectory(&dance.poses);
        let track = JointTrack::new(&positions, model::rig::JOINT_COUNT, RETRIEVAL_FPS)
            .with_context(|| format!("{}", path.display()))?;
        let intensity = beat_intensity(&dance.grid, &summed_joint_speed(&track), RETRIEVAL_FPS);
        let music = accompany(
            &dance.grid,
            &intensity,
            dance.seconds,
            seed.wrapping_add(i as u64),
        );
        let wav = out.join(format!("{}.wav", dance.name));
        write_atomic(
            &wav,
            &offline::files::wav_mono_16(&music.samples, ACCOMPANIMENT_RATE),
        )
        .with_context(|| format!("writing {}", wav.display()))?;
        let beats: String = music
            .beats
            .iter()
            .map(|(t, pos)| format!("{t:.3}\t{pos}\n"))
            .collect();
        let beats_path = out.join(format!("{}.beats", dance.name));
        write_atomic(&beats_path, beats.as_bytes())
            .with_context(|| format!("writing {}", beats_path.display()))?;
        let bar = dance
            .grid
            .beats_per_bar
            .map_or("– (4 assumed)".to_owned(), |b| format!("{b}/4"));
        println!(
            "| {} | {:.1} | {:.1} | {:.2} | {bar} | {} | {} |",
            dance.name,
            dance.seconds,
            dance.grid.tempo_bpm,
            dance.grid.confidence,
            music.beats.len(),
            wav.display()
        );
        written += 1;
    }
    if written == 0 {
        bail!("no dance in {} could be read", dir.display());
    }
    Ok(())
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

/// `library build --bvh DIR`: the library of a folder of dances without music.
fn build_from_moves(
    dir: &Path,
    name: Option<String>,
    import: &super::import_args::ImportArgs,
    out: &Path,
    max_poses: usize,
    jobs: usize,
) -> Result<()> {
    use offline::moves::{MIN_CONFIDENCE, library, read_moves_folder};
    let started = Instant::now();
    let settings = import.settings()?;
    let read = read_moves_folder(dir, &settings, jobs)?;
    let mut dances = Vec::new();
    let mut failed = Vec::new();
    for (path, result) in read {
        match result {
            Ok(d) => dances.push(d),
            Err(e) => failed.push((path, e)),
        }
    }
    let (full, clips) = library(&dances);
    if full.clips.is_empty() {
        let reasons: Vec<String> = failed.iter().map(|(_, e)| e.to_string()).collect();
        bail!(
            "no dance in {} gave a clip ({} could not be read, {} had no beat the motion confirms){}",
            dir.display(),
            failed.len(),
            dances.len(),
            if reasons.is_empty() {
                String::new()
            } else {
                format!(":\n{}", reasons.join("\n"))
            }
        );
    }
    let name = name.unwrap_or_else(|| {
        dir.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "moves".into())
    });
    let library = full.subset(max_poses);
    let kept: Vec<String> = dances
        .iter()
        .zip(&clips)
        .filter(|(_, c)| **c > 0)
        .map(|(d, _)| d.name.clone())
        .collect();
    let meta = moves_metadata(&name, &library, &kept, full.poses.len());
    let bytes = library.to_bytes(&meta);
    write_atomic(out, &bytes).with_context(|| format!("writing {}", out.display()))?;

    println!(
        "| dance | seconds | tempo (BPM) | confidence | bar | clips | joints named as | axes | unit | unmapped joints | bone error, limbs / girdles (°) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for (d, c) in dances.iter().zip(&clips) {
        let bar = d
            .grid
            .beats_per_bar
            .map_or("–".to_owned(), |b| format!("{b}/4"));
        let unmapped = if d.import.unmapped.is_empty() {
            "none".to_owned()
        } else if d.import.unmapped.len() <= 3 {
            d.import.unmapped.join(", ")
        } else {
            format!(
                "{} ({}, …)",
                d.import.unmapped.len(),
                d.import.unmapped[..2].join(", ")
            )
        };
        let clips = if *c > 0 {
            c.to_string()
        } else {
            format!("skipped (confidence < {MIN_CONFIDENCE})")
        };
        println!(
            "| {} | {:.1} | {:.1} | {:.2} | {bar} | {clips} | {} | {} | {} | {unmapped} | {:.1} / {:.1} |",
            d.name,
            d.seconds,
            d.grid.tempo_bpm,
            d.grid.confidence,
            d.import.convention,
            d.import.axes,
            d.import.unit(),
            d.import.bone_error_deg,
            d.import.girdle_error_deg,
        );
    }
    for (_, e) in &failed {
        println!("skipped {e}");
    }
    println!(
        "{}: library {name:?}, {} clips, {} poses ({:.2} MB) from {} of {} dances in {:.1} s",
        out.display(),
        library.clips.len(),
        library.poses.len(),
        bytes.len() as f64 / 1e6,
        kept.len(),
        dances.len() + failed.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Metadata stored in a library cut from a folder of dances: its name and what it was cut from.
fn moves_metadata(
    name: &str,
    library: &model::retrieval::ClipLibrary,
    dances: &[String],
    full_poses: usize,
) -> String {
    let metadata = serde_json::json!({
        "kind": "danced retrieval clip library",
        "name": name,
        "fps": model::retrieval::RETRIEVAL_FPS,
        "clips": library.clips.len(),
        "poses": library.poses.len(),
        "poses_before_subsetting": full_poses,
        "source": "dances without music, cut on the beat found from their motion",
        "dances": dances,
    });
    serde_json::to_string_pretty(&metadata).unwrap_or_default()
}
