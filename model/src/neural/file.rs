//! The model file: magic, format version, JSON metadata (frame rate, look-ahead, feature
//! layouts, rig, network sizes, training summary, tensor list), the tensors as little-endian
//! f32, and a CRC-32 over everything before it. Loading validates all of it and returns a
//! [`ModelError`], never panics; saving writes a temporary file and renames it over the
//! target, so a crash never leaves a half-written model.

use std::io::Write;
use std::path::Path;

use crate::ModelError;
use crate::motion::{MOTION_FEATURE_DIM, MOTION_LAYOUT_VERSION};
use crate::neural::config::NetConfig;
use crate::neural::tensors::{NamedTensors, POSE_MAX, POSE_MIN, SEED_MOTION, SEED_MUSIC, Tensor};
use crate::neural::token::Normalizer;
use crate::rig::JOINT_COUNT;
use dsp::feature::{FEATURE_DIM, FEATURE_LAYOUT_VERSION};
use serde::{Deserialize, Serialize};

/// First bytes of every model file.
pub const MAGIC: &[u8; 8] = b"DANCEDNN";
/// Version of this file layout; bump on any incompatible change.
pub const FORMAT_VERSION: u32 = 2;
/// Frames per second every model here runs at.
pub const FRAME_RATE: f64 = 25.0;

/// What the model was trained on, for the record.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainingSummary {
    /// Training dances.
    pub dances: usize,
    /// Training frames.
    pub frames: usize,
    /// Optimiser steps taken.
    pub steps: u64,
    /// Sequences seen.
    pub sequences: u64,
    /// Wall-clock training time, seconds.
    pub seconds: f64,
    /// Seed of the run.
    pub seed: u64,
    /// Last validation NLL, nats per frame (normalised features), if measured.
    pub validation_nll: Option<f64>,
    /// What the model was trained on (data set, split, dances), and under which terms.
    #[serde(default)]
    pub data: String,
    /// How it was trained: the recipe file's text, verbatim (models trained before recipes
    /// carry the `danced-train dancer` options of their runs instead).
    #[serde(default)]
    pub recipe: String,
    /// `sha256:` and the hex digest of every frame each stage trained on (dance names, motion
    /// and music features, in order): two models with the same hash saw the same data.
    #[serde(default)]
    pub data_hash: String,
    /// Frames ahead of the analysis the training music was predicted by (`dsp::predicted_stream`;
    /// 0 for models trained on the analysed frames themselves, before predicted features).
    #[serde(default)]
    pub horizon_frames: usize,
}

/// The metadata block.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelMeta {
    /// File format version.
    pub format_version: u32,
    /// Frames per second.
    pub frame_rate: f64,
    /// Music look-ahead, frames.
    pub lookahead_frames: usize,
    /// Motion feature layout version.
    pub motion_layout_version: u32,
    /// Motion feature width.
    pub motion_dim: usize,
    /// Music feature layout version.
    pub music_layout_version: u32,
    /// Music feature width.
    pub music_dim: usize,
    /// Rig joints.
    pub joint_count: usize,
    /// Network sizes.
    pub config: NetConfig,
    /// Training record.
    pub training: TrainingSummary,
    /// Tensor names and shapes, in payload order.
    pub tensors: Vec<(String, Vec<usize>)>,
}

/// A complete model: sizes, weights (with normalisation statistics) and training record.
#[derive(Clone, Debug, PartialEq)]
pub struct NeuralModel {
    /// Network sizes.
    pub config: NetConfig,
    /// All weights, including `norm.*` and the seed clip `seed.*`.
    pub tensors: NamedTensors,
    /// Training record.
    pub training: TrainingSummary,
}

fn take<'a>(bytes: &mut &'a [u8], n: usize) -> Result<&'a [u8], ModelError> {
    if bytes.len() < n {
        return Err(ModelError::ModelFileTruncated);
    }
    let (head, tail) = bytes.split_at(n);
    *bytes = tail;
    Ok(head)
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = flate2::Crc::new();
    crc.update(bytes);
    crc.sum()
}

/// Tensor names of style `index`'s seed clip (motion, music).
fn style_seed_names(index: usize) -> (String, String) {
    (
        format!("{SEED_MOTION}.style{index}"),
        format!("{SEED_MUSIC}.style{index}"),
    )
}

