//! Fan-out of frames and events to any number of OSC receivers over UDP.

use crate::error::ProtocolError;
use crate::frame::{AnalysisEvent, BodyFrame};
use crate::native::NativeEncoder;
use crate::output_counters::OutputCounters;
use crate::packet_pool::PacketPool;
use crate::vmc::VmcEncoder;
use crate::vrchat::VrchatEncoder;
use std::io;
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};

/// The OSC layout a receiver expects.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TargetKind {
    /// danced's own layout (TouchDesigner, Max, anything custom); also gets analysis events.
    Native,
    /// VMC protocol Performer (VSeeFace, Warudo, VMC).
    Vmc,
    /// VRChat OSC trackers.
    Vrchat,
}

/// One receiver of our OSC output.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct OscTarget {
    /// The layout it expects.
    pub kind: TargetKind,
    /// Where to send.
    pub addr: SocketAddr,
}

/// A target from "host:port" (IPv6 as "[::1]:9000"); a host name resolves once, here, preferring
/// IPv4 since most OSC receivers listen only on IPv4.
pub fn parse_target(kind: TargetKind, host_port: &str) -> Result<OscTarget, ProtocolError> {
    let bad = |reason: String| ProtocolError::BadTarget {
        input: host_port.to_string(),
        reason,
    };
    let s = host_port.trim();
    let Some((host, port)) = s.rsplit_once(':') else {
        return Err(bad("no port".into()));
    };
    if host.is_empty() {
        return Err(bad("no host".into()));
    }
    let port: u16 = port
        .parse()
        .map_err(|_| bad(format!("port {port:?} is not a number in 1..=65535")))?;
    if port == 0 {
        return Err(bad("port 0 cannot be sent to".into()));
    }
    let addrs: Vec<SocketAddr> = s
        .to_socket_addrs()
        .map_err(|e| bad(format!("cannot resolve: {e}")))?
        .collect();
    let addr = addrs
        .iter()
        .find(|a| a.is_ipv4())
        .or_else(|| addrs.first())
        .copied()
        .ok_or_else(|| bad("host resolves to no address".into()))?;
    Ok(OscTarget { kind, addr })
}

/// Largest UDP payload over IPv4; anything longer is refused by the operating system.
pub const MAX_UDP_PAYLOAD: usize = 65_507;

/// Sends every frame to every target in the layout it expects, counting what went out, what
/// failed and what was altered; never blocks, never panics on network trouble, and once warm
/// (after the first frame) never allocates, so it can run on a real-time thread.
#[derive(Debug)]
pub struct OscOutput {
    socket_v4: UdpSocket,
    socket_v6: Option<UdpSocket>,
    targets: Vec<OscTarget>,
    native: NativeEncoder,
    vmc: VmcEncoder,
    vrchat: VrchatEncoder,
    // Buffers reused frame after frame, never shrunk, so sending does not allocate.
    pool: PacketPool,
    sent: SendCounters,
}

/// The socket side of the counters (the encoders keep the rest).
#[derive(Debug, Default)]
struct SendCounters {
    packets_sent: u64,
    bytes_sent: u64,
    send_errors: u64,
    oversized_packets: u64,
    last_error: Option<io::ErrorKind>,
}

impl OscOutput {
    /// An output to `targets` with default encoders.
    pub fn new(targets: Vec<OscTarget>) -> Result<Self, ProtocolError> {
        Self::with_encoders(
            targets,
            NativeEncoder::default(),
            VmcEncoder::default(),
            VrchatEncoder::default(),
        )
    }

    /// An output to `targets` with the given encoders (prefix, split bundles, tracker map).
    pub fn with_encoders(
        targets: Vec<OscTarget>,
        native: NativeEncoder,
        vmc: VmcEncoder,
        vrchat: VrchatEncoder,
    ) -> Result<Self, ProtocolError> {
        let socket_v4 = bind("0.0.0.0:0")?;
        let mut out = Self {
            socket_v4,
            socket_v6: None,
            targets: Vec::new(),
            native,
            vmc,
            vrchat,
            pool: PacketPool::new(),
            sent: SendCounters::default(),
        };
        for t in targets {
            out.add_target(t)?;
        }
        Ok(out)
    }

    /// Adds a receiver (binding an IPv6 socket the first time one needs it).
    pub fn add_target(&mut self, target: OscTarget) -> Result<(), ProtocolError> {
        if target.addr.is_ipv6() && self.socket_v6.is_none() {
            self.socket_v6 = Some(bind("[::]:0")?);
        }
        self.targets.push(target);
        Ok(())
    }

    /// The receivers, in the order they are sent to.
    pub fn targets(&self) -> &[OscTarget] {
        &self.targets
    }

