//! The whole trainable network: transformer context → flow over the next pose. One forward
//! pass scores every position of a batch of sequences (teacher forcing).

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use crate::body_shape::BodyShape;
use crate::flow::Flow;
use crate::layers::WeightRows;
use crate::transformer::Transformer;
use model::ModelError;
use model::motion::{MOTION_FEATURE_DIM, ROTATIONS};
use model::neural::config::NetConfig;
use model::neural::tensors::NamedTensors;
use model::neural::token::{
    FLAG_AT, FTG_AT, KEY_AT, KEY_CONDITION_CLAMP, KEY_CONDITION_DIM, KEY_ROT_DIM, LEVEL_AT,
    POSE_AT, TOKEN_DIM,
};

/// Normalised values of a key-pose rollout's poses are clamped to ± this before they are fed
/// back (the live range clamp keeps poses within the training data's, a few σ).
pub const ROLLOUT_BOUND: f32 = 8.0;

/// A key-pose rollout with a normalised value beyond ± this has exploded and is not scored.
pub const ROLLOUT_EXPLODED: f32 = 1e3;

/// Where and how [`Net::key_rollout`] free-runs.
#[derive(Clone, Copy, Debug)]
pub struct FreeRun {
    /// The token that announces the key pose (the free run starts there).
    pub at: usize,
    /// Frames from the announcement to the key pose.
    pub horizon: usize,
    /// Temperature of the samples.
    pub temperature: f32,
    /// Steps the gradient flows back through from the pose reached (the poses fed back
    /// before them are constants: truncated back-propagation); 1 teaches only the step onto
    /// the key, None every step.
    pub backprop_steps: Option<usize>,
    /// Frames before the key over which the distance is scored too, weighted 1 − g / this at
    /// g frames to go (so the pose is drawn onto the key gradually, not in one step); 0
    /// scores the key frame alone.
    pub approach: usize,
}

/// What [`Net::key_rollout`] produced.
pub struct FreeRunOutcome {
    /// Per sequence `[b]`, the weighted distance of the poses reached from the key (see
    /// [`FreeRun::approach`]).
    pub key_distance: Tensor<1>,
    /// The tokens the free run fed the transformer, `[b, at + horizon + 1, TOKEN_DIM]`: the
    /// batch's up to the announcement, then its own poses fed back (as they were fed: without
    /// a gradient beyond `backprop_steps`).
    pub tokens: Tensor<3>,
    /// The poses sampled, one per token from the announcement on, `[b, horizon + 1,
    /// MOTION_FEATURE_DIM]`, with their gradient.
    pub poses: Tensor<3>,
    /// Per sequence, whether its free run stayed within ±[`ROLLOUT_EXPLODED`] (and, replayed,
    /// finite); one that did not went on from the mean pose, without a gradient, and is not to
    /// be scored.
    pub kept: Vec<bool>,
}

/// `pose` `[b, width]` with the rows of sequences not `kept` (already, or now: beyond
/// ±[`ROLLOUT_EXPLODED`]) replaced by the mean pose, 0, without a gradient; `kept` updated.
/// None if a value is not finite or no sequence is kept.
pub fn leave_out_exploded(pose: Tensor<2>, kept: &mut [bool]) -> Option<Tensor<2>> {
    let [b, width] = pose.dims();
    let largest = crate::layers::values(pose.clone().abs().max_dim(1));
    if largest.len() != b || kept.len() != b || largest.iter().any(|m| !m.is_finite()) {
        return None;
    }
    for (k, m) in kept.iter_mut().zip(&largest) {
        *k &= *m <= ROLLOUT_EXPLODED;
    }
    if !kept.iter().any(|k| *k) {
        return None;
    }
    if kept.iter().all(|k| *k) {
        return Some(pose);
    }
    let lost: Vec<bool> = kept
        .iter()
        .flat_map(|&k| std::iter::repeat_n(!k, width))
        .collect();
    let lost = Tensor::<2, burn::tensor::Bool>::from_data(
        burn::tensor::TensorData::new(lost, [b, width]),
        &pose.device(),
    );
    Some(pose.mask_fill(lost, 0.0))
}

impl FreeRunOutcome {
    /// How many sequences exploded and are not to be scored.
    pub fn exploded(&self) -> usize {
        self.kept.iter().filter(|k| !**k).count()
    }

    /// The mean over the kept sequences of `per_sequence` `[b, …]` (rows of the exploded ones
    /// weigh nothing).
    pub fn kept_mean<const D: usize>(&self, per_sequence: Tensor<D>) -> Tensor<1> {
        let dims = per_sequence.dims();
        let device = per_sequence.device();
        let per_row: usize = dims[1..].iter().product();
        let kept = self.kept.iter().filter(|k| **k).count().max(1);
        let weights: Vec<f32> = self
            .kept
            .iter()
            .map(|&k| {
                if k {
                    1.0 / (kept * per_row) as f32
                } else {
                    0.0
                }
            })
            .collect();
        let mut shape = [1; D];
        shape[0] = dims[0];
        let w = Tensor::<D>::from_data(burn::tensor::TensorData::new(weights, shape), &device);
        (per_sequence * w).sum()
    }

    /// Per sequence `[b]`, the approach-weighted distance (as [`FreeRunOutcome::key_distance`]
    /// weighs it, `approach` frames) of the poses reached from the key, measured as `shape`
    /// says: the body shape's mean joint distance, cm. None if no step is scored.
    pub fn key_distance_cm(&self, shape: &BodyShape, approach: usize) -> Option<Tensor<1>> {
        let [b, steps, _] = self.poses.dims();
        let w = self.tokens.dims()[1];
        let key = self
            .tokens
            .clone()
            .narrow(1, w - steps, 1)
            .reshape([b, TOKEN_DIM])
            .narrow(1, KEY_AT, KEY_ROT_DIM);
        approach_weighted(self.poses.clone(), key, approach, |pose, key| {
            shape.distance_cm(pose.narrow(1, ROTATIONS, KEY_ROT_DIM), key)
        })
    }
}

