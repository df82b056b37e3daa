//! Retrieval dancer v0: plays one-beat clips cut from training dances, time-warped onto the
//! live beat phase, and picks the next clip at every live beat.
//!
//! The library cuts every training dance at the frames where its music's beat phase wraps, so
//! a clip spans exactly one beat. Each clip's root is stored relative to its first frame's
//! ground position and heading, so it can be played anywhere. At run time the current clip's
//! progress *is* the live beat phase (so motion accents land on the live beats whatever the
//! tempo), and when the live phase wraps the next clip is chosen by a cost: pose continuity,
//! tempo and energy match and bar position. Clip switches are hidden by decaying the pose
//! offset at the switch to identity ("inertialization-lite"). A key pose is shown over the
//! dance ([`crate::key_overlay`]); the clips are matched to the dance under it.

use dsp::feature::{FEATURE_DIM, FeatureLayout, phase_of};
use glam::{Quat, Vec3};

use crate::ModelError;
use crate::key_overlay::{KEY_BLEND_FRAMES, KeyOverlay};
use crate::motion::{heading, yaw};
use crate::rig::{JOINT_COUNT, Pose};
use crate::source::{
    Controls, MotionSource, MovesReport, MovesSwitch, SourceControls, SourceReport,
    TravelPreference,
};

/// Frame rate of the library and of the dancer's output (tang2018 fits are 25 fps).
pub const RETRIEVAL_FPS: f64 = 25.0;
/// Shortest clip kept, frames (faster than 375 BPM is a tracker glitch).
const MIN_CLIP_FRAMES: usize = 4;
/// Longest clip kept, frames (slower than 30 BPM is a tracker glitch).
const MAX_CLIP_FRAMES: usize = 50;
/// How many of the cheapest clips temperature sampling chooses among.
const TOP_K: usize = 8;
/// Weight of pose continuity: per unit of Σ(1 − |dot|) over joints.
const W_POSE: f32 = 20.0;
/// Weight of tempo mismatch, per unit of |ln(tempo_clip / tempo_live)|.
const W_TEMPO: f32 = 4.0;
/// Weight of energy mismatch, per 10 dB.
const W_ENERGY: f32 = 1.0;
/// Weight of bar-position mismatch, per half bar.
const W_BAR: f32 = 0.5;
/// Cost weight of a clip moving less than the library's typical clip (0 to 1 of it). At 4 the
/// dancer still froze about once every two minutes on the validation songs (20–23 times in
/// 5-minute runs); 8 removed most freezes and lowered FMD (0.79 → 0.62 at T = 0.5); 16 raised
/// FID_k at T = 0 to 56.
const W_STILL: f32 = 8.0;
/// Weight of root-velocity mismatch, per m/s of horizontal speed difference (in the heading frame).
///
/// Without it, continuity of rotations alone happily chains a travelling step into a standing
/// one: the dancer stops crossing the floor and the clip switches show up as root jerks.
const W_VELOCITY: f32 = 2.0;
/// Weight of a clip's travel against the stage's preferred direction, per metre the clip
/// travels the other way at full strength (the edge of the stage). A beat's clip travels up
/// to about 0.3 m, so at the edge an outward step costs about what a tempo off by 50 % does.
/// On five rendered songs (5 min each, bounded 1.5 m) the clamp acted on 0.12 / 0.77 / 2.31 /
/// 0.96 / 0.24 % of frames at 6 against 2.12 / 0.89 / 1.07 / 0.28 / 0.41 % at 0 (ballad,
/// swing, rock, disco, ambient): it helps on the songs where the clamp acts most. Inward
/// travel earns nothing: rewarded, it picked the clips that travel most, a capture's glitches
/// among them (FID_k 76 against 38 on one eval seed).
const W_STAGE: f32 = 6.0;
/// Most beats a switch of moves cued for the next bar waits for the bar's first beat (a bar of
/// 7 and the beat it was cued in); past them it lands on the next beat.
const MAX_BEATS_TO_BAR: u32 = 8;
/// Duration of the offset decay at a clip switch, seconds.
const BLEND_SECONDS: f32 = 0.25;
/// Smoothing factor of the live energy (per frame, ≈ 0.4 s time constant at 25 fps).
const ENERGY_ALPHA: f32 = 0.1;

/// One beat of a training dance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clip {
    /// Index of the clip's first pose in [`ClipLibrary::poses`].
    pub start: usize,
    /// Frames from the first to the last pose (the clip holds `len + 1` poses, the last being the next clip's first).
    pub len: usize,
    /// Tempo the clip was danced at, BPM.
    pub tempo: f32,
    /// Mean music energy over the clip, dBFS.
    pub energy: f32,
    /// Bar phase at the clip's first frame, [0, 1).
    pub bar_phase: f32,
    /// Beat phase at the first frame (just after the wrap), [0, 1).
    pub phase_start: f32,
    /// Beat phase at the last frame (just after the next wrap), [0, 1).
    pub phase_end: f32,
    /// How much the clip moves: mean over frames of Σ_joints (1 − |dot|) between consecutive
    /// local rotations.
    pub motion: f32,
}

/// One-beat clips cut from training dances, stored relative to their first frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipLibrary {
    /// Every clip's poses back to back; roots relative to the clip's first ground position and heading.
    pub poses: Vec<Pose>,
    /// The clips.
    pub clips: Vec<Clip>,
    /// Median [`Clip::motion`] over the library: what "moving normally" means for these dances.
    pub typical_motion: f32,
}

/// Shortest distance between two phases in turns, [0, 0.5].
fn circular_distance(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(1.0);
    d.min(1.0 - d)
}

/// The hips rotation with its heading removed.
fn deheaded(hips: Quat) -> Quat {
    yaw(-heading(hips)) * hips
}