    /// The local address frames are sent from (IPv4 socket).
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket_v4.local_addr()
    }

    /// Every counter of this output and its encoders.
    pub fn counters(&self) -> OutputCounters {
        OutputCounters {
            packets_sent: self.sent.packets_sent,
            bytes_sent: self.sent.bytes_sent,
            send_errors: self.sent.send_errors,
            oversized_packets: self.sent.oversized_packets,
            non_finite_replaced: self.native.replaced_non_finite()
                + self.vmc.replaced_non_finite()
                + self.vrchat.replaced_non_finite(),
            clamped_values: self.native.clamped_values(),
            vrchat_missing_bones: self.vrchat.missing_bones(),
        }
    }

    /// UDP datagrams handed to the operating system.
    pub fn packets_sent(&self) -> u64 {
        self.sent.packets_sent
    }

    /// Bytes in those datagrams (OSC payload only).
    pub fn bytes_sent(&self) -> u64 {
        self.sent.bytes_sent
    }

    /// Datagrams the operating system refused (buffer full, unreachable, refused, too big).
    pub fn send_errors(&self) -> u64 {
        self.sent.send_errors
    }

    /// The kind of the most recent send error, for a log line.
    pub fn last_error(&self) -> Option<io::ErrorKind> {
        self.sent.last_error
    }

    /// Encodes `frame`, and one analysis event of each kind, in every layout this output
    /// sends, without sending anything: the buffers grow to their working size here, at
    /// set-up, so the first real frame on the real-time thread does not allocate either.
    pub fn prepare(&mut self, frame: &BodyFrame) {
        for kind in [TargetKind::Native, TargetKind::Vmc, TargetKind::Vrchat] {
            if !self.targets.iter().any(|t| t.kind == kind) {
                continue;
            }
            self.pool.clear();
            match kind {
                TargetKind::Native => self.native.write_frame(frame, self.pool.next_packet()),
                TargetKind::Vmc => self.vmc.write_frame(frame, &mut self.pool),
                TargetKind::Vrchat => self.vrchat.write_frame(frame, &mut self.pool),
            }
        }
        let events = [
            AnalysisEvent::Beat {
                time_s: 0.0,
                index_in_bar: 1,
                beats_per_bar: 4,
                tempo_bpm: 120.0,
                bar_confidence: 1.0,
            },
            AnalysisEvent::NextBeat {
                time_s: 0.0,
                in_s: 0.0,
                index_in_bar: 1,
                beats_per_bar: 4,
                tempo_bpm: 120.0,
            },
            AnalysisEvent::Onset {
                time_s: 0.0,
                strength: 0.0,
            },
            AnalysisEvent::Tempo {
                bpm: 120.0,
                confidence: 0.0,
            },
            AnalysisEvent::Chroma {
                time_s: 0.0,
                chroma: [0.0; 12],
            },
            AnalysisEvent::Energy {
                time_s: 0.0,
                db: -120.0,
            },
            AnalysisEvent::RelativeLevel {
                time_s: 0.0,
                db: -60.0,
            },
        ];
        for e in &events {
            self.pool.clear();
            self.native.write_event(e, self.pool.next_packet());
        }
        self.pool.clear();
    }

    /// Sends the frame to every target; each layout is encoded at most once per frame.
    pub fn send_frame(&mut self, frame: &BodyFrame) {
        for kind in [TargetKind::Native, TargetKind::Vmc, TargetKind::Vrchat] {
            if !self.targets.iter().any(|t| t.kind == kind) {
                continue;
            }
            match kind {
                TargetKind::Native => {
                    self.pool.clear();
                    self.native.write_frame(frame, self.pool.next_packet());
                }
                TargetKind::Vmc => self.vmc.write_frame(frame, &mut self.pool),
                TargetKind::Vrchat => self.vrchat.write_frame(frame, &mut self.pool),
            }
            self.send_packets(kind);
        }
    }

    /// Sends an analysis event to the native targets (the other layouts have no place for it).
    pub fn send_event(&mut self, event: &AnalysisEvent) {
        if !self.targets.iter().any(|t| t.kind == TargetKind::Native) {
            return;
        }
        self.pool.clear();
        self.native.write_event(event, self.pool.next_packet());
        self.send_packets(TargetKind::Native);
    }

    fn send_packets(&mut self, kind: TargetKind) {
        for target in self.targets.iter().filter(|t| t.kind == kind) {
            let socket = match (target.addr, &self.socket_v6) {
                (SocketAddr::V6(_), Some(v6)) => v6,
                _ => &self.socket_v4,
            };
            for packet in self.pool.packets() {
                match socket.send_to(packet, target.addr) {
                    Ok(n) => {
                        self.sent.packets_sent += 1;
                        self.sent.bytes_sent += n as u64;
                    }
                    Err(e) => {
                        self.sent.send_errors += 1;
                        if packet.len() > MAX_UDP_PAYLOAD {
                            self.sent.oversized_packets += 1;
                        }
                        self.sent.last_error = Some(e.kind());
                    }
                }
            }
        }
    }
}