/// A group of a token's inputs, and the weights that read them alone (a recipe stage's
/// `train_only`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputPath {
    /// The key pose, its count-down and flag: the embedding's rows for them and each flow
    /// coupling's key conditioning. Those inputs are zero on a token without a key, so these
    /// rows cannot change how the network dances with no key pending.
    Key,
}

/// Transformer plus flow head.
#[derive(Module, Debug)]
pub struct Net {
    /// The causal transformer.
    pub transformer: Transformer,
    /// The flow over the next pose's normalised features.
    pub flow: Flow,
}

impl Net {
    /// Builds the network from named tensors.
    pub fn load(t: &NamedTensors, c: &NetConfig, device: &Device) -> Result<Self, ModelError> {
        c.check()
            .map_err(|e| ModelError::WeightMissing(format!("(bad config: {e})")))?;
        Ok(Net {
            transformer: Transformer::load(t, c, device)?,
            flow: Flow::load(t, "flow", &c.flow(), device)?,
        })
    }

    /// What the flow is conditioned on, `[b·s, flow context]`: the transformer's context
    /// `[b·s, d_model]`, for a `key_to_flow` network each token's key conditioning as
    /// `model::neural::token::key_condition` computes it live, and for a `level_to_flow` one
    /// each token's relative level.
    pub fn flow_context(&self, ctx: Tensor<2>, tokens: Tensor<3>) -> Tensor<2> {
        let c = self.transformer.config();
        if !c.key_to_flow && !c.level_to_flow {
            return ctx;
        }
        let [b, s, _] = tokens.dims();
        let flat = tokens.reshape([b * s, TOKEN_DIM]);
        let mut parts = vec![ctx];
        if c.key_to_flow {
            let flag = flat.clone().narrow(1, FLAG_AT, 1);
            let key = flat.clone().narrow(1, KEY_AT, KEY_ROT_DIM);
            let pose = flat.clone().narrow(1, POSE_AT + ROTATIONS, KEY_ROT_DIM);
            parts.push(((key - pose) * flag).clamp(-KEY_CONDITION_CLAMP, KEY_CONDITION_CLAMP));
            parts.push(
                flat.clone()
                    .narrow(1, FTG_AT, KEY_CONDITION_DIM - KEY_ROT_DIM),
            );
        }
        if c.level_to_flow {
            parts.push(flat.narrow(1, LEVEL_AT, 1));
        }
        Tensor::cat(parts, 1)
    }

    /// The weights that read `path`'s inputs and nothing else.
    pub fn path_rows(&self, path: InputPath) -> Vec<WeightRows> {
        let c = self.transformer.config();
        // A coupling's first layer reads [half the pose, the flow's context].
        let flow_rows = |at: usize, width: usize| -> Vec<WeightRows> {
            self.flow
                .steps
                .iter()
                .map(|step| {
                    let inputs = step.c1.w.val().dims()[0];
                    let context_at = inputs - c.flow().context;
                    WeightRows {
                        param: step.c1.w.id,
                        rows: context_at + at..context_at + at + width,
                    }
                })
                .collect()
        };
        match path {
            InputPath::Key => {
                let mut rows = vec![self.transformer.embedding_rows(KEY_AT..TOKEN_DIM)];
                if c.key_to_flow {
                    rows.extend(flow_rows(c.key_condition_at(), KEY_CONDITION_DIM));
                }
                rows
            }
        }
    }

    /// Writes the trainable weights into `t` (normalisation and seed entries are left as they
    /// are).
    pub fn store(&self, t: &mut NamedTensors) {
        self.transformer.store(t);
        self.flow.store(t, "flow");
    }

    /// The flow's NLL of the next pose per row `[b·s]`, nats per frame: targets
    /// `[b, s, MOTION_FEATURE_DIM]` given tokens `[b, s, TOKEN_DIM]` and the tokens' styles
    /// `[b·s, styles]`.
    pub fn score(
        &self,
        tokens: Tensor<3>,
        styles: Option<Tensor<2>>,
        targets: Tensor<3>,
    ) -> Tensor<1> {
        let [b, s, _] = targets.dims();
        let ctx = self.transformer.forward(tokens.clone(), styles);
        let ctx = self.flow_context(ctx, tokens);
        self.flow
            .log_prob(targets.reshape([b * s, MOTION_FEATURE_DIM]), ctx)
            .neg()
    }

    /// Free-runs the network from token `at` of each sequence to token `at + horizon`, as the
    /// live dancer does: each step samples the next pose from the flow (z ~ N(0, T²I), drawn
    /// from `rng`) and feeds it back as the next token's previous pose (the tokens' music, key
    /// and count-down stay the batch's), the transformer seeing the whole sequence so far as
    /// the live cache does. Returns the distance, per sequence `[b]`, between the rotations of
    /// the pose reached on the last step and the key the token at `at` announces (normalised
    /// units; Yang et al.'s key-pose loss, which their flow needed to reach a key: the one-step
    /// likelihood gives no reason to), with the tokens fed and the poses sampled. Poses fed
    /// back more than `backprop_steps` steps before the last are constants (truncated
    /// back-propagation). A sequence whose pose explodes (beyond ±[`ROLLOUT_EXPLODED`]) goes on
    /// from the mean pose, without a gradient, and is marked not [`FreeRunOutcome::kept`];
    /// None if the flow has become numerically singular, a pose is not finite or every
    /// sequence exploded. A fully detached run (`backprop_steps` Some(1), no styles) is replayed ([`Net::replayed_key_rollout`]): the same outcome for the cost of
    /// one forward pass instead of one a step, except that a sequence whose pose is not finite
    /// is left out instead of the whole run.
    pub fn key_rollout(
        &self,
        tokens: Tensor<3>,
        styles: Option<Tensor<3>>,
        run: &FreeRun,
        rng: &mut model::neural::rng::Rng,
    ) -> Option<FreeRunOutcome> {
        if run.backprop_steps == Some(1) && styles.is_none() {
            return self.replayed_key_rollout(tokens, run, rng);
        }
        self.stepped_key_rollout(tokens, styles, run, rng)
    }