/// Σ over joints of (1 − |dot|), the hips compared without heading.
fn pose_distance(a: &[Quat; JOINT_COUNT], a_hips: Quat, b: &[Quat; JOINT_COUNT]) -> f32 {
    let mut d = 1.0 - a_hips.dot(deheaded(b[0])).abs().min(1.0);
    for j in 1..JOINT_COUNT {
        d += 1.0 - a[j].dot(b[j]).abs().min(1.0);
    }
    d
}

/// `q` or `−q`, whichever has w ≥ 0 (the shorter rotation of the two).
fn shortest(q: Quat) -> Quat {
    if q.w < 0.0 { -q } else { q }
}

/// What a clip is cut by and matched on, frame by frame: the beat and bar the dance is on, its
/// tempo and how loud the music under it is. From the music for dances captured with their
/// songs ([`ClipLibrary::from_dances`]); from the motion's own beat grid for dances without.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameCue {
    /// Beat phase, [0, 1) (0 on the beat); `None` where unknown.
    pub beat_phase: Option<f32>,
    /// Bar phase, [0, 1).
    pub bar_phase: f32,
    /// Tempo, BPM; not finite or ≤ 0 where unknown.
    pub tempo: f32,
    /// Music energy, dBFS; not finite where unknown.
    pub energy: f32,
}

impl FrameCue {
    /// The cue of one frame of music features.
    pub fn of_music(m: &[f32; FEATURE_DIM]) -> FrameCue {
        FrameCue {
            beat_phase: phase_of(m[FeatureLayout::BEAT_SIN], m[FeatureLayout::BEAT_COS]),
            bar_phase: phase_of(m[FeatureLayout::BAR_SIN], m[FeatureLayout::BAR_COS])
                .unwrap_or(0.0),
            tempo: m[FeatureLayout::TEMPO],
            energy: m[FeatureLayout::ENERGY],
        }
    }
}

impl ClipLibrary {
    /// Cuts each (poses, music features) pair, 25 fps and frame-aligned, into one-beat clips.
    ///
    /// Pairs of different lengths are cut over their common length. Beats whose poses are not
    /// finite or whose length is implausible are skipped.
    pub fn from_dances(dances: &[(Vec<Pose>, Vec<[f32; FEATURE_DIM]>)]) -> Self {
        let cued: Vec<(Vec<Pose>, Vec<FrameCue>)> = dances
            .iter()
            .map(|(poses, music)| {
                (
                    poses.clone(),
                    music.iter().map(FrameCue::of_music).collect(),
                )
            })
            .collect();
        Self::from_cues(&cued)
    }

    /// Cuts each (poses, cues) pair, 25 fps and frame-aligned, into one-beat clips at the
    /// frames where the beat phase wraps; see [`ClipLibrary::from_dances`].
    pub fn from_cues(dances: &[(Vec<Pose>, Vec<FrameCue>)]) -> Self {
        Self::from_cues_counted(dances).0
    }

    /// [`ClipLibrary::from_cues`], with how many clips each dance gave.
    pub fn from_cues_counted(dances: &[(Vec<Pose>, Vec<FrameCue>)]) -> (Self, Vec<usize>) {
        let mut lib = ClipLibrary {
            poses: Vec::new(),
            clips: Vec::new(),
            typical_motion: 0.0,
        };
        let mut phases = Vec::new();
        let mut wraps = Vec::new();
        let mut counts = Vec::with_capacity(dances.len());
        for (poses, cues) in dances {
            let before = lib.clips.len();
            let n = poses.len().min(cues.len());
            phases.clear();
            wraps.clear();
            let mut prev: Option<f32> = None;
            for (i, c) in cues.iter().enumerate().take(n) {
                let p = c.beat_phase.or(prev);
                if let (Some(a), Some(b)) = (prev, p)
                    && b < a - 0.5
                {
                    wraps.push(i);
                }
                phases.push(p.unwrap_or(0.0));
                prev = p;
            }
            for w in wraps.windows(2) {
                let (s, e) = (w[0], w[1]);
                let len = e - s;
                if !(MIN_CLIP_FRAMES..=MAX_CLIP_FRAMES).contains(&len)
                    || !poses[s..=e].iter().all(Pose::is_finite)
                {
                    continue;
                }
                lib.push_clip(&poses[s..=e], &cues[s..=e], phases[s], phases[e]);
            }
            counts.push(lib.clips.len() - before);
        }
        let mut motions: Vec<f32> = lib.clips.iter().map(|c| c.motion).collect();
        motions.sort_by(f32::total_cmp);
        lib.typical_motion = motions.get(motions.len() / 2).copied().unwrap_or(0.0);
        (lib, counts)
    }

    /// Appends one clip made of `poses` (len + 1 frames) and the cues under them.
    fn push_clip(&mut self, poses: &[Pose], cues: &[FrameCue], phase_start: f32, phase_end: f32) {
        let len = poses.len() - 1;
        let h0 = heading(poses[0].local_rotations[0]);
        let to_local = yaw(-h0);
        let origin = Vec3::new(poses[0].root_position.x, 0.0, poses[0].root_position.z);
        let start = self.poses.len();
        for p in poses {
            let mut r = *p;
            r.root_position = to_local * (p.root_position - origin);
            r.local_rotations[0] = (to_local * p.local_rotations[0]).normalize();
            self.poses.push(r);
        }
        let (mut tempo_sum, mut tempo_n, mut energy_sum, mut energy_n) = (0.0, 0, 0.0, 0);
        for c in &cues[..len] {
            if c.tempo.is_finite() && c.tempo > 0.0 {
                tempo_sum += c.tempo;
                tempo_n += 1;
            }
            if c.energy.is_finite() {
                energy_sum += c.energy;
                energy_n += 1;
            }
        }
        let tempo = if tempo_n > 0 {
            tempo_sum / tempo_n as f32
        } else {
            (60.0 * RETRIEVAL_FPS / len as f64) as f32
        };
        let energy = if energy_n > 0 {
            energy_sum / energy_n as f32
        } else {
            -60.0
        };
        let bar_phase = cues[0].bar_phase;
        let motion = poses
            .windows(2)
            .map(|w| {
                (0..JOINT_COUNT)
                    .map(|j| {
                        1.0 - w[0].local_rotations[j]
                            .dot(w[1].local_rotations[j])
                            .abs()
                            .min(1.0)
                    })
                    .sum::<f32>()
            })
            .sum::<f32>()
            / len as f32;
        self.clips.push(Clip {
            start,
            len,
            tempo,
            energy,
            bar_phase,
            phase_start,
            phase_end,
            motion,
        });
    }

