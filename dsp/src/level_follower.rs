//! How far the music sits below its own recent loudest level, in dB: "quieter than before".
//!
//! The energy feature is absolute (dBFS), so a dancer reading it alone cannot tell a quietly
//! mastered song from a breakdown in a loud one: their levels overlap (tang2018's quietest
//! waltzes sit where the training breakdowns do). A compressor's detector answers the relative
//! question: the level is smoothed over a fraction of a beat, a peak follower holds its loudest
//! and lets go slowly, and the feature is the smoothed level minus that peak. It is 0 dB (or a
//! few dB under, between hits) in steady music, drops by the breakdown's depth when the music
//! falls away and climbs back at the release rate if the music stays down, and is 0 again the
//! frame the music returns. Causal and allocation-free; the first frame heard sets both levels,
//! so a quiet intro reads 0 (nothing louder has been heard yet).

/// Time constant of the level's smoothing, seconds: long enough to ride over the gaps between
/// drum hits, short enough to follow a breakdown within a beat.
pub const SMOOTHING_S: f64 = 0.4;
/// How fast the held peak lets go, dB a second: a breakdown of 9 s at −6 dB still reads −4 dB
/// at its end, and a song that stays 12 dB down reads steady again after 48 s.
pub const RELEASE_DB_PER_S: f64 = 0.25;
/// The feature's floor, dB: silence after loud music is as quiet as it gets.
pub const FLOOR_DB: f32 = -60.0;

/// Streaming follower of the level below the recent peak (see the module's notes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LevelFollower {
    smoothing: f64,
    release_db: f64,
    smoothed_db: f64,
    peak_db: f64,
    started: bool,
}

impl LevelFollower {
    /// A follower fed `rate` levels a second.
    pub fn new(rate: f64) -> Self {
        let rate = if rate.is_finite() && rate > 0.0 {
            rate
        } else {
            1.0
        };
        Self {
            smoothing: 1.0 - (-1.0 / (SMOOTHING_S * rate)).exp(),
            release_db: RELEASE_DB_PER_S / rate,
            smoothed_db: 0.0,
            peak_db: 0.0,
            started: false,
        }
    }

    /// Takes the next level (dB) and returns how far the smoothed level sits below the held
    /// peak, in [`FLOOR_DB`, 0]. A non-finite level is ignored (the last answer is repeated).
    pub fn next(&mut self, level_db: f32) -> f32 {
        if level_db.is_finite() {
            let x = f64::from(level_db);
            if self.started {
                self.smoothed_db += self.smoothing * (x - self.smoothed_db);
            } else {
                self.smoothed_db = x;
                self.peak_db = x;
                self.started = true;
            }
            self.peak_db = (self.peak_db - self.release_db).max(self.smoothed_db);
        }
        ((self.smoothed_db - self.peak_db) as f32).clamp(FLOOR_DB, 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RATE: f64 = 25.0;

    fn run(follower: &mut LevelFollower, level: f32, seconds: f64) -> f32 {
        let mut last = 0.0;
        for _ in 0..(seconds * RATE).round() as usize {
            last = follower.next(level);
        }
        last
    }

    #[test]
    fn steady_music_reads_zero_at_any_level() {
        for level in [-40.0, -20.0, -6.0] {
            let mut f = LevelFollower::new(RATE);
            assert_eq!(run(&mut f, level, 30.0), 0.0, "{level} dB");
        }
    }

    #[test]
    fn a_breakdown_reads_its_depth_then_climbs_back_at_the_release_rate() {
        let mut f = LevelFollower::new(RATE);
        run(&mut f, -14.0, 20.0);
        // A beat (0.5 s) in, most of a 10 dB drop shows.
        let early = run(&mut f, -24.0, 0.5);
        assert!((-10.0..-6.5).contains(&early), "{early}");
        // After 8 s the smoothing has settled and the peak has let go 2 dB.
        let late = run(&mut f, -24.0, 7.5);
        assert!((late - -8.0).abs() < 0.05, "{late}");
        // The music returns: a beat later the follower reads the new loud level as its peak.
        let back = run(&mut f, -14.0, 0.5);
        assert!(back > -2.0, "{back}");
        assert_eq!(run(&mut f, -14.0, 5.0), 0.0);
        // Staying down long enough, the quieter level becomes the new normal.
        let settled = run(&mut f, -26.0, 60.0);
        assert_eq!(settled, 0.0);
    }

    #[test]
    fn a_quiet_start_reads_zero_and_silence_after_music_reads_the_floor() {
        let mut f = LevelFollower::new(RATE);
        assert_eq!(f.next(-45.0), 0.0);
        run(&mut f, -10.0, 5.0);
        assert_eq!(run(&mut f, -120.0, 10.0), FLOOR_DB);
    }

    #[test]
    fn a_non_finite_level_repeats_the_last_answer() {
        let mut f = LevelFollower::new(RATE);
        run(&mut f, -10.0, 5.0);
        let before = run(&mut f, -20.0, 1.0);
        assert_eq!(f.next(f32::NAN), before);
        assert_eq!(f.next(f32::NEG_INFINITY), before);
        assert!(f.next(-20.0) < before);
    }
}