    /// [`Net::key_rollout`] step by step: every step re-encodes the sequence so far with its
    /// gradient, so any `backprop_steps` and styles can be honoured.
    pub fn stepped_key_rollout(
        &self,
        tokens: Tensor<3>,
        styles: Option<Tensor<3>>,
        run: &FreeRun,
        rng: &mut model::neural::rng::Rng,
    ) -> Option<FreeRunOutcome> {
        let [b, s, _] = tokens.dims();
        let FreeRun {
            at,
            horizon,
            temperature,
            backprop_steps,
            approach,
        } = *run;
        let last = (at + horizon).min(s - 1);
        let device = tokens.device();
        let key = tokens
            .clone()
            .narrow(1, at, 1)
            .reshape([b, TOKEN_DIM])
            .narrow(1, KEY_AT, KEY_ROT_DIM);
        let mut seq: Vec<Tensor<3>> = (0..=at).map(|t| tokens.clone().narrow(1, t, 1)).collect();
        // The weighted sum of the distances scored so far, and the weights' sum.
        let mut scored: Option<(Tensor<1>, f32)> = None;
        let mut poses = Vec::with_capacity(last + 1 - at);
        let mut kept = vec![true; b];
        for t in at..=last {
            // The whole sequence so far, not the last window: each layer's keys and values
            // at the window's first tokens carry what those tokens attended to in turn (as
            // the live cache keeps them), so the re-encoded window alone is another function.
            let w = t + 1;
            let input = Tensor::cat(seq[..=t].to_vec(), 1);
            let rows = styles.as_ref().map(|st| {
                let width = st.dims()[2];
                st.clone().narrow(1, 0, w).reshape([b * w, width])
            });
            let ctx = self
                .transformer
                .forward(input.clone(), rows)
                .reshape([b, w, self.transformer.width()])
                .narrow(1, w - 1, 1)
                .reshape([b, self.transformer.width()]);
            let ctx = self.flow_context(ctx, input.narrow(1, w - 1, 1));
            // Drawn from the trainer's own generator, not the backend's: that one is global
            // to the process, and a draw here would change what another user seeded.
            let noise: Vec<f32> = (0..b * MOTION_FEATURE_DIM)
                .map(|_| temperature * rng.normal())
                .collect();
            let z = Tensor::from_data(
                burn::tensor::TensorData::new(noise, [b, MOTION_FEATURE_DIM]),
                &device,
            );
            let pose = self.flow.inverse(z, ctx)?;
            // A sequence that exploded (the flow's inverse amplifies by up to 1/σ per coupling)
            // goes on from a constant: clamped, it would be scored as if it had danced. A
            // non-finite pose drops the whole run: its zero gradient times an infinite one
            // would put NaN in the weights. One that merely strayed is clamped as the live
            // range clamp would.
            let pose = leave_out_exploded(pose, &mut kept)?.clamp(-ROLLOUT_BOUND, ROLLOUT_BOUND);
            let weight = approach_weight(last - t, approach);
            if weight > 0.0 {
                let d = key_distance(pose.clone(), key.clone()).mul_scalar(weight);
                scored = Some(match scored {
                    Some((sum, w)) => (sum + d, w + weight),
                    None => (d, weight),
                });
            }
            poses.push(pose.clone().reshape([b, 1, MOTION_FEATURE_DIM]));
            if t == last {
                break;
            }
            let rest = tokens.clone().narrow(1, t + 1, 1).narrow(
                2,
                MOTION_FEATURE_DIM,
                TOKEN_DIM - MOTION_FEATURE_DIM,
            );
            let fed = if backprop_steps.is_some_and(|k| last - t >= k) {
                pose.detach()
            } else {
                pose
            };
            seq.push(Tensor::cat(
                vec![fed.reshape([b, 1, MOTION_FEATURE_DIM]), rest],
                2,
            ));
        }
        let (sum, weights) = scored?;
        Some(FreeRunOutcome {
            key_distance: sum.div_scalar(weights),
            tokens: Tensor::cat(seq, 1),
            poses: Tensor::cat(poses, 1),
            kept,
        })
    }

