//! The interface every motion generator behind the daemon implements: retrieval today, the
//! neural model later.
//!
//! The trait is shaped by the live setting. Music arrives one feature frame at a time and the
//! character must move *now*, so generation is per-frame and causal: [`MotionSource::step`]
//! sees the current music frame plus a fixed, declared look-ahead ([`MotionSource::lookahead_frames`],
//! which the caller pays for as latency) and never the rest of the song. The performer's
//! controls ([`Controls`]: temperature, an optional key pose to hit) are passed with every
//! frame, because they change live and a source must react on the next frame without being
//! rebuilt. A source is built once (loading clips or weights is the slow, allocating part) and
//! `step` then writes into a caller-owned [`Pose`] without allocating, so it can run on a
//! real-time thread. [`MotionSource::reset`] starts a new performance with a seed, which makes
//! any randomness reproducible.

use dsp::feature::FEATURE_DIM;
use glam::Quat;

use crate::rig::{JOINT_COUNT, Pose};
use crate::style::StyleRequest;

/// A pose the performer asks the dancer to reach at a given moment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeyPoseTarget {
    /// Target local rotation of every joint (the hips' heading is taken relative to the dancer's own; root translation is ignored).
    pub rotations: [Quat; JOINT_COUNT],
    /// Frames left until the pose must be reached (0 = this frame).
    pub frames_to_go: u32,
}

/// Where the neural dancer sends a key pose while its end blend is on. With the blend off (or
/// its frames 0) the key always goes to the network: nothing else would bring it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeyPoseRoute {
    /// The network reads the key and the blend's pose is fed back to it, so it sees itself
    /// arrive and dances on from the key pose.
    Network,
    /// The network dances on without the key; only the pose shown is blended onto the key and,
    /// after the deadline, glides back onto the network's dance. The shipped route: the
    /// shipped network's own approach to a key is far less like dancing (`danced eval`'s
    /// transition table).
    Overlay,
}

impl KeyPoseRoute {
    /// Every route, in the order `/keypose/route N` numbers them.
    pub const ALL: [KeyPoseRoute; 2] = [KeyPoseRoute::Overlay, KeyPoseRoute::Network];

    /// Its index in [`Self::ALL`].
    pub fn index(self) -> usize {
        match self {
            KeyPoseRoute::Overlay => 0,
            KeyPoseRoute::Network => 1,
        }
    }

    /// The route at `index` of [`Self::ALL`].
    pub fn from_index(index: usize) -> Option<Self> {
        Self::ALL.get(index).copied()
    }

    /// The route named `s` (`overlay` or `network`, case-insensitive).
    pub fn parse(s: &str) -> Option<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "overlay" => Some(KeyPoseRoute::Overlay),
            "network" => Some(KeyPoseRoute::Network),
            _ => None,
        }
    }

    /// The name [`KeyPoseRoute::parse`] reads.
    pub fn name(self) -> &'static str {
        match self {
            KeyPoseRoute::Overlay => "overlay",
            KeyPoseRoute::Network => "network",
        }
    }
}

/// Live controls passed with every frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Controls {
    /// Randomness of the choices: 0 = always the most likely motion, higher = more varied.
    pub temperature: f32,
    /// A key pose to reach, if any.
    pub key_pose: Option<KeyPoseTarget>,
    /// Depth of the beat accent, overriding the source's own (None keeps it; sources that
    /// time their motion otherwise ignore it).
    pub beat_accent: Option<f32>,
    /// The style to dance (sources without a style input ignore it).
    pub style: StyleRequest,
    /// Where key poses go, overriding the source's own route (None keeps it; sources without
    /// a route ignore it). A change takes effect once no key pose is pending or being let go.
    pub key_route: Option<KeyPoseRoute>,
}

impl Default for Controls {
    /// Deterministic choices, no key pose, the style the music suggests.
    fn default() -> Self {
        Controls {
            temperature: 0.0,
            key_pose: None,
            beat_accent: None,
            style: StyleRequest::Auto,
            key_route: None,
        }
    }
}

/// The live controls a source honours beyond those every source takes (temperature, key
/// poses, seed, pause): the daemon refuses the others, counted, rather than pass on what
/// would change nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct SourceControls {
    /// [`Controls::style`]: a network with a style input.
    pub style: bool,
    /// [`Controls::key_route`]: a source that can hand key poses to its network.
    pub key_route: bool,
    /// [`Controls::beat_accent`]: a source that retimes its own motion within the beat.
    pub beat_accent: bool,
    /// [`MotionSource::select_moves`]: a source holding several sets of moves.
    pub moves: bool,
}

impl SourceControls {
    /// Every control honoured.
    pub const ALL: SourceControls = SourceControls {
        style: true,
        key_route: true,
        beat_accent: true,
        moves: true,
    };
}

/// When a switch of moves takes effect.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MovesSwitch {
    /// At the next beat.
    NextBeat,
    /// At the next bar's first beat.
    NextBar,
}

/// Which set of moves a source dances, of how many.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MovesReport {
    /// The set danced (index in the order the source was given them).
    pub active: usize,
    /// Sets it holds.
    pub count: usize,
    /// A switch asked for and not yet made: the set it will go to.
    pub pending: Option<usize>,
    /// Switches made since the last reset.
    pub switches: u64,
}