    /// The first pose of `clip` (relative to its own start).
    pub fn first_pose(&self, clip: &Clip) -> &Pose {
        &self.poses[clip.start]
    }

    /// Samples `clip` at fractional frame `u` ∈ [0, len] into `out` (clip-relative root).
    fn sample(&self, clip: &Clip, u: f32, out: &mut Pose) {
        let u = u.clamp(0.0, clip.len as f32);
        let i = (u.floor() as usize).min(clip.len.saturating_sub(1));
        let f = u - i as f32;
        let a = &self.poses[clip.start + i];
        let b = &self.poses[clip.start + i + 1];
        out.root_position = a.root_position.lerp(b.root_position, f);
        for j in 0..JOINT_COUNT {
            out.local_rotations[j] = a.local_rotations[j]
                .slerp(b.local_rotations[j], f)
                .normalize();
        }
    }
}

/// Small deterministic xorshift64* generator (no allocation, no dependency).
#[derive(Clone, Copy, Debug)]
struct Rng(u64);

impl Rng {
    /// A generator seeded through splitmix64, so nearby seeds give unrelated streams.
    fn new(seed: u64) -> Self {
        let mut z = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        Rng(if z == 0 { 0x2545_F491_4F6C_DD1D } else { z })
    }

    /// Uniform in [0, 1).
    fn next_f32(&mut self) -> f32 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        ((x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32) / (1u64 << 24) as f32
    }
}

/// The v0 motion source: beat-synchronous clip retrieval with inertialization-lite blending.
#[derive(Clone, Debug)]
pub struct RetrievalDancer {
    /// The libraries it can play, in the order given.
    libraries: Vec<ClipLibrary>,
    /// The library it plays.
    active: usize,
    /// A switch asked for: the library, and when.
    pending: Option<(usize, MovesSwitch)>,
    /// Library switches made since the last reset.
    switches: u64,
    /// Beats passed since the pending switch was asked for.
    beats_waited: u32,
    /// Randomness for temperature sampling.
    rng: Rng,
    /// Whether a clip has been chosen since the last reset.
    started: bool,
    /// Index of the clip playing.
    clip: usize,
    /// Live beat phase of the last frame, [0, 1).
    phase: f32,
    /// Whether the phase has been mid-beat since the last wrap (a wrap now starts a clip).
    armed: bool,
    /// Smooths the heard phase the clips are warped onto.
    follower: crate::phase_follower::PhaseFollower,
    /// How far ahead of the heard beat the clips are timed, seconds.
    hit_lead_s: f32,
    /// Live bar phase of the last frame, [0, 1).
    bar_phase: f32,
    /// Live tempo, BPM (0 = unknown).
    tempo: f32,
    /// Smoothed live energy, dBFS (NaN until the first finite value).
    energy: f32,
    /// World ground position where the clip's relative root is anchored.
    anchor: Vec3,
    /// World heading the clip's relative root is rotated by, radians.
    anchor_heading: f32,
    /// Per-joint offsets captured at the last discontinuity, decaying to identity.
    offsets: [Quat; JOINT_COUNT],
    /// Root offset captured at the last discontinuity, decaying to zero.
    root_offset: Vec3,
    /// Frames since the offsets were captured.
    blend_frame: u32,
    /// The last output pose.
    last_out: Pose,
    /// The output pose before the last (for velocity extrapolation at switches).
    prev_out: Pose,
    /// The last clip pose in world space, before offsets and key blending.
    last_raw: Pose,
    /// Scratch pose for sampling.
    scratch: Pose,
    /// The key pose shown over the dance.
    overlay: KeyOverlay,
    /// Where the stage would have the dance travel.
    travel_preference: Option<TravelPreference>,
    /// Costs of the cheapest clips found at the last choice.
    best_cost: [f32; TOP_K],
    /// Indices of the cheapest clips found at the last choice.
    best_idx: [usize; TOP_K],
}

impl RetrievalDancer {
    /// Sets how far ahead of the heard beat the clips are timed, seconds (default
    /// [`crate::phase_follower::HIT_LEAD_S`]; 0 = on the heard phase itself).
    pub fn set_hit_lead(&mut self, seconds: f32) {
        self.hit_lead_s = if seconds.is_finite() {
            seconds.clamp(-0.2, 0.2)
        } else {
            0.0
        };
    }

    /// A dancer playing `library`; fails if the library holds no clip.
    pub fn new(library: ClipLibrary, seed: u64) -> Result<Self, ModelError> {
        Self::with_libraries(vec![library], seed)
    }

    /// A dancer holding several libraries, playing the first, switched live by
    /// [`MotionSource::select_moves`]; fails if there is none or one holds no clip.
    pub fn with_libraries(libraries: Vec<ClipLibrary>, seed: u64) -> Result<Self, ModelError> {
        if libraries.is_empty() || libraries.iter().any(|l| l.clips.is_empty()) {
            return Err(ModelError::EmptyClipLibrary);
        }
        let mut d = RetrievalDancer {
            libraries,
            active: 0,
            pending: None,
            switches: 0,
            beats_waited: 0,
            rng: Rng::new(seed),
            started: false,
            clip: 0,
            phase: 0.0,
            armed: true,
            follower: crate::phase_follower::PhaseFollower::new(),
            hit_lead_s: crate::phase_follower::HIT_LEAD_S,
            bar_phase: 0.0,
            tempo: 0.0,
            energy: f32::NAN,
            anchor: Vec3::ZERO,
            anchor_heading: 0.0,
            offsets: [Quat::IDENTITY; JOINT_COUNT],
            root_offset: Vec3::ZERO,
            blend_frame: u32::MAX,
            last_out: Pose::rest(),
            prev_out: Pose::rest(),
            last_raw: Pose::rest(),
            scratch: Pose::rest(),
            overlay: KeyOverlay::default(),
            travel_preference: None,
            best_cost: [f32::INFINITY; TOP_K],
            best_idx: [0; TOP_K],
        };
        d.reset(seed);
        Ok(d)
    }

