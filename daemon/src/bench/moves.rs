//! How a clip library dances to songs it never heard: beat by tempo band, freezes, foot skating
//! against its source dances', and whether a judge still sees its source's moves in it.

use anyhow::Result;
use glam::Vec3;
use model::metrics::{FreezeParams, JointTrack, beat_align, detect_freezes};
use model::rig::JOINT_COUNT;

use crate::eval::{
    STYLE_WINDOW_S, StyleClassifier, TEMPO_BANDS, foot_skating_mps, half_beat_later, windows_of,
};

/// Frames a second of every track here.
const FPS: f64 = model::retrieval::RETRIEVAL_FPS;

/// Foot skating of a track ([`foot_skating_mps`] of its positions at 25 fps).
pub fn skating(positions: &[Vec3]) -> Result<f64> {
    foot_skating_mps(&JointTrack::new(positions, JOINT_COUNT, FPS)?)
}

/// The judge's class for the library's source dances; classes below it are tang2018's styles.
pub const SOURCE_CLASS: usize = crate::eval::STYLES.len();

/// The judge: nearest centroid on the kinetic features of [`STYLE_WINDOW_S`] windows, fit on
/// tang2018's training dances (one centroid per style, `styles` giving each dance's) and the
/// library's source dances ([`SOURCE_CLASS`]).
pub fn judge(
    tang2018: &[Vec<Vec3>],
    styles: &[Option<usize>],
    source: &[Vec<Vec3>],
) -> Option<StyleClassifier> {
    let frames = (STYLE_WINDOW_S * FPS) as usize;
    let windows: Vec<(usize, Vec<f64>)> = tang2018
        .iter()
        .zip(styles)
        .filter_map(|(p, s)| Some((p, (*s)?)))
        .flat_map(|(p, s)| windows_of(p, frames).into_iter().map(move |w| (s, w)))
        .chain(
            source
                .iter()
                .flat_map(|p| windows_of(p, frames).into_iter().map(|w| (SOURCE_CLASS, w))),
        )
        .collect();
    StyleClassifier::fit(&windows)
}

/// One song danced by one library.
pub struct SongScore {
    /// BeatAlign on the song's beats minus on the beats shifted half a beat.
    pub on_minus_off: f64,
    /// The song's tempo band ([`TEMPO_BANDS`] index), if in one.
    pub band: Option<usize>,
    /// Freezes detected.
    pub freezes: usize,
    /// Foot skating, m/s.
    pub skating: f64,
    /// 10 s windows the judge named tang2018 (any style) and the source.
    pub judged: [usize; 2],
    /// Seconds danced.
    pub seconds: f64,
}

impl SongScore {
    /// Scores `positions` (25 fps) against `beats` of a song at `bpm`.
    pub fn of(
        positions: &[Vec3],
        beats: &[f64],
        bpm: f64,
        judge: Option<&StyleClassifier>,
    ) -> Result<SongScore> {
        let track = JointTrack::new(positions, JOINT_COUNT, FPS)?;
        let off = half_beat_later(beats);
        let mut judged = [0; 2];
        if let Some(judge) = judge {
            for w in windows_of(positions, (STYLE_WINDOW_S * FPS) as usize) {
                if let Some(k) = judge.classify(&w) {
                    judged[usize::from(k == SOURCE_CLASS)] += 1;
                }
            }
        }
        Ok(SongScore {
            on_minus_off: beat_align(&track, beats) - beat_align(&track, &off),
            band: TEMPO_BANDS
                .iter()
                .position(|&(lo, hi)| (lo..hi).contains(&bpm)),
            freezes: detect_freezes(&track, FreezeParams::default())?.freezes,
            skating: skating(positions)?,
            judged,
            seconds: track.duration_s(),
        })
    }
}

/// One library's row of the dancing table.
pub struct MovesRow {
    /// The library.
    pub library: String,
    /// Which judge class is its own (0: tang2018, 1: the source folder).
    pub own_class: usize,
    /// Its songs' scores.
    pub songs: Vec<SongScore>,
    /// Foot skating of the dances it was cut from, m/s.
    pub source_skating: f64,
}

