//! The clock flags of `danced run` and `danced demo`: where the beat grid comes from and the
//! clocks danced leads.

use crate::live::config::Config;

/// The clock flags (each overrides `[clock]`).
#[derive(clap::Args, Debug, Default)]
pub struct ClockArgs {
    /// Where the beat grid comes from: audio (the beats heard), midi (the clock on --midi),
    /// link (the Link session; with --link) or tap.
    #[arg(long, value_name = "SOURCE")]
    pub clock: Option<String>,
    /// Join an Ableton Link session: followed with `--clock link`, led from the grid followed
    /// otherwise (builds with Link only).
    #[arg(long)]
    pub link: bool,
    /// Send MIDI clock (and Start/Stop) from the grid followed to the output port whose name
    /// contains this.
    #[arg(long, value_name = "PORT")]
    pub midi_clock_out: Option<String>,
    /// Pull an external clock's phase toward the beats heard.
    #[arg(long)]
    pub clock_trim: bool,
    /// Beats per bar of a MIDI clock or tapped beats.
    #[arg(long, value_name = "N")]
    pub beats_per_bar: Option<u32>,
}

impl ClockArgs {
    /// Writes the flags given into `config`.
    pub fn apply(&self, config: &mut Config) {
        if let Some(s) = &self.clock {
            config.clock.source = s.clone();
        }
        config.clock.link |= self.link;
        if self.midi_clock_out.is_some() {
            config.clock.midi_out = self.midi_clock_out.clone();
        }
        config.clock.trim |= self.clock_trim;
        if let Some(b) = self.beats_per_bar {
            config.clock.beats_per_bar = b;
        }
    }
}
