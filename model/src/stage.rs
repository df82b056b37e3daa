//! The stage: where on the floor the dance is placed, so a renderer's camera, an avatar app or
//! a VR rig finds the character where it expects it.
//!
//! A dancer's own motion travels (the captured ballroom crosses its floor; the neural dancer
//! drifts 10–12 m in 90 s). [`Stage`] maps each pose a source makes onto the stage by a rigid
//! turn and shift about the vertical, changed a little each frame:
//!
//! - [`StageMode::Bounded`]: as the centre of the dance's steps nears the edge, its drift is
//!   bent back inward by turning the whole dance about the vertical, at most
//!   [`MAX_TURN_DEG_PER_S`], and the dance glides back towards the centre ([`GLIDE_MPS`] while
//!   a toe is planted, [`AIR_GLIDE_MPS`] while none is). A rigid turn keeps every joint's
//!   motion and every foot contact as danced; only the turn itself could slide a planted foot,
//!   so it pivots about the planted toe (the dancer turns on the spot it stands on, as a dancer
//!   turns), and the stance leg holds a planted toe against the glide ([`FootLock`] with the
//!   leg only, up to a stride). A hard clamp that shifts the dance back is the last resort
//!   ([`StageCounts::clamped`]): the neural dancer's fastest steps outrun the glide.
//! - [`StageMode::InPlace`]: the hips' travel over the floor is removed (their sway within
//!   [`IN_PLACE_TRAVEL_S`] kept) and the stance leg holds a planted toe where it was put
//!   ([`FootLock`] with the leg only), so what remains of sliding is what a leg cannot reach.
//! - [`StageMode::Free`]: the source's own motion, untouched.
//!
//! Both kept modes start the dance at the stage's centre facing the audience and, while the
//! dancer keeps facing away for a while, turn it slowly back towards them
//! ([`FACING_TURN_DEG_PER_S`]); a dancer that spins has no lasting facing and is left alone.
//!
//! [`StagedSource`] puts any [`MotionSource`] on a stage. Nothing here allocates after setup.

use std::f32::consts::{FRAC_PI_2, PI, TAU};

use dsp::feature::FEATURE_DIM;
use glam::{Vec2, Vec3};

use crate::foot_lock::{CONTACT_HEIGHT_M, CONTACT_VERTICAL_SPEED_MPS, FootLock};
use crate::motion::{heading, yaw};
use crate::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use crate::source::{Controls, MotionSource, SourceControls, SourceReport, TravelPreference};

/// How the dance is kept on the stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StageMode {
    /// Within [`StageSettings::radius_m`] of the centre: the travel turns back before the edge.
    #[default]
    Bounded,
    /// On the spot: the hips' travel removed.
    InPlace,
    /// Wherever the dance goes: the source's motion untouched.
    Free,
}

impl StageMode {
    /// Every mode, in the order `/stage/mode N` numbers them.
    pub const ALL: [StageMode; 3] = [StageMode::Bounded, StageMode::InPlace, StageMode::Free];

    /// The mode named `s` (`bounded`, `in_place` or `in-place`, `free`; case-insensitive).
    pub fn parse(s: &str) -> Option<Self> {
        match s.trim().to_ascii_lowercase().replace('-', "_").as_str() {
            "bounded" => Some(StageMode::Bounded),
            "in_place" => Some(StageMode::InPlace),
            "free" => Some(StageMode::Free),
            _ => None,
        }
    }

    /// The name [`StageMode::parse`] reads.
    pub fn name(self) -> &'static str {
        match self {
            StageMode::Bounded => "bounded",
            StageMode::InPlace => "in_place",
            StageMode::Free => "free",
        }
    }
}

/// Default stage radius, metres: a full-body camera framing a 1.8 m dancer from 5–6 m away
/// (the browser view's) sees about ±1.7 m sideways, so hips within 1.5 m keep the arms in.
pub const DEFAULT_RADIUS_M: f32 = 1.5;

/// Smallest stage radius accepted, metres (a single step is about 0.3 m).
pub const MIN_RADIUS_M: f32 = 0.3;

/// Largest turn the steering adds, degrees per second (a slow pivot, not a spin). At 60 the
/// retrieval dancer's kinetics left the data (FID_k 50–74 against 37–42 free, validation
/// songs, T = 0.5, seeds 1–3); at 30 it stays (39.4, seed 1), for a clamp acting more often
/// on fast rendered songs.
pub const MAX_TURN_DEG_PER_S: f32 = 30.0;