    /// [`Net::key_rollout`] of a fully detached run, in two passes. When no fed pose carries a
    /// gradient, the free run itself needs none: the live runtime (loaded with these weights)
    /// draws it, with the same noise in the same order, at the cost of a cached step a token.
    /// Then one causal forward pass over the tokens it fed gives every step's context at
    /// once — the context of token t depends on tokens up to t only, so it is the one the
    /// step-by-step run re-encoded — and the flow's inverse of each step's noise there gives
    /// the poses again, now with their gradient. Stepping through burn instead re-encoded the
    /// whole sequence with its gradient at every one of up to 51 steps: most of a rollout
    /// step's time. A sequence whose free run is not finite is left out as an exploded one
    /// is; None only if every sequence is, or the flow is singular.
    pub fn replayed_key_rollout(
        &self,
        tokens: Tensor<3>,
        run: &FreeRun,
        rng: &mut model::neural::rng::Rng,
    ) -> Option<FreeRunOutcome> {
        const P: usize = MOTION_FEATURE_DIM;
        let [b, s, _] = tokens.dims();
        let FreeRun {
            at,
            horizon,
            temperature,
            approach,
            ..
        } = *run;
        let last = (at + horizon).min(s - 1);
        if at > last {
            return None;
        }
        let (steps, fed_len) = (last + 1 - at, last + 1);
        let device = tokens.device();
        let mut weights = NamedTensors::default();
        self.store(&mut weights);
        let mut live =
            model::neural::runtime::Runtime::new(&weights, self.transformer.config()).ok()?;
        let host = crate::layers::values(tokens.clone());
        // Step-major, as the step-by-step run draws it.
        let noise: Vec<f32> = (0..steps * b * P)
            .map(|_| temperature * rng.normal())
            .collect();
        let mut fed = vec![0.0f32; b * fed_len * TOKEN_DIM];
        let mut kept = vec![true; b];
        let mut sampled = [0.0f32; P];
        let mut pose = [0.0f32; P];
        for q in 0..b {
            live.reset();
            for i in 0..fed_len {
                let token = &mut fed[(q * fed_len + i) * TOKEN_DIM..][..TOKEN_DIM];
                token.copy_from_slice(&host[(q * s + i) * TOKEN_DIM..][..TOKEN_DIM]);
                if i > at {
                    token[..P].copy_from_slice(&pose);
                }
                live.push(token);
                if i < at {
                    continue;
                }
                live.sample(&noise[((i - at) * b + q) * P..][..P], &mut sampled);
                // As `leave_out_exploded` and the clamp treat the step-by-step run's poses,
                // except that a pose that is not finite leaves out its sequence, not the run.
                kept[q] &= sampled.iter().all(|v| v.abs() <= ROLLOUT_EXPLODED);
                for (p, v) in pose.iter_mut().zip(&sampled) {
                    *p = if kept[q] {
                        v.clamp(-ROLLOUT_BOUND, ROLLOUT_BOUND)
                    } else {
                        0.0
                    };
                }
            }
        }
        // A left-out sequence is scored as a copy of a kept one, so no value that is not
        // finite enters the graph (its zero gradient times an infinite one would be NaN);
        // it weighs nothing.
        let donor = kept.iter().position(|k| *k)?;
        for q in (0..b).filter(|&q| !kept[q]) {
            fed.copy_within(
                donor * fed_len * TOKEN_DIM..(donor + 1) * fed_len * TOKEN_DIM,
                q * fed_len * TOKEN_DIM,
            );
        }
        let fed = Tensor::<3>::from_data(
            burn::tensor::TensorData::new(fed, [b, fed_len, TOKEN_DIM]),
            &device,
        );
        let key =
            fed.clone()
                .narrow(1, at, 1)
                .reshape([b, TOKEN_DIM])
                .narrow(1, KEY_AT, KEY_ROT_DIM);
        let ctx = self.transformer.forward(fed.clone(), None);
        let ctx = self.flow_context(ctx, fed.clone());
        let ctx_width = ctx.dims()[1];
        let ctx = ctx
            .reshape([b, fed_len, ctx_width])
            .narrow(1, at, steps)
            .reshape([b * steps, ctx_width]);
        let mut z = vec![0.0f32; b * steps * P];
        for q in 0..b {
            let from = if kept[q] { q } else { donor };
            for g in 0..steps {
                z[(q * steps + g) * P..][..P].copy_from_slice(&noise[(g * b + from) * P..][..P]);
            }
        }
        let z = Tensor::<2>::from_data(burn::tensor::TensorData::new(z, [b * steps, P]), &device);
        let poses = self.flow.inverse(z, ctx)?.reshape([b, steps * P]);
        let poses = leave_out_exploded(poses, &mut kept)?
            .clamp(-ROLLOUT_BOUND, ROLLOUT_BOUND)
            .reshape([b, steps, P]);
        Some(FreeRunOutcome {
            key_distance: approach_weighted(poses.clone(), key, approach, key_distance)?,
            tokens: fed,
            poses,
            kept,
        })
    }

    /// Per sequence and step `[b, horizon + 1]`, this network's NLL (nats) of a free run's
    /// sampled poses with the key pose hidden from it (key, count-down and flag zeroed, as on a token
    /// without a key): how much the run looks like dancing to a network that does not know
    /// where it is going. `before` `[b, ≥ at, MOTION_FEATURE_DIM]` are the targets of the
    /// tokens before the announcement (scored, not counted); `styles` as for `key_rollout`.
    pub fn keyless_nll(
        &self,
        run: &FreeRunOutcome,
        styles: Option<Tensor<3>>,
        before: Tensor<3>,
    ) -> Tensor<2> {
        let [b, w, _] = run.tokens.dims();
        let steps = run.poses.dims()[1];
        let at = w - steps;
        let device = run.tokens.device();
        let keyless = Tensor::cat(
            vec![
                run.tokens.clone().narrow(2, 0, KEY_AT),
                Tensor::zeros([b, w, TOKEN_DIM - KEY_AT], &device),
            ],
            2,
        );
        let targets = if at == 0 {
            run.poses.clone()
        } else {
            Tensor::cat(vec![before.narrow(1, 0, at), run.poses.clone()], 1)
        };
        let rows = styles.map(|st| {
            let width = st.dims()[2];
            st.narrow(1, 0, w).reshape([b * w, width])
        });
        self.score(keyless, rows, targets)
            .reshape([b, w])
            .narrow(1, at, steps)
    }

    /// Data-dependent initialisation of the flow's actnorms from one batch.
    pub fn data_init(
        self,
        tokens: Tensor<3>,
        styles: Option<Tensor<2>>,
        targets: Tensor<3>,
    ) -> Self {
        let [b, s, _] = targets.dims();
        let ctx = self.transformer.forward(tokens.clone(), styles);
        let ctx = self.flow_context(ctx, tokens);
        let flow = self
            .flow
            .data_init(targets.reshape([b * s, MOTION_FEATURE_DIM]), ctx);
        Net {
            transformer: self.transformer,
            flow,
        }
    }
}

