//! Artefact detectors of our own: frozen stretches and foot skating.

use super::JointTrack;
use crate::ModelError;

/// How [`detect_freezes`] decides that the dancer has stopped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FreezeParams {
    /// Length of the analysis windows in seconds (default 1 s).
    ///
    /// One second spans two beats at 120 BPM: a held pose on one beat is choreography, a whole
    /// second without motion is not, and FACT's "freezes after several seconds" failure lasts
    /// far longer.
    pub window_s: f64,
    /// A window whose mean joint speed is below this is frozen, in m/s (default 0.05 m/s).
    ///
    /// Mean over all joints and frames of the window. Dancing moves the average joint at roughly
    /// 0.5–1.5 m/s, while standing still with breathing and balance sway stays near 0.01–0.03
    /// m/s; 0.05 m/s (5 cm per second) separates the two with margin both ways.
    pub speed_floor_mps: f64,
}

impl Default for FreezeParams {
    fn default() -> Self {
        Self {
            window_s: 1.0,
            speed_floor_mps: 0.05,
        }
    }
}

/// What [`detect_freezes`] found.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FreezeReport {
    /// Number of freezes: runs of consecutive frozen windows, each counted once.
    pub freezes: usize,
    /// Total frozen time in seconds.
    pub frozen_s: f64,
    /// Number of frozen windows.
    pub frozen_windows: usize,
    /// Number of windows analysed.
    pub windows: usize,
    /// Time analysed in seconds (the track's duration).
    pub analysed_s: f64,
}

/// Finds stretches where the whole body nearly stops moving.
///
/// The track's frame-to-frame intervals are tiled into windows of as near `window_s` as divides
/// the track evenly (so there is no short, noisy remainder window); a window is frozen when the
/// mean joint speed over its intervals is below `speed_floor_mps`. A motionless track is one
/// freeze as long as the track. Tracks under two frames report nothing.
pub fn detect_freezes(
    track: &JointTrack<'_>,
    params: FreezeParams,
) -> Result<FreezeReport, ModelError> {
    if !(params.window_s.is_finite() && params.window_s > 0.0) {
        return Err(ModelError::BadParameter {
            name: "window_s",
            value: params.window_s,
        });
    }
    if !(params.speed_floor_mps.is_finite() && params.speed_floor_mps >= 0.0) {
        return Err(ModelError::BadParameter {
            name: "speed_floor_mps",
            value: params.speed_floor_mps,
        });
    }
    let n = track.frames();
    if n < 2 {
        return Ok(FreezeReport::default());
    }
    let fps = track.fps();
    let joints = track.joints();
    let intervals = n - 1;
    let speed: Vec<f64> = (0..intervals)
        .map(|i| {
            (0..joints)
                .map(|j| (track.pos(i + 1, j) - track.pos(i, j)).length())
                .sum::<f64>()
                * fps
                / joints as f64
        })
        .collect();
    let per_window = ((params.window_s * fps).round() as usize).max(1);
    let windows = ((intervals as f64 / per_window as f64).round() as usize).clamp(1, intervals);
    let bound = |w: usize| (2 * w * intervals + windows) / (2 * windows);
    let mut report = FreezeReport {
        windows,
        analysed_s: intervals as f64 / fps,
        ..FreezeReport::default()
    };
    let mut in_freeze = false;
    for w in 0..windows {
        let (a, b) = (bound(w), bound(w + 1));
        let mean = speed[a..b].iter().sum::<f64>() / (b - a) as f64;
        let frozen = mean < params.speed_floor_mps;
        if frozen {
            report.frozen_windows += 1;
            report.frozen_s += (b - a) as f64 / fps;
            if !in_freeze {
                report.freezes += 1;
            }
        }
        in_freeze = frozen;
    }
    Ok(report)
}

/// Where the floor is for [`foot_skating`] when a capture does not say: the 5th percentile of
/// the toes' heights over the whole track (captures put the floor anywhere; a few frames of
/// noise below it must not count), in metres; 0 for an empty track.
pub fn toe_floor_y(track: &JointTrack<'_>, toe_joints: &[usize]) -> Result<f64, ModelError> {
    for &toe in toe_joints {
        track.check_joint(toe)?;
    }
    let mut heights: Vec<f64> = (0..track.frames())
        .flat_map(|f| toe_joints.iter().map(move |&t| (f, t)))
        .map(|(f, t)| track.pos(f, t).y)
        .collect();
    heights.sort_by(f64::total_cmp);
    Ok(heights.get(heights.len() / 20).copied().unwrap_or(0.0))
}

