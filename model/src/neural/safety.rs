//! The neural dancer's safety nets: what is done to the network's samples before they become
//! a pose. Each can be switched off and each counts the frames it acted on, so a report can say
//! what the network did alone and what was done for it.

/// Which nets are on. The non-finite guard (a non-finite or exploding sample is replaced by
/// the last good pose) is not among them: it is always on, so nothing invalid is ever sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SafetyNets {
    /// Samples clamped to the training data's range (widened by `RANGE_MARGIN`).
    pub range_clamp: bool,
    /// Steps over the floor shortened to keep the sustained speed within the limit.
    pub speed_limit: bool,
    /// A restart from the seed clip after a run of held frames.
    pub restart: bool,
    /// The beat accent: the motion retimed within each beat.
    pub beat_accent: bool,
    /// The end blend: rotations pulled onto a key pose in the frames before its deadline (and,
    /// shown over the dance, glided back off it after).
    pub key_blend: bool,
    /// The foot lock: a planted toe's drift taken back.
    pub foot_lock: bool,
}

impl SafetyNets {
    /// Every net on: the shipped setting.
    pub const SHIPPED: SafetyNets = SafetyNets {
        range_clamp: true,
        speed_limit: true,
        restart: true,
        beat_accent: true,
        key_blend: true,
        foot_lock: true,
    };

    /// Every net off: the network alone (behind the non-finite guard).
    pub const NETWORK_ONLY: SafetyNets = SafetyNets {
        range_clamp: false,
        speed_limit: false,
        restart: false,
        beat_accent: false,
        key_blend: false,
        foot_lock: false,
    };
}

impl Default for SafetyNets {
    fn default() -> Self {
        Self::SHIPPED
    }
}

/// Frames each net acted on since the last reset.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct SafetyCounts {
    /// Frames stepped.
    pub frames: u64,
    /// Frames whose sample was non-finite or exploding (the last good pose was held).
    pub held: u64,
    /// Frames with at least one value clamped to the data's range (features the data holds
    /// constant are pinned too but not counted).
    pub range_clamped: u64,
    /// Values clamped (of `frames` × the pose features), constant features not counted.
    pub range_clamped_values: u64,
    /// Frames whose step over the floor was shortened.
    pub speed_limited: u64,
    /// Restarts from the seed clip.
    pub restarts: u64,
    /// Frames retimed by a non-zero beat accent.
    pub accented: u64,
    /// Frames blended towards a key pose or, after it, back off it.
    pub key_blended: u64,
    /// Frames whose root the foot lock moved.
    pub foot_locked: u64,
}

impl SafetyCounts {
    /// One line for a summary: each net's share of the frames.
    pub fn summary(&self) -> String {
        let pct = |n: u64| 100.0 * n as f64 / self.frames.max(1) as f64;
        format!(
            "held {} ({:.1} %), range-clamped {:.1} % ({:.2} % of values), speed-limited {:.1} %, restarts {}, beat-accented {:.1} %, key-blended {:.1} %, foot-locked {:.1} % of {} frames",
            self.held,
            pct(self.held),
            pct(self.range_clamped),
            100.0 * self.range_clamped_values as f64
                / (self.frames.max(1) * crate::motion::MOTION_FEATURE_DIM as u64) as f64,
            pct(self.speed_limited),
            self.restarts,
            pct(self.accented),
            pct(self.key_blended),
            pct(self.foot_locked),
            self.frames
        )
    }
}