    /// Builds the library from (poses, music features) pairs and a dancer playing it.
    pub fn from_dances(
        dances: &[(Vec<Pose>, Vec<[f32; FEATURE_DIM]>)],
        seed: u64,
    ) -> Result<Self, ModelError> {
        Self::new(ClipLibrary::from_dances(dances), seed)
    }

    /// The clip library it plays.
    pub fn library(&self) -> &ClipLibrary {
        &self.libraries[self.active]
    }

    /// Makes a pending library switch due at this beat the active one; whether it did.
    fn take_due_switch(&mut self) -> bool {
        let Some((index, at)) = self.pending else {
            return false;
        };
        // The clips are timed a little ahead of the heard beat, so on a bar's first beat the
        // heard bar phase is just short of 1 (or just past 0): within half a beat of a 4/4 bar.
        let on_bar = circular_distance(self.bar_phase, 0.0) < 0.125;
        self.beats_waited = self.beats_waited.saturating_add(1);
        // A bar tracker that has lost the bar must not hold the switch back for long.
        if at == MovesSwitch::NextBar && !on_bar && self.beats_waited <= MAX_BEATS_TO_BAR {
            return false;
        }
        self.pending = None;
        if index != self.active {
            self.active = index;
            self.switches += 1;
        }
        true
    }

    /// Index of the clip playing (for debugging and tests).
    pub fn current_clip(&self) -> usize {
        self.clip
    }

    /// Live beat phase as last read from the music, [0, 1).
    pub fn phase(&self) -> f32 {
        self.phase
    }

    /// Updates the live beat/bar phase, tempo and energy from one music frame; returns whether the beat phase wrapped.
    fn read_music(&mut self, m: Option<&[f32; FEATURE_DIM]>) -> bool {
        let Some(m) = m else { return false };
        let mut wrapped = false;
        let t = m[FeatureLayout::TEMPO];
        if t.is_finite() && t >= 0.0 {
            self.tempo = t;
        }
        if let Some(p) = phase_of(m[FeatureLayout::BEAT_SIN], m[FeatureLayout::BEAT_COS]) {
            let p =
                self.follower
                    .follow_ahead(p, self.tempo, RETRIEVAL_FPS as f32, self.hit_lead_s);
            // A beat is passed once per beat: a grid re-anchored near the beat can step the
            // phase back over the wrap, which must not start a second clip.
            wrapped = self.started && self.armed && p < self.phase - 0.5;
            if wrapped {
                self.armed = false;
            } else if (0.25..0.75).contains(&p) {
                self.armed = true;
            }
            self.phase = p;
        }
        if let Some(b) = phase_of(m[FeatureLayout::BAR_SIN], m[FeatureLayout::BAR_COS]) {
            self.bar_phase = b;
        }
        let e = m[FeatureLayout::ENERGY];
        if e.is_finite() {
            self.energy = if self.energy.is_finite() {
                self.energy + ENERGY_ALPHA * (e - self.energy)
            } else {
                e
            };
        }
        wrapped
    }

    /// The cost of playing `clip` next, given the last output's rotations (hips de-headed), its
    /// velocity in its heading frame and the stage's preferred travel in that frame.
    fn cost(&self, clip: &Clip, hips: Quat, velocity: Vec3, preferred: Option<Vec3>) -> f32 {
        let lib = &self.libraries[self.active];
        let mut c = W_POSE
            * pose_distance(
                &self.last_out.local_rotations,
                hips,
                &lib.first_pose(clip).local_rotations,
            );
        if self.tempo > 0.0 && clip.tempo > 0.0 {
            c += W_TEMPO * (clip.tempo / self.tempo).ln().abs();
        }
        if self.energy.is_finite() {
            c += W_ENERGY * (clip.energy - self.energy).abs() / 10.0;
        }
        c += W_BAR * 2.0 * circular_distance(clip.bar_phase, self.bar_phase);
        // Continuity alone favours clips that barely move (their first pose is close to anything
        // still), which makes the dancer freeze: clips quieter than the library's typical one pay.
        if lib.typical_motion > 0.0 {
            c += W_STILL * (1.0 - clip.motion / lib.typical_motion).max(0.0);
        }
        if self.tempo > 0.0 {
            // The clip's first-frame root velocity as it will play, warped onto the live beat.
            let p = &lib.poses[clip.start..clip.start + 2];
            let frames_per_beat = 60.0 * RETRIEVAL_FPS as f32 / self.tempo;
            let played = (p[1].root_position - p[0].root_position) * clip.len as f32
                / frames_per_beat
                * RETRIEVAL_FPS as f32;
            let d = Vec3::new(played.x - velocity.x, 0.0, played.z - velocity.z);
            c += W_VELOCITY * d.length();
        }
        if let Some(preferred) = preferred {
            let travel = lib.poses[clip.start + clip.len].root_position
                - lib.poses[clip.start].root_position;
            // Outward travel pays; inward travel earns nothing, or the clips that travel most
            // (a capture's glitches among them) would win near the edge.
            c += W_STAGE * (-travel.with_y(0.0).dot(preferred)).max(0.0);
        }
        c
    }