/// When [`foot_skating`] considers a toe to be on the ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactParams {
    /// Height of the floor in metres (default 0).
    pub ground_y_m: f64,
    /// A toe joint lower than this above the floor may be in contact, in metres (default 0.05).
    ///
    /// The toe joint sits a couple of centimetres above the sole; 5 cm is the contact height
    /// that common foot-skate metrics (e.g. those of recent motion-diffusion papers) use.
    pub max_height_m: f64,
    /// …and only if it moves vertically slower than this, in m/s (default 0.1).
    ///
    /// A planted toe moves vertically at ~0 m/s, one being lifted or set down at 0.3 m/s or
    /// more; 0.1 m/s keeps touch-down and lift-off frames out of the contact set.
    pub max_vertical_speed_mps: f64,
}

impl Default for ContactParams {
    fn default() -> Self {
        Self {
            ground_y_m: 0.0,
            max_height_m: 0.05,
            max_vertical_speed_mps: 0.1,
        }
    }
}

/// What [`foot_skating`] found.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FootSkating {
    /// Mean horizontal toe speed while in contact, in m/s (0 when never in contact).
    pub mean_speed_mps: f64,
    /// Time in contact summed over the toes, in seconds.
    pub contact_s: f64,
    /// Fraction of toe-intervals in contact, in [0, 1].
    pub contact_fraction: f64,
}

