//! [`NeuralDancer`]: the trained network as a [`MotionSource`]. Each frame pushes one token
//! (the previous output pose, the music `lookahead` frames ahead, the key pose if any) through
//! the cached transformer, draws z ~ N(0, T²I) (correlated from frame to frame), inverts the
//! flow, retimes the step within the beat, and decodes the features into a pose with the
//! streaming [`MotionDecoder`]. A non-finite or exploding output is never
//! passed on: the last good pose is held and the frame counted.
//!
//! The dance starts from a seed clip (Transflower's "motion prompt": a window of real motion
//! with its music, stored in the model file) pushed through the cache at reset, so the first
//! sampled frame already has a full window of in-distribution context: a single seed pose
//! drifted out of the data's range within a few frames.

use dsp::feature::{FEATURE_DIM, FeatureLayout};

use crate::ModelError;
use crate::foot_lock::{self, FootLock};
use crate::key_overlay::KeyOverlay;
use crate::motion::{
    MOTION_FEATURE_DIM, MotionDecoder, ROOT_DFACING, ROOT_DX, ROOT_DZ, ROTATION_DIM, ROTATIONS,
    RootState,
};
use crate::neural::file::{FRAME_RATE, NeuralModel};
use crate::neural::rng::Rng;
use crate::neural::runtime::Runtime;
use crate::neural::safety::{SafetyCounts, SafetyNets};
use crate::neural::token::{self, KEY_ROT_DIM, Normalizer, TOKEN_DIM};
use crate::rig::{Pose, Skeleton};
use crate::rotation::{quat_to_6d, sixd_to_quat};
use crate::source::{
    Controls, KeyPoseRoute, MotionSource, SourceControls, SourceReport, finite_clamp,
};
use crate::style::{DanceStyle, StyleFromMusic, StyleRequest};

/// A normalised output beyond this many standard deviations counts as exploding.
pub const EXPLODED_SIGMAS: f32 = 50.0;

/// Samples are clamped to the training data's range widened by this fraction of it on each
/// side: beyond the data the network extrapolates, and its own extrapolations fed back run
/// away (hips drifting up by a metre within seconds, measured before the clamp).
pub const RANGE_MARGIN: f32 = 0.05;

/// A feature whose training range is narrower than this (raw units) is one the data holds
/// constant.
pub const CONSTANT_FEATURE_RANGE: f32 = 1e-3;

pub use crate::key_overlay::{KEY_BLEND_FRAMES, KEY_RELEASE_FRAMES};

/// Default depth of the beat accent (see [`NeuralDancer::set_beat_accent`]): none, because the
/// shipped network learned its accent from training dances retimed within each beat
/// (`danced-train dancer --beat-retime 0.2`); on top of that, an accent cost FID_k (42.9 against
/// 37.8 on seed 1, 79.2 against 37.6 on seed 2). Models trained on the dances as captured
/// dance better with about 0.15.
pub const BEAT_ACCENT: f32 = 0.0;

/// Frame-to-frame correlation of the latent noise: z_t = ρ z_{t−1} + √(1 − ρ²) ε_t, still
/// N(0, T²I) at every frame. With independent draws (ρ = 0) temperature only added tremor,
/// which the dance's 5-second statistics average away (Dist_k 3.7–4.3 at T = 0.5 and 1 against
/// 4.4 at T = 0, FID_k 49–59); held for about a second (ρ = 0.95 at 25 fps) a draw becomes a
/// choice of how to move, and diversity rises with T (Dist_k 4.4 / 5.5–6.1 / 10.6–11.1).
pub const NOISE_CORRELATION: f32 = 0.95;

/// Fastest hips speed over the floor, m/s, the dancer may keep up: the training dances' fastest
/// 5-second mean is 2.4 m/s. Free-running, the network sometimes settled into travelling at
/// 5–7 m/s for a minute (measured on the validation songs); beyond this, steps are shortened.
pub const SUSTAINED_SPEED_LIMIT_MPS: f32 = 2.5;

/// Frames the sustained speed is averaged over (an exponential average, 2 s at 25 fps), so
/// short bursts as fast as the training data's pass untouched.
pub const SPEED_AVERAGE_FRAMES: f32 = 50.0;

/// After this many held frames in a row the dancer restarts from its seed clip (keeping its
/// place on the floor) rather than stand still. Held frames come in runs: the held pose fed
/// back keeps the context where the flow failed (with correlated noise, runs of 25 frames
/// were measured, each a visible freeze), so the restart comes early.
pub const RESTART_AFTER_HELD: u32 = 4;

/// Frames over which the pose glides from where the dancer stood to the restarted motion.
pub const RESTART_BLEND_FRAMES: u32 = 10;

/// The neural motion source.
pub struct NeuralDancer {
    runtime: Runtime,
    norm: Normalizer,
    seed_motion: Vec<f32>,
    /// Per style (by index), its own seed clip, normalised (motion, music); empty for a model
    /// without them, or after [`NeuralDancer::set_seed_pose`].
    style_seeds: Vec<Option<(Vec<f32>, Vec<f32>)>>,
    seed_music: Vec<f32>,
    low: Vec<f32>,
    high: Vec<f32>,
    /// Features the training data varies (the others it holds constant: joints the fitted rig
    /// never turns; the clamp pins those too, which is not counted as the net acting).
    varying: Vec<bool>,
    decoder: MotionDecoder,
    rng: Rng,
    previous: Vec<f32>,
    token: Vec<f32>,
    music: Vec<f32>,
    key_raw: Vec<f32>,
    key: Vec<f32>,
    z: Vec<f32>,
    /// The unit-variance AR(1) process the latent is drawn from (z = T × this).
    noise: Vec<f32>,
    noise_correlation: f32,
    sample: Vec<f32>,
    features: [f32; MOTION_FEATURE_DIM],
    last_good: Pose,
    held_in_a_row: u32,
    nets: SafetyNets,
    counts: SafetyCounts,
    key_blend_frames: u32,
    /// The route set up ([`NeuralDancer::set_key_pose_route`]), and the one in effect (a
    /// route asked for live takes over once no key is pending or being let go: switched
    /// halfway, the pose shown would jump).
    key_route: KeyPoseRoute,
    route_now: KeyPoseRoute,
    /// The key pose shown over the dance, and the rotations let go (raw 6D).
    overlay: KeyOverlay,
    released_raw: Vec<f32>,
    beat_accent: f32,
    /// Pose the dancer glides from after a restart, and the frames of the glide left.
    glide_from: Pose,
    glide_left: u32,
    foot_lock: FootLock,
    previous_raw: [f32; MOTION_FEATURE_DIM],
    /// The range clamp's bounds in raw units (`low`, `high` are normalised).
    low_raw: [f32; MOTION_FEATURE_DIM],
    high_raw: [f32; MOTION_FEATURE_DIM],
    mean_speed_mps: f32,
    horizon_frames: usize,
    style_from_music: StyleFromMusic,
    style: DanceStyle,
}