/// Largest turn towards the audience, degrees per second (well under the steering's, so it
/// never looks like a correction).
pub const FACING_TURN_DEG_PER_S: f32 = 10.0;

/// How far past the radius the hips may go before the hard clamp shifts the dance back, m.
pub const CLAMP_MARGIN_M: f32 = 0.05;

/// How much faster than the dance's own step the hips walk back onto a moved or shrunk
/// stage, m/s.
pub const RETURN_MPS: f32 = 1.0;

/// Time constant of the drift the steering reads, s: the dance's steps out and back (a
/// ballroom dancer's reach 0.5–1 m and return within a few beats) average out, the drift that
/// carries the dance away does not.
pub const TRAVEL_S: f32 = 2.0;

/// How far ahead the steering looks along the drift, s.
pub const LOOK_AHEAD_S: f32 = 2.0;

/// Fastest the bounded stage glides the dance back from its edge while a toe is planted, m/s.
pub const GLIDE_MPS: f32 = 0.3;

/// …and while none is (nothing slides), m/s.
pub const AIR_GLIDE_MPS: f32 = 1.0;

/// Time over which the largest reach of the steps about their centre is forgotten, s.
pub const REACH_MEMORY_S: f32 = 8.0;

/// Share of the room left for the steps' centre inside which the dancer goes where the dance
/// takes it, unsteered.
pub const FREE_ZONE: f32 = 0.5;

/// Time constant of the facing the turn towards the audience reads, s.
pub const FACING_S: f32 = 2.0;

/// In place: hip travel slower than this time constant is removed, faster sway kept, s.
pub const IN_PLACE_TRAVEL_S: f32 = 0.5;

/// Where the dance is placed and how it is kept there.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct StageSettings {
    /// How the dance is kept on the stage.
    pub mode: StageMode,
    /// Radius of the stage, metres (bounded: the hips stay inside it).
    pub radius_m: f32,
    /// Centre of the stage on the floor, metres: x (sideways) and z (towards the audience).
    pub centre: [f32; 2],
    /// Direction the audience is in, degrees about the vertical: 0 = +z (the browser view's
    /// camera and an avatar app's default), 90 = +x.
    pub facing_deg: f32,
}

impl Default for StageSettings {
    /// Bounded, [`DEFAULT_RADIUS_M`] about the origin, facing +z.
    fn default() -> Self {
        StageSettings {
            mode: StageMode::Bounded,
            radius_m: DEFAULT_RADIUS_M,
            centre: [0.0, 0.0],
            facing_deg: 0.0,
        }
    }
}

impl StageSettings {
    /// The settings with every value finite and in range: a radius below [`MIN_RADIUS_M`] or
    /// non-finite becomes the smallest or the default, a non-finite centre or facing 0.
    pub fn sanitized(self) -> Self {
        let radius_m = if self.radius_m.is_finite() {
            self.radius_m.max(MIN_RADIUS_M)
        } else {
            DEFAULT_RADIUS_M
        };
        let finite = |v: f32| if v.is_finite() { v } else { 0.0 };
        StageSettings {
            mode: self.mode,
            radius_m,
            centre: self.centre.map(finite),
            facing_deg: finite(self.facing_deg),
        }
    }
}

/// What the stage did since the last reset.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageCounts {
    /// Frames placed.
    pub frames: u64,
    /// Frames on which the steering turned the dance.
    pub steered: u64,
    /// Frames on which the dance was glided back from the edge.
    pub glided: u64,
    /// Frames on which the hard clamp shifted the dance back inside.
    pub clamped: u64,
    /// Largest turn the stage added in one frame, degrees per second.
    pub max_turn_deg_per_s: f32,
}

