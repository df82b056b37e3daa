//! The shipped dancers: the neural dancer with the model built into the binary, the retrieval
//! dancer playing the clip library built into the binary, and the builder that cuts that
//! library from the tang2018 training split.

use std::path::Path;

use anyhow::{Context, Result, bail};
use model::neural::dancer::NeuralDancer;
use model::neural::file::NeuralModel;
use model::neural::safety::SafetyNets;
use model::retrieval::{ClipLibrary, RetrievalDancer};
use model::source::MotionSource;
use model::stage::{StageSettings, StagedSource};

/// The neural dance model shipped in the repository (`configs/models/default.dnn`).
pub const SHIPPED_MODEL: &[u8] = include_bytes!("../../configs/models/default.dnn");

/// Path of the shipped model relative to the repository root (for messages).
pub const SHIPPED_MODEL_PATH: &str = "configs/models/default.dnn";

/// Which motion source drives the character.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SourceKind {
    /// The causal transformer with a normalizing-flow head (`configs/models/default.dnn`).
    Neural,
    /// One-beat clips of the training dances, time-warped to the live beat.
    Retrieval,
}

impl SourceKind {
    /// The source `run`, `demo` and `generate` use when none is named.
    pub const DEFAULT: SourceKind = SourceKind::Neural;

    /// Every source, for messages.
    pub const NAMES: &str = "neural, retrieval";

    /// The source called `name` in configuration files and on the command line.
    pub fn parse(name: &str) -> Option<SourceKind> {
        match name {
            "neural" => Some(SourceKind::Neural),
            "retrieval" => Some(SourceKind::Retrieval),
            _ => None,
        }
    }

    /// The name `parse` accepts.
    pub fn name(self) -> &'static str {
        match self {
            SourceKind::Neural => "neural",
            SourceKind::Retrieval => "retrieval",
        }
    }
}

/// Where a source's data comes from (`None` = the one built into danced) and how it dances.
#[derive(Clone, Debug, Default)]
pub struct SourceSettings<'a> {
    /// Depth of the neural dancer's beat accent (`None`: its default,
    /// [`model::neural::dancer::BEAT_ACCENT`]).
    pub beat_accent: Option<f32>,
    /// Share of a planted foot's slide the neural dancer's stance leg holds (`None`: its
    /// default, [`model::foot_lock::DEFAULT_PLANT`]).
    pub foot_plant: Option<f32>,
    /// Neural model file.
    pub model: Option<&'a Path>,
    /// Clip libraries of the retrieval dancer, the first danced first (none: the built-in).
    pub libraries: &'a [LibraryChoice],
    /// The neural network alone: every safety net off but the non-finite guard.
    pub network_only: bool,
    /// Where the neural dancer sends key poses (`None`: its default, the overlay).
    pub key_route: Option<model::source::KeyPoseRoute>,
    /// Where on the floor it dances.
    pub stage: StageSettings,
}

/// One clip library the retrieval dancer holds: its file and, optionally, the name performers
/// switch to it by (default: the name it was built with, else its file name).
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LibraryChoice {
    /// The library file (`danced library build` writes them).
    pub path: std::path::PathBuf,
    /// Its name for `/danced/control/moves`, the status line and the view.
    pub name: Option<String>,
}

impl LibraryChoice {
    /// A library file with no name of its own.
    pub fn file(path: impl Into<std::path::PathBuf>) -> Self {
        LibraryChoice {
            path: path.into(),
            name: None,
        }
    }
}

/// Name of the built-in clip library.
pub const SHIPPED_CLIPS_NAME: &str = "tang2018";

/// The libraries `choices` name (the built-in one when none), each with its name.
pub fn load_libraries(choices: &[LibraryChoice]) -> Result<Vec<(String, ClipLibrary)>> {
    if choices.is_empty() {
        let (library, _) = load_library(None)?;
        return Ok(vec![(SHIPPED_CLIPS_NAME.to_owned(), library)]);
    }
    let mut out: Vec<(String, ClipLibrary)> = Vec::with_capacity(choices.len());
    for choice in choices {
        let (library, metadata) = load_library(Some(&choice.path))?;
        let name = choice
            .name
            .clone()
            .or_else(|| {
                serde_json::from_str::<serde_json::Value>(&metadata)
                    .ok()?
                    .get("name")?
                    .as_str()
                    .map(str::to_owned)
            })
            .or_else(|| {
                choice
                    .path
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
            })
            .unwrap_or_else(|| format!("library {}", out.len()));
        if out.iter().any(|(n, _)| n.eq_ignore_ascii_case(&name)) {
            bail!(
                "two clip libraries are called {name:?}: name one of them ({})",
                choice.path.display()
            );
        }
        out.push((name, library));
    }
    Ok(out)
}

