//! Every loss or change on the way out shows in `OscOutput::counters()`: each counter provoked on
//! its own, the others staying put.

use glam::{Quat, Vec3};
use protocols::{
    AnalysisEvent, BodyFrame, BoneSample, NativeEncoder, OscOutput, OscTarget, OutputCounters,
    TargetKind, VmcEncoder, VrchatEncoder, VrchatTrackerMap,
};
use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, UNIX_EPOCH};

fn bone(bone: &'static str) -> BoneSample {
    BoneSample {
        bone,
        local_position: Vec3::new(0.0, 0.1, 0.0),
        local_rotation: Quat::IDENTITY,
        world_position: Vec3::ONE,
        world_rotation: Quat::IDENTITY,
    }
}

fn frame() -> BodyFrame {
    BodyFrame {
        frame_index: 1,
        audio_time_s: 0.5,
        timetag: UNIX_EPOCH + Duration::from_secs(1_700_000_000),
        root_position: Vec3::ZERO,
        root_rotation: Quat::IDENTITY,
        bones: vec![bone("Hips"), bone("Head")],
    }
}

/// A receiver that is kept open (so sends to it succeed) and its address.
fn receiver() -> (UdpSocket, SocketAddr) {
    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
    let a = s.local_addr().unwrap();
    (s, a)
}

fn output(kind: TargetKind, addr: SocketAddr, vrchat: VrchatEncoder) -> OscOutput {
    OscOutput::with_encoders(
        vec![OscTarget { kind, addr }],
        NativeEncoder::default(),
        VmcEncoder::new(true),
        vrchat,
    )
    .unwrap()
}

/// Two trackers, so the default head and one tracker find their bones in [`frame`].
fn hips_and_head() -> VrchatEncoder {
    VrchatEncoder::new(VrchatTrackerMap::new(&["Hips"], Some("Head")).unwrap())
}

#[test]
fn a_clean_frame_counts_only_what_was_sent() {
    let (_r, addr) = receiver();
    for kind in [TargetKind::Native, TargetKind::Vmc, TargetKind::Vrchat] {
        let mut out = output(kind, addr, hips_and_head());
        out.send_frame(&frame());
        let c = out.counters();
        assert!(c.packets_sent > 0 && c.bytes_sent > 0, "{kind:?}: {c:?}");
        assert_eq!(
            c,
            OutputCounters {
                packets_sent: c.packets_sent,
                bytes_sent: c.bytes_sent,
                ..OutputCounters::default()
            },
            "{kind:?}"
        );
    }
}

#[test]
fn non_finite_values_are_counted_for_every_layout() {
    let (_r, addr) = receiver();
    let mut f = frame();
    f.bones[0].world_position.x = f32::NAN; // native and VRChat send it
    f.bones[0].local_position.y = f32::INFINITY; // VMC sends it
    for (kind, want) in [
        (TargetKind::Native, 1),
        (TargetKind::Vmc, 1),
        (TargetKind::Vrchat, 1),
    ] {
        let mut out = output(kind, addr, hips_and_head());
        out.send_frame(&f);
        let c = out.counters();
        assert_eq!(c.non_finite_replaced, want, "{kind:?}: {c:?}");
        assert_eq!(c.send_errors, 0);
    }
    // Events: a NaN tempo and an infinite time, and an int beyond int32 clamped.
    let mut out = output(TargetKind::Native, addr, hips_and_head());
    out.send_event(&AnalysisEvent::Beat {
        time_s: f64::INFINITY,
        index_in_bar: 1,
        beats_per_bar: u32::MAX,
        tempo_bpm: f32::NAN,
        bar_confidence: 0.5,
    });
    let c = out.counters();
    assert_eq!((c.non_finite_replaced, c.clamped_values), (2, 1), "{c:?}");
}

#[test]
fn vrchat_trackers_without_their_bone_are_counted() {
    let (_r, addr) = receiver();
    let map = VrchatTrackerMap::new(&["Hips", "LeftFoot"], Some("Head")).unwrap();
    let mut out = output(TargetKind::Vrchat, addr, VrchatEncoder::new(map));
    for _ in 0..3 {
        out.send_frame(&frame());
    }
    let c = out.counters();
    assert_eq!(c.vrchat_missing_bones, 3, "LeftFoot, once a frame: {c:?}");
    assert_eq!(c.packets_sent, 3 * 4, "Hips and head, two messages each");
}

#[test]
fn refused_and_oversized_datagrams_are_counted() {
    // Broadcast without SO_BROADCAST: the operating system refuses every datagram at once.
    let refused: SocketAddr = "255.255.255.255:9".parse().unwrap();
    let mut out = output(TargetKind::Native, refused, hips_and_head());
    out.send_frame(&frame());
    out.send_event(&AnalysisEvent::Tempo {
        bpm: 120.0,
        confidence: 1.0,
    });
    let c = out.counters();
    assert_eq!((c.packets_sent, c.send_errors), (0, 2), "{c:?}");
    assert_eq!(c.oversized_packets, 0);
    assert!(out.last_error().is_some());

    // A frame too big for one datagram: refused, and counted as oversized too.
    let (_r, addr) = receiver();
    let mut out = output(TargetKind::Native, addr, hips_and_head());
    let mut big = frame();
    big.bones = vec![bone("LeftUpperArm"); 2000];
    out.send_frame(&big);
    out.send_frame(&frame());
    let c = out.counters();
    assert_eq!((c.send_errors, c.oversized_packets), (1, 1), "{c:?}");
    assert_eq!(c.packets_sent, 1);
}