/// The dancing table: BeatAlign on − off by tempo band, freezes, skating against the source
/// dances', and the share of windows the judge names the library's own source.
pub fn moves_table(rows: &[MovesRow]) -> String {
    let mut out = String::from(
        "| library | BeatAlign on − half-beat-shifted, 60–100 / 100–130 / 130–180 BPM (songs) | freezes (minutes danced) | foot skating m/s: dancing / its source dances | judge names its source |\n| --- | --- | --- | --- | --- |\n",
    );
    for row in rows {
        let mut bands = Vec::new();
        for b in 0..TEMPO_BANDS.len() {
            let in_band: Vec<f64> = row
                .songs
                .iter()
                .filter(|s| s.band == Some(b))
                .map(|s| s.on_minus_off)
                .collect();
            bands.push(if in_band.is_empty() {
                "–".to_owned()
            } else {
                format!(
                    "{:+.3} ({})",
                    in_band.iter().sum::<f64>() / in_band.len() as f64,
                    in_band.len()
                )
            });
        }
        let freezes: usize = row.songs.iter().map(|s| s.freezes).sum();
        let minutes: f64 = row.songs.iter().map(|s| s.seconds).sum::<f64>() / 60.0;
        let skating =
            row.songs.iter().map(|s| s.skating).sum::<f64>() / row.songs.len().max(1) as f64;
        let windows: usize = row.songs.iter().map(|s| s.judged[0] + s.judged[1]).sum();
        let own: usize = row.songs.iter().map(|s| s.judged[row.own_class]).sum();
        out.push_str(&format!(
            "| {} | {} | {freezes} ({minutes:.0}) | {skating:.3} / {:.3} | {:.0} % of {windows} |\n",
            row.library,
            bands.join(" / "),
            row.source_skating,
            100.0 * own as f64 / windows.max(1) as f64
        ));
    }
    out
}

/// One live switch of moves, danced.
#[derive(Clone, Copy, Debug)]
pub struct SwitchScore {
    /// Seconds from the song's beat (or bar's first beat) nearest the frame the new moves
    /// started to that frame (negative: ahead of it, as the dancer times its moves ahead of
    /// the heard beat).
    pub landing_s: f64,
    /// Which beat (or bar) after the cue that was: 1 the next, 2 the one after (a cue within
    /// the dancer's anticipation of the next), …
    pub beats_after_cue: usize,
    /// Whether it was cued for the next bar (else the next beat).
    pub on_bar: bool,
    /// Largest root step over the frames around the switch, metres per model frame.
    pub root_step_m: f64,
    /// The same per 60 Hz frame as sent (the sender interpolates between model frames).
    pub root_step_60_m: f64,
    /// Largest joint step there, metres per model frame.
    pub joint_step_m: f64,
}

/// The switch table: how many, when they landed, how far the root and joints moved.
pub fn switch_table(switches: &[SwitchScore], normal: (f64, f64)) -> String {
    let (normal_root, normal_joint) = normal;
    let mut out = String::from(
        "| switches cued on | switches | within 70 ms of a beat (bar) | on the first / second / a later one after the cue | landing: median / largest distance from it | root step at the switch: median / largest, per 25 fps model frame | largest root step per 60 Hz frame sent: at a switch / while dancing | largest joint step per model frame: at a switch / while dancing |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for (label, on_bar) in [("the next bar", true), ("the next beat", false)] {
        let of: Vec<&SwitchScore> = switches.iter().filter(|s| s.on_bar == on_bar).collect();
        if of.is_empty() {
            continue;
        }
        let mut landing: Vec<f64> = of.iter().map(|s| s.landing_s.abs() * 1000.0).collect();
        landing.sort_by(f64::total_cmp);
        let mut steps: Vec<f64> = of.iter().map(|s| s.root_step_m).collect();
        steps.sort_by(f64::total_cmp);
        let joints = of.iter().map(|s| s.joint_step_m).fold(0.0, f64::max);
        let sent = of.iter().map(|s| s.root_step_60_m).fold(0.0, f64::max);
        let within = of.iter().filter(|s| s.landing_s.abs() <= 0.07).count();
        let nth = |n: usize| of.iter().filter(|s| s.beats_after_cue == n).count();
        let later = of.iter().filter(|s| s.beats_after_cue > 2).count();
        out.push_str(&format!(
            "| {label} | {} | {:.0} % | {} / {} / {later} | {:.0} / {:.0} ms | {:.3} / {:.3} m | {sent:.3} / {normal_root:.3} m | {joints:.3} / {normal_joint:.3} m |\n",
            of.len(),
            100.0 * within as f64 / of.len() as f64,
            nth(1),
            nth(2),
            landing[landing.len() / 2],
            landing[landing.len() - 1],
            steps[steps.len() / 2],
            steps[steps.len() - 1],
        ));
    }
    out
}