/// `source` on the stage `settings` describe (free: its motion exactly as made).
pub fn on_stage<S: MotionSource + Send + 'static>(
    source: S,
    settings: StageSettings,
) -> Box<dyn MotionSource + Send> {
    Box::new(StagedSource::new(
        source,
        settings,
        model::rig::Skeleton::default_adult(),
    ))
}

/// Reads the neural model from `path`, or the shipped one when `path` is `None`.
pub fn load_model(path: Option<&Path>) -> Result<NeuralModel> {
    match path {
        None => NeuralModel::from_bytes(SHIPPED_MODEL)
            .with_context(|| format!("reading the built-in model ({SHIPPED_MODEL_PATH})")),
        Some(p) => NeuralModel::load(p).with_context(|| format!("reading {}", p.display())),
    }
}

/// The neural dancer on `model`, seeded with `seed`.
pub fn neural_dancer(model: &NeuralModel, seed: u64) -> Result<NeuralDancer> {
    let mut d = NeuralDancer::new(model).context("starting the neural dancer")?;
    d.reset(seed);
    Ok(d)
}

/// The neural dancer on `settings`' model (the shipped one by default), seeded with `seed`,
/// dancing as `settings` say (a clip library among them is not read).
pub fn configured_neural_dancer(settings: &SourceSettings<'_>, seed: u64) -> Result<NeuralDancer> {
    let mut d = neural_dancer(&load_model(settings.model)?, seed)?;
    if let Some(a) = settings.beat_accent {
        d.set_beat_accent(a);
    }
    if let Some(p) = settings.foot_plant {
        d.set_foot_plant(p);
    }
    if settings.network_only {
        d.set_safety_nets(SafetyNets::NETWORK_ONLY);
    }
    if let Some(r) = settings.key_route {
        d.set_key_pose_route(r);
    }
    Ok(d)
}

/// Refuses, by name, a style the dancer cannot honour: one other than `auto` for a dancer
/// without a style input (asked for on the command line or in the configuration).
pub fn check_style(source: &dyn MotionSource, style: model::style::StyleRequest) -> Result<()> {
    if style != model::style::StyleRequest::Auto && !source.controls().style {
        bail!(
            "style {}: the loaded dancer has no style input (it dances what the music suggests); leave dancer.style / --style at auto",
            style.name()
        );
    }
    Ok(())
}

/// Opens the motion source `kind` with `settings`, seeded with `seed`, on its stage.
pub fn open_source(
    kind: SourceKind,
    settings: &SourceSettings<'_>,
    seed: u64,
) -> Result<Box<dyn MotionSource + Send>> {
    open_source_named(kind, settings, seed).map(|(source, _)| source)
}

/// [`open_source`], with the names of the sets of moves the source holds, in its order (the
/// retrieval dancer's libraries; none for the neural dancer).
pub fn open_source_named(
    kind: SourceKind,
    settings: &SourceSettings<'_>,
    seed: u64,
) -> Result<(Box<dyn MotionSource + Send>, Vec<String>)> {
    let mut names = Vec::new();
    let source: Box<dyn MotionSource + Send> = match kind {
        SourceKind::Neural => {
            if !settings.libraries.is_empty() {
                bail!("a clip library is for the retrieval source, not the neural one");
            }
            Box::new(configured_neural_dancer(settings, seed)?)
        }
        SourceKind::Retrieval => {
            if settings.model.is_some() {
                bail!("a model file is for the neural source, not the retrieval one");
            }
            if settings.network_only {
                bail!(
                    "--network-only is for the neural source: the retrieval dancer has no network"
                );
            }
            let (library_names, libraries) =
                load_libraries(settings.libraries)?.into_iter().unzip();
            names = library_names;
            Box::new(
                RetrievalDancer::with_libraries(libraries, seed)
                    .context("starting the retrieval dancer")?,
            )
        }
    };
    Ok((on_stage(source, settings.stage), names))
}

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

/// Cuts the full clip library from the training split of `data/tang2018` (fitted, aligned and
/// featurised exactly as `danced dataset build` does); returns it with the dances used.
pub fn training_library(data: &Path, jobs: usize) -> Result<(ClipLibrary, Vec<String>)> {
    let built = offline::dataset::build_all(
        data,
        jobs,
        |dance, validation| !validation && dance.audio.is_some(),
        false,
    )?;
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
        offline::dataset::DATASET_VERSION,
        names.join(", ")
    )
}

