//! The retrieval dancer end to end: the built-in clip library, the streaming analysis of a song,
//! and the motion it produces, scored with the dance metrics against the song's exact beats.

mod common;

use model::metrics::{FreezeParams, JointTrack, detect_freezes};
use model::rig::{JOINT_COUNT, Pose, Skeleton};

/// Dances `seconds` of the demo song with the retrieval dancer at `temperature`; returns the
/// poses (25 fps) and the song's beats.
fn dance_to_demo(seconds: f64, temperature: f32, seed: u64) -> (Vec<Pose>, Vec<f64>) {
    let mut dancer = daemon::dancer::open_source(
        daemon::dancer::SourceKind::Retrieval,
        &daemon::dancer::SourceSettings::default(),
        seed,
    )
    .expect("the built-in library loads");
    common::dance_to_demo(dancer.as_mut(), seconds, temperature, seed)
}

#[test]
fn shipped_library_says_what_it_was_cut_from() {
    let (library, meta) = daemon::dancer::load_library(None).unwrap();
    assert!(library.clips.len() > 3000, "{} clips", library.clips.len());
    assert!(meta.contains("tang2018"), "{meta}");
    assert!(meta.contains("training split"), "{meta}");
    assert!(
        daemon::dancer::SHIPPED_CLIPS.len() < 4_000_000,
        "the shipped library stays a few MB"
    );
}

#[test]
fn damaged_library_file_is_named_in_the_error() {
    let dir = std::env::temp_dir().join(format!("danced-lib-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cut.danclips");
    std::fs::write(
        &path,
        &daemon::dancer::SHIPPED_CLIPS[..daemon::dancer::SHIPPED_CLIPS.len() / 2],
    )
    .unwrap();
    let err = format!(
        "{:#}",
        daemon::dancer::load_library(Some(&path)).unwrap_err()
    );
    assert!(err.contains("cut.danclips"), "{err}");
    assert!(err.contains("corrupted"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn retrieval_dancer_moves_on_the_beat_of_the_demo_song() {
    let (poses, beats) = dance_to_demo(40.0, 0.5, 3);
    assert!(poses.iter().all(Pose::is_finite));
    // The first 5 s are skipped: the beat tracker locks within them.
    let (on, off) = common::beat_align_on_and_off(&poses, &beats);
    let positions = Skeleton::default_adult().trajectory(&poses[5 * 25..]);
    let track = JointTrack::new(&positions, JOINT_COUNT, 25.0).unwrap();
    eprintln!("BeatAlign on the beats {on:.3}, half a beat off {off:.3}");
    assert!(on > off + 0.1, "on {on:.3} vs off {off:.3}");
    let freezes = detect_freezes(&track, FreezeParams::default()).unwrap();
    assert_eq!(freezes.freezes, 0, "{freezes:?}");
}

#[test]
fn temperature_widens_the_choice_and_seeds_reproduce() {
    let (a, _) = dance_to_demo(20.0, 0.0, 1);
    let (b, _) = dance_to_demo(20.0, 0.0, 2);
    let (c, _) = dance_to_demo(20.0, 1.0, 1);
    let (d, _) = dance_to_demo(20.0, 1.0, 2);
    let (e, _) = dance_to_demo(20.0, 1.0, 2);
    let differ = |x: &[Pose], y: &[Pose]| common::frames_differing(x, y, 0.999);
    assert_eq!(differ(&a, &b), 0, "T = 0 ignores the seed");
    assert_eq!(differ(&d, &e), 0, "a seed reproduces");
    assert!(differ(&c, &d) > 100, "T = 1 depends on the seed");
}
