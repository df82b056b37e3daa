//! The dance styles a dancer can be asked for (tang2018's four ballroom styles), the request a
//! performer makes live (one of them, or `auto`), and the rule `auto` follows: the style the
//! music's meter and tempo suggest.

use dsp::feature::FeatureLayout;

/// One of the four ballroom styles the training dances hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DanceStyle {
    /// Cha-cha (4/4, ~120–130 BPM).
    ChaCha,
    /// Rumba (4/4, ~100–110 BPM).
    Rumba,
    /// Tango (4/4, ~120–130 BPM; one training dance).
    Tango,
    /// Waltz (3/4).
    Waltz,
}

/// What a performer asks for: a style, or `auto` (the style the music suggests).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum StyleRequest {
    /// Chosen from the music's meter and tempo ([`StyleFromMusic`]).
    #[default]
    Auto,
    /// This style, whatever the music.
    Style(DanceStyle),
}

impl DanceStyle {
    /// Every style, in index order (the order of tang2018's name letters C, R, T, W).
    pub const ALL: [DanceStyle; 4] = [
        DanceStyle::ChaCha,
        DanceStyle::Rumba,
        DanceStyle::Tango,
        DanceStyle::Waltz,
    ];

    /// Number of styles.
    pub const COUNT: usize = 4;

    /// Position in [`Self::ALL`] (the row of a model's style embedding).
    pub fn index(self) -> usize {
        self as usize
    }

    /// The style at `index` of [`Self::ALL`].
    pub fn from_index(index: usize) -> Option<Self> {
        Self::ALL.get(index).copied()
    }

    /// The name users type and see: `cha-cha`, `rumba`, `tango`, `waltz`.
    pub const fn name(self) -> &'static str {
        match self {
            DanceStyle::ChaCha => "cha-cha",
            DanceStyle::Rumba => "rumba",
            DanceStyle::Tango => "tango",
            DanceStyle::Waltz => "waltz",
        }
    }

    /// A style by name, case-insensitive; `chacha` and `cha_cha` read as `cha-cha`.
    pub fn from_name(name: &str) -> Option<Self> {
        let n: String = name
            .trim()
            .chars()
            .filter(|c| c.is_ascii_alphabetic())
            .map(|c| c.to_ascii_lowercase())
            .collect();
        match n.as_str() {
            "chacha" => Some(DanceStyle::ChaCha),
            "rumba" => Some(DanceStyle::Rumba),
            "tango" => Some(DanceStyle::Tango),
            "waltz" => Some(DanceStyle::Waltz),
            _ => None,
        }
    }

    /// The style of a tang2018 dance by its name (`DANCE_W_3` is a waltz).
    pub fn of_tang_dance(dance: &str) -> Option<Self> {
        match crate::tang2018::style_letter(dance)? {
            'C' => Some(DanceStyle::ChaCha),
            'R' => Some(DanceStyle::Rumba),
            'T' => Some(DanceStyle::Tango),
            'W' => Some(DanceStyle::Waltz),
            _ => None,
        }
    }
}

impl StyleRequest {
    /// `auto` or a style's name (see [`DanceStyle::from_name`]).
    pub fn parse(name: &str) -> Option<Self> {
        if name.trim().eq_ignore_ascii_case("auto") {
            return Some(StyleRequest::Auto);
        }
        DanceStyle::from_name(name).map(StyleRequest::Style)
    }

    /// `auto` or the style's name.
    pub const fn name(self) -> &'static str {
        match self {
            StyleRequest::Auto => "auto",
            StyleRequest::Style(s) => s.name(),
        }
    }
}

/// 4/4 songs slower than this are danced as a rumba, the rest as a cha-cha, BPM: between the
/// training rumbas (~104) and cha-chas (~124).
pub const RUMBA_BELOW_BPM: f32 = 112.0;

/// Time constant of the meter and tempo estimates, frames (4 s at 25 fps).
const SMOOTHING_FRAMES: f32 = 100.0;

/// Largest beat-phase step per frame that counts, radians (a quarter turn).
const MAX_BEAT_TURN: f32 = std::f32::consts::FRAC_PI_2;