impl NeuralDancer {
    /// A dancer running `model` (validated already if it came from [`NeuralModel::load`]).
    pub fn new(model: &NeuralModel) -> Result<Self, ModelError> {
        let runtime = Runtime::new(&model.tensors, &model.config)?;
        let norm = model.normalizer()?;
        let (motion, music) = model.seed_clip()?;
        let (seed_motion, seed_music) = normalised_clip(&norm, motion, music);
        let style_seeds = (0..model.config.styles)
            .map(|i| {
                model
                    .style_seed_clip(i)
                    .map(|(motion, music)| normalised_clip(&norm, motion, music))
            })
            .collect();
        let (lo, hi) = model.pose_range()?;
        let (mut low, mut high) = (vec![0.0; MOTION_FEATURE_DIM], vec![0.0; MOTION_FEATURE_DIM]);
        let (mut l, mut h) = (vec![0.0; MOTION_FEATURE_DIM], vec![0.0; MOTION_FEATURE_DIM]);
        for i in 0..MOTION_FEATURE_DIM {
            let margin = RANGE_MARGIN * (hi[i] - lo[i]);
            l[i] = lo[i] - margin;
            h[i] = hi[i] + margin;
        }
        norm.pose(&l, &mut low);
        norm.pose(&h, &mut high);
        let (mut low_raw, mut high_raw) = ([0.0; MOTION_FEATURE_DIM], [0.0; MOTION_FEATURE_DIM]);
        for i in 0..MOTION_FEATURE_DIM {
            low_raw[i] = l[i].min(h[i]);
            high_raw[i] = l[i].max(h[i]);
        }
        let varying = (0..MOTION_FEATURE_DIM)
            .map(|i| hi[i] - lo[i] > CONSTANT_FEATURE_RANGE)
            .collect();
        let mut d = NeuralDancer {
            horizon_frames: model.training.horizon_frames,
            runtime,
            norm,
            low,
            high,
            low_raw,
            high_raw,
            varying,
            previous: vec![0.0; MOTION_FEATURE_DIM],
            seed_motion,
            style_seeds,
            seed_music,
            decoder: MotionDecoder::new(RootState::ORIGIN),
            rng: Rng::new(0),
            token: vec![0.0; TOKEN_DIM],
            music: vec![0.0; FEATURE_DIM],
            key_raw: vec![0.0; KEY_ROT_DIM],
            key: vec![0.0; KEY_ROT_DIM],
            z: vec![0.0; MOTION_FEATURE_DIM],
            noise: vec![0.0; MOTION_FEATURE_DIM],
            noise_correlation: NOISE_CORRELATION,
            sample: vec![0.0; MOTION_FEATURE_DIM],
            features: [0.0; MOTION_FEATURE_DIM],
            last_good: Pose::rest(),
            held_in_a_row: 0,
            nets: SafetyNets::SHIPPED,
            counts: SafetyCounts::default(),
            key_blend_frames: KEY_BLEND_FRAMES,
            key_route: KeyPoseRoute::Overlay,
            route_now: KeyPoseRoute::Overlay,
            overlay: KeyOverlay::default(),
            released_raw: vec![0.0; KEY_ROT_DIM],
            beat_accent: BEAT_ACCENT,
            glide_from: Pose::rest(),
            glide_left: 0,
            foot_lock: FootLock::new(
                Skeleton::default_adult(),
                FRAME_RATE as f32,
                foot_lock::DEFAULT_STRENGTH,
            )
            .with_plant(foot_lock::DEFAULT_PLANT),
            previous_raw: [0.0; MOTION_FEATURE_DIM],
            mean_speed_mps: 0.0,
            style_from_music: StyleFromMusic::new(),
            style: DanceStyle::Waltz,
        };
        d.reset(0);
        Ok(d)
    }

    /// Replaces the seed clip's motion by standing still in one pose (raw motion features):
    /// the "motion prompt" the dance starts from. Takes effect at the next reset.
    pub fn set_seed_pose(&mut self, features: &[f32; MOTION_FEATURE_DIM]) {
        self.style_seeds.clear();
        for row in self.seed_motion.chunks_exact_mut(MOTION_FEATURE_DIM) {
            self.norm.pose(features, row);
        }
    }

    /// Sets where key poses go while the end blend is on (default [`KeyPoseRoute::Overlay`]).
    pub fn set_key_pose_route(&mut self, route: KeyPoseRoute) {
        self.key_route = route;
        self.route_now = route;
    }

    /// Sets the most frames over which a key pose is blended in before its deadline (0: the
    /// network's own arrival, unaided).
    pub fn set_key_blend_frames(&mut self, frames: u32) {
        self.key_blend_frames = frames;
    }

    /// Sets the depth `a` of the beat accent in [0, 1): the network's motion is retimed within
    /// each beat, its pace scaled by 1 − a·cos(2π·beat phase), so the dancer slows into every
    /// beat and speeds up between (the pace over a whole beat is unchanged). A network trained
    /// on the dances as captured puts its kinematic beats barely above chance (BeatAlign 0.245
    /// against 0.229 on other songs' beats) and needs it; the retrieval dancer's time-warp does
    /// the same job for its clips.
    /// 0 turns it off; values outside [0, 0.9] are clamped.
    /// A live [`Controls::beat_accent`] overrides it.
    pub fn set_beat_accent(&mut self, depth: f32) {
        self.beat_accent = clean_accent(depth);
    }

    /// Sets the frame-to-frame correlation ρ of the latent noise, in [0, 0.999] (0: a fresh
    /// draw every frame; see [`NOISE_CORRELATION`]). Takes effect at the next frame.
    pub fn set_noise_correlation(&mut self, rho: f32) {
        self.noise_correlation = finite_clamp(rho, 0.0, 0.999);
    }