    /// Chooses the next clip: the cheapest at temperature 0, else softmax sampling among the `TOP_K` cheapest.
    fn choose(&mut self, controls: &Controls) -> usize {
        let hips = deheaded(self.last_out.local_rotations[0]);
        // Live root velocity in m/s, in the frame of the dancer's heading (as clips store it).
        let to_heading_frame = yaw(-heading(self.last_out.local_rotations[0]));
        let velocity = to_heading_frame
            * (self.last_out.root_position - self.prev_out.root_position)
            * RETRIEVAL_FPS as f32;
        let preferred = self.travel_preference.and_then(|p| {
            let d = Vec3::new(p.direction[0], 0.0, p.direction[1]);
            let w = crate::source::finite_clamp(p.strength, 0.0, 1.0);
            (d.is_finite() && w > 0.0).then(|| to_heading_frame * d.normalize_or_zero() * w)
        });
        self.best_cost = [f32::INFINITY; TOP_K];
        self.best_idx = [0; TOP_K];
        for i in 0..self.libraries[self.active].clips.len() {
            let c = self.cost(
                &self.libraries[self.active].clips[i],
                hips,
                velocity,
                preferred,
            );
            let c = if c.is_finite() { c } else { f32::MAX };
            if c >= self.best_cost[TOP_K - 1] {
                continue;
            }
            let mut k = TOP_K - 1;
            while k > 0 && self.best_cost[k - 1] > c {
                self.best_cost[k] = self.best_cost[k - 1];
                self.best_idx[k] = self.best_idx[k - 1];
                k -= 1;
            }
            self.best_cost[k] = c;
            self.best_idx[k] = i;
        }
        let t = controls.temperature;
        if !(t.is_finite() && t > 1e-6) {
            return self.best_idx[0];
        }
        let n = self.libraries[self.active].clips.len().min(TOP_K);
        let c0 = self.best_cost[0];
        let mut weights = [0.0f32; TOP_K];
        let mut total = 0.0;
        for (w, &c) in weights.iter_mut().zip(&self.best_cost).take(n) {
            let e = (-(c - c0) / t).exp();
            *w = if e.is_finite() { e } else { 0.0 };
            total += *w;
        }
        let mut r = self.rng.next_f32() * total;
        for (&w, &i) in weights.iter().zip(&self.best_idx).take(n) {
            if r < w {
                return i;
            }
            r -= w;
        }
        self.best_idx[0]
    }

    /// Fractional frame of the current clip for the live phase.
    fn clip_frame(&self) -> f32 {
        let clip = &self.libraries[self.active].clips[self.clip];
        let span = (1.0 + clip.phase_end - clip.phase_start).max(0.25);
        (self.phase - clip.phase_start) / span * clip.len as f32
    }

    /// Samples the current clip at the live phase and places it in the world, into `scratch`.
    fn sample_world(&mut self) {
        let u = self.clip_frame();
        self.libraries[self.active].sample(
            &self.libraries[self.active].clips[self.clip],
            u,
            &mut self.scratch,
        );
        let rot = yaw(self.anchor_heading);
        self.scratch.root_position = self.anchor + rot * self.scratch.root_position;
        self.scratch.local_rotations[0] = (rot * self.scratch.local_rotations[0]).normalize();
    }

    /// Captures the offsets that carry the output, extrapolated one frame at its last velocity,
    /// into the new raw pose in `scratch`, restarting the decay.
    fn capture_offsets(&mut self) {
        for j in 0..JOINT_COUNT {
            let last = self.last_out.local_rotations[j];
            let velocity = shortest(last * self.prev_out.local_rotations[j].inverse());
            let predicted = (velocity * last).normalize();
            let o = predicted * self.scratch.local_rotations[j].inverse();
            self.offsets[j] = shortest(o.normalize());
        }
        let predicted = 2.0 * self.last_out.root_position - self.prev_out.root_position;
        self.root_offset = predicted - self.scratch.root_position;
        self.blend_frame = 0;
    }

    /// Switches to clip `next`, anchored so that the root and heading continue from the last raw pose.
    fn switch_to(&mut self, next: usize) {
        self.clip = next;
        let u = self.clip_frame();
        self.libraries[self.active].sample(
            &self.libraries[self.active].clips[next],
            u,
            &mut self.scratch,
        );
        let rel_heading = heading(self.scratch.local_rotations[0]);
        let world_heading = heading(self.last_raw.local_rotations[0]);
        self.anchor_heading = world_heading - rel_heading;
        let rel_ground = Vec3::new(
            self.scratch.root_position.x,
            0.0,
            self.scratch.root_position.z,
        );
        let last_ground = Vec3::new(
            self.last_raw.root_position.x,
            0.0,
            self.last_raw.root_position.z,
        );
        self.anchor = last_ground - yaw(self.anchor_heading) * rel_ground;
        if !self.anchor.is_finite() || !self.anchor_heading.is_finite() {
            self.anchor = Vec3::ZERO;
            self.anchor_heading = 0.0;
        }
        self.sample_world();
        self.capture_offsets();
    }
}

impl MotionSource for RetrievalDancer {
    fn frame_rate(&self) -> f64 {
        RETRIEVAL_FPS
    }

    fn lookahead_frames(&self) -> usize {
        0
    }