fn bind(addr: &str) -> Result<UdpSocket, ProtocolError> {
    let socket = UdpSocket::bind(addr).map_err(|source| ProtocolError::Bind {
        addr: addr.to_string(),
        source,
    })?;
    // A slow receiver must never stall the frame clock: a full buffer drops the datagram.
    socket.set_nonblocking(true)?;
    Ok(socket)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::BoneSample;
    use glam::{Quat, Vec3};
    use rosc::{OscPacket, decoder::decode_udp};
    use std::time::{Duration, Instant, UNIX_EPOCH};

    #[test]
    fn parse_target_accepts_hosts_and_explains_errors() {
        let t = parse_target(TargetKind::Vmc, "127.0.0.1:39539").unwrap();
        assert_eq!(t.addr, "127.0.0.1:39539".parse().unwrap());
        let t = parse_target(TargetKind::Native, "localhost:9000").unwrap();
        assert_eq!(t.addr.port(), 9000);
        let t = parse_target(TargetKind::Vrchat, "[::1]:9000").unwrap();
        assert!(t.addr.is_ipv6());
        for bad in [
            "127.0.0.1",
            "127.0.0.1:0",
            "127.0.0.1:99999",
            ":9000",
            "127.0.0.1:abc",
        ] {
            let e = parse_target(TargetKind::Native, bad)
                .unwrap_err()
                .to_string();
            assert!(e.contains("host:port") && e.contains(bad), "{e}");
        }
    }

    fn frame() -> BodyFrame {
        let bone = |b| BoneSample {
            bone: b,
            local_position: Vec3::ZERO,
            local_rotation: Quat::IDENTITY,
            world_position: Vec3::ONE,
            world_rotation: Quat::IDENTITY,
        };
        BodyFrame {
            frame_index: 1,
            audio_time_s: 0.5,
            timetag: UNIX_EPOCH + Duration::from_secs(1_700_000_000),
            root_position: Vec3::new(0.0, 0.0, 3.0),
            root_rotation: Quat::IDENTITY,
            bones: vec![bone("Hips"), bone("Head")],
        }
    }

    fn receiver() -> UdpSocket {
        let s = UdpSocket::bind("127.0.0.1:0").unwrap();
        s.set_read_timeout(Some(Duration::from_millis(500)))
            .unwrap();
        s
    }

    fn recv_all(s: &UdpSocket, n: usize) -> Vec<OscPacket> {
        let mut buf = [0u8; 65536];
        (0..n)
            .map(|_| {
                let len = s.recv(&mut buf).unwrap();
                decode_udp(&buf[..len]).unwrap().1
            })
            .collect()
    }

    #[test]
    fn fans_out_frames_in_each_targets_layout_and_events_to_native_only() {
        let (native, vmc, vrc, native2) = (receiver(), receiver(), receiver(), receiver());
        let target = |kind, s: &UdpSocket| OscTarget {
            kind,
            addr: s.local_addr().unwrap(),
        };
        let mut out = OscOutput::new(vec![
            target(TargetKind::Native, &native),
            target(TargetKind::Vmc, &vmc),
            target(TargetKind::Vrchat, &vrc),
            target(TargetKind::Native, &native2),
        ])
        .unwrap();
        out.send_frame(&frame());
        out.send_event(&AnalysisEvent::Tempo {
            bpm: 120.0,
            confidence: 0.9,
        });
        // Native: 1 bundle + 1 event each; VMC: 1 bundle; VRChat: Hips and Head present
        // (Head as head tracker) → 2 trackers × 2 messages.
        assert_eq!(out.packets_sent(), 2 + 2 + 1 + 4);
        assert_eq!(out.send_errors(), 0);
        for s in [&native, &native2] {
            let got = recv_all(s, 2);
            let OscPacket::Bundle(b) = &got[0] else {
                panic!()
            };
            let OscPacket::Message(root) = &b.content[1] else {
                panic!()
            };
            assert_eq!(root.addr, "/danced/root");
            assert_eq!(root.args[2], rosc::OscType::Float(3.0));
            let OscPacket::Message(tempo) = &got[1] else {
                panic!()
            };
            assert_eq!(tempo.addr, "/danced/tempo");
        }
        let OscPacket::Bundle(b) = &recv_all(&vmc, 1)[0] else {
            panic!()
        };
        assert_eq!(b.content.len(), 5);
        let got = recv_all(&vrc, 4);
        let OscPacket::Message(m) = &got[0] else {
            panic!()
        };
        assert_eq!(m.addr, "/tracking/trackers/1/position");
        assert!(out.bytes_sent() > 200);
    }

    #[test]
    fn network_failures_are_counted_not_fatal() {
        // Nothing listens here; with many frames some sends may fail (refused) or succeed
        // silently, but none may panic or block.
        let dead = {
            let s = UdpSocket::bind("127.0.0.1:0").unwrap();
            s.local_addr().unwrap()
        };
        let mut out = OscOutput::new(vec![OscTarget {
            kind: TargetKind::Native,
            addr: dead,
        }])
        .unwrap();
        let start = Instant::now();
        for _ in 0..1000 {
            out.send_frame(&frame());
        }
        assert_eq!(out.packets_sent() + out.send_errors(), 1000);
        assert!(start.elapsed() < Duration::from_secs(2));
        // A datagram over 64 KiB cannot be sent: counted as an error.
        let mut big = frame();
        big.bones = vec![big.bones[0]; 2000];
        out.send_frame(&big);
        assert!(out.send_errors() >= 1);
        assert!(out.last_error().is_some());
    }
}
