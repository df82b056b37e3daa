//! The real-time sender allocates nothing once warm: after one frame, every further frame and
//! event to every layout (native, VMC whole and split, VRChat) performs no heap allocation,
//! reallocation or free on the sending thread.
//!
//! The workspace's counting global allocator (`counting-alloc`, the one `danced` runs with)
//! counts only on the current thread and only while it runs counted code, so the test harness,
//! the other tests and the receiving side do not disturb the count.

use counting_alloc::{CountingAllocator, RtThread, count_here};
use glam::{Quat, Vec3};
use protocols::{
    AnalysisEvent, BodyFrame, BoneSample, NativeEncoder, OscOutput, OscTarget, TargetKind,
    VmcEncoder, VrchatEncoder,
};
use std::net::UdpSocket;
use std::time::{Duration, UNIX_EPOCH};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Allocator calls (allocations, reallocations and frees) made on this thread by `f`, counted
/// as the sender's real-time code.
fn counted<R>(f: impl FnOnce() -> R) -> (R, u64) {
    count_here(RtThread::Sender, f)
}

const BONES: [&str; 22] = [
    "Hips",
    "Spine",
    "Chest",
    "UpperChest",
    "Neck",
    "Head",
    "LeftShoulder",
    "LeftUpperArm",
    "LeftLowerArm",
    "LeftHand",
    "RightShoulder",
    "RightUpperArm",
    "RightLowerArm",
    "RightHand",
    "LeftUpperLeg",
    "LeftLowerLeg",
    "LeftFoot",
    "LeftToes",
    "RightUpperLeg",
    "RightLowerLeg",
    "RightFoot",
    "RightToes",
];

fn frame(i: u64) -> BodyFrame {
    let t = i as f32 / 60.0;
    BodyFrame {
        frame_index: i,
        audio_time_s: f64::from(t),
        timetag: UNIX_EPOCH + Duration::from_secs(1_700_000_000) + Duration::from_millis(16 * i),
        root_position: Vec3::new(t.sin(), 0.0, t.cos()),
        root_rotation: Quat::from_rotation_y(t),
        bones: BONES
            .iter()
            .enumerate()
            .map(|(k, &bone)| BoneSample {
                bone,
                local_position: Vec3::new(0.0, 0.1 * k as f32, 0.0),
                local_rotation: Quat::from_rotation_z(t + k as f32 * 0.1),
                world_position: Vec3::new(k as f32, 1.0, t),
                world_rotation: Quat::from_rotation_x(t * 0.5),
            })
            .collect(),
    }
}

fn events(i: u64) -> [AnalysisEvent; 6] {
    let t = i as f64 / 60.0;
    let mut chroma = [0.0; 12];
    chroma[(i % 12) as usize] = 1.0;
    [
        AnalysisEvent::Beat {
            time_s: t,
            index_in_bar: (i % 4) as u32 + 1,
            beats_per_bar: 4,
            tempo_bpm: 120.0,
            bar_confidence: 0.9,
        },
        AnalysisEvent::Onset {
            time_s: t,
            strength: 0.5,
        },
        AnalysisEvent::Tempo {
            bpm: 121.0,
            confidence: 0.75,
        },
        AnalysisEvent::Chroma { time_s: t, chroma },
        AnalysisEvent::Energy {
            time_s: t,
            db: -12.0,
        },
        AnalysisEvent::RelativeLevel {
            time_s: t,
            db: -9.0,
        },
    ]
}

fn receiver() -> UdpSocket {
    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
    s.set_nonblocking(true).unwrap();
    s
}

/// Datagrams waiting on `s`, thrown away so the socket buffers never fill.
fn drain(s: &UdpSocket, buf: &mut [u8]) -> usize {
    let mut n = 0;
    while s.recv(buf).is_ok() {
        n += 1;
    }
    n
}

#[test]
fn the_counter_counts() {
    let (v, calls) = counted(|| std::hint::black_box(Vec::<u8>::with_capacity(10)));
    drop(v);
    assert!(calls >= 1, "a Vec::with_capacity(10) was not counted");
}

#[test]
fn warm_sender_allocates_nothing_for_any_layout() {
    // Proves the counter counts on this thread, in this test, before relying on a zero.
    let (v, calls) = counted(|| std::hint::black_box(Vec::<u8>::with_capacity(10)));
    drop(v);
    assert!(calls >= 1, "a Vec::with_capacity(10) was not counted");

    let sockets: Vec<UdpSocket> = (0..4).map(|_| receiver()).collect();
    let target = |kind, s: &UdpSocket| OscTarget {
        kind,
        addr: s.local_addr().unwrap(),
    };
    let mut whole = OscOutput::new(vec![
        target(TargetKind::Native, &sockets[0]),
        target(TargetKind::Vmc, &sockets[1]),
        target(TargetKind::Vrchat, &sockets[2]),
    ])
    .unwrap();
    let mut split = OscOutput::with_encoders(
        vec![target(TargetKind::Vmc, &sockets[3])],
        NativeEncoder::default(),
        VmcEncoder::new(true),
        VrchatEncoder::default(),
    )
    .unwrap();
    let mut buf = vec![0u8; 65536];

    // Warm-up: one frame (events need no warm-up of their own).
    for out in [&mut whole, &mut split] {
        out.send_frame(&frame(0));
    }
    let mut received = [0usize; 4];
    for (r, s) in received.iter_mut().zip(&sockets) {
        *r += drain(s, &mut buf);
    }

    const FRAMES: u64 = 240;
    let mut total_calls = 0;
    for i in 1..=FRAMES {
        let (f, ev) = (frame(i), events(i));
        let ((), calls) = counted(|| {
            for out in [&mut whole, &mut split] {
                out.send_frame(&f);
                for e in &ev {
                    out.send_event(e);
                }
            }
        });
        total_calls += calls;
        for (r, s) in received.iter_mut().zip(&sockets) {
            *r += drain(s, &mut buf);
        }
    }
    // Loopback delivers at once, but the last datagrams may still be on their way: wait (with
    // a generous deadline) until as many have arrived as were sent, then check them exactly.
    let sent = (whole.packets_sent() + split.packets_sent()) as usize;
    testkit::wait_until(Duration::from_secs(10), || {
        for (r, s) in received.iter_mut().zip(&sockets) {
            *r += drain(s, &mut buf);
        }
        received.iter().sum::<usize>() >= sent
    });
    println!(
        "allocator calls: {total_calls} over {FRAMES} frames ({:.1} per frame)",
        total_calls as f64 / FRAMES as f64
    );
    assert_eq!(total_calls, 0, "the warm sender allocated");

    // Everything went out and arrived, nothing was lost or altered: native 1 bundle + 6 events
    // (none in the warm-up), VMC whole 1 bundle, VRChat 8 trackers + head × 2 messages, VMC
    // split more than one bundle.
    for out in [&whole, &split] {
        let c = out.counters();
        assert_eq!(
            (c.send_errors, c.non_finite_replaced, c.vrchat_missing_bones),
            (0, 0, 0),
            "{c:?}"
        );
    }
    let n = FRAMES as usize + 1;
    assert_eq!(received[0], n + 6 * FRAMES as usize);
    assert_eq!(received[1], n);
    assert_eq!(received[2], n * 18);
    assert!(received[3] >= n * 2, "{} split bundles", received[3]);
    assert_eq!(
        whole.packets_sent() as usize,
        received[0] + received[1] + received[2]
    );
    assert_eq!(split.packets_sent() as usize, received[3]);
}
