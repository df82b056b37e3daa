//! `danced metrics`: dance metrics of any BVH motion against a song's tracked beats.

use std::path::PathBuf;

use anyhow::{Context, Result};
use model::metrics::{ContactParams, FreezeParams, JointTrack};
use model::rig::{JOINT_COUNT, Joint, Skeleton};

use offline::analysis::{AnalyzeOptions, analyze_file};

/// Options of `danced metrics`.
#[derive(clap::Args, Debug)]
pub struct MetricsArgs {
    /// The motion (any BVH rig with recognisable joint names).
    pub bvh: PathBuf,
    /// The song the motion dances to.
    #[arg(long)]
    pub audio: PathBuf,
    /// Song time of the motion's first frame, seconds.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub offset: f64,
    /// How the file's joints and axes are read.
    #[command(flatten)]
    pub import: super::import_args::ImportArgs,
}

/// Runs `danced metrics`.
pub fn metrics(args: &MetricsArgs) -> Result<()> {
    let MetricsArgs {
        bvh: bvh_path,
        audio,
        offset,
        import,
    } = args;
    let offset = *offset;
    let skeleton = Skeleton::default_adult();
    let motion = offline::moves::read_dance(bvh_path, &import.settings()?)?;
    let positions = skeleton.trajectory(&motion.poses);
    let track = JointTrack::new(&positions, JOINT_COUNT, motion.fps)?;
    let opts = AnalyzeOptions::native(None);
    let a = analyze_file(audio, opts, &mut |_, _| {})
        .with_context(|| format!("analysing {}", audio.display()))?;
    let beats: Vec<f64> = a
        .beats
        .iter()
        .map(|b| b.time_s - offset)
        .filter(|t| *t >= 0.0)
        .collect();
    println!(
        "motion      {} ({} frames at {:.2} fps, {:.1} s)",
        bvh_path.display(),
        track.frames(),
        track.fps(),
        track.duration_s()
    );
    println!(
        "music       {} ({} beats in the motion's span, {:.1} BPM)",
        audio.display(),
        beats.iter().filter(|t| **t <= track.duration_s()).count(),
        a.median_tempo()
    );
    println!(
        "BeatAlign   {:.3}",
        model::metrics::beat_align(&track, &beats)
    );
    match model::metrics::beat_offset(&track, Joint::Hips.index(), &beats) {
        Ok(o) => println!("beat offset {:.3} ± {:.3} s", o.mean_s, o.sd_s),
        Err(e) => println!("beat offset – ({e})"),
    }
    let kinetic = model::metrics::kinetic_features(&track)?;
    let energy: f64 = kinetic.iter().sum::<f64>() / kinetic.len().max(1) as f64;
    println!(
        "kinetic     mean feature {energy:.4} over {} values",
        kinetic.len()
    );
    let f = model::metrics::detect_freezes(&track, FreezeParams::default())?;
    println!(
        "freezes     {} ({:.1} s frozen of {:.1} s)",
        f.freezes, f.frozen_s, f.analysed_s
    );
    let toes = [Joint::LeftToes.index(), Joint::RightToes.index()];
    let ground_y_m = model::metrics::toe_floor_y(&track, &toes)?;
    let s = model::metrics::foot_skating(
        &track,
        &toes,
        ContactParams {
            ground_y_m,
            ..ContactParams::default()
        },
    )?;
    println!(
        "foot skate  {:.3} m/s while in contact ({:.0} % of the time; floor at {ground_y_m:.3} m)",
        s.mean_speed_mps,
        100.0 * s.contact_fraction
    );
    Ok(())
}
