//! Recipes: what `danced-train dancer` trains, stage by stage, as a TOML file.
//!
//! A recipe is the whole of a model's training settings, so a shipped model is reproduced by
//! running its recipe, and the model file records the recipe's text. The shipped dancer's
//! recipe (`configs/models/default.recipe.toml`) is built in: it is what runs without one.

use std::path::Path;

use serde::Deserialize;
use serde::de::DeserializeOwned;

use crate::error::TrainingError;

/// A recipe file's text, or an error naming the file.
pub(crate) fn read_recipe_text(path: &Path) -> Result<String, TrainingError> {
    std::fs::read_to_string(path)
        .map_err(|e| TrainingError::recipe(format!("cannot read {}: {e}", path.display())))
}

/// Parses a recipe's TOML and checks its ranges with `check`; `origin` names it in errors.
pub(crate) fn parse_recipe<R: DeserializeOwned>(
    text: &str,
    origin: &str,
    check: impl Fn(&R) -> Result<(), String>,
) -> Result<R, TrainingError> {
    let recipe: R =
        toml::from_str(text).map_err(|e| TrainingError::recipe(format!("{origin}: {e}")))?;
    check(&recipe).map_err(|e| TrainingError::recipe(format!("{origin}: {e}")))?;
    Ok(recipe)
}

/// The shipped neural dancer's recipe, verbatim.
pub const SHIPPED_DANCER_RECIPE: &str = include_str!("../../configs/models/default.recipe.toml");

/// Where [`SHIPPED_DANCER_RECIPE`] lives in the repository (for messages and the model file).
pub const SHIPPED_DANCER_RECIPE_PATH: &str = "configs/models/default.recipe.toml";

/// The neural dancer's recipe: its stages, run in order, each continuing from the weights the
/// one before it left.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DancerRecipe {
    /// The stages, in order.
    #[serde(rename = "stage")]
    pub stages: Vec<DancerStage>,
}

/// One stage of a [`DancerRecipe`].
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DancerStage {
    /// What the stage is for, in a word or two (shown in the progress lines).
    pub name: String,
    /// Optimiser steps; the learning rate warms up over the first 200 and then falls along a
    /// cosine to a tenth of its peak over the rest.
    pub steps: u64,
    /// Seed of initialisation (first stage), batch sampling and the rollouts' noise.
    #[serde(default = "defaults::seed")]
    pub seed: u64,
    /// Sequences per batch.
    #[serde(default = "defaults::batch")]
    pub batch: usize,
    /// Tokens per training sequence (longer than the 64-token attention window, so most
    /// positions train the full sliding window the live dancer always has).
    #[serde(default = "defaults::sequence")]
    pub sequence: usize,
    /// Peak learning rate.
    #[serde(default = "defaults::lr")]
    pub lr: f64,
    /// Fraction of sequences trained without a key pose announced.
    #[serde(default = "defaults::key_drop")]
    pub key_drop: f64,
    /// Noise on the previous pose in training tokens, in standard deviations: live, the
    /// network reads its own samples, never the clean capture.
    #[serde(default = "defaults::input_noise")]
    pub input_noise: f32,
    /// Fraction of sequences trained with the music hidden.
    #[serde(default)]
    pub music_drop: f64,
    /// Retime every training dance within each beat (time runs at 1 − depth·cos(beat
    /// phase), as the live beat accent does); 0 trains on the dances as captured.
    #[serde(default)]
    pub beat_retime: f64,
    /// The flow also reads the key pose directly (beside the transformer's context). A
    /// network built without it is widened, the new weights at zero (the same dancer).
    #[serde(default)]
    pub key_to_flow: bool,
    /// Train only the weights that read these inputs; every other weight stays as the stage
    /// found it.
    #[serde(default)]
    pub train_only: Option<TrainOnly>,
    /// Free-running rollouts towards announced key poses, scored beside the likelihood.
    #[serde(default)]
    pub rollout: Option<RolloutSettings>,
}

/// The inputs a [`DancerStage::train_only`] stage trains the weights of.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TrainOnly {
    /// The key pose, its count-down and flag (the embedding's rows and the flow couplings'):
    /// with no key pending the network dances exactly as the stage found it.
    Key,
}

