//! Click tracks with known times: onset and beat timing, and how soon each is reported.

use dsp::{AnalysisSink, Analyzer, AnalyzerConfig, BeatEvent, BeatTrackerKind, OnsetEvent};

#[derive(Default)]
struct Events {
    onsets: Vec<OnsetEvent>,
    beats: Vec<BeatEvent>,
}

impl AnalysisSink for Events {
    fn onset(&mut self, o: &OnsetEvent) {
        self.onsets.push(*o);
    }
    fn beat(&mut self, b: &BeatEvent) {
        self.beats.push(*b);
    }
}

/// A 5 ms decaying 1.5 kHz blip with a noise attack every beat, starting at `first` seconds.
fn click_track(rate: u32, bpm: f64, first: f64, seconds: f64) -> (Vec<f32>, Vec<f64>) {
    let n = (rate as f64 * seconds) as usize;
    let mut x = vec![0.0f32; n];
    let mut clicks = Vec::new();
    let mut t = first;
    let mut seed = 1u64;
    while t < seconds - 0.1 {
        clicks.push(t);
        let start = (t * rate as f64).round() as usize;
        for k in 0..(0.03 * rate as f64) as usize {
            let tt = k as f64 / rate as f64;
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let noise = ((seed >> 33) as f64 / (1u64 << 31) as f64 - 0.5) * (-tt / 0.002).exp();
            let tone = (std::f64::consts::TAU * 1500.0 * tt).sin() * (-tt / 0.01).exp();
            x[start + k] += (0.5 * tone + 0.8 * noise) as f32;
        }
        t += 60.0 / bpm;
    }
    (x, clicks)
}

fn analyse(rate: u32, x: &[f32]) -> Events {
    let mut a = Analyzer::new(AnalyzerConfig {
        sample_rate: rate,
        channels: 1,
        model_rate: None,
        tracker: BeatTrackerKind::Native,
        beat_params: Default::default(),
        bar_params: Default::default(),
        networks: Default::default(),
    })
    .unwrap();
    let mut ev = Events::default();
    for block in x.chunks(256) {
        a.process(block, &mut ev);
    }
    ev
}

fn nearest(t: f64, refs: &[f64]) -> f64 {
    refs.iter()
        .map(|r| t - r)
        .min_by(|a, b| a.abs().total_cmp(&b.abs()))
        .unwrap()
}

#[test]
fn onsets_on_clicks_are_accurate_and_reported_within_30_ms() {
    for rate in [22_050, 44_100, 48_000] {
        let (x, clicks) = click_track(rate, 120.0, 0.537, 20.0);
        let ev = analyse(rate, &x);
        assert_eq!(
            ev.onsets.len(),
            clicks.len(),
            "{rate} Hz: one onset per click"
        );
        let mut errors: Vec<f64> = ev
            .onsets
            .iter()
            .map(|o| nearest(o.time_s, &clicks))
            .collect();
        let mut lags: Vec<f64> = ev
            .onsets
            .iter()
            .map(|o| o.decided_at_s - o.time_s + nearest(o.time_s, &clicks))
            .collect();
        errors.sort_by(f64::total_cmp);
        lags.sort_by(f64::total_cmp);
        let median_err = errors[errors.len() / 2];
        eprintln!(
            "{rate} Hz: onset error median {:.1} ms, report lag max {:.1} ms",
            median_err * 1e3,
            lags[lags.len() - 1] * 1e3
        );
        assert!(
            median_err.abs() < 0.006,
            "{rate} Hz: onset times are {median_err} s off"
        );
        assert!(errors.iter().all(|e| e.abs() < 0.012));
        assert!(
            lags[lags.len() - 1] <= 0.030,
            "{rate} Hz: an onset was reported {} s after its click",
            lags[lags.len() - 1]
        );
    }
}

#[test]
fn beats_on_a_click_track_land_on_the_clicks_in_time() {
    let rate = 44_100;
    let (x, clicks) = click_track(rate, 128.0, 0.3, 30.0);
    let ev = analyse(rate, &x);
    let late: Vec<&BeatEvent> = ev.beats.iter().filter(|b| b.time_s > 5.0).collect();
    assert!(late.len() >= 50, "only {} beats after 5 s", late.len());
    for b in &late {
        let e = nearest(b.time_s, &clicks);
        let real_lag = b.decided_at_s - (b.time_s - e);
        assert!(
            e.abs() < 0.02,
            "beat at {:.3} is {:.1} ms from a click",
            b.time_s,
            e * 1e3
        );
        assert!(
            real_lag <= 0.05,
            "beat at {:.3} decided {:.1} ms after its click",
            b.time_s,
            real_lag * 1e3
        );
    }
    let tempo = late.last().unwrap().tempo_bpm;
    assert!((tempo - 128.0).abs() < 1.5, "tempo {tempo}");
}