    fn step(&mut self, music: &[[f32; FEATURE_DIM]], controls: &Controls, out: &mut Pose) {
        let wrapped = self.read_music(music.first());
        if !self.started {
            self.started = true;
            self.last_out = Pose::rest();
            self.prev_out = Pose::rest();
            self.clip = self.choose(controls);
            self.anchor = Vec3::ZERO;
            self.anchor_heading = 0.0;
            self.sample_world();
            // Start from rest in the clip's first pose: nothing to extrapolate from yet.
            self.last_out = self.scratch;
            self.prev_out = self.scratch;
        } else if wrapped {
            self.take_due_switch();
            let next = self.choose(controls);
            self.switch_to(next);
        } else {
            self.sample_world();
        }
        self.last_raw = self.scratch;

        let blend_frames = BLEND_SECONDS * RETRIEVAL_FPS as f32;
        let s = (self.blend_frame as f32 / blend_frames).min(1.0);
        let w = (1.0 - s) * (1.0 - s);
        *out = self.scratch;
        if w > 0.0 {
            for j in 0..JOINT_COUNT {
                let o = Quat::IDENTITY.slerp(self.offsets[j], w);
                out.local_rotations[j] = (o * out.local_rotations[j]).normalize();
            }
            out.root_position += self.root_offset * w;
        }
        self.blend_frame = self.blend_frame.saturating_add(1);

        // The key is shown over the dance: clip matching and switch offsets follow the dance
        // alone (following the blended pose, every switch during a blend applied the key twice).
        let dance = *out;
        self.overlay.read_cue(controls.key_pose.as_ref());
        let frames_to_go = controls.key_pose.map(|k| k.frames_to_go);
        let weights = self.overlay.weights(frames_to_go, KEY_BLEND_FRAMES, true);
        let h = heading(dance.local_rotations[0]);
        for (w, key) in [
            (weights.release, self.overlay.released()),
            (weights.blend, self.overlay.target()),
        ] {
            let Some(w) = w else { continue };
            for j in 0..JOINT_COUNT {
                let target = if j == 0 {
                    yaw(h) * deheaded(key[0])
                } else {
                    key[j]
                };
                let target = target.normalize();
                if target.is_finite() {
                    out.local_rotations[j] = out.local_rotations[j].slerp(target, w).normalize();
                }
            }
        }
        if !out.is_finite() {
            // Unreachable with finite clips; keep the stream alive regardless.
            *out = self.last_out;
        }
        self.prev_out = self.last_out;
        self.last_out = if dance.is_finite() { dance } else { *out };
    }

    fn reset(&mut self, seed: u64) {
        self.rng = Rng::new(seed);
        self.pending = None;
        self.switches = 0;
        self.started = false;
        self.clip = 0;
        self.phase = 0.0;
        self.armed = true;
        self.follower.reset();
        self.bar_phase = 0.0;
        self.tempo = 0.0;
        self.energy = f32::NAN;
        self.anchor = Vec3::ZERO;
        self.anchor_heading = 0.0;
        self.offsets = [Quat::IDENTITY; JOINT_COUNT];
        self.root_offset = Vec3::ZERO;
        self.blend_frame = u32::MAX;
        self.last_out = Pose::rest();
        self.prev_out = Pose::rest();
        self.last_raw = Pose::rest();
        self.overlay.reset();
        self.travel_preference = None;
    }

    fn reseed(&mut self, seed: u64) {
        // Only the next clip choices change; the clip playing and its blend carry on.
        self.rng = Rng::new(seed);
    }

    fn prefer_travel(&mut self, preference: Option<TravelPreference>) {
        self.travel_preference = preference;
    }

    fn controls(&self) -> SourceControls {
        SourceControls {
            moves: self.libraries.len() > 1,
            ..SourceControls::default()
        }
    }

    fn report(&self) -> SourceReport {
        SourceReport {
            moves: (self.libraries.len() > 1).then_some(MovesReport {
                active: self.active,
                count: self.libraries.len(),
                pending: self.pending.map(|(i, _)| i),
                switches: self.switches,
            }),
            ..SourceReport::default()
        }
    }