/// The key-pose rollouts of a stage (Yang et al.'s key-pose loss).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RolloutSettings {
    /// Weight of the distance from the pose reached to the key pose.
    pub key_weight: f64,
    /// Sequences free-run per step.
    pub sequences: usize,
    /// Longest rollout, frames (each is drawn from 12 up to it; at most the sequence minus a
    /// window).
    pub horizon: usize,
    /// Temperature of the rollouts' samples.
    pub temperature: f32,
    /// Back-propagate through only the last K steps of each rollout (the poses fed back before
    /// them are constants); absent: every step.
    #[serde(default)]
    pub backprop_steps: Option<usize>,
    /// Fraction of rollouts whose key pose is a frame from anywhere in the training dances
    /// rather than the dance's own future (a performer calls poses the dance was not heading
    /// for).
    #[serde(default)]
    pub foreign: f64,
    /// Score the distance on the last N frames before the key too, weighted 1 − g / N at g
    /// frames to go; 0 scores the key frame alone.
    #[serde(default)]
    pub approach: usize,
    /// Score the distance as the body shape's mean joint distance, this many cm to one unit of
    /// `key_weight`; absent: the distance in normalised rotations.
    #[serde(default)]
    pub key_cm: Option<f64>,
    /// Weight of the rollouts' kinetic mismatch (each joint's speed and acceleration over the
    /// free run against the dance's over the same frames); 0: off.
    #[serde(default)]
    pub kinetic: f64,
    /// A frozen copy of the weights the stage starts from, not told the key, scores the
    /// rollouts; absent: none.
    #[serde(default)]
    pub critic: Option<CriticSettings>,
}

/// The frozen critic of a stage's rollouts.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CriticSettings {
    /// Weight of the rollouts' NLL under the critic (nats per frame) beside the likelihood.
    pub weight: f64,
    /// Frames the critic finds at least this likely (NLL at or below it) cost nothing, so the
    /// free run is not rewarded for being likelier than dancing; absent: no floor.
    #[serde(default)]
    pub floor: Option<f64>,
}

/// The defaults of a stage's settings (the shipped recipe's values).
mod defaults {
    pub fn seed() -> u64 {
        1
    }
    pub fn batch() -> usize {
        8
    }
    pub fn sequence() -> usize {
        128
    }
    pub fn lr() -> f64 {
        1e-3
    }
    pub fn key_drop() -> f64 {
        0.3
    }
    pub fn input_noise() -> f32 {
        0.1
    }
}

impl DancerRecipe {
    /// The shipped dancer's recipe.
    pub fn shipped() -> Self {
        Self::parse(SHIPPED_DANCER_RECIPE, SHIPPED_DANCER_RECIPE_PATH)
            .expect("the shipped recipe is valid (tested)")
    }

    /// Reads and checks a recipe file.
    pub fn read(path: &Path) -> Result<(Self, String), TrainingError> {
        let text = read_recipe_text(path)?;
        let recipe = Self::parse(&text, &path.display().to_string())?;
        Ok((recipe, text))
    }