/// Foot skating: how fast toes slide horizontally while they should be planted.
///
/// For every toe and every interval between consecutive frames, the toe is in contact when its
/// mean height over the interval is below `ground_y_m + max_height_m` and its vertical speed is
/// below `max_vertical_speed_mps`; the result averages its horizontal (x–z) speed over all
/// contact intervals of all toes. A planted foot scores 0, as does a lifted one (no contact).
pub fn foot_skating(
    track: &JointTrack<'_>,
    toe_joints: &[usize],
    params: ContactParams,
) -> Result<FootSkating, ModelError> {
    for &toe in toe_joints {
        track.check_joint(toe)?;
    }
    for (name, value) in [
        ("ground_y_m", params.ground_y_m),
        ("max_height_m", params.max_height_m),
        ("max_vertical_speed_mps", params.max_vertical_speed_mps),
    ] {
        if !value.is_finite() {
            return Err(ModelError::BadParameter { name, value });
        }
    }
    let n = track.frames();
    if n < 2 || toe_joints.is_empty() {
        return Ok(FootSkating::default());
    }
    let fps = track.fps();
    let ceiling = params.ground_y_m + params.max_height_m;
    let (mut contacts, mut speed_sum) = (0usize, 0.0);
    for &toe in toe_joints {
        for i in 0..n - 1 {
            let (p0, p1) = (track.pos(i, toe), track.pos(i + 1, toe));
            let height = 0.5 * (p0.y + p1.y);
            let d = p1 - p0;
            if height < ceiling && d.y.abs() * fps < params.max_vertical_speed_mps {
                contacts += 1;
                speed_sum += (d.x * d.x + d.z * d.z).sqrt() * fps;
            }
        }
    }
    let total = toe_joints.len() * (n - 1);
    Ok(FootSkating {
        mean_speed_mps: if contacts > 0 {
            speed_sum / contacts as f64
        } else {
            0.0
        },
        contact_s: contacts as f64 / fps,
        contact_fraction: contacts as f64 / total as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    const FPS: f64 = 60.0;

    /// Two joints; `moving(t)` says whether the body is dancing at time t.
    fn body(seconds: f64, moving: impl Fn(f64) -> bool) -> Vec<Vec3> {
        let frames = (seconds * FPS).round() as usize + 1;
        let mut p = Vec::with_capacity(frames * 2);
        let mut phase = 0.0f64;
        for i in 0..frames {
            let t = i as f64 / FPS;
            if moving(t) {
                phase += 2.0 * std::f64::consts::PI * 2.0 / FPS;
            }
            p.push(Vec3::new(0.0, 1.0 + 0.1 * phase.sin() as f32, 0.0));
            p.push(Vec3::new(0.3 * phase.cos() as f32, 1.4, 0.0));
        }
        p
    }

    #[test]
    fn toe_floor_is_the_fifth_percentile_of_toe_heights() {
        // Joint 0 (a toe) at heights 0.00, 0.01, …, 0.99 m; joint 1 high above, not a toe.
        let p: Vec<Vec3> = (0..100)
            .flat_map(|i| {
                [
                    Vec3::new(0.0, i as f32 * 0.01, 0.0),
                    Vec3::new(0.0, 5.0, 0.0),
                ]
            })
            .collect();
        let track = JointTrack::new(&p, 2, FPS).unwrap();
        assert!((toe_floor_y(&track, &[0]).unwrap() - 0.05).abs() < 1e-6);
        assert!(toe_floor_y(&track, &[2]).is_err());
    }

    #[test]
    fn motionless_track_is_one_long_freeze() {
        let p = vec![Vec3::new(0.0, 1.0, 0.0); 2 * (5 * 60 + 1)];
        let r = detect_freezes(
            &JointTrack::new(&p, 2, FPS).unwrap(),
            FreezeParams::default(),
        )
        .unwrap();
        assert_eq!(r.freezes, 1);
        assert_eq!(r.frozen_windows, r.windows);
        assert_eq!(r.windows, 5);
        assert!((r.frozen_s - 5.0).abs() < 1e-9 && (r.analysed_s - 5.0).abs() < 1e-9);
    }

    #[test]
    fn moving_track_has_no_freeze() {
        let p = body(5.0, |_| true);
        let r = detect_freezes(
            &JointTrack::new(&p, 2, FPS).unwrap(),
            FreezeParams::default(),
        )
        .unwrap();
        assert_eq!((r.freezes, r.frozen_windows, r.frozen_s), (0, 0, 0.0));
    }

    #[test]
    fn separate_stops_are_separate_freezes() {
        // Moves 0–2 s, stops 2–4 s, moves 4–6 s, stops 6–9 s.
        let p = body(9.0, |t| t < 2.0 || (4.0..6.0).contains(&t));
        let r = detect_freezes(
            &JointTrack::new(&p, 2, FPS).unwrap(),
            FreezeParams::default(),
        )
        .unwrap();
        assert_eq!(r.freezes, 2);
        assert_eq!(r.frozen_windows, 5);
        assert!((r.frozen_s - 5.0).abs() < 1e-9, "{r:?}");
    }

    #[test]
    fn freeze_degenerate_inputs() {
        let e = JointTrack::new(&[], 2, FPS).unwrap();
        assert_eq!(
            detect_freezes(&e, FreezeParams::default()).unwrap(),
            FreezeReport::default()
        );
        // Shorter than a window: one window covering the track.
        let p = vec![Vec3::ZERO; 2 * 10];
        let r = detect_freezes(
            &JointTrack::new(&p, 2, FPS).unwrap(),
            FreezeParams::default(),
        )
        .unwrap();
        assert_eq!((r.windows, r.freezes), (1, 1));
        let bad = FreezeParams {
            window_s: 0.0,
            ..FreezeParams::default()
        };
        assert!(detect_freezes(&e, bad).is_err());
        let bad = FreezeParams {
            speed_floor_mps: f64::NAN,
            ..FreezeParams::default()
        };
        assert!(detect_freezes(&e, bad).is_err());
    }

    /// Joint 0 is a hip that bobs, joint 1 the toe following `toe(t)`.
    fn foot(toe: impl Fn(f64) -> Vec3) -> Vec<Vec3> {
        (0..=120)
            .flat_map(|i| {
                let t = i as f64 / FPS;
                [
                    Vec3::new(0.0, 0.9 + 0.05 * (t as f32 * 6.0).sin(), 0.0),
                    toe(t),
                ]
            })
            .collect()
    }

    fn skate(p: &[Vec3]) -> FootSkating {
        foot_skating(
            &JointTrack::new(p, 2, FPS).unwrap(),
            &[1],
            ContactParams::default(),
        )
        .unwrap()
    }

    #[test]
    fn sliding_foot_skates_at_its_speed() {
        let p = foot(|t| Vec3::new(0.4 * t as f32, 0.02, 0.3 * t as f32));
        let s = skate(&p);
        assert!((s.mean_speed_mps - 0.5).abs() < 1e-4, "{s:?}");
        assert!((s.contact_fraction - 1.0).abs() < 1e-12);
        assert!((s.contact_s - 2.0).abs() < 1e-9);
    }

    #[test]
    fn planted_or_lifted_foot_does_not_skate() {
        let planted = skate(&foot(|_| Vec3::new(0.1, 0.02, 0.0)));
        assert_eq!(planted.mean_speed_mps, 0.0);
        assert!((planted.contact_fraction - 1.0).abs() < 1e-12);
        let lifted = skate(&foot(|t| Vec3::new(0.5 * t as f32, 0.3, 0.0)));
        assert_eq!(lifted, FootSkating::default());
        // Stepping down fast through the contact band while sliding is not contact.
        let stepping = skate(&foot(|t| {
            Vec3::new(0.5 * t as f32, 0.04 - 0.5 * t as f32, 0.0)
        }));
        assert_eq!(stepping.contact_fraction, 0.0);
    }

    #[test]
    fn skating_degenerate_inputs() {
        let p = foot(|_| Vec3::ZERO);
        let t = JointTrack::new(&p, 2, FPS).unwrap();
        assert!(foot_skating(&t, &[2], ContactParams::default()).is_err());
        assert_eq!(
            foot_skating(&t, &[], ContactParams::default()).unwrap(),
            FootSkating::default()
        );
        let e = JointTrack::new(&[], 2, FPS).unwrap();
        assert_eq!(
            foot_skating(&e, &[1], ContactParams::default()).unwrap(),
            FootSkating::default()
        );
        let bad = ContactParams {
            max_height_m: f64::INFINITY,
            ..ContactParams::default()
        };
        assert!(foot_skating(&t, &[1], bad).is_err());
    }
}
