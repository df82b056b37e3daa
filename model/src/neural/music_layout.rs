//! Reading models trained on an older music feature layout.
//!
//! Layout version 2 appended the relative level (index 83) to version 1's 83 values. A
//! version-1 model is widened on load with zero weight on the new value (and mean 0, deviation
//! 1 for it), so it dances exactly as it did: the network cannot see what it never learnt.

use dsp::feature::{FEATURE_DIM, FEATURE_DIM_V1, FEATURE_LAYOUT_VERSION};

use crate::ModelError;
use crate::neural::tensors::{NamedTensors, SEED_MUSIC};
use crate::neural::token::MUSIC_AT;

/// Whether this build reads a model trained on music layout `version` with `dim` features
/// (its own, or one [`upgrade`] widens), said before any of the file's weights are read; Err is
/// a [`ModelError::ModelFileMismatch`].
pub fn readable(version: u32, dim: usize) -> Result<(), ModelError> {
    match (version, dim) {
        (FEATURE_LAYOUT_VERSION, FEATURE_DIM) | (1, FEATURE_DIM_V1) => Ok(()),
        _ => Err(ModelError::ModelFileMismatch(format!(
            "music layout is v{version} × {dim}, this build reads v1 × {FEATURE_DIM_V1} and v{FEATURE_LAYOUT_VERSION} × {FEATURE_DIM}"
        ))),
    }
}