/// Places a source's poses on the stage, frame by frame.
pub struct Stage {
    settings: StageSettings,
    skeleton: Skeleton,
    frame_rate: f32,
    /// The turn about the vertical from the source's floor to the stage, radians.
    turn: f32,
    /// The shift on the floor (x, z) after the turn, metres.
    shift: Vec2,
    started: bool,
    /// Whether the next frame goes on from where the hips were shown (after a change of mode).
    rebase: bool,
    /// Hips on the stage at the last frame (x, z).
    last_hips: Vec2,
    /// Drift velocity on the stage (over [`TRAVEL_S`]), m/s.
    travel: Vec2,
    /// Centre of the dance's steps: the hips on the stage low-passed over [`TRAVEL_S`].
    steps_centre: Vec2,
    /// Largest reach of the hips from the steps' centre lately ([`REACH_MEMORY_S`]), m.
    reach: f32,
    /// The way the steering is turning: +1, −1, or 0 when it is not.
    turning: f32,
    /// Smoothed facing direction on the stage (unit when the dancer holds one, shorter while
    /// it turns about).
    facing: Vec2,
    /// In place: the source's hips (x, z) low-passed over [`IN_PLACE_TRAVEL_S`].
    drift: Vec2,
    /// Toes in the source's frame at the last frame.
    last_toes: [Vec3; 2],
    /// In place: the stance legs' hold of planted toes.
    plant: FootLock,
    positions: [Vec3; JOINT_COUNT],
    counts: StageCounts,
}

/// The two toes, whose contacts the pivot is chosen from.
const TOES: [Joint; 2] = [Joint::LeftToes, Joint::RightToes];

/// (x, z) of a point.
fn ground(p: Vec3) -> Vec2 {
    Vec2::new(p.x, p.z)
}

/// `v` (x, z) turned by `angle` about +y, as [`yaw`] turns a point.
fn turned(v: Vec2, angle: f32) -> Vec2 {
    let (s, c) = angle.sin_cos();
    Vec2::new(c * v.x + s * v.y, -s * v.x + c * v.y)
}

/// The signed angle about +y that turns direction `from` onto `to` (both x, z), in (−π, π].
fn angle_between(from: Vec2, to: Vec2) -> f32 {
    // yaw(a) maps (x, z) = (sin h, cos h) to (sin(h + a), cos(h + a)).
    let a = to.x.atan2(to.y) - from.x.atan2(from.y);
    wrap(a)
}

/// `a` wrapped into (−π, π].
fn wrap(a: f32) -> f32 {
    let w = (a + PI).rem_euclid(TAU) - PI;
    if w <= -PI { w + TAU } else { w }
}

