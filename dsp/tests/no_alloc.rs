//! The per-block path allocates nothing: the workspace's counting global allocator
//! (`counting-alloc`, the one `danced` runs with) watches `Analyzer::process` over minutes of
//! audio at every supported kind of input, counting this thread's allocator calls while the
//! analysis runs.

use counting_alloc::{CountingAllocator, RtThread, count_here};
use dsp::{
    AnalysisSink, Analyzer, AnalyzerConfig, BeatEvent, BeatTrackerKind, FeatureFrame, HopFrame,
    OnsetEvent,
};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

/// A sink that only counts, as a real-time consumer would (copying into preallocated storage).
#[derive(Default)]
struct Tally {
    hops: usize,
    beats: usize,
    onsets: usize,
    frames: usize,
}

impl AnalysisSink for Tally {
    fn hop(&mut self, _: &HopFrame) {
        self.hops += 1;
    }
    fn onset(&mut self, _: &OnsetEvent) {
        self.onsets += 1;
    }
    fn beat(&mut self, _: &BeatEvent) {
        self.beats += 1;
    }
    fn feature(&mut self, _: &FeatureFrame) {
        self.frames += 1;
    }
}

fn count_allocations(
    rate: u32,
    channels: u16,
    block: usize,
    tracker: BeatTrackerKind,
) -> (u64, Tally) {
    let mut analyzer = Analyzer::new(AnalyzerConfig {
        sample_rate: rate,
        channels,
        model_rate: Some(30.0),
        tracker,
        beat_params: Default::default(),
        bar_params: Default::default(),
        networks: Default::default(),
    })
    .unwrap();
    // A drum-like signal so every event path (onsets, beats, bars, frames) is exercised.
    let seconds = 60.0;
    let frames = (rate as f64 * seconds) as usize;
    let beat = (rate as f64 * 0.5) as usize;
    let mut seed = 3u64;
    let signal: Vec<f32> = (0..frames * channels as usize)
        .map(|i| {
            let f = i / channels as usize;
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let noise = (seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5;
            let env = (-((f % beat) as f32) / (0.02 * rate as f32)).exp();
            noise * env + 0.1 * (f as f32 * 0.05).sin()
        })
        .collect();
    let mut tally = Tally::default();
    let ((), allocations) = count_here(RtThread::Analysis, || {
        for chunk in signal.chunks(block * channels as usize) {
            analyzer.process(chunk, &mut tally);
        }
    });
    (allocations, tally)
}

#[test]
fn process_never_allocates() {
    // The counter itself must see an allocation, or a zero below would prove nothing.
    let (probe, allocations) = count_here(RtThread::Analysis, || {
        std::hint::black_box(Box::new([0u8; 64]))
    });
    drop(probe);
    assert_eq!(allocations, 1);

    let mut kinds = vec![BeatTrackerKind::Native];
    if cfg!(feature = "aubio") {
        kinds.push(BeatTrackerKind::Aubio);
    }
    for tracker in kinds {
        for (rate, channels, block) in [
            (22_050, 1, 256),
            (44_100, 2, 64),
            (48_000, 2, 1000),
            (96_000, 6, 4096),
            (32_000, 1, 1),
        ] {
            let (allocs, tally) = count_allocations(rate, channels, block, tracker);
            assert_eq!(
                allocs, 0,
                "{tracker:?} {rate} Hz × {channels} in blocks of {block}: {allocs} allocations"
            );
            assert!(
                tally.hops > 5000 && tally.frames > 1700,
                "{rate} Hz: {} hops {} frames",
                tally.hops,
                tally.frames
            );
            if tracker == BeatTrackerKind::Native {
                assert!(
                    tally.beats > 60 && tally.onsets > 60,
                    "{rate} Hz: {} beats {} onsets",
                    tally.beats,
                    tally.onsets
                );
            }
        }
    }
}