/// What a source reports of its last frame, for the stats, the status line and the view.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SourceReport {
    /// The style danced (`None`: the source has no style input).
    pub style: Option<crate::style::DanceStyle>,
    /// Where key poses went (`None`: the source has no route to choose).
    pub key_route: Option<KeyPoseRoute>,
    /// How often each of its safety nets acted since the last reset (`None`: it has none).
    pub safety: Option<crate::neural::safety::SafetyCounts>,
    /// What the stage did since the last reset (`None`: not on a stage).
    pub stage: Option<crate::stage::StageCounts>,
    /// Which of its sets of moves it dances (`None`: it has one).
    pub moves: Option<MovesReport>,
}

/// Where the stage would have the dancer travel, in the source's own floor frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TravelPreference {
    /// Unit direction on the floor (x, z) the dance should rather go.
    pub direction: [f32; 2],
    /// How much it matters, 0–1 (1: at the edge of the stage).
    pub strength: f32,
}

/// A streaming, causal motion generator driven by music feature frames.
pub trait MotionSource {
    /// Output frames per second; `step` must be called once per frame at this rate.
    fn frame_rate(&self) -> f64;

    /// Music frames needed beyond the current one in every `step` call.
    fn lookahead_frames(&self) -> usize;

    /// Frames ahead of the analysis its music was predicted by in training
    /// (`dsp::predicted_stream`): live, the pipeline predicts at least this far, so the source
    /// hears what it learned on. 0 = no preference.
    fn horizon_frames(&self) -> usize {
        0
    }

    /// Produces the next pose from the current music frame (`music[0]`), its look-ahead
    /// (`music[1..]`) and the live controls; never allocates.
    fn step(&mut self, music: &[[f32; FEATURE_DIM]], controls: &Controls, out: &mut Pose);

    /// Starts a new performance from scratch, seeding any randomness with `seed`.
    fn reset(&mut self, seed: u64);

    /// The controls it honours beyond those every source takes.
    fn controls(&self) -> SourceControls {
        SourceControls::default()
    }

    /// What it did at the last frame.
    fn report(&self) -> SourceReport {
        SourceReport::default()
    }

    /// Changes the style seed mid-performance: the randomness restarts from `seed` while the
    /// dance goes on from where the dancer stands (no restart, no jump); never allocates and
    /// costs no more than a step, so it can run on the real-time thread between two steps.
    fn reseed(&mut self, seed: u64);

    /// Hears where the stage would have the dance travel from now on (`None`: anywhere). A
    /// source that chooses its steps may prefer those going that way; the others ignore it.
    fn prefer_travel(&mut self, _preference: Option<TravelPreference>) {}

    /// Switches to its set of moves `index` at `at`, gliding from the move it is in; false
    /// (and nothing changes) if it has no such set. Never allocates.
    fn select_moves(&mut self, _index: usize, _at: MovesSwitch) -> bool {
        false
    }
}

/// A source that stands still in the rest pose at 25 frames a second: for measuring what is
/// not the dance (the beats, the clocks) through the live pipeline.
#[derive(Clone, Copy, Debug, Default)]
pub struct Standing;

impl MotionSource for Standing {
    fn frame_rate(&self) -> f64 {
        25.0
    }

    fn lookahead_frames(&self) -> usize {
        0
    }

    fn step(&mut self, _music: &[[f32; FEATURE_DIM]], _controls: &Controls, out: &mut Pose) {
        *out = Pose::rest();
    }

    fn reset(&mut self, _seed: u64) {}

    fn reseed(&mut self, _seed: u64) {}
}

/// A boxed source is a source (so a stage can hold whichever the daemon opened).
impl<S: MotionSource + ?Sized> MotionSource for Box<S> {
    fn frame_rate(&self) -> f64 {
        (**self).frame_rate()
    }

    fn lookahead_frames(&self) -> usize {
        (**self).lookahead_frames()
    }

    fn horizon_frames(&self) -> usize {
        (**self).horizon_frames()
    }

    fn step(&mut self, music: &[[f32; FEATURE_DIM]], controls: &Controls, out: &mut Pose) {
        (**self).step(music, controls, out)
    }

    fn reset(&mut self, seed: u64) {
        (**self).reset(seed)
    }

    fn controls(&self) -> SourceControls {
        (**self).controls()
    }

    fn report(&self) -> SourceReport {
        (**self).report()
    }

    fn reseed(&mut self, seed: u64) {
        (**self).reseed(seed)
    }

    fn prefer_travel(&mut self, preference: Option<TravelPreference>) {
        (**self).prefer_travel(preference)
    }

    fn select_moves(&mut self, index: usize, at: MovesSwitch) -> bool {
        (**self).select_moves(index, at)
    }
}

/// `x` clamped to `lo..=hi`; a non-finite `x` (a NaN from a controller, say) reads as 0.
pub(crate) fn finite_clamp(x: f32, lo: f32, hi: f32) -> f32 {
    if x.is_finite() { x.clamp(lo, hi) } else { 0.0 }
}