    /// Sets the share of a planted toe's drift the [`FootLock`] takes back (0: off; default
    /// [`foot_lock::DEFAULT_STRENGTH`]).
    pub fn set_foot_lock(&mut self, strength: f32) {
        self.foot_lock.set_strength(strength);
    }

    /// Sets the share of a planted toe's remaining drift the stance leg holds by bending (0:
    /// the legs are never touched; default [`foot_lock::DEFAULT_PLANT`]).
    pub fn set_foot_plant(&mut self, plant: f32) {
        self.foot_lock.set_plant(plant);
    }

    /// Switches the safety nets on or off ([`SafetyNets::NETWORK_ONLY`]: the network alone);
    /// set before dancing (the foot lock's offset and the speed average carry on as they are).
    pub fn set_safety_nets(&mut self, nets: SafetyNets) {
        self.nets = nets;
    }

    /// Pushes the seed clip through the cache; the next frame continues it.
    /// The seed clip of the style danced now (its own, where the model has one).
    fn prime(&mut self) {
        self.runtime.reset();
        let (seed_motion, seed_music) = match self.style_seeds.get(self.style.index()) {
            Some(Some((m, x))) => (m, x),
            _ => (&self.seed_motion, &self.seed_music),
        };
        let n = seed_motion.len() / MOTION_FEATURE_DIM;
        for f in 1..n {
            token::fill(
                &mut self.token,
                &seed_motion[(f - 1) * MOTION_FEATURE_DIM..f * MOTION_FEATURE_DIM],
                &seed_music[f * FEATURE_DIM..(f + 1) * FEATURE_DIM],
                None,
            );
            self.runtime.push(&self.token);
        }
        self.previous
            .copy_from_slice(&seed_motion[(n - 1) * MOTION_FEATURE_DIM..]);
        self.norm.unpose(&self.previous, &mut self.previous_raw);
    }

    /// Retimes the raw `features` of the next frame within the beat (`beat_cos`: cosine of the
    /// beat phase at this frame, 1 on the beat) and shortens its step over the floor where the
    /// sustained speed would pass the limit.
    fn shape_motion(&mut self, beat_cos: f32, accent: f32) {
        let pace = 1.0 - accent * beat_cos.clamp(-1.0, 1.0);
        for (i, (f, p)) in self.features.iter_mut().zip(&self.previous_raw).enumerate() {
            *f = match i {
                // Displacements per frame: the pace scales them directly.
                ROOT_DX | ROOT_DZ | ROOT_DFACING => pace * *f,
                // Poses: the pace scales the step from the previous one.
                _ => p + pace * (*f - p),
            };
        }
        let fps = FRAME_RATE as f32;
        let step = self.features[ROOT_DX].hypot(self.features[ROOT_DZ]);
        let alpha = 1.0 / SPEED_AVERAGE_FRAMES;
        let mean = self.mean_speed_mps + alpha * (step * fps - self.mean_speed_mps);
        if self.nets.speed_limit && mean > SUSTAINED_SPEED_LIMIT_MPS && step > 0.0 {
            // The longest step that keeps the average at the limit.
            let allowed = (self.mean_speed_mps
                + (SUSTAINED_SPEED_LIMIT_MPS - self.mean_speed_mps) / alpha)
                .max(0.0)
                / fps;
            let k = (allowed / step).min(1.0);
            self.features[ROOT_DX] *= k;
            self.features[ROOT_DZ] *= k;
            self.counts.speed_limited += 1;
        }
        let step = self.features[ROOT_DX].hypot(self.features[ROOT_DZ]);
        self.mean_speed_mps += alpha * (step * fps - self.mean_speed_mps);
    }

    /// The style danced at the last frame (requested, or chosen from the music for `auto`;
    /// a model without a style input dances it only as far as its music suggests it).
    pub fn style(&self) -> DanceStyle {
        self.style
    }

    /// Whether the model takes a style input (models before issue 21 do not).
    pub fn has_style_input(&self) -> bool {
        self.runtime.config().styles > 0
    }

    /// The last flow sample, normalised features (for diagnostics: a held frame's culprit).
    pub fn last_sample(&self) -> &[f32] {
        &self.sample
    }
}

impl MotionSource for NeuralDancer {
    fn frame_rate(&self) -> f64 {
        FRAME_RATE
    }

    fn lookahead_frames(&self) -> usize {
        self.runtime.config().lookahead
    }

    fn horizon_frames(&self) -> usize {
        self.horizon_frames
    }