/// 0 below `lo`, 1 above `hi`, smooth between.
fn smoothstep(lo: f32, hi: f32, x: f32) -> f32 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl Stage {
    /// A stage for poses of `skeleton` arriving at `frame_rate` frames per second.
    pub fn new(settings: StageSettings, skeleton: Skeleton, frame_rate: f32) -> Self {
        let frame_rate = if frame_rate.is_finite() && frame_rate > 0.0 {
            frame_rate
        } else {
            25.0
        };
        Stage {
            settings: settings.sanitized(),
            skeleton,
            frame_rate,
            turn: 0.0,
            shift: Vec2::ZERO,
            started: false,
            rebase: false,
            last_hips: Vec2::ZERO,
            travel: Vec2::ZERO,
            steps_centre: Vec2::ZERO,
            reach: 0.0,
            turning: 0.0,
            facing: Vec2::ZERO,
            drift: Vec2::ZERO,
            last_toes: [Vec3::ZERO; 2],
            plant: FootLock::new(skeleton, frame_rate, 0.0).with_plant(1.0),
            positions: [Vec3::ZERO; JOINT_COUNT],
            counts: StageCounts::default(),
        }
    }

    /// The settings in force.
    pub fn settings(&self) -> StageSettings {
        self.settings
    }

    /// Changes the settings; the dance goes on from where it stands (a new centre or radius
    /// is reached by steering, not by a jump; leaving free mode starts from the dancer's spot).
    pub fn set_settings(&mut self, settings: StageSettings) {
        let settings = settings.sanitized();
        if settings.mode != self.settings.mode {
            self.plant.reset();
            self.rebase = true;
        }
        self.settings = settings;
    }

    /// What the stage did since the last reset.
    pub fn counts(&self) -> StageCounts {
        self.counts
    }

    /// Starts a new performance: the next pose is placed at the centre, facing the audience.
    pub fn reset(&mut self) {
        self.turn = 0.0;
        self.shift = Vec2::ZERO;
        self.started = false;
        self.rebase = false;
        self.travel = Vec2::ZERO;
        self.steps_centre = Vec2::ZERO;
        self.reach = 0.0;
        self.turning = 0.0;
        self.facing = Vec2::ZERO;
        self.drift = Vec2::ZERO;
        self.plant.reset();
        self.counts = StageCounts::default();
    }

    /// Where the source should prefer to travel, in its own frame (for sources that choose
    /// their steps, e.g. the retrieval dancer): towards the centre, as strongly as the dancer is
    /// near the edge. `None` when free or in the middle of the stage.
    pub fn travel_preference(&self) -> Option<TravelPreference> {
        if self.settings.mode != StageMode::Bounded || !self.started {
            return None;
        }
        let to_centre = Vec2::from(self.settings.centre) - self.last_hips;
        let r = self.settings.radius_m;
        let strength = smoothstep(FREE_ZONE * r, r, to_centre.length());
        if strength <= 0.0 {
            return None;
        }
        let dir = turned(to_centre.normalize_or_zero(), -self.turn);
        Some(TravelPreference {
            direction: [dir.x, dir.y],
            strength,
        })
    }

    /// Places `pose` (as the source made it) on the stage; never allocates.
    pub fn place(&mut self, pose: &mut Pose) {
        if self.settings.mode == StageMode::Free {
            self.counts.frames += 1;
            if pose.is_finite() {
                self.last_hips = ground(pose.root_position);
                self.turn = 0.0;
                self.shift = Vec2::ZERO;
                self.started = true;
            }
            return;
        }
        if !pose.is_finite() {
            return;
        }
        let dt = 1.0 / self.frame_rate;
        let raw_hips = ground(pose.root_position);
        let raw_heading = heading(pose.local_rotations[0]);
        let centre = Vec2::from(self.settings.centre);
        let audience = self.settings.facing_deg.to_radians();
        self.skeleton.world_positions(pose, &mut self.positions);
        let toes = TOES.map(|t| self.positions[t.index()]);
        if !self.started {
            self.started = true;
            self.turn = wrap(audience - raw_heading);
            self.drift = raw_hips;
            self.shift = centre - turned(raw_hips, self.turn);
            self.last_hips = centre;
            self.last_toes = toes;
            self.travel = Vec2::ZERO;
            self.steps_centre = centre;
            self.reach = 0.0;
            self.facing = Vec2::new(audience.sin(), audience.cos());
        } else if self.rebase {
            // Go on from where the hips were shown, not from the source's own spot.
            self.shift = self.last_hips - turned(raw_hips, self.turn);
            self.drift = raw_hips;
            self.steps_centre = self.last_hips;
            self.last_toes = toes;
        }
        self.rebase = false;

        // The turn this frame: back from the edge (bounded), towards the audience (both).
        let hips = turned(raw_hips, self.turn) + self.shift;
        let step = hips - self.last_hips;
        let a_travel = 1.0 - (-dt / TRAVEL_S).exp();
        if step.length() < 0.5 {
            // A longer step is a jump of the source (a restart), not travel.
            self.travel += a_travel * (step / dt - self.travel);
            self.steps_centre += a_travel * (hips - self.steps_centre);
        } else {
            self.steps_centre = hips;
        }
        let forget = (-dt / REACH_MEMORY_S).exp();
        self.reach = (self.reach * forget).max((hips - self.steps_centre).length());
        let h = raw_heading + self.turn;
        let a_facing = 1.0 - (-dt / FACING_S).exp();
        self.facing += a_facing * (Vec2::new(h.sin(), h.cos()) - self.facing);
        let mut rate = 0.0;
        let mut urgency = 0.0;
        if self.settings.mode == StageMode::Bounded {
            (rate, urgency) = self.steering(self.steps_centre - centre);
        }
        if rate != 0.0 {
            self.counts.steered += 1;
        }
        let face_error = angle_between(self.facing, Vec2::new(audience.sin(), audience.cos()));
        let hold = self.facing.length().min(1.0);
        let face_max = FACING_TURN_DEG_PER_S.to_radians();
        let face_rate = (face_error * 0.5).clamp(-face_max, face_max) * hold * (1.0 - urgency);
        let max = MAX_TURN_DEG_PER_S.to_radians();
        let rate = (rate + face_rate).clamp(-max, max);
        let d_turn = rate * dt;

        // Pivot about the planted toe (the lower one), else the hips.
        let mut pivot = hips;
        let mut lowest = f32::MAX;
        for (now, before) in toes.iter().zip(&self.last_toes) {
            let rising = (now.y - before.y).abs() * self.frame_rate;
            if now.y < CONTACT_HEIGHT_M
                && before.y < CONTACT_HEIGHT_M
                && rising < CONTACT_VERTICAL_SPEED_MPS
                && now.y < lowest
            {
                lowest = now.y;
                pivot = turned(ground(*now), self.turn) + self.shift;
            }
        }
        self.last_toes = toes;
        if d_turn != 0.0 {
            self.turn = wrap(self.turn + d_turn);
            self.shift = turned(self.shift - pivot, d_turn) + pivot;
            let deg = rate.abs().to_degrees();
            if deg > self.counts.max_turn_deg_per_s {
                self.counts.max_turn_deg_per_s = deg;
            }
        }

        if self.settings.mode == StageMode::Bounded && urgency > 0.0 {
            // Glide the whole dance back towards the centre as its steps near the edge: faster
            // while no toe is planted (nothing slides); while one is, the stance leg holds it
            // against the glide (below).
            let speed = if lowest == f32::MAX {
                AIR_GLIDE_MPS
            } else {
                GLIDE_MPS
            };
            self.shift -= (self.steps_centre - centre).normalize_or_zero() * urgency * speed * dt;
            self.counts.glided += 1;
        }
        let mut placed = turned(raw_hips, self.turn) + self.shift;
        if self.settings.mode == StageMode::InPlace {
            let a_drift = 1.0 - (-dt / IN_PLACE_TRAVEL_S).exp();
            self.drift += a_drift * (raw_hips - self.drift);
            placed = centre + turned(raw_hips - self.drift, self.turn);
        }
        let out = placed - centre;
        let limit = self.settings.radius_m + CLAMP_MARGIN_M;
        if out.length() > limit {
            // Within a step of the edge this is the whole excess; far outside (the stage moved
            // or shrank, or free mode ended) the hips walk back instead of jumping.
            let back = (out - out * (limit / out.length()))
                .clamp_length_max(RETURN_MPS * dt + (placed - self.last_hips).length());
            placed -= back;
            self.shift -= back;
            self.counts.clamped += 1;
        }
        self.last_hips = placed;
        self.counts.frames += 1;

        pose.root_position.x = placed.x;
        pose.root_position.z = placed.y;
        pose.local_rotations[0] = (yaw(self.turn) * pose.local_rotations[0]).normalize();
        // The stance leg holds a planted toe where it was put against the glide, the clamp and
        // (in place) the travel taken away.
        self.plant.process(pose, 1.0);
    }

    /// The containment turn for the steps' centre at `from_centre` (rad/s, signed about +y)
    /// and how urgent it is (0 in the free zone, 1 at the edge of the room heading out).
    fn steering(&mut self, from_centre: Vec2) -> (f32, f32) {
        // The steps' centre has the stage less their reach (but never under 40 % of it).
        let room = (self.settings.radius_m - self.reach).max(0.4 * self.settings.radius_m);
        // Where the drift outward will have taken it (a dance circling about does not head
        // for the edge, whichever way it faces now).
        let d = from_centre.length();
        let outward = self.travel.dot(from_centre.normalize_or_zero()).max(0.0);
        let urgency = smoothstep(FREE_ZONE * room, room, d + outward * LOOK_AHEAD_S);
        let speed = self.travel.length();
        if urgency <= 0.0 || speed < 1e-3 {
            self.turning = 0.0;
            return (0.0, urgency);
        }
        // Turn the travel towards the centre, harder the more it points away from it. Heading
        // straight out, either way round will do: keep to the way the turn began, or it
        // flips with every wobble of the drift and never comes round.
        let mut error = angle_between(self.travel, -from_centre);
        if self.turning != 0.0 && error.abs() > FRAC_PI_2 && error.signum() != self.turning {
            error = self.turning * (TAU - error.abs());
        }
        self.turning = error.signum();
        let max = MAX_TURN_DEG_PER_S.to_radians();
        let rate = max * urgency * (error.abs() / FRAC_PI_2).min(1.0) * (speed / 0.05).min(1.0);
        (rate.copysign(error), urgency)
    }
}