/// Motion features of standing still in the pose `rotations` (hips at the default rig's
/// height): a seed ("motion prompt") for the neural dancer.
pub fn standing_features(
    rotations: &[glam::Quat; model::rig::JOINT_COUNT],
) -> model::motion::MotionFeatures {
    let skeleton = model::rig::Skeleton::default_adult();
    let mut pose = model::rig::Pose::rest();
    pose.local_rotations = *rotations;
    pose.root_position = glam::Vec3::new(0.0, skeleton.hip_height(), 0.0);
    let mut encoder = model::motion::MotionEncoder::new();
    let mut out = [0.0; model::motion::MOTION_FEATURE_DIM];
    // The second frame of a still pose: zero velocities.
    encoder.encode_frame(&pose, &mut out);
    encoder.encode_frame(&pose, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use dsp::feature::FEATURE_DIM;
    use glam::Quat;
    use model::rig::{JOINT_COUNT, Joint, Pose};
    use model::source::KeyPoseRoute;
    use model::source::{Controls, KeyPoseTarget};

    /// The shipped dancer's poses over the 40 frames up to a key pose's deadline (arms raised,
    /// announced 40 frames ahead), the key sent by `route`.
    fn towards_a_key(route: Option<KeyPoseRoute>) -> Vec<[Quat; JOINT_COUNT]> {
        let settings = SourceSettings {
            key_route: route,
            ..SourceSettings::default()
        };
        let mut d = open_source(SourceKind::Neural, &settings, 1).expect("the shipped dancer");
        let music = vec![[0.0f32; FEATURE_DIM]; d.lookahead_frames() + 1];
        let mut rotations = [Quat::IDENTITY; JOINT_COUNT];
        rotations[Joint::LeftUpperArm.index()] = Quat::from_rotation_z(1.2);
        rotations[Joint::RightUpperArm.index()] = Quat::from_rotation_z(-1.2);
        let mut pose = Pose::default();
        (0..40u32)
            .map(|f| {
                let controls = Controls {
                    key_pose: Some(KeyPoseTarget {
                        rotations,
                        frames_to_go: 39 - f,
                    }),
                    ..Controls::default()
                };
                d.step(&music, &controls, &mut pose);
                pose.local_rotations
            })
            .collect()
    }

    #[test]
    fn on_a_free_stage_the_dance_is_exactly_the_dancers_own() {
        let a = offline::analysis::analyze_samples(
            "demo",
            &crate::demo_track::demo_track(12.0).samples,
            crate::demo_track::DEMO_RATE,
            2,
            offline::analysis::AnalyzeOptions::native(Some(25.0)),
        )
        .unwrap();
        let music: Vec<_> = a.features.iter().map(|f| f.values).collect();
        let dance = |source: &mut dyn MotionSource| {
            crate::offline_dance::dance_stream(source, &music, 0, music.len() - 1, |_| Controls {
                temperature: 0.5,
                ..Controls::default()
            })
        };
        let free = SourceSettings {
            stage: StageSettings {
                mode: model::stage::StageMode::Free,
                ..StageSettings::default()
            },
            ..SourceSettings::default()
        };
        let mut staged = open_source(SourceKind::Neural, &free, 3).unwrap();
        let mut own = configured_neural_dancer(&free, 3).unwrap();
        let (placed, made) = (dance(&mut *staged), dance(&mut own));
        assert_eq!(placed.len(), 299);
        assert_eq!(placed, made);
        // On the default stage the same dance is placed otherwise, starting at the centre.
        let mut bounded = open_source(SourceKind::Neural, &SourceSettings::default(), 3).unwrap();
        let on_stage = dance(&mut *bounded);
        assert_ne!(on_stage, made);
        let start = on_stage[0].root_position;
        assert!(start.x.abs() < 1e-4 && start.z.abs() < 1e-4, "{start}");
    }

    #[test]
    fn the_key_route_setting_reaches_the_dancer() {
        let default = towards_a_key(None);
        assert_eq!(default, towards_a_key(Some(KeyPoseRoute::Overlay)));
        // The shipped network reads the key: handed to it, the dance on the way differs.
        assert_ne!(default, towards_a_key(Some(KeyPoseRoute::Network)));
    }
}