    /// Parses and checks a recipe's text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, TrainingError> {
        parse_recipe(text, origin, Self::check)
    }

    /// Every setting within its range, naming the first that is not.
    fn check(&self) -> Result<(), String> {
        if self.stages.is_empty() {
            return Err("a recipe needs at least one [[stage]]".into());
        }
        for (i, s) in self.stages.iter().enumerate() {
            let at = |what: &str| format!("stage {} ({:?}): {what}", i + 1, s.name);
            let fraction = |v: f64| (0.0..=1.0).contains(&v);
            if s.steps == 0 {
                return Err(at("steps must be at least 1"));
            }
            if s.batch == 0 || s.sequence < 2 {
                return Err(at("batch must be at least 1 and sequence at least 2"));
            }
            if !(s.lr.is_finite() && s.lr > 0.0 && s.lr < 1.0) {
                return Err(at("lr must be in (0, 1)"));
            }
            if !fraction(s.key_drop) || !fraction(s.music_drop) {
                return Err(at("key_drop and music_drop are fractions in 0..=1"));
            }
            if !(s.input_noise.is_finite() && s.input_noise >= 0.0) {
                return Err(at("input_noise must be ≥ 0"));
            }
            if !(0.0..0.9).contains(&s.beat_retime) {
                return Err(at("beat_retime is a depth in 0..0.9"));
            }
            if i == 0 && s.train_only.is_some() {
                return Err(at(
                    "the first stage trains a new network: train_only needs a stage before it",
                ));
            }
            if let Some(r) = &s.rollout {
                if !(r.key_weight.is_finite() && r.key_weight >= 0.0) {
                    return Err(at("rollout.key_weight must be ≥ 0"));
                }
                if r.sequences == 0 || r.horizon < crate::train::KEY_HORIZON_MIN {
                    return Err(at(&format!(
                        "rollout.sequences must be at least 1 and rollout.horizon at least {}",
                        crate::train::KEY_HORIZON_MIN
                    )));
                }
                if !(r.temperature.is_finite() && r.temperature >= 0.0) {
                    return Err(at("rollout.temperature must be ≥ 0"));
                }
                if r.backprop_steps == Some(0) {
                    return Err(at("rollout.backprop_steps must be at least 1"));
                }
                if !fraction(r.foreign) {
                    return Err(at("rollout.foreign is a fraction in 0..=1"));
                }
                if r.key_cm.is_some_and(|c| !(c.is_finite() && c > 0.0)) {
                    return Err(at("rollout.key_cm must be above 0"));
                }
                if !(r.kinetic.is_finite() && r.kinetic >= 0.0) {
                    return Err(at("rollout.kinetic must be ≥ 0"));
                }
                if let Some(c) = &r.critic {
                    if i == 0 {
                        return Err(at(
                            "a critic is a copy of the weights a stage starts from: the first stage has none",
                        ));
                    }
                    if !(c.weight.is_finite() && c.weight > 0.0)
                        || c.floor.is_some_and(|f| !f.is_finite())
                    {
                        return Err(at(
                            "rollout.critic.weight must be above 0, its floor finite",
                        ));
                    }
                }
                if r.key_weight == 0.0 && r.critic.is_none() {
                    return Err(at(
                        "rollouts with key_weight 0 need a critic (nothing would score them)",
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_recipe_parses_into_its_three_stages() {
        let r = DancerRecipe::shipped();
        let names: Vec<_> = r.stages.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["dance", "keys", "key-weights"]);
        assert_eq!(r.stages[2].train_only, Some(TrainOnly::Key));
        let rollout = r.stages[1].rollout.as_ref().unwrap();
        assert_eq!(rollout.backprop_steps, Some(1));
        assert_eq!(rollout.critic.as_ref().unwrap().floor, Some(-269.0));
    }

    #[test]
    fn the_recipe_builds_the_shipped_models_network() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/models/default.dnn");
        let shipped = model::neural::file::NeuralModel::load(&path).unwrap();
        let key_to_flow = DancerRecipe::shipped().stages.iter().any(|s| s.key_to_flow);
        assert_eq!(
            shipped.config,
            model::neural::config::NetConfig {
                key_to_flow,
                ..Default::default()
            }
        );
        let steps: u64 = DancerRecipe::shipped().stages.iter().map(|s| s.steps).sum();
        assert_eq!(shipped.training.steps, steps);
    }

    #[test]
    fn an_unknown_setting_or_an_out_of_range_value_is_refused_by_name() {
        let unknown = "[[stage]]\nname = \"a\"\nsteps = 10\nmirror = true\n";
        let err = DancerRecipe::parse(unknown, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("unknown field `mirror`"), "{err}");
        let range = "[[stage]]\nname = \"a\"\nsteps = 10\nkey_drop = 1.5\n";
        let err = DancerRecipe::parse(range, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("stage 1 (\"a\"): key_drop"), "{err}");
        let critic_first = "[[stage]]\nname = \"a\"\nsteps = 10\n[stage.rollout]\nkey_weight = 1.0\nsequences = 2\nhorizon = 20\ntemperature = 0.0\n[stage.rollout.critic]\nweight = 0.1\n";
        let err = DancerRecipe::parse(critic_first, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("the first stage has none"), "{err}");
        assert!(DancerRecipe::parse("", "x.toml").is_err());
    }

    #[test]
    fn a_stage_takes_the_shipped_defaults_for_what_it_leaves_out() {
        let r = DancerRecipe::parse("[[stage]]\nname = \"a\"\nsteps = 10\n", "x.toml").unwrap();
        let s = &r.stages[0];
        let shipped = &DancerRecipe::shipped().stages[0];
        assert_eq!(
            (s.seed, s.batch, s.sequence, s.lr, s.key_drop, s.input_noise),
            (
                shipped.seed,
                shipped.batch,
                shipped.sequence,
                shipped.lr,
                shipped.key_drop,
                shipped.input_noise
            )
        );
        assert_eq!(
            (s.beat_retime, s.key_to_flow, s.rollout.clone()),
            (0.0, false, None)
        );
    }
}