    fn step(&mut self, music: &[[f32; FEATURE_DIM]], controls: &Controls, out: &mut Pose) {
        // Short music (the stream's end) repeats its last frame; none at all reads as the mean.
        let heard_frame = music.get(self.lookahead_frames()).or(music.last());
        match heard_frame {
            Some(frame) => self.norm.music(frame, &mut self.music),
            None => self.music.fill(0.0),
        }
        for v in self.music.iter_mut() {
            if !v.is_finite() {
                *v = 0.0;
            }
        }
        let heard = match heard_frame {
            Some(frame) => self.style_from_music.push(frame),
            None => self.style_from_music.style(),
        };
        let style = match controls.style {
            StyleRequest::Auto => heard,
            StyleRequest::Style(s) => s,
        };
        let changed = style != self.style;
        self.style = style;
        self.runtime.set_style(Some(self.style.index()));
        if changed && matches!(self.style_seeds.get(style.index()), Some(Some(_))) {
            // A new style starts from its own seed clip, as a restart does (a window of tokens
            // in one frame), gliding there: its label over another style's motion is a context
            // training never saw, and from it the network ran off the data within seconds.
            self.prime();
            self.glide_from = self.last_good;
            self.glide_left = RESTART_BLEND_FRAMES;
        }
        let key = controls.key_pose.map(|k| {
            token::key_rotations(&k.rotations, &mut self.key_raw);
            self.norm.key(&self.key_raw, &mut self.key);
            k.frames_to_go
        });
        if self.overlay.at_rest() {
            self.route_now = controls.key_route.unwrap_or(self.key_route);
        }
        self.overlay.read_cue(controls.key_pose.as_ref());
        let overlay = self.nets.key_blend
            && self.key_blend_frames > 0
            && self.route_now == KeyPoseRoute::Overlay;
        token::fill(
            &mut self.token,
            &self.previous,
            &self.music,
            key.filter(|_| !overlay).map(|f| (&self.key[..], f)),
        );
        self.runtime.push(&self.token);
        let t = finite_clamp(controls.temperature, 0.0, f32::INFINITY);
        let rho = self.noise_correlation;
        let fresh = (1.0 - rho * rho).sqrt();
        for (z, n) in self.z.iter_mut().zip(self.noise.iter_mut()) {
            *n = rho * *n + fresh * self.rng.normal();
            *z = t * *n;
        }
        self.runtime.sample(&self.z, &mut self.sample);
        self.counts.frames += 1;
        let good = self
            .sample
            .iter()
            .all(|v| v.is_finite() && v.abs() < EXPLODED_SIGMAS);
        if good {
            if self.nets.range_clamp {
                let mut clamped = 0;
                let bounds = self.low.iter().zip(&self.high).zip(&self.varying);
                for (s, ((lo, hi), varying)) in self.sample.iter_mut().zip(bounds) {
                    let c = s.clamp(*lo, *hi);
                    clamped += u64::from(*varying && c != *s);
                    *s = c;
                }
                self.counts.range_clamped += u64::from(clamped > 0);
                self.counts.range_clamped_values += clamped;
            }
            self.norm.unpose(&self.sample, &mut self.features);
            let beat_cos = music
                .first()
                .map(|now| now[FeatureLayout::BEAT_COS])
                .filter(|c| c.is_finite())
                .unwrap_or(0.0);
            let accent = match controls.beat_accent {
                _ if !self.nets.beat_accent => 0.0,
                Some(a) => clean_accent(a),
                None => self.beat_accent,
            };
            self.counts.accented += u64::from(accent > 0.0);
            self.shape_motion(beat_cos, accent);
            if self.nets.range_clamp {
                // The accent's pace extrapolates the step (pace > 1) or starts it from a pose
                // outside the range (the seed's, a key pose's): the pose shown stays in range.
                // Displacements are left to the speed limit, which may take them below it.
                let bounds = self.low_raw.iter().zip(&self.high_raw);
                for (i, (f, (lo, hi))) in self.features.iter_mut().zip(bounds).enumerate() {
                    if !matches!(i, ROOT_DX | ROOT_DZ | ROOT_DFACING) {
                        *f = f.clamp(*lo, *hi);
                    }
                }
            }
            // How far into a key pose's arrival this frame is: the end blend's weight, and how
            // much of a held foot lets go (a leg bent to hold its toe would bend the key pose
            // too, blended or not).
            let frames = if self.nets.key_blend {
                self.key_blend_frames
            } else {
                0
            };
            let weights = self.overlay.weights(key, frames, overlay);
            let let_go = self
                .overlay
                .arrival(key, self.key_blend_frames.max(KEY_BLEND_FRAMES))
                .unwrap_or(0.0)
                .max(weights.release.unwrap_or(0.0));
            // The features decoded into the pose shown: the network's, or blended onto a key.
            let mut shown = self.features;
            // Both are heading-free 6D rotations, blended along the arc between them (a straight
            // line between two 6D rotations far apart turns fastest halfway): first off the
            // key let go, then onto the key due.
            if let Some(w) = weights.release {
                token::key_rotations(self.overlay.released(), &mut self.released_raw);
                let rotations = &mut shown[ROTATIONS..ROTATIONS + KEY_ROT_DIM];
                slerp_rotations(rotations, &self.released_raw, w);
            }
            if let Some(w) = weights.blend {
                let rotations = &mut shown[ROTATIONS..ROTATIONS + KEY_ROT_DIM];
                slerp_rotations(rotations, &self.key_raw, w);
            }
            if weights.acts() {
                self.counts.key_blended += 1;
            }
            if weights.blend.is_some() && !overlay {
                // Routed to the network, the blend is fed back so that it sees itself arrive;
                // as an overlay the network keeps its own dance under it.
                self.features = shown;
            }
            self.norm.pose(&self.features, &mut self.sample);
            self.decoder.decode_frame(&shown, out);
            if self.glide_left > 0 {
                let w = self.glide_left as f32 / (RESTART_BLEND_FRAMES + 1) as f32;
                for (r, from) in out
                    .local_rotations
                    .iter_mut()
                    .zip(&self.glide_from.local_rotations)
                {
                    *r = r.slerp(*from, w);
                }
                self.glide_left -= 1;
            }
            if self.nets.foot_lock && self.foot_lock.process(out, 1.0 - let_go) {
                self.counts.foot_locked += 1;
            }
            self.last_good = *out;
            self.previous.copy_from_slice(&self.sample);
            self.previous_raw = self.features;
            self.held_in_a_row = 0;
        } else {
            self.counts.held += 1;
            self.held_in_a_row += 1;
            *out = self.last_good;
            if self.nets.restart && self.held_in_a_row >= RESTART_AFTER_HELD {
                // A rare, one-frame cost (a window of tokens) instead of a frozen dancer.
                self.prime();
                self.noise.fill(0.0);
                self.glide_from = self.last_good;
                self.glide_left = RESTART_BLEND_FRAMES;
                self.counts.restarts += 1;
                self.held_in_a_row = 0;
            }
        }
    }

    fn reset(&mut self, seed: u64) {
        // The seed clip is pushed with the style `auto` starts from, whatever the last run
        // danced, so a reset starts the same dance every time.
        self.style_from_music.reset();
        self.style = self.style_from_music.style();
        self.runtime.set_style(Some(self.style.index()));
        self.prime();
        self.rng = Rng::new(seed);
        for n in self.noise.iter_mut() {
            *n = self.rng.normal();
        }
        self.decoder = MotionDecoder::new(RootState::ORIGIN);
        self.norm.unpose(&self.previous, &mut self.features);
        let mut probe = MotionDecoder::new(RootState::ORIGIN);
        probe.decode_frame(&self.features, &mut self.last_good);
        self.held_in_a_row = 0;
        self.counts = SafetyCounts::default();
        self.mean_speed_mps = 0.0;
        self.glide_left = 0;
        self.overlay.reset();
        self.foot_lock.reset();
    }

    fn controls(&self) -> SourceControls {
        SourceControls {
            style: self.has_style_input(),
            key_route: true,
            beat_accent: true,
            moves: false,
        }
    }

    fn report(&self) -> SourceReport {
        SourceReport {
            style: self.has_style_input().then_some(self.style),
            key_route: Some(self.route_now),
            safety: Some(self.counts),
            stage: None,
            moves: None,
        }
    }