/// Widens the tensors of a model trained on music layout `version` (`dim` values a frame) to
/// the current layout; Err ([`ModelError::ModelFileMismatch`]) names what does not fit.
pub fn upgrade(tensors: &mut NamedTensors, version: u32, dim: usize) -> Result<(), ModelError> {
    readable(version, dim)?;
    if version == FEATURE_LAYOUT_VERSION && dim == FEATURE_DIM {
        return Ok(());
    }
    let added = FEATURE_DIM - FEATURE_DIM_V1;
    for (name, t) in tensors.map.iter_mut() {
        match (name.as_str(), t.shape.as_slice()) {
            ("embed.w", &[_, width]) => {
                // The token's rows: the new music value's sits after version 1's music.
                let at = (MUSIC_AT + FEATURE_DIM_V1) * width;
                t.data
                    .splice(at..at, std::iter::repeat_n(0.0, added * width));
                t.shape[0] += added;
            }
            ("norm.music_mean" | "norm.music_std", &[n]) if n == FEATURE_DIM_V1 => {
                let fill = if name == "norm.music_std" { 1.0 } else { 0.0 };
                t.data.extend(std::iter::repeat_n(fill, added));
                t.shape[0] = FEATURE_DIM;
            }
            (n, &[_, FEATURE_DIM_V1]) if n.starts_with(SEED_MUSIC) => {
                let mut wide = Vec::with_capacity(t.shape[0] * FEATURE_DIM);
                for row in t.data.chunks_exact(FEATURE_DIM_V1) {
                    wide.extend_from_slice(row);
                    wide.extend(std::iter::repeat_n(0.0, added));
                }
                t.data = wide;
                t.shape[1] = FEATURE_DIM;
            }
            _ => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::neural::file::NeuralModel;
    use crate::neural::runtime::Runtime;
    use crate::neural::token::TOKEN_DIM;
    use dsp::feature::FeatureLayout;

    fn shipped() -> Option<NeuralModel> {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/models/default.dnn");
        NeuralModel::load(&path).ok()
    }

    /// `model`'s tensors as a layout-1 file holds them: the relative level's embedding row,
    /// normalisation and seed music taken out.
    fn as_version_1(model: &NeuralModel) -> NamedTensors {
        let mut t = model.tensors.clone();
        let level = FeatureLayout::RELATIVE_LEVEL;
        for (name, tensor) in t.map.iter_mut() {
            match (name.as_str(), tensor.shape.clone().as_slice()) {
                ("embed.w", &[_, width]) => {
                    let at = (MUSIC_AT + level) * width;
                    tensor.data.drain(at..at + width);
                    tensor.shape[0] -= 1;
                }
                ("norm.music_mean" | "norm.music_std", _) => {
                    tensor.data.remove(level);
                    tensor.shape[0] -= 1;
                }
                (n, &[rows, FEATURE_DIM]) if n.starts_with(SEED_MUSIC) => {
                    for r in (0..rows).rev() {
                        tensor.data.remove(r * FEATURE_DIM + level);
                    }
                    tensor.shape[1] -= 1;
                }
                _ => {}
            }
        }
        t
    }

    #[test]
    fn a_version_1_model_is_widened_and_deaf_to_the_new_value() {
        let mut model = shipped().expect("the shipped model loads");
        model.tensors = as_version_1(&model);
        assert_eq!(model.tensors.map["embed.w"].shape[0], TOKEN_DIM - 1);
        upgrade(&mut model.tensors, 1, FEATURE_DIM_V1).expect("widened");
        assert_eq!(model.tensors.map["embed.w"].shape[0], TOKEN_DIM);
        let norm = model.normalizer().expect("normalizer");
        assert_eq!(norm.music_mean.len(), FEATURE_DIM);
        assert_eq!(norm.music_std[FeatureLayout::RELATIVE_LEVEL], 1.0);
        let (_, seed_music) = model.seed_clip().expect("seed clip");
        assert_eq!(seed_music.len(), model.config.window * FEATURE_DIM);
        let mut tokens = vec![0.0f32; TOKEN_DIM];
        for (i, v) in tokens.iter_mut().enumerate() {
            *v = ((i * 37 % 11) as f32 - 5.0) * 0.1;
        }
        let context = |at: usize, value: f32| {
            let mut rt = Runtime::new(&model.tensors, &model.config).expect("runtime");
            let mut t = tokens.clone();
            t[MUSIC_AT + at] = value;
            rt.push(&t).to_vec()
        };
        let level = FeatureLayout::RELATIVE_LEVEL;
        assert_eq!(context(level, 0.0), context(level, -3.0));
        // The energy, which the model did learn to read, moves it: the test can fail.
        let energy = FeatureLayout::ENERGY;
        assert_ne!(context(energy, 0.0), context(energy, -3.0));
    }

    #[test]
    fn an_unknown_layout_is_refused() {
        let mut t = NamedTensors::default();
        assert!(upgrade(&mut t, 1, 80).is_err());
        assert!(upgrade(&mut t, 3, FEATURE_DIM).is_err());
        assert!(upgrade(&mut t, FEATURE_LAYOUT_VERSION, FEATURE_DIM).is_ok());
        // The file reader asks before it decodes a single weight.
        assert!(readable(1, 80).is_err());
        assert!(readable(3, FEATURE_DIM).is_err());
        assert!(readable(1, FEATURE_DIM_V1).is_ok());
        assert!(readable(FEATURE_LAYOUT_VERSION, FEATURE_DIM).is_ok());
    }

    #[test]
    fn widening_inserts_the_new_row_after_the_old_music() {
        let width = 2;
        let v1_rows = TOKEN_DIM - 1;
        let mut t = NamedTensors::default();
        let embed: Vec<f32> = (0..v1_rows * width).map(|i| i as f32 + 1.0).collect();
        t.insert("embed.w", &[v1_rows, width], embed.clone());
        t.insert(
            SEED_MUSIC,
            &[2, FEATURE_DIM_V1],
            vec![7.0; 2 * FEATURE_DIM_V1],
        );
        t.insert(
            "norm.music_std",
            &[FEATURE_DIM_V1],
            vec![3.0; FEATURE_DIM_V1],
        );
        upgrade(&mut t, 1, FEATURE_DIM_V1).expect("upgrade");
        let w = t.get("embed.w", &[TOKEN_DIM, width]).expect("embed");
        let new_row = MUSIC_AT + FEATURE_DIM_V1;
        assert_eq!(&w[..new_row * width], &embed[..new_row * width]);
        assert_eq!(&w[new_row * width..(new_row + 1) * width], &[0.0, 0.0]);
        assert_eq!(&w[(new_row + 1) * width..], &embed[new_row * width..]);
        let seed = t.get(SEED_MUSIC, &[2, FEATURE_DIM]).expect("seed");
        assert_eq!(seed[FEATURE_DIM_V1], 0.0);
        assert_eq!(seed[FEATURE_DIM], 7.0);
        let std = t.get("norm.music_std", &[FEATURE_DIM]).expect("std");
        assert_eq!(std[FEATURE_DIM_V1], 1.0);
    }
}