/// Frames a new choice must persist before `auto` switches to it (2 s at 25 fps): a fill or a
/// tempo wobble near the boundary does not flip the dance back and forth.
const HOLD_FRAMES: u32 = 50;

/// `auto`'s rule, fed one music frame at a time: 3/4 (the bar phase turning a third of a turn
/// per beat) is a waltz; 4/4 below [`RUMBA_BELOW_BPM`] a rumba, above it a cha-cha. Tango is
/// never chosen (its tempo and meter are a cha-cha's; it stays a request). Allocation-free.
#[derive(Clone, Debug)]
pub struct StyleFromMusic {
    last_beat: Option<f32>,
    last_bar: Option<f32>,
    beat_turn: f32,
    bar_turn: f32,
    tempo: f32,
    chosen: DanceStyle,
    candidate: DanceStyle,
    held: u32,
}

impl Default for StyleFromMusic {
    fn default() -> Self {
        Self::new()
    }
}

fn wrapped(d: f32) -> f32 {
    let tau = std::f32::consts::TAU;
    (d + std::f32::consts::PI).rem_euclid(tau) - std::f32::consts::PI
}

impl StyleFromMusic {
    /// Starts with no music heard: a waltz (the data's most common style) until the music says
    /// otherwise.
    pub fn new() -> Self {
        StyleFromMusic {
            last_beat: None,
            last_bar: None,
            beat_turn: 0.0,
            bar_turn: 0.0,
            tempo: 0.0,
            chosen: DanceStyle::Waltz,
            candidate: DanceStyle::Waltz,
            held: 0,
        }
    }

    /// Forgets the music heard (a new performance).
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Beats per bar the bar phase currently turns at (None before beats are heard).
    pub fn beats_per_bar(&self) -> Option<f32> {
        (self.bar_turn > 1e-3 && self.beat_turn > 1e-3).then(|| self.beat_turn / self.bar_turn)
    }

    /// Reads one music frame (raw features) and returns the style it suggests now.
    pub fn push(&mut self, music: &[f32]) -> DanceStyle {
        let get = |i: usize| music.get(i).copied().filter(|v| v.is_finite());
        let beat = get(FeatureLayout::BEAT_SIN)
            .zip(get(FeatureLayout::BEAT_COS))
            .map(|(s, c)| s.atan2(c));
        let bar = get(FeatureLayout::BAR_SIN)
            .zip(get(FeatureLayout::BAR_COS))
            .map(|(s, c)| s.atan2(c));
        let tempo = get(FeatureLayout::TEMPO).unwrap_or(0.0);
        let k = 1.0 / SMOOTHING_FRAMES;
        if let (Some(b), Some(r), Some(lb), Some(lr)) = (beat, bar, self.last_beat, self.last_bar) {
            let (db, dr) = (wrapped(b - lb), wrapped(r - lr));
            // Only steady forward motion of both phases counts: a phase reset (the tracker
            // re-finding the beat, the bar pointer recounting) is not a bar. A bar holds at
            // least two beats, and no beat is shorter than 4 frames (375 BPM at 25 fps).
            if tempo > 0.0 && db > 0.0 && db < MAX_BEAT_TURN && dr > 0.0 && dr <= 0.5 * db {
                self.beat_turn += k * (db - self.beat_turn);
                self.bar_turn += k * (dr - self.bar_turn);
            }
        }
        self.last_beat = beat;
        self.last_bar = bar;
        if tempo > 0.0 {
            self.tempo = if self.tempo > 0.0 {
                self.tempo + k * (tempo - self.tempo)
            } else {
                tempo
            };
        }
        let suggested = match self.beats_per_bar() {
            Some(n) if n < 3.5 => DanceStyle::Waltz,
            Some(_) if self.tempo < RUMBA_BELOW_BPM => DanceStyle::Rumba,
            Some(_) => DanceStyle::ChaCha,
            None => self.chosen,
        };
        if suggested == self.chosen {
            self.held = 0;
        } else if suggested == self.candidate {
            self.held += 1;
            if self.held >= HOLD_FRAMES {
                self.chosen = suggested;
                self.held = 0;
            }
        } else {
            self.candidate = suggested;
            self.held = 1;
        }
        self.chosen
    }

