//! `--plot`: one PNG with what a user checks at a glance — onset strength and the learned beat
//! activation with onsets and beats, how late each beat was decided, tempo, and the bar: phase, each
//! beat's count and meter, and the bar tracker's confidence.

use std::path::Path;

use plotters::prelude::*;

use offline::analysis::FileAnalysis;

/// Why a plot could not be drawn.
#[derive(Debug, thiserror::Error)]
#[error("cannot draw plot {path}: {reason}")]
pub struct PlotError {
    path: String,
    reason: String,
}

/// Draws `analysis` (which must have been run with `keep_hops`) into a PNG at `path`.
pub fn plot_analysis(analysis: &FileAnalysis, title: &str, path: &Path) -> Result<(), PlotError> {
    draw(analysis, title, path).map_err(|e| PlotError {
        path: path.display().to_string(),
        reason: e.to_string(),
    })
}

fn draw(a: &FileAnalysis, title: &str, path: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, (1600, 1000)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, ("sans-serif", 22))?;
    let panels = root.split_evenly((4, 1));
    let t_end = a.duration_s.max(1.0);
    let beat_color = RGBColor(0, 140, 60);

    // Onset strength, onsets, beats.
    let max_s = a
        .hops
        .iter()
        .map(|h| h.onset_strength)
        .fold(1e-3f32, f32::max) as f64;
    let mut c = ChartBuilder::on(&panels[0])
        .margin(8)
        .x_label_area_size(24)
        .y_label_area_size(60)
        .caption(
            "onset strength (blue) · beat activation, 0–1 to full height (orange) · onsets (red) · beats (green)",
            ("sans-serif", 16),
        )
        .build_cartesian_2d(0.0..t_end, 0.0..max_s * 1.05)?;
    c.configure_mesh().disable_mesh().draw()?;
    for b in &a.beats {
        c.draw_series(LineSeries::new(
            [(b.time_s, 0.0), (b.time_s, max_s)],
            beat_color.stroke_width(1),
        ))?;
    }
    c.draw_series(LineSeries::new(
        a.hops.iter().map(|h| (h.time_s, h.onset_strength as f64)),
        &BLUE,
    ))?;
    c.draw_series(LineSeries::new(
        a.hops
            .iter()
            .map(|h| (h.time_s, h.beat_activation as f64 * max_s)),
        RGBColor(240, 140, 0).stroke_width(1),
    ))?;
    c.draw_series(
        a.onsets
            .iter()
            .map(|o| Circle::new((o.time_s, o.strength as f64), 3, RED.filled())),
    )?;

    // Decision lag of each beat.
    let mut c = ChartBuilder::on(&panels[1])
        .margin(8)
        .x_label_area_size(24)
        .y_label_area_size(60)
        .caption(
            "beat decided after it happened (ms); dashed: 50 ms",
            ("sans-serif", 16),
        )
        .build_cartesian_2d(0.0..t_end, -50.0..150.0)?;
    c.configure_mesh().disable_mesh().draw()?;
    c.draw_series(DashedLineSeries::new(
        [(0.0, 50.0), (t_end, 50.0)],
        6,
        4,
        BLACK.stroke_width(1),
    ))?;
    c.draw_series(a.beats.iter().map(|b| {
        Circle::new(
            (
                b.time_s,
                ((b.decided_at_s - b.time_s) * 1000.0).clamp(-50.0, 150.0),
            ),
            3,
            beat_color.filled(),
        )
    }))?;

    // Tempo.
    let max_t = a.hops.iter().map(|h| h.tempo_bpm).fold(60.0, f64::max) * 1.1;
    let mut c = ChartBuilder::on(&panels[2])
        .margin(8)
        .x_label_area_size(24)
        .y_label_area_size(60)
        .caption("tempo (BPM)", ("sans-serif", 16))
        .build_cartesian_2d(0.0..t_end, 0.0..max_t)?;
    c.configure_mesh().disable_mesh().draw()?;
    c.draw_series(LineSeries::new(
        a.hops.iter().map(|h| (h.time_s, h.tempo_bpm)),
        &MAGENTA,
    ))?;

    // Bar phase, each beat's count, and how sure the bar tracker is.
    let mut c = ChartBuilder::on(&panels[3])
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .caption(
            "bar: phase (cyan), each beat's count (blue 4/4, orange 3/4; downbeats bold), confidence (grey)",
            ("sans-serif", 16),
        )
        .build_cartesian_2d(0.0..t_end, 0.0..1.15)?;
    c.configure_mesh()
        .disable_mesh()
        .x_desc("time (s)")
        .draw()?;
    c.draw_series(
        a.hops
            .iter()
            .map(|h| Circle::new((h.time_s, h.bar_phase), 1, CYAN.filled())),
    )?;
    c.draw_series(LineSeries::new(
        a.hops
            .iter()
            .map(|h| (h.time_s, f64::from(h.bar_confidence))),
        &RGBColor(150, 150, 150),
    ))?;
    let orange = RGBColor(230, 120, 0);
    c.draw_series(a.beats.iter().map(|b| {
        let colour = if b.beats_per_bar == 3 { orange } else { BLUE };
        let size = if b.beat_in_bar == 1 { 18 } else { 12 };
        Text::new(
            b.beat_in_bar.to_string(),
            (b.time_s, 1.12),
            ("sans-serif", size).into_font().color(&colour),
        )
    }))?;
    c.draw_series(
        a.beats
            .iter()
            .filter(|b| b.beat_in_bar == 1)
            .map(|b| Circle::new((b.time_s, 0.0), 4, BLACK.filled())),
    )?;
    root.present()?;
    Ok(())
}
