//! Our OSC output as a real third-party receiver (liblo's `oscdump`) sees it.

use glam::{Quat, Vec3};
use protocols::{BodyFrame, BoneSample, NativeEncoder, VmcEncoder};
use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant, UNIX_EPOCH};

/// Kills oscdump however the test ends.
struct Reaper(Child);

impl Drop for Reaper {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn frame() -> BodyFrame {
    let bone = |bone, y: f32| BoneSample {
        bone,
        local_position: Vec3::new(0.0, y, 0.0),
        local_rotation: Quat::from_rotation_z(0.5),
        world_position: Vec3::new(0.25, y, -0.5),
        world_rotation: Quat::IDENTITY,
    };
    BodyFrame {
        frame_index: 42,
        audio_time_s: 12.5,
        // In the past: liblo holds bundles timetagged in the future until their time.
        timetag: UNIX_EPOCH + Duration::from_secs(1_700_000_000) + Duration::from_millis(500),
        root_position: Vec3::new(0.5, 0.0, -1.0),
        root_rotation: Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
        bones: vec![bone("Hips", 0.9), bone("LeftUpperArm", 1.3)],
    }
}

fn message(addr: &str) -> Vec<u8> {
    rosc::encoder::encode(&rosc::OscPacket::Message(rosc::OscMessage {
        addr: addr.into(),
        args: vec![rosc::OscType::Int(1)],
    }))
    .unwrap()
}

/// One printed message: timestamp, address, type tags, values.
#[derive(Debug)]
struct Line {
    time: String,
    addr: String,
    types: String,
    values: Vec<String>,
}

fn parse_line(line: &str) -> Option<Line> {
    let mut parts = line.split_whitespace();
    let time = parts.next()?.to_string();
    let addr = parts.next()?.to_string();
    let types = parts.next().unwrap_or("").to_string();
    let values = parts.map(|v| v.trim_matches('"').to_string()).collect();
    Some(Line {
        time,
        addr,
        types,
        values,
    })
}

fn floats(l: &Line) -> Vec<f32> {
    l.values.iter().filter_map(|v| v.parse().ok()).collect()
}

fn close(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5)
}

#[test]
fn oscdump_reads_native_and_vmc_bundles() {
    if !testkit::require_program("oscdump", "apt-get install liblo-tools") {
        return;
    }
    let start = Instant::now();
    let port = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let child = Command::new("oscdump")
        .args(["-L", &port.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start oscdump");
    let mut child = Reaper(child);
    let stdout = child.0.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let dest = ("127.0.0.1", port);

    // oscdump prints nothing when it is ready, so probe until it echoes.
    let deadline = start + Duration::from_secs(4);
    let mut ready = false;
    while !ready && Instant::now() < deadline {
        socket.send_to(&message("/probe"), dest).unwrap();
        while let Ok(line) = rx.recv_timeout(Duration::from_millis(50)) {
            ready |= line.contains("/probe");
        }
    }
    assert!(ready, "oscdump on port {port} never answered");

    let f = frame();
    let mut native = NativeEncoder::default();
    socket.send_to(native.encode_frame(&f), dest).unwrap();
    for packet in VmcEncoder::new(false).encode_frame(&f) {
        socket.send_to(&packet, dest).unwrap();
    }
    socket.send_to(&message("/done"), dest).unwrap();

    let mut lines = Vec::new();
    while Instant::now() < deadline {
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(line) if line.contains("/done") => break,
            Ok(line) if line.contains("/probe") => {}
            Ok(line) => lines.push(parse_line(&line).expect("a message line")),
            Err(_) => {}
        }
    }
    let find = |addr: &str| {
        lines
            .iter()
            .find(|l| l.addr == addr)
            .unwrap_or_else(|| panic!("{addr} missing from oscdump output: {lines:#?}"))
    };

    // The bundle's NTP timetag, as oscdump prints it (hex seconds . hex fraction).
    let want_time = format!(
        "{:08x}.{:08x}",
        1_700_000_000u32 + 2_208_988_800,
        1u32 << 31
    );
    let frame_line = find("/danced/frame");
    assert_eq!(frame_line.time, want_time);
    assert_eq!(frame_line.types, "if");
    assert_eq!(
        frame_line.values,
        vec!["42".to_string(), "12.500000".to_string()]
    );
    let root = find("/danced/root");
    assert_eq!(root.types, "fffffff");
    let s = std::f32::consts::FRAC_1_SQRT_2;
    assert!(
        close(&floats(root), &[0.5, 0.0, -1.0, 0.0, s, 0.0, s]),
        "{root:?}"
    );
    let arm = find("/danced/joint/LeftUpperArm");
    assert_eq!(arm.types, "fffffff");
    let (sz, cz) = (0.25f32.sin(), 0.25f32.cos());
    assert!(
        close(&floats(arm), &[0.25, 1.3, -0.5, 0.0, 0.0, sz, cz]),
        "{arm:?}"
    );

    let vmc_root = find("/VMC/Ext/Root/Pos");
    assert_eq!(vmc_root.time, want_time);
    assert_eq!(vmc_root.types, "sfffffff");
    assert_eq!(vmc_root.values[0], "root");
    assert!(close(
        &floats(vmc_root),
        &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    ));
    let bones: Vec<&Line> = lines
        .iter()
        .filter(|l| l.addr == "/VMC/Ext/Bone/Pos")
        .collect();
    assert_eq!(bones.len(), 2);
    assert_eq!(bones[1].values[0], "LeftUpperArm");
    assert!(close(&floats(bones[1]), &[0.0, 1.3, 0.0, 0.0, 0.0, sz, cz]));
    let ok = find("/VMC/Ext/OK");
    assert_eq!((ok.types.as_str(), ok.values[0].as_str()), ("i", "1"));
    let t = find("/VMC/Ext/T");
    assert_eq!(t.types, "f");
    assert!(close(&floats(t), &[12.5]));
    assert!(start.elapsed() < Duration::from_secs(5));
}