/// A [`MotionSource`] on a [`Stage`]: each pose the source makes is placed on the stage, and
/// the source hears where the stage would have it travel.
pub struct StagedSource<S> {
    source: S,
    stage: Stage,
}

impl<S: MotionSource> StagedSource<S> {
    /// `source` on a stage set by `settings`, for poses of `skeleton`.
    pub fn new(source: S, settings: StageSettings, skeleton: Skeleton) -> Self {
        let rate = source.frame_rate() as f32;
        StagedSource {
            source,
            stage: Stage::new(settings, skeleton, rate),
        }
    }

    /// The stage.
    pub fn stage(&self) -> &Stage {
        &self.stage
    }

    /// The stage, to change its settings live.
    pub fn stage_mut(&mut self) -> &mut Stage {
        &mut self.stage
    }

    /// The source.
    pub fn source(&self) -> &S {
        &self.source
    }

    /// The source, mutably.
    pub fn source_mut(&mut self) -> &mut S {
        &mut self.source
    }
}

impl<S: MotionSource> MotionSource for StagedSource<S> {
    fn frame_rate(&self) -> f64 {
        self.source.frame_rate()
    }

    fn lookahead_frames(&self) -> usize {
        self.source.lookahead_frames()
    }

    fn horizon_frames(&self) -> usize {
        self.source.horizon_frames()
    }

