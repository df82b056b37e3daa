//! Your own moves, on the dance captures in `../shared/data`: every BVH file there imports
//! standing, with its bones pointing where the file's do; CMU's dances without music become a
//! clip library in well under a minute; the library dances on the beat of a song it never heard.

use std::path::{Path, PathBuf};
use std::time::Instant;

use model::metrics::{JointTrack, beat_align};
use model::retrieval::{RETRIEVAL_FPS, RetrievalDancer};
use model::rig::{JOINT_COUNT, Joint, Skeleton};
use model::source::{Controls, MotionSource};
use offline::moves::{ImportSettings, library, read_dance, read_moves_folder};

/// Every BVH file under `dir` (one level of folders).
fn bvh_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let p = entry.path();
        if p.is_dir() {
            out.extend(offline::moves::bvh_files(&p).unwrap_or_default());
        }
    }
    out.sort();
    out
}

#[test]
fn every_dance_file_of_the_shared_data_stands_with_its_bones_where_the_file_has_them() {
    let Some(data) = testkit::require_shared("cmu-dance") else {
        return;
    };
    let skeleton = Skeleton::default_adult();
    let files = bvh_files(&data);
    assert!(files.len() >= 86 + 13, "{} files", files.len());
    let (mut worst_bones, mut worst_lean, mut floor_dances) = (0.0f32, 0.0f32, 0);
    for path in &files {
        let r = read_dance(path, &ImportSettings::default())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(r.axes_detected, "{}", path.display());
        worst_bones = worst_bones.max(r.bone_error_deg);
        assert!(
            r.bone_error_deg < 5.0,
            "{}: bones {:.2}° off",
            path.display(),
            r.bone_error_deg
        );
        // Standing (hips at least 90 % of their rest height): the hips-to-head direction
        // within 35° of up on average (ballet leans up to 25°, a figure lying down or upside
        // down is 90° or 180° off); the lowest joint near the floor when the dancer is lowest
        // (its 10th percentile).
        let mut world = [glam::Vec3::ZERO; JOINT_COUNT];
        let (mut up, mut lows) = (glam::Vec3::ZERO, Vec::new());
        for pose in &r.poses {
            skeleton.world_positions(pose, &mut world);
            let low = world.iter().map(|p| p.y).fold(f32::MAX, f32::min);
            lows.push(low);
            if world[Joint::Hips.index()].y - low > 0.9 * skeleton.hip_height() {
                up += (world[Joint::Head.index()] - world[Joint::Hips.index()]).normalize_or_zero();
            }
        }
        lows.sort_by(f32::total_cmp);
        let standing = lows[lows.len() / 10];
        assert!(
            (0.0..0.05).contains(&standing),
            "{}: lowest joint {standing} m above the floor",
            path.display()
        );
        if up == glam::Vec3::ZERO {
            // A dance on the floor throughout (49_15: never standing): nothing to check.
            floor_dances += 1;
            continue;
        }
        let lean = up.angle_between(glam::Vec3::Y).to_degrees();
        worst_lean = worst_lean.max(lean);
        assert!(
            lean < 35.0,
            "{}: leaning {lean:.0}° standing",
            path.display()
        );
    }
    assert!(floor_dances <= 3, "{floor_dances} dances never standing");
    eprintln!(
        "{} files, worst bone error {worst_bones:.2}°, worst lean standing {worst_lean:.0}°",
        files.len()
    );
}

#[test]
fn a_folder_of_dances_without_music_becomes_a_library_that_dances_on_the_beat() {
    let Some(data) = testkit::require_shared("cmu-dance") else {
        return;
    };
    let started = Instant::now();
    let read = read_moves_folder(&data.join("cmu-dance"), &ImportSettings::default(), 1).unwrap();
    let dances: Vec<_> = read.into_iter().filter_map(|(_, r)| r.ok()).collect();
    let (lib, clips) = library(&dances);
    let seconds = started.elapsed().as_secs_f64();
    // 27 minutes of capture, on one thread: the issue asks for a minute; CI's machine is slower.
    assert!(seconds < 30.0, "{seconds:.1} s");
    assert!(dances.len() >= 80, "{} dances read", dances.len());
    assert!(clips.iter().filter(|&&c| c > 0).count() >= 75, "{clips:?}");
    assert!(lib.clips.len() > 1500, "{} clips", lib.clips.len());

    // Danced to a click at 128 BPM it never heard: its moves land on the beats, not between.
    let tempo = 128.0;
    let frames = (60.0 * RETRIEVAL_FPS) as usize;
    let music: Vec<[f32; dsp::feature::FEATURE_DIM]> = (0..frames)
        .map(|i| {
            let beats = i as f64 / RETRIEVAL_FPS * tempo / 60.0;
            let mut m = [0.0f32; dsp::feature::FEATURE_DIM];
            let (b, bar) = (
                (beats.fract() * std::f64::consts::TAU) as f32,
                ((beats / 4.0).fract() * std::f64::consts::TAU) as f32,
            );
            use dsp::feature::FeatureLayout as L;
            m[L::BEAT_SIN] = b.sin();
            m[L::BEAT_COS] = b.cos();
            m[L::BAR_SIN] = bar.sin();
            m[L::BAR_COS] = bar.cos();
            m[L::TEMPO] = tempo as f32;
            m[L::ENERGY] = -15.0;
            m
        })
        .collect();
    let mut dancer = RetrievalDancer::new(lib, 1).unwrap();
    let mut out = model::rig::Pose::rest();
    let controls = Controls {
        temperature: 0.5,
        ..Controls::default()
    };
    let poses: Vec<_> = music
        .iter()
        .map(|m| {
            dancer.step(std::slice::from_ref(m), &controls, &mut out);
            out
        })
        .collect();
    let positions = Skeleton::default_adult().trajectory(&poses);
    let track = JointTrack::new(&positions, JOINT_COUNT, RETRIEVAL_FPS).unwrap();
    let period = 60.0 / tempo;
    let on: Vec<f64> = (1..)
        .map(|k| k as f64 * period)
        .take_while(|&t| t < 60.0)
        .collect();
    let off: Vec<f64> = on.iter().map(|t| t + period / 2.0).collect();
    let (a, b) = (beat_align(&track, &on), beat_align(&track, &off));
    assert!(
        a - b > 0.15,
        "BeatAlign {a:.3} on the beats, {b:.3} between"
    );
}
