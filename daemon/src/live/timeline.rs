//! The sender thread's view of the run: the audio clock (when each block of audio entered the
//! ring) and the newest poses with their audio times, filled from the queues the analysis and
//! motion threads write. Owned by the sender alone; every buffer is preallocated.

use model::rig::Pose;

/// A fixed-capacity ring that overwrites its oldest element; allocates only in `new`.
#[derive(Clone, Debug)]
pub struct FixedRing<T: Copy> {
    items: Vec<T>,
    start: usize,
    len: usize,
}

impl<T: Copy + Default> FixedRing<T> {
    /// A ring holding at most `capacity` (≥ 1) elements.
    pub fn new(capacity: usize) -> Self {
        Self {
            items: vec![T::default(); capacity.max(1)],
            start: 0,
            len: 0,
        }
    }

    /// Appends, dropping the oldest element when full.
    pub fn push(&mut self, item: T) {
        let cap = self.items.len();
        if self.len == cap {
            self.items[self.start] = item;
            self.start = (self.start + 1) % cap;
        } else {
            self.items[(self.start + self.len) % cap] = item;
            self.len += 1;
        }
    }

    /// Elements held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the ring is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The `i`-th element, oldest first.
    pub fn get(&self, i: usize) -> Option<&T> {
        (i < self.len).then(|| &self.items[(self.start + i) % self.items.len()])
    }

    /// The newest element.
    pub fn last(&self) -> Option<&T> {
        self.len.checked_sub(1).and_then(|i| self.get(i))
    }

    /// Index of the first element for which `pred` is false, assuming `pred` is true for a
    /// prefix (binary search).
    pub fn partition_point(&self, pred: impl Fn(&T) -> bool) -> usize {
        let (mut lo, mut hi) = (0, self.len);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if self.get(mid).is_some_and(&pred) {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        lo
    }
}

/// Audio up to `audio_end_s` (stream seconds) had entered the ring at `wall_ns`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Anchor {
    /// Stream time of the block's last sample, seconds.
    pub audio_end_s: f64,
    /// Wall time it entered the ring, ns since the pipeline epoch.
    pub wall_ns: u64,
}

/// A model pose with its audio time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TimedPose {
    /// Audio time the pose depicts, stream seconds.
    pub time_s: f64,
    /// The pose.
    pub pose: Pose,
    /// The beat grid its music was predicted with (the sender's beat messages follow it).
    pub grid: dsp::BeatGrid,
}

/// The sender's clock and pose history.
#[derive(Clone, Debug)]
pub struct Timeline {
    /// One anchor per audio block, oldest first (about 12 s at 256-frame blocks).
    pub anchors: FixedRing<Anchor>,
    /// The newest model poses, oldest first.
    pub poses: FixedRing<TimedPose>,
    /// Audio seconds per wall second (1 live; the replay speed otherwise).
    pub speed: f64,
}

impl Timeline {
    /// An empty timeline for audio running `speed` times faster than the wall clock.
    pub fn new(speed: f64) -> Self {
        Self {
            anchors: FixedRing::new(2048),
            poses: FixedRing::new(64),
            speed,
        }
    }

    /// The stream time whose audio entered the ring at `wall_ns`, interpolated linearly between
    /// anchors (smooth, unlike the blocky arrival), extrapolated by at most `max_ahead_s`.
    pub fn audio_time_at(&self, wall_ns: u64, max_ahead_s: f64) -> Option<f64> {
        let first = *self.anchors.get(0)?;
        if wall_ns <= first.wall_ns {
            return Some(first.audio_end_s);
        }
        let i = self.anchors.partition_point(|a| a.wall_ns <= wall_ns);
        let a = *self.anchors.get(i - 1)?;
        match self.anchors.get(i) {
            Some(b) => {
                let span = (b.wall_ns - a.wall_ns) as f64;
                let frac = (wall_ns - a.wall_ns) as f64 / span.max(1.0);
                Some(a.audio_end_s + frac * (b.audio_end_s - a.audio_end_s))
            }
            None => {
                let ahead = (wall_ns - a.wall_ns) as f64 * 1e-9 * self.speed;
                Some(a.audio_end_s + ahead.min(max_ahead_s))
            }
        }
    }

    /// Wall time (ns) at which the sample at `audio_s` entered the ring: the arrival of the
    /// block holding it (extrapolated for audio not yet arrived).
    pub fn ingest_wall_ns(&self, audio_s: f64) -> Option<u64> {
        let i = self.anchors.partition_point(|a| a.audio_end_s < audio_s);
        match self.anchors.get(i) {
            Some(a) => Some(a.wall_ns),
            None => {
                let a = self.anchors.last()?;
                let ahead_ns = (audio_s - a.audio_end_s) / self.speed * 1e9;
                Some(a.wall_ns + ahead_ns.max(0.0) as u64)
            }
        }
    }

    /// The two poses around `t` and the blend weight of the later one; `late` when `t` is past
    /// the newest pose (which is then held). `None` before the first pose.
    pub fn bracket(&self, t: f64) -> Option<(TimedPose, TimedPose, f32, bool)> {
        let newest = *self.poses.last()?;
        if t >= newest.time_s {
            return Some((newest, newest, 1.0, t > newest.time_s));
        }
        let i = self.poses.partition_point(|p| p.time_s <= t);
        if i == 0 {
            let oldest = *self.poses.get(0)?;
            return Some((oldest, oldest, 0.0, false));
        }
        let a = *self.poses.get(i - 1)?;
        let b = *self.poses.get(i)?;
        let w = ((t - a.time_s) / (b.time_s - a.time_s).max(1e-9)).clamp(0.0, 1.0);
        Some((a, b, w as f32, false))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_overwrites_oldest() {
        let mut r = FixedRing::<u32>::new(3);
        for i in 0..5 {
            r.push(i);
        }
        assert_eq!(r.len(), 3);
        assert_eq!((r.get(0), r.last()), (Some(&2), Some(&4)));
        assert_eq!(r.partition_point(|&x| x < 4), 2);
    }

    #[test]
    fn clock_interpolates_and_maps_back() {
        let mut t = Timeline::new(1.0);
        t.anchors.push(Anchor {
            audio_end_s: 1.0,
            wall_ns: 1_000_000_000,
        });
        t.anchors.push(Anchor {
            audio_end_s: 1.1,
            wall_ns: 1_100_000_000,
        });
        let a = t.audio_time_at(1_050_000_000, 0.1).unwrap();
        assert!((a - 1.05).abs() < 1e-9);
        assert_eq!(t.ingest_wall_ns(1.05), Some(1_100_000_000));
        let ahead = t.audio_time_at(2_000_000_000, 0.1).unwrap();
        assert!((ahead - 1.2).abs() < 1e-9);
    }
}