    fn reseed(&mut self, seed: u64) {
        // The correlated noise carries on from its current value, so the pose glides.
        self.rng = Rng::new(seed);
    }
}

/// A raw seed clip (motion rows, music rows) normalised with `norm`.
fn normalised_clip(norm: &Normalizer, motion: &[f32], music: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let mut m = vec![0.0; motion.len()];
    for (raw, out) in motion
        .chunks_exact(MOTION_FEATURE_DIM)
        .zip(m.chunks_exact_mut(MOTION_FEATURE_DIM))
    {
        norm.pose(raw, out);
    }
    let mut x = vec![0.0; music.len()];
    for (raw, out) in music
        .chunks_exact(FEATURE_DIM)
        .zip(x.chunks_exact_mut(FEATURE_DIM))
    {
        norm.music(raw, out);
    }
    (m, x)
}

/// A beat accent depth in [0, 0.9] (non-finite: 0).
fn clean_accent(depth: f32) -> f32 {
    finite_clamp(depth, 0.0, 0.9)
}

/// Turns each 6D rotation of `rotations` the fraction `w` of the way along the arc to the
/// same joint's in `target`.
fn slerp_rotations(rotations: &mut [f32], target: &[f32], w: f32) {
    for (f, k) in rotations
        .chunks_exact_mut(ROTATION_DIM)
        .zip(target.chunks_exact(ROTATION_DIM))
    {
        let mut from = [0.0; ROTATION_DIM];
        let mut to = [0.0; ROTATION_DIM];
        from.copy_from_slice(f);
        to.copy_from_slice(k);
        f.copy_from_slice(&quat_to_6d(sixd_to_quat(from).slerp(sixd_to_quat(to), w)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::neural::config::NetConfig;
    use crate::neural::file::TrainingSummary;
    use crate::neural::tensors::init_net;
    use crate::source::KeyPoseTarget;
    use glam::Quat;

    fn counts(d: &NeuralDancer) -> SafetyCounts {
        d.report()
            .safety
            .expect("the neural dancer has safety nets")
    }

    /// Frames whose output was non-finite or exploding (the last good pose held instead).
    fn held_frames(d: &NeuralDancer) -> u64 {
        counts(d).held
    }

    fn dancer(noise: f32) -> NeuralDancer {
        let c = NetConfig::tiny();
        let mut tensors = init_net(&c, 1);
        tensors.perturb(2, noise);
        NeuralDancer::new(&NeuralModel {
            config: c,
            tensors,
            training: TrainingSummary::default(),
        })
        .unwrap()
    }

    #[test]
    fn is_deterministic_per_seed_and_finite() {
        let mut d = dancer(0.05);
        let music = vec![[0.1f32; FEATURE_DIM]; 3];
        let controls = Controls {
            temperature: 0.7,
            key_pose: Some(KeyPoseTarget {
                rotations: [Quat::IDENTITY; 22],
                frames_to_go: 12,
            }),
            ..Controls::default()
        };
        let run = |d: &mut NeuralDancer| {
            d.reset(5);
            let mut pose = Pose::rest();
            let mut out = Vec::new();
            for _ in 0..40 {
                d.step(&music, &controls, &mut pose);
                out.push(pose);
            }
            out
        };
        let a = run(&mut d);
        let b = run(&mut d);
        assert_eq!(a, b);
        assert!(a.iter().all(|p| p.is_finite()));
        assert_eq!(d.lookahead_frames(), 2);
    }

    /// Poses of 30 frames at T = 0 with `style` requested.
    fn styled_run(d: &mut NeuralDancer, style: StyleRequest) -> Vec<Pose> {
        let music = vec![[0.1f32; FEATURE_DIM]; 3];
        let controls = Controls {
            style,
            ..Controls::default()
        };
        d.reset(5);
        let mut pose = Pose::rest();
        (0..30)
            .map(|_| {
                d.step(&music, &controls, &mut pose);
                pose
            })
            .collect()
    }

    #[test]
    fn a_requested_style_changes_the_dance_and_a_model_without_styles_ignores_it() {
        let mut d = dancer(0.05);
        assert!(d.has_style_input());
        let runs: Vec<Vec<Pose>> = DanceStyle::ALL
            .iter()
            .map(|s| styled_run(&mut d, StyleRequest::Style(*s)))
            .collect();
        for (i, a) in runs.iter().enumerate() {
            assert!(a.iter().all(|p| p.is_finite()));
            for b in &runs[i + 1..] {
                assert_ne!(a, b, "two styles danced alike");
            }
        }
        assert_eq!(d.style(), DanceStyle::Waltz);
        // Auto on music without beats keeps its starting choice (waltz): the same dance.
        assert_eq!(styled_run(&mut d, StyleRequest::Auto), runs[3]);
        // A model from before styles: the request changes nothing.
        let mut c = NetConfig::tiny();
        c.styles = 0;
        let mut tensors = init_net(&c, 1);
        tensors.perturb(2, 0.05);
        let mut old = NeuralDancer::new(&NeuralModel {
            config: c,
            tensors,
            training: TrainingSummary::default(),
        })
        .unwrap();
        assert!(!old.has_style_input());
        let a = styled_run(&mut old, StyleRequest::Style(DanceStyle::ChaCha));
        let b = styled_run(&mut old, StyleRequest::Style(DanceStyle::Rumba));
        assert_eq!(a, b);
    }

    #[test]
    fn a_key_route_asked_for_live_takes_over_once_no_key_is_pending() {
        let music = vec![[0.1f32; FEATURE_DIM]; 3];
        let key = |frames_to_go| {
            Some(KeyPoseTarget {
                rotations: [Quat::from_rotation_x(0.8); 22],
                frames_to_go,
            })
        };
        // Frames 0..20 a key due at frame 19, then none; the network route asked for from
        // frame 10 (halfway to the key), or `from` on.
        let run = |d: &mut NeuralDancer, from: usize| {
            d.reset(5);
            let mut pose = Pose::rest();
            let mut routes = Vec::new();
            let mut poses = Vec::new();
            for i in 0..100 {
                let controls = Controls {
                    temperature: 0.5,
                    key_pose: if i < 20 { key(19 - i as u32) } else { None },
                    key_route: (i >= from).then_some(KeyPoseRoute::Network),
                    ..Controls::default()
                };
                d.step(&music, &controls, &mut pose);
                routes.push(d.report().key_route.unwrap());
                poses.push(pose);
            }
            (routes, poses)
        };
        let mut d = dancer(0.05);
        let (routes, live) = run(&mut d, 10);
        // The key asked for under the overlay keeps it, and so does its let-go.
        let switched = routes
            .iter()
            .position(|r| *r == KeyPoseRoute::Network)
            .unwrap();
        assert!(
            routes[..switched]
                .iter()
                .all(|r| *r == KeyPoseRoute::Overlay)
        );
        assert_eq!(switched, 20 + KEY_RELEASE_FRAMES as usize - 1, "{routes:?}");
        assert!(
            routes[switched..]
                .iter()
                .all(|r| *r == KeyPoseRoute::Network)
        );
        // The same dance as a route asked for only once the let-go is over.
        let (_, later) = run(&mut d, switched);
        assert_eq!(live, later);
        // At rest, the route takes over at once: a key then goes to the network.
        let (routes, from_start) = run(&mut d, 0);
        assert!(routes.iter().all(|r| *r == KeyPoseRoute::Network));
        let mut set_up = dancer(0.05);
        set_up.set_key_pose_route(KeyPoseRoute::Network);
        let (_, network) = run(&mut set_up, usize::MAX);
        assert_eq!(from_start, network);
        assert_ne!(from_start, live);
    }

    #[test]
    fn a_style_with_its_own_seed_clip_starts_from_it_and_one_without_keeps_the_dance() {
        let c = NetConfig::tiny();
        let mut tensors = init_net(&c, 1);
        tensors.perturb(2, 0.05);
        let plain = NeuralModel {
            config: c,
            tensors,
            training: TrainingSummary::default(),
        };
        // A cha-cha seed: the default clip standing still in its first pose.
        let mut seeded = plain.clone();
        let (motion, music) = seeded.seed_clip().unwrap();
        let first = motion[..MOTION_FEATURE_DIM].to_vec();
        let still: Vec<f32> = first.iter().cycle().take(motion.len()).copied().collect();
        let music = music.to_vec();
        seeded.set_style_seed_clip(DanceStyle::ChaCha.index(), still, music);
        assert!(seeded.style_seed_clip(DanceStyle::ChaCha.index()).is_some());
        assert!(seeded.style_seed_clip(DanceStyle::Rumba.index()).is_none());
        let mut with = NeuralDancer::new(&seeded).unwrap();
        let mut without = NeuralDancer::new(&plain).unwrap();
        let cha_cha = StyleRequest::Style(DanceStyle::ChaCha);
        let rumba = StyleRequest::Style(DanceStyle::Rumba);
        // The switch to cha-cha re-primes from its clip: another dance from the first frame.
        let a = styled_run(&mut with, cha_cha);
        let b = styled_run(&mut without, cha_cha);
        assert_ne!(a[0], b[0]);
        assert!(a.iter().all(|p| p.is_finite()));
        // It glides there from where the dancer stood, as a restart does.
        with.reset(5);
        let mut pose = Pose::rest();
        let controls = Controls {
            style: cha_cha,
            ..Controls::default()
        };
        with.step(&[[0.1f32; FEATURE_DIM]; 3], &controls, &mut pose);
        assert_eq!(with.glide_left, RESTART_BLEND_FRAMES - 1);
        assert_eq!(counts(&with).restarts, 0);
        // A style without its own clip goes on from the dance as it stands, in both models.
        assert_eq!(
            styled_run(&mut with, rumba),
            styled_run(&mut without, rumba)
        );
    }

    /// Horizontal distance the hips cover in the first frame after a reset with `accent`, on
    /// music whose beat phase has cosine `beat_cos`.
    fn first_step(d: &mut NeuralDancer, accent: f32, beat_cos: f32) -> f32 {
        let mut music = [[0.1f32; FEATURE_DIM]; 3];
        for m in music.iter_mut() {
            m[FeatureLayout::BEAT_SIN] = 0.0;
            m[FeatureLayout::BEAT_COS] = beat_cos;
        }
        d.set_beat_accent(accent);
        d.reset(3);
        let mut pose = Pose::rest();
        d.step(&music, &Controls::default(), &mut pose);
        assert_eq!(held_frames(d), 0);
        pose.root_position.x.hypot(pose.root_position.z)
    }

    #[test]
    fn beat_accent_slows_into_the_beat_and_speeds_up_between() {
        let mut d = dancer(0.05);
        for cos in [1.0, -1.0, 0.0] {
            let own = first_step(&mut d, 0.0, cos);
            assert!(own > 1e-3, "the untrained network should move: {own}");
            let accented = first_step(&mut d, 0.5, cos);
            let want = 1.0 - 0.5 * cos;
            assert!(
                (accented / own - want).abs() < 1e-3,
                "cos {cos}: {accented} / {own}, want {want}"
            );
        }
        // A live control overrides the dancer's own depth for as long as it is sent.
        let own = first_step(&mut d, 0.0, 1.0);
        let mut music = [[0.1f32; FEATURE_DIM]; 3];
        for m in music.iter_mut() {
            m[FeatureLayout::BEAT_SIN] = 0.0;
            m[FeatureLayout::BEAT_COS] = 1.0;
        }
        d.set_beat_accent(0.0);
        d.reset(3);
        let mut pose = Pose::rest();
        let live = Controls {
            beat_accent: Some(0.5),
            ..Controls::default()
        };
        d.step(&music, &live, &mut pose);
        let stepped = pose.root_position.x.hypot(pose.root_position.z);
        assert!((stepped / own - 0.5).abs() < 1e-3, "{stepped} / {own}");
        // Out-of-range depths are clamped, not passed on.
        assert!((first_step(&mut d, 5.0, 1.0) / own - 0.1).abs() < 1e-3);
        assert_eq!(first_step(&mut d, f32::NAN, 1.0), own);
    }

    #[test]
    fn correlated_noise_changes_the_pose_slowly_but_as_widely() {
        let mut d = dancer(0.05);
        d.set_beat_accent(0.0);
        let controls = Controls {
            temperature: 1.0,
            ..Controls::default()
        };
        // Mean frame-to-frame change and spread over time of one joint's rotation.
        let mut run = |rho: f32| {
            d.set_noise_correlation(rho);
            d.reset(9);
            let mut pose = Pose::rest();
            let mut q = Vec::new();
            for _ in 0..400 {
                d.step(&[[0.1; FEATURE_DIM]; 3], &controls, &mut pose);
                q.push(pose.local_rotations[8]);
            }
            let step = q.windows(2).map(|w| w[0].angle_between(w[1])).sum::<f32>() / 399.0;
            let spread = q.iter().map(|r| r.angle_between(q[0])).sum::<f32>() / 400.0;
            (step, spread)
        };
        let (step_free, spread_free) = run(0.0);
        let (step_held, spread_held) = run(0.95);
        assert!(step_held < 0.5 * step_free, "{step_held} vs {step_free}");
        assert!(
            spread_held > 0.5 * spread_free,
            "{spread_held} vs {spread_free}"
        );
    }

    /// A dancer on the untrained tiny network whose samples are clamped to ±0.5 in every
    /// feature, except where `narrow` sets (feature, low, high).
    fn ranged_dancer(narrow: &[(usize, f32, f32)]) -> NeuralDancer {
        let c = NetConfig::tiny();
        let mut tensors = init_net(&c, 1);
        tensors.perturb(3, 0.05);
        let mut model = NeuralModel {
            config: c,
            tensors,
            training: TrainingSummary::default(),
        };
        let mut lo = [-0.5f32; MOTION_FEATURE_DIM];
        let mut hi = [0.5f32; MOTION_FEATURE_DIM];
        for &(i, l, h) in narrow {
            lo[i] = l;
            hi[i] = h;
        }
        model.set_pose_range(&[lo, hi]);
        NeuralDancer::new(&model).unwrap()
    }

    #[test]
    fn network_only_switches_every_net_off_and_each_net_counts_when_it_acts() {
        let key = [glam::Quat::from_rotation_x(0.4); crate::rig::JOINT_COUNT];
        let run = |nets: SafetyNets| {
            let mut d = ranged_dancer(&[(ROOT_DZ, 0.2, 0.3), (ROOT_DX, 0.0, 0.0)]);
            d.set_safety_nets(nets);
            d.set_beat_accent(0.15);
            d.reset(4);
            let mut pose = Pose::rest();
            let mut music = [[0.3f32; FEATURE_DIM]; 3];
            for (i, frame) in (0..300).enumerate() {
                music[0][FeatureLayout::BEAT_COS] = (frame as f32 * 0.5).cos();
                let controls = Controls {
                    temperature: 1.0,
                    key_pose: Some(KeyPoseTarget {
                        rotations: key,
                        frames_to_go: (80 - (i % 80)) as u32,
                    }),
                    ..Controls::default()
                };
                d.step(&music, &controls, &mut pose);
                assert!(pose.is_finite());
            }
            counts(&d)
        };
        let shipped = run(SafetyNets::SHIPPED);
        assert_eq!(shipped.frames, 300);
        assert_eq!(shipped.accented, 300, "{shipped:?}");
        assert!(shipped.speed_limited > 100, "{shipped:?}");
        // The first cue is blended over its last 49 frames (49..=1 to go); each later one
        // begins by letting the last go over 49 frames, so from frame 80 on every frame blends.
        assert_eq!(shipped.held, 0, "{shipped:?}");
        assert_eq!(shipped.key_blended, 49 + 220, "{shipped:?}");
        let alone = run(SafetyNets::NETWORK_ONLY);
        assert_eq!(
            alone,
            SafetyCounts {
                frames: 300,
                held: alone.held,
                ..SafetyCounts::default()
            }
        );
    }

    #[test]
    fn sustained_speed_is_limited_but_bursts_pass() {
        // Every frame steps 0.2–0.3 m forward: 5–7.5 m/s, a sprint no dance keeps up.
        let mut d = ranged_dancer(&[(ROOT_DZ, 0.2, 0.3), (ROOT_DX, 0.0, 0.0)]);
        d.set_beat_accent(0.0);
        d.set_foot_lock(0.0);
        d.reset(4);
        let mut pose = Pose::rest();
        let controls = Controls {
            temperature: 1.0,
            ..Controls::default()
        };
        let mut track = Vec::new();
        for _ in 0..500 {
            d.step(&[[0.3; FEATURE_DIM]; 3], &controls, &mut pose);
            track.push(pose.root_position);
        }
        let speed = |a: usize, b: usize| {
            let s: f32 = (a + 1..b)
                .map(|i| (track[i] - track[i - 1]).with_y(0.0).length())
                .sum();
            s * FRAME_RATE as f32 / (b - a - 1) as f32
        };
        // The first frames run free: the average starts from standing.
        assert!(speed(0, 4) > 4.5, "burst {}", speed(0, 4));
        let sustained = speed(250, 500);
        assert!(
            (SUSTAINED_SPEED_LIMIT_MPS - 0.1..=SUSTAINED_SPEED_LIMIT_MPS + 0.05)
                .contains(&sustained),
            "sustained {sustained} m/s"
        );
        assert!(
            counts(&d).speed_limited > 400,
            "{}",
            counts(&d).speed_limited
        );
    }

    #[test]
    fn samples_stay_within_the_training_range() {
        // A narrow range: every height between 0.9 and 1.0 m, every other feature in ±0.5.
        let mut d = ranged_dancer(&[(crate::motion::ROOT_Y, 0.9, 1.0)]);
        d.reset(4);
        let mut pose = Pose::rest();
        let controls = Controls {
            temperature: 1.0,
            ..Controls::default()
        };
        let margin = RANGE_MARGIN * 0.1 + 1e-4;
        let mut sampled = 0;
        for _ in 0..100 {
            let held = held_frames(&d);
            d.step(&[[0.3; FEATURE_DIM]; 3], &controls, &mut pose);
            if held_frames(&d) > held {
                continue;
            }
            sampled += 1;
            assert!(
                (0.9 - margin..=1.0 + margin).contains(&pose.root_position.y),
                "hips at {}",
                pose.root_position.y
            );
        }
        assert!(sampled > 50, "{sampled} frames sampled");
    }

    #[test]
    fn a_key_pose_is_reached_at_its_deadline() {
        let mut d = dancer(0.05);
        d.reset(2);
        let target = Quat::from_rotation_x(0.8);
        let mut rotations = [Quat::IDENTITY; 22];
        for r in rotations.iter_mut().skip(1) {
            *r = target;
        }
        // Counts down to the key pose from 40 frames; returns the pose at the deadline.
        let arrive = |d: &mut NeuralDancer| {
            let mut pose = Pose::rest();
            let music = [[0.1f32; FEATURE_DIM]; 3];
            for ftg in (0..=40u32).rev() {
                let controls = Controls {
                    temperature: 0.5,
                    key_pose: Some(KeyPoseTarget {
                        rotations,
                        frames_to_go: ftg,
                    }),
                    ..Controls::default()
                };
                d.step(&music, &controls, &mut pose);
            }
            pose
        };
        let pose = arrive(&mut d);
        assert_eq!(held_frames(&d), 0);
        for j in 1..22 {
            let a = pose.local_rotations[j].angle_between(target);
            assert!(a < 0.02, "joint {j} is {a} rad off");
        }
        // Without the blend the untrained network lands anywhere.
        d.set_key_blend_frames(0);
        d.reset(2);
        let pose = arrive(&mut d);
        let worst = (1..22)
            .map(|j| pose.local_rotations[j].angle_between(target))
            .fold(0.0f32, f32::max);
        assert!(worst > 0.1, "{worst}");
    }

    #[test]
    fn an_overlaid_key_pose_leaves_the_dance_under_it_untouched() {
        let cue = |rotations, due: u32, i: u32| {
            Some(KeyPoseTarget {
                rotations,
                frames_to_go: due - i,
            })
        };
        // Every pose shown over 200 frames, with the cues `cues` gives each frame.
        let run = |cues: &dyn Fn(u32) -> Option<KeyPoseTarget>| {
            let mut d = dancer(0.05);
            // The foot lock works on the pose shown, so a leg it holds through an overlay
            // stays held after it: off, to compare the network's dance alone.
            d.set_foot_lock(0.0);
            d.set_foot_plant(0.0);
            d.reset(2);
            let music = [[0.1f32; FEATURE_DIM]; 3];
            let mut pose = Pose::rest();
            (0..200u32)
                .map(|i| {
                    let controls = Controls {
                        temperature: 0.0,
                        key_pose: cues(i),
                        ..Controls::default()
                    };
                    d.step(&music, &controls, &mut pose);
                    pose
                })
                .collect::<Vec<_>>()
        };
        let free = run(&|_| None);
        // Key poses 0.8 rad from the dance's own at frames 100 and 140 in every joint but the
        // hips (a pose half a turn away from the one shown has no shortest way there).
        let pose_of = |frame: usize, turn: Quat| {
            let mut r = [Quat::IDENTITY; 22];
            for (j, q) in r.iter_mut().enumerate().skip(1) {
                *q = free[frame].local_rotations[j] * turn;
            }
            r
        };
        let (rotations, other) = (
            pose_of(100, Quat::from_rotation_x(0.8)),
            pose_of(140, Quat::from_rotation_y(-0.8)),
        );
        // One cue, announced at frame 20 and due at frame 100.
        let cued = run(&|i| {
            (20..=100)
                .contains(&i)
                .then(|| cue(rotations, 100, i))
                .flatten()
        });
        let angle =
            |a: &Pose, b: &Pose, j: usize| a.local_rotations[j].angle_between(b.local_rotations[j]);
        // The blend takes the last 50 frames before the deadline (51..=100), the release the 49
        // after it (101..=149); outside them the network's dance is shown as it is.
        for i in (0..=50).chain(150..200) {
            assert_eq!(
                cued[i].local_rotations, free[i].local_rotations,
                "frame {i}"
            );
        }
        let key_pose = Pose {
            local_rotations: {
                let mut r = free[100].local_rotations;
                r[1..22].copy_from_slice(&rotations[1..]);
                r
            },
            ..free[100]
        };
        for j in 1..22 {
            assert!(
                angle(&cued[100], &key_pose, j) < 0.02,
                "joint {j} at the deadline"
            );
            assert!(angle(&cued[75], &free[75], j) > 0.01, "joint {j} mid-blend");
        }
        // A cue cleared halfway (frame 80); one replaced halfway by another pose due at 140;
        // and cues every 60 frames announced 48 ahead, each arriving while the last is let go.
        let cleared = run(&|i| {
            (20..80)
                .contains(&i)
                .then(|| cue(rotations, 100, i))
                .flatten()
        });
        let replaced = run(&|i| match i {
            20..80 => cue(rotations, 100, i),
            80..=140 => cue(other, 140, i),
            _ => None,
        });
        let every_60 = run(&|i| {
            let due = (i / 60) * 60 + 59;
            let poses = [rotations, other];
            (due - i <= 48)
                .then(|| cue(poses[(i / 60) as usize % 2], due, i))
                .flatten()
        });
        // Onto a key and off it the pose glides: no frame moves a joint by more than the dance
        // does plus a tenth of the way between the key and the dance.
        for (name, shown) in [
            ("one cue", &cued),
            ("cleared", &cleared),
            ("replaced", &replaced),
            ("every 60 frames", &every_60),
        ] {
            assert_ne!(shown, &free, "{name}");
            for j in 1..22 {
                let gap = angle(&key_pose, &free[100], j);
                assert!(gap > 0.3, "joint {j}: the key is {gap} rad from the dance");
                let worst = |m: &[Pose]| {
                    (10..m.len())
                        .map(|i| angle(&m[i], &m[i - 1], j))
                        .fold(0.0f32, f32::max)
                };
                let (c, f) = (worst(shown), worst(&free));
                assert!(
                    c < f + 0.1 * gap,
                    "{name}, joint {j}: {c} rad a frame against {f}"
                );
            }
        }
    }

    #[test]
    fn exploding_output_holds_the_last_good_pose() {
        // A saturated coupling scale makes the flow's inverse overflow: every frame must be caught.
        let c = NetConfig::tiny();
        let mut tensors = init_net(&c, 1);
        let rest = c.flow().rest();
        let mut b = vec![-300.0; rest];
        b.extend(vec![0.0; rest]);
        tensors.insert("flow.0.c2.b", &[2 * rest], b);
        let model = NeuralModel {
            config: c,
            tensors,
            training: TrainingSummary::default(),
        };
        let mut d = NeuralDancer::new(&model).unwrap();
        d.reset(1);
        let mut pose = Pose::rest();
        let controls = Controls {
            temperature: 1.0,
            ..Controls::default()
        };
        for _ in 0..2 * RESTART_AFTER_HELD {
            d.step(&[[0.0; FEATURE_DIM]], &controls, &mut pose);
            assert!(pose.is_finite());
        }
        assert_eq!(held_frames(&d), 2 * RESTART_AFTER_HELD as u64);
        assert_eq!(counts(&d).restarts, 2);
    }
}
