//! How far a dance wanders and how it faces: what a fixed camera, an avatar app or a VR rig
//! sees of the stage ([`Wander::of`]), for `danced bench stage`.

use anyhow::Result;
use glam::{Vec2, Vec3};
use model::metrics::{ContactParams, JointTrack, foot_skating, toe_floor_y};
use model::motion::heading;
use model::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use model::stage::{StageCounts, StageMode, StageSettings};

/// Where the hips may be and still count as inside: the radius and this margin, m.
pub const INSIDE_MARGIN_M: f32 = 0.1;

/// How a dance used the stage.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Wander {
    /// Largest distance of the hips from the stage's centre (free: from where they started), m.
    pub max_distance_m: f32,
    /// Share of frames with the hips within the radius and [`INSIDE_MARGIN_M`].
    pub inside: f64,
    /// Share of frames the hard clamp acted on.
    pub clamped: f64,
    /// Share of frames the steering turned the dance.
    pub steered: f64,
    /// Share of frames the dance was glided back from the edge.
    pub glided: f64,
    /// Largest turn the stage added, degrees per second.
    pub max_turn_deg_per_s: f32,
    /// Foot skating, m/s while a toe is in contact (the eval's measure).
    pub skating_mps: f64,
    /// Share of frames the dancer faces the audience (within ±90°).
    pub facing_audience: f64,
    /// Seconds of motion.
    pub seconds: f64,
}

impl Wander {
    /// Measures `poses` at `fps` danced on `stage`, with the stage's `counts` (`None`: a
    /// capture, no stage).
    pub fn of(
        poses: &[Pose],
        fps: f64,
        stage: &StageSettings,
        counts: Option<StageCounts>,
    ) -> Result<Wander> {
        let Some(first) = poses.first() else {
            return Ok(Wander::default());
        };
        let centre = if stage.mode == StageMode::Free || counts.is_none() {
            Vec2::new(first.root_position.x, first.root_position.z)
        } else {
            Vec2::from(stage.centre)
        };
        let audience = stage.facing_deg.to_radians();
        let (mut max_distance_m, mut inside, mut facing) = (0.0f32, 0usize, 0usize);
        for p in poses {
            let d = (Vec2::new(p.root_position.x, p.root_position.z) - centre).length();
            max_distance_m = max_distance_m.max(d);
            inside += usize::from(d <= stage.radius_m + INSIDE_MARGIN_M);
            facing += usize::from((heading(p.local_rotations[0]) - audience).cos() > 0.0);
        }
        let skeleton = Skeleton::default_adult();
        let positions: Vec<Vec3> = skeleton.trajectory(poses);
        let track = JointTrack::new(&positions, JOINT_COUNT, fps)?;
        let toes = [Joint::LeftToes.index(), Joint::RightToes.index()];
        let skating = foot_skating(
            &track,
            &toes,
            ContactParams {
                ground_y_m: toe_floor_y(&track, &toes)?,
                ..ContactParams::default()
            },
        )?;
        let n = poses.len() as f64;
        let c = counts.unwrap_or_default();
        let share = |k: u64| k as f64 / (c.frames.max(1)) as f64;
        Ok(Wander {
            max_distance_m,
            inside: inside as f64 / n,
            clamped: share(c.clamped),
            steered: share(c.steered),
            glided: share(c.glided),
            max_turn_deg_per_s: c.max_turn_deg_per_s,
            skating_mps: skating.mean_speed_mps,
            facing_audience: facing as f64 / n,
            seconds: n / fps,
        })
    }
}

/// One row of the wander table.
#[derive(Clone, Debug, PartialEq)]
pub struct WanderRow {
    /// The song.
    pub song: String,
    /// The dancer.
    pub dancer: String,
    /// The stage mode (or "captured").
    pub mode: String,
    /// What was measured.
    pub wander: Wander,
}

/// The rows as a Markdown table.
pub fn wander_table(rows: &[WanderRow], radius_m: f32) -> String {
    let mut t = format!(
        "| song | dancer | stage | largest distance (m) | inside {:.1} m | clamped | steered | glided | added turn, max (°/s) | skating (m/s) | facing the audience |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
        radius_m + INSIDE_MARGIN_M
    );
    for r in rows {
        let w = &r.wander;
        t += &format!(
            "| {} | {} | {} | {:.2} | {:.1} % | {:.2} % | {:.1} % | {:.1} % | {:.0} | {:.3} | {:.0} % |\n",
            r.song,
            r.dancer,
            r.mode,
            w.max_distance_m,
            100.0 * w.inside,
            100.0 * w.clamped,
            100.0 * w.steered,
            100.0 * w.glided,
            w.max_turn_deg_per_s,
            w.skating_mps,
            100.0 * w.facing_audience
        );
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use model::motion::yaw;

    #[test]
    fn a_walk_out_of_the_stage_is_measured_from_its_start_when_free() {
        let skeleton = Skeleton::default_adult();
        // 4 s walking along +x at 0.5 m/s, facing +x (sideways to the audience at +z).
        let poses: Vec<Pose> = (0..100)
            .map(|f| {
                let mut p = skeleton.rest_pose();
                p.root_position.x = 2.0 + 0.02 * f as f32;
                p.local_rotations[0] = yaw(if f < 25 { 0.0 } else { 1.6 });
                p
            })
            .collect();
        let free = StageSettings {
            mode: StageMode::Free,
            ..StageSettings::default()
        };
        let w = Wander::of(&poses, 25.0, &free, None).unwrap();
        assert!(
            (w.max_distance_m - 1.98).abs() < 1e-4,
            "{}",
            w.max_distance_m
        );
        // Inside 1.6 m of the start for its first 1.6 / 0.02 + 1 frames.
        assert!((w.inside - 0.81).abs() < 1e-9, "{}", w.inside);
        assert!((w.facing_audience - 0.25).abs() < 1e-9);
        assert!(
            w.skating_mps > 0.4,
            "the toes slide with the body: {}",
            w.skating_mps
        );
        assert_eq!(w.seconds, 4.0);
    }
}