impl NeuralModel {
    /// The seed clip ("motion prompt"): raw motion features of `window` frames and, row for
    /// row, the raw music frame each of them was heard with `lookahead` frames earlier (the
    /// music their token carries).
    pub fn seed_clip(&self) -> Result<(&[f32], &[f32]), ModelError> {
        let n = self.config.window;
        Ok((
            self.tensors.get(SEED_MOTION, &[n, MOTION_FEATURE_DIM])?,
            self.tensors
                .get(SEED_MUSIC, &[n, dsp::feature::FEATURE_DIM])?,
        ))
    }

    /// The seed clip of style `index` (see [`crate::style::DanceStyle`]), as
    /// [`Self::seed_clip`]; None where the file has none (models before per-style seeds).
    pub fn style_seed_clip(&self, index: usize) -> Option<(&[f32], &[f32])> {
        let n = self.config.window;
        let (motion, music) = style_seed_names(index);
        Some((
            self.tensors.get(&motion, &[n, MOTION_FEATURE_DIM]).ok()?,
            self.tensors
                .get(&music, &[n, dsp::feature::FEATURE_DIM])
                .ok()?,
        ))
    }

    /// Stores the seed clip of style `index` (raw, as [`Self::set_seed_clip`]).
    pub fn set_style_seed_clip(&mut self, index: usize, motion: Vec<f32>, music: Vec<f32>) {
        let n = self.config.window;
        let (m, x) = style_seed_names(index);
        self.tensors.insert(&m, &[n, MOTION_FEATURE_DIM], motion);
        self.tensors
            .insert(&x, &[n, dsp::feature::FEATURE_DIM], music);
    }

    /// The range of every raw pose feature in the training data (lowest, highest).
    pub fn pose_range(&self) -> Result<(&[f32], &[f32]), ModelError> {
        Ok((
            self.tensors.get(POSE_MIN, &[MOTION_FEATURE_DIM])?,
            self.tensors.get(POSE_MAX, &[MOTION_FEATURE_DIM])?,
        ))
    }

    /// Stores the training data's pose range from its frames.
    pub fn set_pose_range(&mut self, frames: &[[f32; MOTION_FEATURE_DIM]]) {
        let mut lo = vec![f32::INFINITY; MOTION_FEATURE_DIM];
        let mut hi = vec![f32::NEG_INFINITY; MOTION_FEATURE_DIM];
        for f in frames {
            for i in 0..MOTION_FEATURE_DIM {
                lo[i] = lo[i].min(f[i]);
                hi[i] = hi[i].max(f[i]);
            }
        }
        if frames.is_empty() {
            lo.fill(-1e6);
            hi.fill(1e6);
        }
        self.tensors.insert(POSE_MIN, &[MOTION_FEATURE_DIM], lo);
        self.tensors.insert(POSE_MAX, &[MOTION_FEATURE_DIM], hi);
    }

    /// Stores the seed clip (see [`NeuralModel::seed_clip`]).
    pub fn set_seed_clip(&mut self, motion: Vec<f32>, music: Vec<f32>) {
        let n = self.config.window;
        self.tensors
            .insert(SEED_MOTION, &[n, MOTION_FEATURE_DIM], motion);
        self.tensors
            .insert(SEED_MUSIC, &[n, dsp::feature::FEATURE_DIM], music);
    }

    /// Normalisation statistics stored in the weights.
    pub fn normalizer(&self) -> Result<Normalizer, ModelError> {
        let t = &self.tensors;
        Ok(Normalizer {
            pose_mean: t.get("norm.pose_mean", &[MOTION_FEATURE_DIM])?.to_vec(),
            pose_std: t.get("norm.pose_std", &[MOTION_FEATURE_DIM])?.to_vec(),
            music_mean: t.get("norm.music_mean", &[FEATURE_DIM])?.to_vec(),
            music_std: t.get("norm.music_std", &[FEATURE_DIM])?.to_vec(),
        })
    }

    /// Stores normalisation statistics in the weights.
    pub fn set_normalizer(&mut self, n: &Normalizer) {
        let t = &mut self.tensors;
        t.insert("norm.pose_mean", &[MOTION_FEATURE_DIM], n.pose_mean.clone());
        t.insert("norm.pose_std", &[MOTION_FEATURE_DIM], n.pose_std.clone());
        t.insert("norm.music_mean", &[FEATURE_DIM], n.music_mean.clone());
        t.insert("norm.music_std", &[FEATURE_DIM], n.music_std.clone());
    }