    /// The style chosen so far.
    pub fn style(&self) -> DanceStyle {
        self.chosen
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dsp::feature::FEATURE_DIM;

    /// Frames of music at `bpm` with `beats` to the bar, 25 fps.
    fn song(bpm: f32, beats: f32, seconds: f32) -> Vec<[f32; FEATURE_DIM]> {
        let frames = (seconds * 25.0) as usize;
        (0..frames)
            .map(|i| {
                let t = i as f32 / 25.0;
                let beat = std::f32::consts::TAU * (t * bpm / 60.0);
                let bar = beat / beats;
                let mut f = [0.0; FEATURE_DIM];
                f[FeatureLayout::BEAT_SIN] = beat.sin();
                f[FeatureLayout::BEAT_COS] = beat.cos();
                f[FeatureLayout::BAR_SIN] = bar.sin();
                f[FeatureLayout::BAR_COS] = bar.cos();
                f[FeatureLayout::TEMPO] = bpm;
                f
            })
            .collect()
    }

    fn style_after(frames: &[[f32; FEATURE_DIM]]) -> DanceStyle {
        let mut s = StyleFromMusic::new();
        frames.iter().map(|f| s.push(f)).last().unwrap()
    }

    #[test]
    fn auto_names_waltz_rumba_and_cha_cha_from_meter_and_tempo() {
        assert_eq!(style_after(&song(87.0, 3.0, 20.0)), DanceStyle::Waltz);
        assert_eq!(style_after(&song(174.0, 3.0, 20.0)), DanceStyle::Waltz);
        assert_eq!(style_after(&song(104.0, 4.0, 20.0)), DanceStyle::Rumba);
        assert_eq!(style_after(&song(124.0, 4.0, 20.0)), DanceStyle::ChaCha);
        let mut s = StyleFromMusic::new();
        for f in song(124.0, 4.0, 20.0) {
            s.push(&f);
        }
        let n = s.beats_per_bar().unwrap();
        assert!((n - 4.0).abs() < 0.1, "{n} beats per bar");
    }

    #[test]
    fn auto_holds_its_choice_through_a_short_change_and_follows_a_long_one() {
        let mut frames = song(124.0, 4.0, 20.0);
        // One second of 3/4 (a fill, a wrong bar) does not make it a waltz ...
        let mut s = StyleFromMusic::new();
        frames.extend(song(124.0, 3.0, 1.0));
        frames.extend(song(124.0, 4.0, 4.0));
        let chosen: Vec<DanceStyle> = frames.iter().map(|f| s.push(f)).collect();
        assert!(chosen[500..].iter().all(|c| *c == DanceStyle::ChaCha));
        // ... but a waltz that goes on is one within 10 s.
        frames.extend(song(87.0, 3.0, 10.0));
        assert_eq!(style_after(&frames), DanceStyle::Waltz);
    }

    #[test]
    fn silence_and_garbage_keep_the_choice() {
        let mut s = StyleFromMusic::new();
        for f in song(124.0, 4.0, 20.0) {
            s.push(&f);
        }
        let mut bad = [f32::NAN; FEATURE_DIM];
        bad[FeatureLayout::TEMPO] = 0.0;
        for _ in 0..500 {
            assert_eq!(s.push(&bad), DanceStyle::ChaCha);
            assert_eq!(s.push(&[0.0; FEATURE_DIM]), DanceStyle::ChaCha);
        }
    }

    #[test]
    fn names_round_trip_and_tang_letters_map() {
        for s in DanceStyle::ALL {
            assert_eq!(DanceStyle::from_name(s.name()), Some(s));
            assert_eq!(DanceStyle::from_index(s.index()), Some(s));
            assert_eq!(StyleRequest::parse(s.name()), Some(StyleRequest::Style(s)));
        }
        assert_eq!(DanceStyle::from_name("ChaCha"), Some(DanceStyle::ChaCha));
        assert_eq!(StyleRequest::parse(" AUTO "), Some(StyleRequest::Auto));
        assert_eq!(StyleRequest::parse("polka"), None);
        assert_eq!(
            DanceStyle::of_tang_dance("DANCE_W_3"),
            Some(DanceStyle::Waltz)
        );
        assert_eq!(
            DanceStyle::of_tang_dance("DANCE_C_2"),
            Some(DanceStyle::ChaCha)
        );
    }
}
