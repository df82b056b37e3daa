//! Degenerate inputs never produce NaN/inf, and give no beats invented from nothing.

use dsp::{
    AnalysisSink, Analyzer, AnalyzerConfig, BeatEvent, BeatTrackerKind, FeatureFrame, HopFrame,
    OnsetEvent,
};

#[derive(Default)]
struct Counts {
    hops: usize,
    beats: usize,
    onsets: usize,
    frames: usize,
    non_finite: usize,
}

impl AnalysisSink for Counts {
    fn hop(&mut self, h: &HopFrame) {
        self.hops += 1;
        let scalars = [
            h.time_s,
            h.tempo_bpm,
            h.tempo_confidence,
            h.beat_phase,
            h.bar_phase,
            h.next_beat_s,
        ];
        let floats = [h.energy_db, h.onset_strength, h.bass_onset_strength];
        if scalars.iter().any(|v| !v.is_finite())
            || floats.iter().any(|v| !v.is_finite())
            || h.mel_db
                .iter()
                .chain(h.chroma.iter())
                .any(|v| !v.is_finite())
        {
            self.non_finite += 1;
        }
    }
    fn onset(&mut self, o: &OnsetEvent) {
        // The start of a sound is an onset; only onsets inside the steady signal are invented.
        if o.time_s > 1.0 {
            self.onsets += 1;
        }
    }
    fn beat(&mut self, _: &BeatEvent) {
        self.beats += 1;
    }
    fn feature(&mut self, f: &FeatureFrame) {
        self.frames += 1;
        if f.values.iter().any(|v| !v.is_finite()) {
            self.non_finite += 1;
        }
    }
}

fn run(rate: u32, channels: u16, seconds: f64, mut sample: impl FnMut(usize) -> f32) -> Counts {
    let mut a = Analyzer::new(AnalyzerConfig {
        sample_rate: rate,
        channels,
        model_rate: Some(30.0),
        tracker: BeatTrackerKind::Native,
        beat_params: Default::default(),
        bar_params: Default::default(),
        networks: Default::default(),
    })
    .unwrap();
    let frames = (rate as f64 * seconds) as usize;
    let mut counts = Counts::default();
    let mut block = Vec::with_capacity(512 * channels as usize);
    let mut i = 0;
    while i < frames {
        block.clear();
        for _ in 0..512.min(frames - i) {
            let x = sample(i);
            for _ in 0..channels {
                block.push(x);
            }
            i += 1;
        }
        a.process(&block, &mut counts);
    }
    counts
}

fn lcg(seed: &mut u64) -> f32 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    ((*seed >> 33) as f32 / (1u64 << 30) as f32) - 1.0
}

#[test]
fn silence_dc_clipping_and_noise_stay_finite_and_beatless() {
    let secs = 30.0;
    let mut seed = 7u64;
    let cases: Vec<(&str, Counts)> = vec![
        ("silence", run(44_100, 2, secs, |_| 0.0)),
        ("dc", run(48_000, 1, secs, |_| 0.9)),
        (
            "clipped square",
            run(
                22_050,
                1,
                secs,
                |i| if (i / 50) % 2 == 0 { 1.0 } else { -1.0 },
            ),
        ),
        ("full-scale noise", run(44_100, 1, secs, |_| lcg(&mut seed))),
        (
            "over-range",
            run(44_100, 1, secs, |i| if i % 3 == 0 { 1e30 } else { -1e30 }),
        ),
        ("nan", run(44_100, 1, secs, |_| f32::NAN)),
    ];
    for (name, c) in &cases {
        eprintln!(
            "{name}: hops {} frames {} beats {} onsets {}",
            c.hops, c.frames, c.beats, c.onsets
        );
        assert_eq!(c.non_finite, 0, "{name}: non-finite output");
        assert!(c.hops > 2500, "{name}: only {} hops", c.hops);
        assert!(c.frames >= 890, "{name}: only {} feature frames", c.frames);
        assert!(c.beats <= 3, "{name}: {} beats invented", c.beats);
        assert!(
            c.onsets == 0,
            "{name}: {} onsets invented after the first second",
            c.onsets
        );
    }
}