/// The weight of a rollout step's key distance `to_go` frames before the key: 1 on the key
/// frame, falling by 1 / `approach` a frame before it; with no approach, 0 or less before it.
fn approach_weight(to_go: usize, approach: usize) -> f32 {
    1.0 - to_go as f32 / approach.max(1) as f32
}

/// The weights of a rollout's `steps` distances (the last on the key frame), each
/// [`approach_weight`] floored at 0, summing to 1; None if none is positive.
fn approach_weights(steps: usize, approach: usize) -> Option<Vec<f32>> {
    let raw: Vec<f32> = (0..steps)
        .map(|g| approach_weight(steps - 1 - g, approach).max(0.0))
        .collect();
    let total: f32 = raw.iter().sum();
    (total > 0.0).then(|| raw.iter().map(|w| w / total).collect())
}

/// Per sequence `[b]`, the [`approach_weights`]-weighted sum over a rollout's poses `[b,
/// steps, MOTION_FEATURE_DIM]` of `distance` `[rows]` from each pose `[rows,
/// MOTION_FEATURE_DIM]` to the `key` `[b, KEY_ROT_DIM]`; None if no step is scored.
fn approach_weighted(
    poses: Tensor<3>,
    key: Tensor<2>,
    approach: usize,
    distance: impl Fn(Tensor<2>, Tensor<2>) -> Tensor<1>,
) -> Option<Tensor<1>> {
    let [b, steps, p] = poses.dims();
    let weights = approach_weights(steps, approach)?;
    let device = key.device();
    let distances = distance(
        poses.reshape([b * steps, p]),
        key.unsqueeze_dim::<3>(1)
            .repeat_dim(1, steps)
            .reshape([b * steps, KEY_ROT_DIM]),
    )
    .reshape([b, steps]);
    let weights =
        Tensor::<2>::from_data(burn::tensor::TensorData::new(weights, [1, steps]), &device);
    Some((distances * weights).sum_dim(1).reshape([b]))
}