    /// The file's bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let meta = ModelMeta {
            format_version: FORMAT_VERSION,
            frame_rate: FRAME_RATE,
            lookahead_frames: self.config.lookahead,
            motion_layout_version: MOTION_LAYOUT_VERSION,
            motion_dim: MOTION_FEATURE_DIM,
            music_layout_version: FEATURE_LAYOUT_VERSION,
            music_dim: FEATURE_DIM,
            joint_count: JOINT_COUNT,
            config: self.config,
            training: self.training.clone(),
            tensors: self
                .tensors
                .map
                .iter()
                .map(|(k, t)| (k.clone(), t.shape.clone()))
                .collect(),
        };
        // Serialising plain data with string keys cannot fail.
        let json = serde_json::to_vec(&meta).unwrap_or_default();
        let mut out = Vec::with_capacity(64 + json.len() + 4 * self.tensors.parameter_count());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        out.extend_from_slice(&(json.len() as u64).to_le_bytes());
        out.extend_from_slice(&json);
        for t in self.tensors.map.values() {
            for v in &t.data {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        let crc = crc32(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        out
    }

    /// Parses and validates a model file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, ModelError> {
        if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
            return Err(ModelError::ModelFileBadMagic);
        }
        let mut rest = &bytes[MAGIC.len()..];
        let version = u32::from_le_bytes(take(&mut rest, 4)?.try_into().unwrap_or_default());
        if version != FORMAT_VERSION {
            return Err(ModelError::ModelFileVersion { found: version });
        }
        let json_len = u64::from_le_bytes(take(&mut rest, 8)?.try_into().unwrap_or_default());
        let json_len = usize::try_from(json_len).map_err(|_| ModelError::ModelFileTruncated)?;
        let json = take(&mut rest, json_len)?;
        if bytes.len() < 4 {
            return Err(ModelError::ModelFileTruncated);
        }
        let meta: ModelMeta = serde_json::from_slice(json).map_err(|e| {
            // A cut inside the JSON reads as a parse error; the checksum can tell which.
            if crc32(&bytes[..bytes.len() - 4]).to_le_bytes() != bytes[bytes.len() - 4..] {
                ModelError::ModelFileChecksum
            } else {
                ModelError::ModelFileMetadata(e.to_string())
            }
        })?;
        let payload: usize = meta
            .tensors
            .iter()
            .map(|(_, s)| s.iter().try_fold(1usize, |a, &b| a.checked_mul(b)))
            .try_fold(0usize, |a, n| {
                n.and_then(|n| a.checked_add(n.checked_mul(4)?))
            })
            .ok_or_else(|| ModelError::ModelFileMetadata("tensor sizes overflow".into()))?;
        if rest.len() < payload + 4 {
            return Err(ModelError::ModelFileTruncated);
        }
        if rest.len() > payload + 4 {
            return Err(ModelError::ModelFileChecksum);
        }
        let body = &bytes[..bytes.len() - 4];
        if crc32(body).to_le_bytes() != bytes[bytes.len() - 4..] {
            return Err(ModelError::ModelFileChecksum);
        }
        let expect = |what: &str, found: String, want: String| {
            if found == want {
                Ok(())
            } else {
                Err(ModelError::ModelFileMismatch(format!(
                    "{what} is {found}, this build needs {want}"
                )))
            }
        };
        expect(
            "frame rate",
            meta.frame_rate.to_string(),
            FRAME_RATE.to_string(),
        )?;
        expect(
            "motion layout",
            format!("v{} × {}", meta.motion_layout_version, meta.motion_dim),
            format!("v{MOTION_LAYOUT_VERSION} × {MOTION_FEATURE_DIM}"),
        )?;
        expect(
            "rig joint count",
            meta.joint_count.to_string(),
            JOINT_COUNT.to_string(),
        )?;
        expect(
            "look-ahead",
            meta.lookahead_frames.to_string(),
            meta.config.lookahead.to_string(),
        )?;
        meta.config
            .check()
            .map_err(|e| ModelError::ModelFileMismatch(e.to_string()))?;
        crate::neural::music_layout::readable(meta.music_layout_version, meta.music_dim)?;
        let mut tensors = NamedTensors::default();
        for (name, shape) in &meta.tensors {
            let n: usize = shape.iter().product();
            let raw = take(&mut rest, 4 * n)?;
            let data = raw
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            tensors.map.insert(
                name.clone(),
                Tensor {
                    shape: shape.clone(),
                    data,
                },
            );
        }
        crate::neural::music_layout::upgrade(
            &mut tensors,
            meta.music_layout_version,
            meta.music_dim,
        )?;
        let mut model = NeuralModel {
            config: meta.config,
            tensors,
            training: meta.training,
        };
        if model.tensors.get(POSE_MIN, &[MOTION_FEATURE_DIM]).is_err()
            && model.tensors.get(POSE_MAX, &[MOTION_FEATURE_DIM]).is_err()
        {
            // Checkpoints written before the range was stored: no clamp until retrained.
            model.set_pose_range(&[]);
        }
        // Building the runtime checks every tensor the network needs (names, shapes, finite,
        // invertible flow maps).
        crate::neural::runtime::Runtime::new(&model.tensors, &model.config)?;
        model.normalizer()?;
        model.seed_clip()?;
        let (lo, hi) = model.pose_range()?;
        if lo
            .iter()
            .zip(hi)
            .any(|(l, h)| l.partial_cmp(h).is_none_or(|o| o.is_gt()))
        {
            return Err(ModelError::ModelFileMetadata(
                "pose range: a lowest value above its highest".into(),
            ));
        }
        Ok(model)
    }

    /// Writes the model atomically (temporary file in the same folder, then rename).
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        let bytes = self.to_bytes();
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let tmp = dir.join(format!(".{name}.tmp{}", std::process::id()));
        let result = (|| {
            let mut f = std::fs::File::create(&tmp)?;
            f.write_all(&bytes)?;
            f.sync_all()?;
            std::fs::rename(&tmp, path)
        })();
        if result.is_err() {
            let _ = std::fs::remove_file(&tmp);
        }
        Ok(result?)
    }

    /// Reads and validates a model file.
    pub fn load(path: &Path) -> Result<Self, ModelError> {
        Self::from_bytes(&std::fs::read(path)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::neural::tensors::init_net;

    fn model() -> NeuralModel {
        let c = NetConfig::tiny();
        NeuralModel {
            config: c,
            tensors: init_net(&c, 3),
            training: TrainingSummary {
                dances: 2,
                ..Default::default()
            },
        }
    }

    #[test]
    fn round_trips_through_a_file() {
        let m = model();
        let dir = std::env::temp_dir().join(format!("danced-nn-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("m.dnn");
        m.save(&path).unwrap();
        assert_eq!(NeuralModel::load(&path).unwrap(), m);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn damaged_files_give_clear_errors() {
        let bytes = model().to_bytes();
        for cut in [0, 5, 13, 30, bytes.len() / 2, bytes.len() - 1] {
            let e = NeuralModel::from_bytes(&bytes[..cut]).unwrap_err();
            assert!(
                matches!(
                    e,
                    ModelError::ModelFileTruncated
                        | ModelError::ModelFileBadMagic
                        | ModelError::ModelFileChecksum
                ),
                "cut at {cut}: {e}"
            );
        }
        let mut flipped = bytes.clone();
        let i = bytes.len() - 100;
        flipped[i] ^= 0x40;
        assert!(matches!(
            NeuralModel::from_bytes(&flipped),
            Err(ModelError::ModelFileChecksum)
        ));
        let mut version = bytes.clone();
        version[8] = 9;
        assert!(matches!(
            NeuralModel::from_bytes(&version),
            Err(ModelError::ModelFileVersion { found: 9 })
        ));
        // A different rig: rewrite the metadata and fix the checksum so only the mismatch remains.
        let pattern = b"\"joint_count\":22";
        let at = bytes
            .windows(pattern.len())
            .position(|w| w == pattern)
            .unwrap();
        let mut other = bytes.clone();
        other[at + pattern.len() - 1] = b'3';
        let n = other.len() - 4;
        let crc = crc32(&other[..n]).to_le_bytes();
        other[n..].copy_from_slice(&crc);
        let e = NeuralModel::from_bytes(&other).unwrap_err();
        assert!(e.to_string().contains("rig joint count is 23"), "{e}");
    }
}