    fn select_moves(&mut self, index: usize, at: MovesSwitch) -> bool {
        if index >= self.libraries.len() {
            return false;
        }
        self.pending = Some((index, at));
        self.beats_waited = 0;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::Joint;
    use crate::rotation::twist_angle;
    use crate::source::KeyPoseTarget;
    use std::f32::consts::{PI, TAU};

    /// One frame of synthetic music at `beats` beats since the start (4 beats to the bar).
    fn music_frame(beats: f64, tempo: f32, energy: f32) -> [f32; FEATURE_DIM] {
        let mut m = [0.0f32; FEATURE_DIM];
        for v in m.iter_mut().take(FeatureLayout::ONSET) {
            *v = -60.0;
        }
        let beat = (beats.rem_euclid(1.0) * std::f64::consts::TAU) as f32;
        let bar = ((beats / 4.0).rem_euclid(1.0) * std::f64::consts::TAU) as f32;
        m[FeatureLayout::BEAT_SIN] = beat.sin();
        m[FeatureLayout::BEAT_COS] = beat.cos();
        m[FeatureLayout::BAR_SIN] = bar.sin();
        m[FeatureLayout::BAR_COS] = bar.cos();
        m[FeatureLayout::ENERGY] = energy;
        m[FeatureLayout::TEMPO] = tempo;
        m
    }

    /// A cheap per-beat pseudo-random number in [−1, 1].
    fn hash(k: i64, salt: u64) -> f32 {
        let mut r = Rng::new((k as u64).wrapping_mul(31).wrapping_add(salt));
        r.next_f32() * 2.0 - 1.0
    }

    /// A synthetic dance: arms swinging once per beat (extremes on the beats), a per-beat head
    /// nod, a bounce, slow walking and turning.
    fn dance(
        tempo: f32,
        amp: f32,
        salt: u64,
        frames: usize,
    ) -> (Vec<Pose>, Vec<[f32; FEATURE_DIM]>) {
        let mut poses = Vec::with_capacity(frames);
        let mut music = Vec::with_capacity(frames);
        for n in 0..frames {
            let b = 0.37 + n as f64 * tempo as f64 / 60.0 / RETRIEVAL_FPS;
            let bf = b as f32;
            let mut p = Pose::rest();
            let h = 0.003 * n as f32;
            p.root_position = Vec3::new(0.01 * n as f32, 0.95 - 0.03 * (TAU * bf).cos(), 0.0);
            p.local_rotations[0] = yaw(h);
            let swing = amp * (PI * bf).cos();
            p.set_rotation(Joint::LeftUpperArm, Quat::from_rotation_z(swing));
            p.set_rotation(Joint::RightUpperArm, Quat::from_rotation_z(-swing));
            let nod = 0.3 * hash(b.floor() as i64, salt) * (PI * b.fract() as f32).sin();
            p.set_rotation(Joint::Head, Quat::from_rotation_x(nod));
            poses.push(p);
            music.push(music_frame(b, tempo, -20.0 + 3.0 * (amp - 1.0)));
        }
        (poses, music)
    }

    fn library() -> Vec<(Vec<Pose>, Vec<[f32; FEATURE_DIM]>)> {
        vec![
            dance(110.0, 0.8, 1, 750),
            dance(120.0, 1.0, 2, 750),
            dance(130.0, 1.2, 3, 750),
        ]
    }

    /// Live music at `tempo` from beat phase `phase0`; returns (music, live phase) per frame.
    fn live(tempo: f64, phase0: f64, frames: usize) -> (Vec<[f32; FEATURE_DIM]>, Vec<f32>) {
        (0..frames)
            .map(|n| {
                let b = phase0 + n as f64 * tempo / 60.0 / RETRIEVAL_FPS;
                (
                    music_frame(b, tempo as f32, -20.0),
                    b.rem_euclid(1.0) as f32,
                )
            })
            .unzip()
    }

    fn run(
        dancer: &mut RetrievalDancer,
        music: &[[f32; FEATURE_DIM]],
        controls: &Controls,
    ) -> Vec<Pose> {
        let mut out = Pose::rest();
        music
            .iter()
            .map(|m| {
                dancer.step(std::slice::from_ref(m), controls, &mut out);
                out
            })
            .collect()
    }

    /// A library of big, slow-travelling moves unlike [`library`]'s: arms held high, a deep
    /// bounce.
    fn other_library() -> ClipLibrary {
        let dances: Vec<_> = [(100.0, 2.0, 7), (125.0, 2.2, 8)]
            .into_iter()
            .map(|(tempo, amp, salt)| {
                let (mut poses, music) = dance(tempo, amp, salt, 750);
                for p in &mut poses {
                    p.set_rotation(Joint::Spine, Quat::from_rotation_x(0.3));
                    p.root_position.y -= 0.05;
                }
                (poses, music)
            })
            .collect();
        ClipLibrary::from_dances(&dances)
    }

    #[test]
    fn a_switch_of_moves_lands_on_the_bar_it_was_cued_for_and_glides() {
        let libraries = vec![ClipLibrary::from_dances(&library()), other_library()];
        let mut d = RetrievalDancer::with_libraries(libraries, 3).unwrap();
        assert!(d.controls().moves);
        assert!(!d.select_moves(2, MovesSwitch::NextBar), "no third library");
        let (music, phases) = live(120.0, 0.0, 1000);
        let controls = Controls::default();
        let skeleton = crate::rig::Skeleton::default_adult();
        let mut out = Pose::rest();
        let mut poses = Vec::new();
        let mut switched_at = None;
        // Cued mid-bar (beat 9.5 of the song: the third beat of bar 3).
        let cue = (9.5 * 60.0 / 120.0 * RETRIEVAL_FPS) as usize;
        for (i, m) in music.iter().enumerate() {
            if i == cue {
                assert!(d.select_moves(1, MovesSwitch::NextBar));
                assert_eq!(d.report().moves.unwrap().pending, Some(1));
            }
            d.step(std::slice::from_ref(m), &controls, &mut out);
            poses.push(out);
            let report = d.report().moves.unwrap();
            if switched_at.is_none() && report.active == 1 {
                switched_at = Some(i);
            }
        }
        let at = switched_at.expect("the switch happened");
        // The next bar starts at beat 12: frame 150; the dancer hits the beat a little early.
        let bar_frame = 12.0 * 60.0 / 120.0 * RETRIEVAL_FPS;
        let late_ms = (at as f64 - bar_frame) / RETRIEVAL_FPS * 1000.0;
        assert!(
            late_ms.abs() <= 70.0,
            "switched at frame {at}, {late_ms} ms from the bar"
        );
        assert!(
            phases[at] < 0.2 || phases[at] > 0.9,
            "on a beat: {}",
            phases[at]
        );
        let report = d.report().moves.unwrap();
        assert_eq!(
            (report.active, report.count, report.pending, report.switches),
            (1, 2, None, 1)
        );
        // The dance is the other library's after the switch: the spine leans.
        let lean = poses[at + 30]
            .rotation(Joint::Spine)
            .angle_between(Quat::IDENTITY);
        assert!(lean > 0.2, "{lean}");
        // It glides: the root and the joints move no more at the switch than while dancing.
        let step = |i: usize| (poses[i].root_position - poses[i - 1].root_position).length();
        let turn = |i: usize| {
            let (mut a, mut b) = ([Vec3::ZERO; JOINT_COUNT], [Vec3::ZERO; JOINT_COUNT]);
            skeleton.world_positions(&poses[i - 1], &mut a);
            skeleton.world_positions(&poses[i], &mut b);
            a.iter()
                .zip(&b)
                .map(|(p, q)| (*p - *q).length())
                .fold(0.0f32, f32::max)
        };
        let around = at - 2..at + 8;
        let normal = (50..at - 10).chain(at + 20..poses.len());
        let largest_step = around.clone().map(step).fold(0.0f32, f32::max);
        assert!(
            largest_step <= 0.1,
            "root step {largest_step} m at the switch"
        );
        let normal_jump = normal.map(turn).fold(0.0f32, f32::max);
        let switch_jump = around.map(turn).fold(0.0f32, f32::max);
        assert!(
            switch_jump <= normal_jump,
            "joints move {switch_jump} m in a frame at the switch, {normal_jump} m at most otherwise"
        );
    }

    #[test]
    fn library_cuts_one_clip_per_beat() {
        let lib = ClipLibrary::from_dances(&library());
        // 750 frames = 30 s: 55, 60 and 65 beats, minus the partial first and last.
        assert!(
            (175..=180).contains(&lib.clips.len()),
            "{}",
            lib.clips.len()
        );
        for c in &lib.clips {
            let first = lib.first_pose(c);
            assert!(first.root_position.x.abs() < 1e-4 && first.root_position.z.abs() < 1e-4);
            assert!(heading(first.local_rotations[0]).abs() < 1e-4);
            assert!((c.len as f32 - 60.0 * 25.0 / c.tempo).abs() <= 1.0);
        }
        assert!(matches!(
            RetrievalDancer::new(ClipLibrary::from_dances(&[]), 0).err(),
            Some(ModelError::EmptyClipLibrary)
        ));
    }

    #[test]
    fn poses_stay_finite_even_with_bad_music() {
        let mut dancer = RetrievalDancer::from_dances(&library(), 7).unwrap();
        let (mut music, _) = live(97.0, 0.1, 400);
        for m in music.iter_mut().skip(100).step_by(7) {
            m[FeatureLayout::BEAT_SIN] = f32::NAN;
            m[FeatureLayout::TEMPO] = f32::INFINITY;
            m[FeatureLayout::ENERGY] = f32::NEG_INFINITY;
        }
        for m in music.iter_mut().skip(300).take(20) {
            *m = [f32::NAN; FEATURE_DIM];
        }
        let controls = Controls {
            temperature: 2.0,
            ..Controls::default()
        };
        let mut out = Pose::rest();
        for m in &music {
            dancer.step(std::slice::from_ref(m), &controls, &mut out);
            assert!(out.is_finite());
        }
        dancer.step(&[], &controls, &mut out);
        assert!(out.is_finite());
        // The root keeps moving (the walk is integrated, not reset per clip).
        assert!(out.root_position.x.abs() + out.root_position.z.abs() > 1.0);
    }

    #[test]
    fn arm_swing_extremes_land_on_the_live_beats() {
        for tempo in [100.0, 125.0, 140.0] {
            let mut dancer = RetrievalDancer::from_dances(&library(), 3).unwrap();
            let (music, phase) = live(tempo, 0.6, 750);
            let poses = run(&mut dancer, &music, &Controls::default());
            let arm: Vec<f32> = poses
                .iter()
                .map(|p| twist_angle(p.rotation(Joint::LeftUpperArm), Vec3::Z))
                .collect();
            // Turning points with 0.2 rad hysteresis, so plateaus and blend ripples are not extremes.
            let (mut err, mut count) = (0.0, 0);
            let (mut ext, mut ext_i, mut rising) = (arm[50], 50, arm[51] > arm[50]);
            for (i, &a) in arm.iter().enumerate().skip(51) {
                if (rising && a > ext) || (!rising && a < ext) {
                    (ext, ext_i) = (a, i);
                } else if (a - ext).abs() > 0.2 {
                    err += circular_distance(phase[ext_i], 0.0);
                    count += 1;
                    (ext, ext_i, rising) = (a, i, !rising);
                }
            }
            let beats = (699.0 * tempo / 60.0 / 25.0) as usize;
            assert!(
                count + 3 >= beats && count <= beats + 3,
                "{count} extremes for {beats} beats"
            );
            let mean = err / count as f32;
            assert!(mean < 0.1, "tempo {tempo}: mean phase error {mean}");
        }
    }

    #[test]
    fn zero_temperature_is_deterministic_and_temperature_varies() {
        let (music, _) = live(118.0, 0.2, 400);
        let cold = Controls::default();
        let a = run(
            &mut RetrievalDancer::from_dances(&library(), 5).unwrap(),
            &music,
            &cold,
        );
        let mut d = RetrievalDancer::from_dances(&library(), 5).unwrap();
        let b = run(&mut d, &music, &cold);
        assert_eq!(a, b);
        d.reset(5);
        assert_eq!(run(&mut d, &music, &cold), a);

        let warm = Controls {
            temperature: 1.0,
            ..Controls::default()
        };
        let mut d = RetrievalDancer::from_dances(&library(), 1).unwrap();
        let x = run(&mut d, &music, &warm);
        d.reset(1);
        assert_eq!(run(&mut d, &music, &warm), x, "same seed, same dance");
        d.reset(2);
        let y = run(&mut d, &music, &warm);
        assert_ne!(x, y, "different seeds should dance differently at T = 1");
    }

    #[test]
    fn key_pose_is_reached_on_time() {
        let mut target = [Quat::IDENTITY; JOINT_COUNT];
        target[Joint::LeftUpperArm.index()] = Quat::from_rotation_x(1.2);
        target[Joint::RightUpperArm.index()] = Quat::from_rotation_z(-1.4);
        target[Joint::Spine.index()] = Quat::from_rotation_x(0.4);
        target[Joint::Head.index()] = Quat::from_rotation_y(0.5);
        target[Joint::Hips.index()] = yaw(2.0) * Quat::from_rotation_x(0.2);
        let mut dancer = RetrievalDancer::from_dances(&library(), 9).unwrap();
        let (music, _) = live(115.0, 0.0, 200);
        let mut out = Pose::rest();
        for (n, m) in music.iter().enumerate() {
            let key_pose = (100..=150).contains(&n).then(|| KeyPoseTarget {
                rotations: target,
                frames_to_go: (150 - n) as u32,
            });
            let controls = Controls {
                temperature: 0.5,
                key_pose,
                ..Controls::default()
            };
            let before = out;
            dancer.step(std::slice::from_ref(m), &controls, &mut out);
            assert!(out.is_finite());
            if n == 150 {
                for (j, t) in target.iter().enumerate().skip(1) {
                    let e = out.local_rotations[j].angle_between(*t);
                    assert!(e < 1e-2, "joint {j}: {e} rad off");
                }
                let e = deheaded(out.local_rotations[0]).angle_between(deheaded(target[0]));
                assert!(e < 1e-2, "hips: {e} rad off");
            }
            if n > 0 {
                // No pops, including when the key pose is let go at frame 151.
                for j in 0..JOINT_COUNT {
                    let jump = out.local_rotations[j].angle_between(before.local_rotations[j]);
                    assert!(jump < 0.6, "frame {n} joint {j} jumped {jump} rad");
                }
            }
        }
    }
}