/// Per sequence `[b]`, the distance between the rotations of `pose` `[b, P]` and `key`
/// `[b, KEY_ROT_DIM]` (normalised units). The distance, not its square (Yang et al.'s L2):
/// its gradient on the pose has unit norm however far the free run strayed, which the chain
/// of steps then carries back.
fn key_distance(pose: Tensor<2>, key: Tensor<2>) -> Tensor<1> {
    let [b, _] = key.dims();
    (pose.narrow(1, ROTATIONS, KEY_ROT_DIM) - key)
        .powi_scalar(2)
        .sum_dim(1)
        .add_scalar(1e-6)
        .sqrt()
        .reshape([b])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::cpu_device;
    use crate::layers::values;
    use burn::tensor::TensorData;
    use model::motion::MOTION_FEATURE_DIM;
    use model::neural::config::NetConfig;
    use model::neural::rng::Rng;
    use model::neural::runtime::Runtime;
    use model::neural::tensors::init_net;
    use model::neural::token::{FLAG_AT, KEY_AT, KEY_ROT_DIM, TOKEN_DIM};

    #[test]
    fn streaming_matches_the_batched_network_across_the_window() {
        streaming_matches_batched(NetConfig::tiny());
    }

    #[test]
    fn streaming_matches_the_batched_network_with_the_key_in_the_flow() {
        let c = NetConfig {
            key_to_flow: true,
            ..NetConfig::tiny()
        };
        streaming_matches_batched(c);
    }

    #[test]
    fn streaming_matches_the_batched_network_with_the_level_in_the_flow() {
        let c = NetConfig {
            key_to_flow: true,
            level_to_flow: true,
            ..NetConfig::tiny()
        };
        streaming_matches_batched(c);
    }

    fn streaming_matches_batched(c: NetConfig) {
        let mut t = init_net(&c, 7);
        t.perturb(8, 0.1);
        let device = cpu_device();
        let net = Net::load(&t, &c, &device).unwrap();
        let mut rt = Runtime::new(&t, &c).unwrap();
        // 2.5 windows, so the sliding window (and the ring wrapping) is exercised.
        let s = c.window * 5 / 2;
        let mut r = Rng::new(1);
        let mut tokens: Vec<f32> = (0..s * TOKEN_DIM).map(|_| r.normal()).collect();
        for i in 0..s {
            // The last token (s − 1 = 19) carries a key, so its key conditioning is not zero.
            tokens[i * TOKEN_DIM + FLAG_AT] = (i % 3 == 1) as u8 as f32;
        }
        assert_eq!(s % 3, 2);
        let tt =
            Tensor::<3>::from_data(TensorData::new(tokens.clone(), [1, s, TOKEN_DIM]), &device);
        // Conditioned on style 1 in both.
        rt.set_style(Some(1));
        let mut onehot = vec![0.0f32; s * c.styles];
        for i in 0..s {
            onehot[i * c.styles + 1] = 1.0;
        }
        let styles = Tensor::<2>::from_data(TensorData::new(onehot, [s, c.styles]), &device);
        let batched = values(net.transformer.forward(tt, Some(styles)));
        let mut worst = 0f32;
        let mut last_ctx = Vec::new();
        for i in 0..s {
            let ctx = rt.push(&tokens[i * TOKEN_DIM..(i + 1) * TOKEN_DIM]);
            for j in 0..c.d_model {
                worst = worst.max((ctx[j] - batched[i * c.d_model + j]).abs());
            }
            last_ctx = ctx.to_vec();
        }
        assert!(
            worst < 1e-3,
            "streaming vs batched context differ by {worst}"
        );
        // The flow inverse agrees with burn's.
        let z: Vec<f32> = (0..MOTION_FEATURE_DIM).map(|_| r.normal()).collect();
        let mut x = vec![0.0; MOTION_FEATURE_DIM];
        rt.sample(&z, &mut x);
        let ctx = Tensor::<2>::from_data(TensorData::new(last_ctx, [1, c.d_model]), &device);
        let last = Tensor::<3>::from_data(
            TensorData::new(tokens[(s - 1) * TOKEN_DIM..].to_vec(), [1, 1, TOKEN_DIM]),
            &device,
        );
        let ctx = net.flow_context(ctx, last);
        assert_eq!(ctx.dims()[1], c.flow().context);
        let zt = Tensor::<2>::from_data(TensorData::new(z, [1, MOTION_FEATURE_DIM]), &device);
        let xb = values(net.flow.inverse(zt, ctx).unwrap());
        let err = x
            .iter()
            .zip(&xb)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(err < 1e-3, "flow inverse differs by {err}");
    }

    #[test]
    fn the_key_rollout_free_runs_as_the_live_runtime_does() {
        for key_to_flow in [false, true] {
            let c = NetConfig {
                key_to_flow,
                ..NetConfig::tiny()
            };
            let mut t = init_net(&c, 3);
            t.perturb(4, 0.03);
            let device = cpu_device();
            let net = Net::load(&t, &c, &device).unwrap();
            let mut rt = Runtime::new(&t, &c).unwrap();
            // Announced after a full window of past and due 1.5 windows later, so the free run
            // slides the window past the announcement.
            let (at, horizon) = (c.window - 1, c.window * 3 / 2);
            let s = at + horizon + 1;
            let mut r = Rng::new(11);
            let mut tokens: Vec<f32> = (0..s * TOKEN_DIM).map(|_| 0.5 * r.normal()).collect();
            // Small, so the distance reflects the pose reached and not mostly the key's size.
            let key: Vec<f32> = (0..KEY_ROT_DIM).map(|_| 0.1 * r.normal()).collect();
            for (i, tok) in tokens.chunks_exact_mut(TOKEN_DIM).enumerate() {
                let announced = i >= at;
                tok[FLAG_AT] = f32::from(u8::from(announced));
                if announced {
                    tok[KEY_AT..KEY_AT + KEY_ROT_DIM].copy_from_slice(&key);
                } else {
                    tok[KEY_AT..KEY_AT + KEY_ROT_DIM].fill(0.0);
                }
            }
            // The runtime, fed its own samples (z = 0) from the announcement on: the distance
            // of each step's pose from the key.
            let mut pose = vec![0.0f32; MOTION_FEATURE_DIM];
            let mut largest = 0.0f32;
            let mut distances = Vec::new();
            let mut sampled = Vec::new();
            for (i, tok) in tokens.chunks_exact(TOKEN_DIM).enumerate() {
                let mut tok = tok.to_vec();
                if i > at {
                    tok[..MOTION_FEATURE_DIM].copy_from_slice(&pose);
                }
                rt.push(&tok);
                if i >= at {
                    rt.sample(&[0.0; MOTION_FEATURE_DIM], &mut pose);
                    sampled.extend_from_slice(&pose);
                    largest = pose.iter().fold(largest, |m, v| m.max(v.abs()));
                    let d = pose[ROTATIONS..ROTATIONS + KEY_ROT_DIM]
                        .iter()
                        .zip(&key)
                        .map(|(a, b)| (a - b) * (a - b))
                        .sum::<f32>()
                        .sqrt();
                    distances.push(d);
                }
            }
            let live = distances[horizon];
            // Over the last 8 frames too, weighted 1 − g / 8 at g frames to go.
            let weights: Vec<f32> = (0..8).map(|g| 1.0 - g as f32 / 8.0).collect();
            let approached = weights
                .iter()
                .enumerate()
                .map(|(g, w)| w * distances[horizon - g])
                .sum::<f32>()
                / weights.iter().sum::<f32>();
            assert!(
                (approached - live).abs() > 1e-3 * live,
                "the approach scores nothing new: {approached} vs {live}"
            );
            assert!(
                largest < ROLLOUT_BOUND,
                "the live free run reached {largest}, beyond the rollout's clamp: not comparable"
            );
            let tt = Tensor::<3>::from_data(TensorData::new(tokens, [1, s, TOKEN_DIM]), &device);
            let mut rng = Rng::new(1);
            for backprop_steps in [None, Some(1), Some(3)] {
                for (approach, expected) in [(0, live), (8, approached)] {
                    let run = FreeRun {
                        at,
                        horizon,
                        temperature: 0.0,
                        backprop_steps,
                        approach,
                    };
                    let outcome = net.key_rollout(tt.clone(), None, &run, &mut rng).unwrap();
                    let poses = values(outcome.poses);
                    assert_eq!(poses.len(), sampled.len());
                    let worst = poses
                        .iter()
                        .zip(&sampled)
                        .map(|(a, b)| (a - b).abs())
                        .fold(0.0, f32::max);
                    assert!(
                        worst < 1e-4,
                        "the rollout's poses differ from the live ones by {worst}"
                    );
                    let trained: f32 = values(outcome.key_distance)[0];
                    assert!(
                        (trained - expected).abs() < 1e-4 * expected,
                        "key_to_flow {key_to_flow}, approach {approach}: rollout {trained} vs live {expected}"
                    );
                }
            }
        }
    }

    /// Every gradient of `loss` on `net`'s weights, in the order the module visits them.
    fn gradient(net: &Net, loss: Tensor<1>) -> Vec<f32> {
        struct Collect<'a> {
            grads: &'a burn::optim::GradientsParams,
            out: Vec<f32>,
        }
        impl burn::module::ModuleVisitor for Collect<'_> {
            fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
                if let Some(g) = self.grads.get::<D>(param.id) {
                    self.out.extend(values(g));
                }
            }
        }
        let grads = burn::optim::GradientsParams::from_grads(loss.backward(), net);
        let mut c = Collect {
            grads: &grads,
            out: Vec::new(),
        };
        net.visit(&mut c);
        c.out
    }

    #[test]
    fn a_replayed_rollout_scores_and_teaches_as_the_stepped_one() {
        for key_to_flow in [false, true] {
            let c = NetConfig {
                key_to_flow,
                ..NetConfig::tiny()
            };
            let mut t = init_net(&c, 7);
            t.perturb(8, 0.03);
            let device = crate::device::training_device();
            let net = Net::load(&t, &c, &device).unwrap();
            // Three sequences, announced after a full window and due 1.5 windows later (the
            // free run slides the window past the announcement), sampled at T = 0.5.
            let (b, at, horizon) = (3, c.window - 1, c.window * 3 / 2);
            let s = at + horizon + 1;
            let mut r = Rng::new(12);
            let mut tokens: Vec<f32> = (0..b * s * TOKEN_DIM).map(|_| 0.5 * r.normal()).collect();
            for (i, tok) in tokens.chunks_exact_mut(TOKEN_DIM).enumerate() {
                let announced = i % s >= at;
                tok[FLAG_AT] = f32::from(u8::from(announced));
                if !announced {
                    tok[KEY_AT..KEY_AT + KEY_ROT_DIM].fill(0.0);
                }
            }
            let tt = Tensor::<3>::from_data(TensorData::new(tokens, [b, s, TOKEN_DIM]), &device);
            let run = FreeRun {
                at,
                horizon,
                temperature: 0.5,
                backprop_steps: Some(1),
                approach: 8,
            };
            let stepped = net
                .stepped_key_rollout(tt.clone(), None, &run, &mut Rng::new(3))
                .unwrap();
            let replayed = net
                .replayed_key_rollout(tt.clone(), &run, &mut Rng::new(3))
                .unwrap();
            assert_eq!(stepped.kept, replayed.kept);
            let worst = |a: Vec<f32>, b: Vec<f32>| {
                assert_eq!(a.len(), b.len());
                a.iter()
                    .zip(&b)
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0, f32::max)
            };
            let fed = worst(
                values(stepped.tokens.clone()),
                values(replayed.tokens.clone()),
            );
            assert!(
                fed < 1e-4,
                "key_to_flow {key_to_flow}: fed tokens differ by {fed}"
            );
            let poses = worst(
                values(stepped.poses.clone()),
                values(replayed.poses.clone()),
            );
            assert!(
                poses < 1e-4,
                "key_to_flow {key_to_flow}: poses differ by {poses}"
            );
            let d = (
                values(stepped.key_distance.clone()),
                values(replayed.key_distance.clone()),
            );
            assert!(worst(d.0.clone(), d.1.clone()) < 1e-4 * d.0[0], "{d:?}");
            // Scored on every step's pose too, so every step's context must carry the gradient.
            let loss = |o: FreeRunOutcome| o.key_distance.sum() + o.poses.sum().mul_scalar(0.1);
            let (g_stepped, g_replayed) = (
                gradient(&net, loss(stepped)),
                gradient(&net, loss(replayed)),
            );
            let scale = g_stepped.iter().fold(0.0f32, |m, g| m.max(g.abs()));
            assert!(scale > 1e-3, "no gradient to compare: {scale}");
            let off = worst(g_stepped, g_replayed);
            assert!(
                off < 1e-3 * scale,
                "key_to_flow {key_to_flow}: gradients differ by {off} (largest {scale})"
            );
        }
    }

    #[test]
    fn a_replayed_rollout_leaves_out_a_sequence_that_breaks_not_the_run() {
        let c = NetConfig {
            key_to_flow: true,
            ..NetConfig::tiny()
        };
        let mut t = init_net(&c, 9);
        t.perturb(10, 0.03);
        let device = crate::device::training_device();
        let net = Net::load(&t, &c, &device).unwrap();
        let (b, at, horizon) = (3, c.window - 1, 12);
        let s = at + horizon + 1;
        let mut r = Rng::new(13);
        let mut tokens: Vec<f32> = (0..b * s * TOKEN_DIM).map(|_| 0.5 * r.normal()).collect();
        for (i, tok) in tokens.chunks_exact_mut(TOKEN_DIM).enumerate() {
            tok[FLAG_AT] = f32::from(u8::from(i % s >= at));
            // The middle sequence's key flag is far beyond any trained value: the flow's
            // inverse, reading it directly, overflows.
            if i / s == 1 && i % s >= at {
                tok[FLAG_AT] = 1e30;
            }
        }
        let tt = Tensor::<3>::from_data(TensorData::new(tokens, [b, s, TOKEN_DIM]), &device);
        let run = FreeRun {
            at,
            horizon,
            temperature: 0.5,
            backprop_steps: Some(1),
            approach: 4,
        };
        assert!(
            net.stepped_key_rollout(tt.clone(), None, &run, &mut Rng::new(3))
                .is_none(),
            "the broken sequence no longer breaks the stepped run: the test proves nothing"
        );
        let outcome = net
            .replayed_key_rollout(tt, &run, &mut Rng::new(3))
            .unwrap();
        assert_eq!(outcome.kept, [true, false, true]);
        let scored = values(outcome.kept_mean(outcome.key_distance.clone()))[0];
        assert!(scored.is_finite() && scored > 0.0, "{scored}");
        let g = gradient(&net, outcome.kept_mean(outcome.key_distance.clone()));
        assert!(g.iter().all(|v| v.is_finite()), "a gradient is not finite");
        assert!(g.iter().any(|v| *v != 0.0), "no gradient at all");
    }

    #[test]
    fn the_keyless_nll_hides_the_key_and_scores_only_the_free_run() {
        let c = NetConfig {
            key_to_flow: true,
            ..NetConfig::tiny()
        };
        let mut t = init_net(&c, 5);
        t.perturb(6, 0.03);
        let device = cpu_device();
        let net = Net::load(&t, &c, &device).unwrap();
        let (at, horizon) = (c.window - 1, 6);
        let s = at + horizon + 1;
        let mut r = Rng::new(3);
        let mut tokens: Vec<f32> = (0..2 * s * TOKEN_DIM).map(|_| 0.5 * r.normal()).collect();
        for (i, tok) in tokens.chunks_exact_mut(TOKEN_DIM).enumerate() {
            tok[FLAG_AT] = f32::from(u8::from(i % s >= at));
        }
        let targets: Vec<f32> = (0..2 * s * MOTION_FEATURE_DIM)
            .map(|_| 0.5 * r.normal())
            .collect();
        let tt = Tensor::<3>::from_data(TensorData::new(tokens, [2, s, TOKEN_DIM]), &device);
        let before = Tensor::<3>::from_data(
            TensorData::new(targets, [2, s, MOTION_FEATURE_DIM]),
            &device,
        );
        let run = FreeRun {
            at,
            horizon,
            temperature: 0.0,
            backprop_steps: Some(1),
            approach: 0,
        };
        let outcome = net.key_rollout(tt, None, &run, &mut Rng::new(1)).unwrap();
        let scored = values(net.keyless_nll(&outcome, None, before.clone()).mean_dim(1));
        // Teacher-forced by hand: the fed tokens with every key field zeroed, the free run's
        // poses as the targets from the announcement on; only those rows counted.
        let fed = values(outcome.tokens.clone());
        let mut keyless = fed.clone();
        for tok in keyless.chunks_exact_mut(TOKEN_DIM) {
            tok[KEY_AT..].fill(0.0);
        }
        let mut targets = values(before.clone());
        let poses = values(outcome.poses.clone());
        for q in 0..2 {
            for (g, pose) in poses[q * (horizon + 1) * MOTION_FEATURE_DIM..]
                .chunks_exact(MOTION_FEATURE_DIM)
                .take(horizon + 1)
                .enumerate()
            {
                let row = (q * s + at + g) * MOTION_FEATURE_DIM;
                targets[row..row + MOTION_FEATURE_DIM].copy_from_slice(pose);
            }
        }
        let tensor3 =
            |v: Vec<f32>, w: usize| Tensor::<3>::from_data(TensorData::new(v, [2, s, w]), &device);
        let rows = values(net.score(
            tensor3(keyless, TOKEN_DIM),
            None,
            tensor3(targets.clone(), MOTION_FEATURE_DIM),
        ));
        for q in 0..2 {
            let by_hand = rows[q * s + at..(q + 1) * s].iter().sum::<f32>() / (horizon + 1) as f32;
            assert!(
                (scored[q] - by_hand).abs() < 1e-4 * by_hand.abs().max(1.0),
                "sequence {q}: {} vs {by_hand}",
                scored[q]
            );
        }
        // With the key visible the same poses score otherwise: the hiding is what is measured.
        let seen = values(net.score(
            tensor3(fed, TOKEN_DIM),
            None,
            tensor3(targets, MOTION_FEATURE_DIM),
        ));
        let seen0 = seen[at..s].iter().sum::<f32>() / (horizon + 1) as f32;
        assert!((seen0 - scored[0]).abs() > 1e-3, "{seen0} vs {}", scored[0]);
    }

    #[test]
    fn an_exploded_sequence_is_left_out_without_a_gradient_and_a_broken_one_drops_the_run() {
        let device = crate::device::training_device();
        let rows = [0.5f32, -2.0, 2.0 * ROLLOUT_EXPLODED, 1.0, 0.25, -0.75];
        let pose =
            Tensor::<2>::from_data(TensorData::new(rows.to_vec(), [3, 2]), &device).require_grad();
        let mut kept = vec![true; 3];
        let out = leave_out_exploded(pose.clone(), &mut kept).expect("two sequences kept");
        assert_eq!(kept, [true, false, true]);
        assert_eq!(values(out.clone()), [0.5, -2.0, 0.0, 0.0, 0.25, -0.75]);
        let grads = (out * 3.0).sum().backward();
        let g = values(pose.grad(&grads).expect("a gradient"));
        assert_eq!(g, [3.0, 3.0, 0.0, 0.0, 3.0, 3.0]);
        // Once left out a sequence stays out, however it dances on.
        let again = Tensor::<2>::from_data(TensorData::new(vec![0.1f32; 6], [3, 2]), &device);
        leave_out_exploded(again, &mut kept).expect("kept");
        assert_eq!(kept, [true, false, true]);
        // Not finite anywhere, or nothing left: the whole run is dropped.
        let broken = Tensor::<2>::from_data(
            TensorData::new(vec![0.0, f32::NAN, 0.0, 0.0, 0.0, 0.0], [3, 2]),
            &device,
        );
        assert!(leave_out_exploded(broken, &mut [true; 3]).is_none());
        let lost = Tensor::<2>::from_data(TensorData::new(vec![1e9f32; 6], [3, 2]), &device);
        assert!(leave_out_exploded(lost, &mut [true; 3]).is_none());
    }

    #[test]
    fn the_kept_mean_weighs_only_the_kept_sequences() {
        let device = cpu_device();
        let outcome = FreeRunOutcome {
            key_distance: Tensor::zeros([3], &device),
            tokens: Tensor::zeros([3, 1, 1], &device),
            poses: Tensor::zeros([3, 1, 1], &device),
            kept: vec![true, false, true],
        };
        assert_eq!(outcome.exploded(), 1);
        let d = Tensor::<1>::from_data(TensorData::new(vec![1.0f32, 1e6, 3.0], [3]), &device);
        assert_eq!(values(outcome.kept_mean(d)), [2.0]);
        let frames = Tensor::<2>::from_data(
            TensorData::new(vec![1.0f32, 2.0, 1e6, 1e6, 3.0, 6.0], [3, 2]),
            &device,
        );
        assert_eq!(values(outcome.kept_mean(frames)), [3.0]);
    }
}