    fn step(&mut self, music: &[[f32; FEATURE_DIM]], controls: &Controls, out: &mut Pose) {
        self.source.prefer_travel(self.stage.travel_preference());
        self.source.step(music, controls, out);
        self.stage.place(out);
    }

    fn reset(&mut self, seed: u64) {
        self.source.reset(seed);
        self.stage.reset();
    }

    fn controls(&self) -> SourceControls {
        self.source.controls()
    }

    fn report(&self) -> SourceReport {
        SourceReport {
            stage: Some(self.stage.counts()),
            ..self.source.report()
        }
    }

    fn reseed(&mut self, seed: u64) {
        self.source.reseed(seed);
    }

    fn prefer_travel(&mut self, preference: Option<TravelPreference>) {
        self.source.prefer_travel(preference);
    }

    fn select_moves(&mut self, index: usize, at: crate::source::MovesSwitch) -> bool {
        self.source.select_moves(index, at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dancer that walks straight on at `speed` m/s, turning `spin` rad/s as it goes.
    struct Walker {
        skeleton: Skeleton,
        speed: f32,
        spin: f32,
        frame: u32,
    }

    impl Walker {
        fn new(speed: f32, spin: f32) -> Self {
            Walker {
                skeleton: Skeleton::default_adult(),
                speed,
                spin,
                frame: 0,
            }
        }
    }

    impl MotionSource for Walker {
        fn frame_rate(&self) -> f64 {
            25.0
        }
        fn lookahead_frames(&self) -> usize {
            0
        }
        fn step(&mut self, _: &[[f32; FEATURE_DIM]], _: &Controls, out: &mut Pose) {
            let t = self.frame as f32 / 25.0;
            let h = 0.7 + self.spin * t;
            *out = self.skeleton.rest_pose();
            // Straight on, or along a circle of radius speed / spin.
            let (x, z) = if self.spin == 0.0 {
                (h.sin() * self.speed * t, h.cos() * self.speed * t)
            } else {
                let r = self.speed / self.spin;
                (r * (0.7f32.cos() - h.cos()), r * (h.sin() - 0.7f32.sin()))
            };
            out.root_position.x = 3.0 + x;
            out.root_position.z = -2.0 + z;
            out.local_rotations[0] = yaw(h);
            self.frame += 1;
        }
        fn reset(&mut self, _: u64) {
            self.frame = 0;
        }
        fn reseed(&mut self, _: u64) {}
    }

    fn run(source: &mut dyn MotionSource, frames: usize) -> Vec<Pose> {
        let music = [[0.0f32; FEATURE_DIM]];
        let mut pose = Pose::rest();
        (0..frames)
            .map(|_| {
                source.step(&music, &Controls::default(), &mut pose);
                pose
            })
            .collect()
    }

    fn distance_from(p: &Pose, centre: [f32; 2]) -> f32 {
        (ground(p.root_position) - Vec2::from(centre)).length()
    }

    #[test]
    fn free_leaves_the_motion_exactly_as_made() {
        let settings = StageSettings {
            mode: StageMode::Free,
            ..StageSettings::default()
        };
        let mut staged =
            StagedSource::new(Walker::new(0.8, 0.0), settings, Skeleton::default_adult());
        let placed = run(&mut staged, 500);
        let made = run(&mut Walker::new(0.8, 0.0), 500);
        assert_eq!(placed, made);
        assert_eq!(staged.report().stage.unwrap().clamped, 0);
    }

    #[test]
    fn a_walker_bounded_stays_inside_turning_no_faster_than_the_limit() {
        // A steady walk at 0.8 m/s is clamped on about 3 % of its frames: the steps' centre
        // the stage keeps inside trails such a walk by 1.6 m (see the research log).
        let settings = StageSettings {
            centre: [1.0, -0.5],
            ..StageSettings::default()
        };
        for speed in [0.3f32, 0.5] {
            let mut staged =
                StagedSource::new(Walker::new(speed, 0.0), settings, Skeleton::default_adult());
            let poses = run(&mut staged, 25 * 300);
            let first = &poses[0];
            assert!(distance_from(first, settings.centre) < 1e-4);
            assert!(
                heading(first.local_rotations[0]).abs() < 1e-4,
                "starts facing the audience"
            );
            let far = poses
                .iter()
                .map(|p| distance_from(p, settings.centre))
                .fold(0.0f32, f32::max);
            assert!(far <= DEFAULT_RADIUS_M + 0.1, "{speed} m/s: {far} m");
            let c = staged.report().stage.unwrap();
            assert_eq!(c.frames, poses.len() as u64);
            assert!(
                (c.clamped as f64) < 0.01 * c.frames as f64,
                "{speed} m/s: clamped {} of {}",
                c.clamped,
                c.frames
            );
            assert!(c.steered > 0);
            assert!(c.max_turn_deg_per_s <= MAX_TURN_DEG_PER_S + 1e-3);
        }
    }

    #[test]
    fn a_planted_toe_stays_put_while_the_steering_turns_about_it() {
        let skeleton = Skeleton::default_adult();
        let mut stage = Stage::new(StageSettings::default(), skeleton, 25.0);
        // A body standing with its toes on the floor, near the edge and (as the steering is
        // told) travelling out: the stage turns it, about the planted toe.
        let mut pose = skeleton.rest_pose();
        let mut p = [Vec3::ZERO; JOINT_COUNT];
        skeleton.world_positions(&pose, &mut p);
        let lowest = TOES.iter().map(|t| p[t.index()].y).fold(f32::MAX, f32::min);
        pose.root_position.y -= lowest - 0.01;
        let mut placed = pose;
        stage.place(&mut placed);
        stage.shift += Vec2::new(1.3, 0.0);
        stage.last_hips += Vec2::new(1.3, 0.0);
        // Both toes are down at the same height: the pivot is the first, the left.
        let lower_toe = |q: &Pose, p: &mut [Vec3; JOINT_COUNT]| {
            skeleton.world_positions(q, p);
            p[Joint::LeftToes.index()]
        };
        let mut last_toe: Option<Vec3> = None;
        let mut max_slide = 0.0f32;
        let mut max_hips_move = 0.0f32;
        let mut last_hips: Option<Vec3> = None;
        // Two frames for the stance leg's hold to take the toe after the shift above.
        for _ in 0..2 {
            stage.travel = Vec2::new(0.5, 0.0);
            let mut placed = pose;
            stage.place(&mut placed);
        }
        let turn_before = stage.turn;
        // Less than a second: the glide back from the edge is held by the stance leg up to
        // a stride (foot_lock::MAX_HOLD_M); beyond that the toe would slide.
        for _ in 0..15 {
            stage.travel = Vec2::new(0.5, 0.0);
            let mut placed = pose;
            stage.place(&mut placed);
            let toe = lower_toe(&placed, &mut p);
            if let Some(last) = last_toe {
                max_slide = max_slide.max((toe - last).with_y(0.0).length());
            }
            if let Some(last) = last_hips {
                max_hips_move = max_hips_move.max((placed.root_position - last).length());
            }
            last_toe = Some(toe);
            last_hips = Some(placed.root_position);
        }
        let turned_deg = wrap(stage.turn - turn_before).abs().to_degrees();
        assert!(turned_deg > 10.0, "turned {turned_deg}°");
        assert!(max_slide < 1e-3, "the planted toe slid {max_slide} m");
        assert!(max_hips_move > 1e-3, "the hips swing about the toe");
    }

    #[test]
    fn in_place_keeps_the_hips_on_the_spot() {
        let settings = StageSettings {
            mode: StageMode::InPlace,
            ..StageSettings::default()
        };
        let mut staged =
            StagedSource::new(Walker::new(0.8, 0.0), settings, Skeleton::default_adult());
        let poses = run(&mut staged, 25 * 60);
        // The low-pass lags a steady walk by its time constant: 0.8 m/s × 0.5 s.
        let far = poses[50..]
            .iter()
            .map(|p| distance_from(p, settings.centre))
            .fold(0.0f32, f32::max);
        assert!(far < 0.8 * IN_PLACE_TRAVEL_S + 0.02, "{far}");
        assert_eq!(staged.report().stage.unwrap().clamped, 0);
    }

    #[test]
    fn a_circling_dancer_well_inside_is_only_nudged() {
        // 0.4 m/s on a circle of 0.4 m radius from the centre: it comes no nearer the edge
        // than 0.7 m, and spinning about it holds no facing for the audience turn to correct.
        let mut staged = StagedSource::new(
            Walker::new(0.4, 1.0),
            StageSettings::default(),
            Skeleton::default_adult(),
        );
        let poses = run(&mut staged, 25 * 60);
        let c = staged.report().stage.unwrap();
        assert_eq!(c.clamped, 0);
        // Half the steering's limit at most, against the dance's own 57°/s.
        assert!(
            c.max_turn_deg_per_s < MAX_TURN_DEG_PER_S / 2.0,
            "{}",
            c.max_turn_deg_per_s
        );
        let far = poses
            .iter()
            .map(|p| distance_from(p, [0.0, 0.0]))
            .fold(0.0f32, f32::max);
        assert!(far < 0.85, "{far}");
    }

    #[test]
    fn a_smaller_stage_is_walked_onto_not_jumped_onto() {
        let mut staged = StagedSource::new(
            Walker::new(0.6, 0.0),
            StageSettings {
                mode: StageMode::Free,
                ..StageSettings::default()
            },
            Skeleton::default_adult(),
        );
        let mut poses = run(&mut staged, 25 * 10);
        staged.stage_mut().set_settings(StageSettings {
            centre: [3.0, -2.0],
            radius_m: 1.0,
            ..StageSettings::default()
        });
        poses.extend(run(&mut staged, 25 * 30));
        let largest_step = poses
            .windows(2)
            .map(|w| (ground(w[1].root_position) - ground(w[0].root_position)).length())
            .fold(0.0f32, f32::max);
        // Walked back at RETURN_MPS faster than the walk, with the glide and the pivot's
        // swing: no frame moves the hips 0.15 m (3.75 m/s), against the 5 m a jump would.
        assert!(largest_step < 0.15, "{largest_step}");
        let end = distance_from(poses.last().unwrap(), [3.0, -2.0]);
        assert!(end <= 1.0 + 0.1, "{end}");
    }

    #[test]
    fn a_non_finite_pose_is_left_alone_and_settings_are_made_sane() {
        let mut stage = Stage::new(StageSettings::default(), Skeleton::default_adult(), 25.0);
        let mut bad = Pose::rest();
        bad.root_position.x = f32::NAN;
        stage.place(&mut bad);
        assert!(bad.root_position.x.is_nan());
        assert_eq!(stage.counts().frames, 0);
        let s = StageSettings {
            radius_m: f32::NAN,
            centre: [f32::INFINITY, 1.0],
            facing_deg: f32::NAN,
            mode: StageMode::Bounded,
        }
        .sanitized();
        assert_eq!(s.radius_m, DEFAULT_RADIUS_M);
        assert_eq!(s.centre, [0.0, 1.0]);
        assert_eq!(s.facing_deg, 0.0);
        for m in StageMode::ALL {
            assert_eq!(StageMode::parse(m.name()), Some(m));
        }
        assert_eq!(StageMode::parse("In-Place"), Some(StageMode::InPlace));
        assert_eq!(StageMode::parse("roam"), None);
    }
}
