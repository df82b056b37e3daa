//! A UDP socket that receives OSC control packets, drained by the daemon's own loop.

use crate::control::{ControlEvent, ControlParser};
use crate::error::ProtocolError;
use std::io;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, UdpSocket};

/// The control port when none is configured (clear of VMC's 39539/39540 and VRChat's 9000/9001).
pub const DEFAULT_CONTROL_PORT: u16 = 9010;

/// Largest UDP payload; a bigger buffer is never needed.
const MAX_DATAGRAM: usize = 65_536;

/// Receives control packets without a thread: call [`ControlReceiver::poll`] from any loop.
#[derive(Debug)]
pub struct ControlReceiver {
    socket: UdpSocket,
    parser: ControlParser,
    buf: Vec<u8>,
    datagrams: u64,
    receive_errors: u64,
    allow: Vec<IpAddr>,
    refused_sources: u64,
}

impl ControlReceiver {
    /// Listens on 127.0.0.1:`port` (local only: anyone who can reach the port steers the dance).
    pub fn localhost(port: u16) -> Result<Self, ProtocolError> {
        Self::bind(
            SocketAddr::from((Ipv4Addr::LOCALHOST, port)),
            ControlParser::default(),
        )
    }

    /// Listens on `addr` (e.g. 0.0.0.0:9010 to accept control from the network) with `parser`.
    pub fn bind(addr: SocketAddr, parser: ControlParser) -> Result<Self, ProtocolError> {
        let socket = UdpSocket::bind(addr).map_err(|source| ProtocolError::Bind {
            addr: addr.to_string(),
            source,
        })?;
        socket.set_nonblocking(true)?;
        Ok(Self {
            socket,
            parser,
            buf: vec![0; MAX_DATAGRAM],
            datagrams: 0,
            receive_errors: 0,
            allow: Vec::new(),
            refused_sources: 0,
        })
    }

    /// Accepts datagrams only from these source addresses (empty: from anyone who can reach
    /// the port). Others are dropped unparsed and counted in [`Self::refused_sources`].
    pub fn set_allowed_sources(&mut self, allow: Vec<IpAddr>) {
        self.allow = allow;
    }

    /// Datagrams dropped because their source is not allowed.
    pub fn refused_sources(&self) -> u64 {
        self.refused_sources
    }

    /// The bound address (the real port when bound to port 0).
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// The parser, for its counters.
    pub fn parser(&self) -> &ControlParser {
        &self.parser
    }

    /// Datagrams received so far.
    pub fn datagrams(&self) -> u64 {
        self.datagrams
    }

    /// Receive errors other than "nothing pending" (e.g. ICMP errors surfacing on Windows).
    pub fn receive_errors(&self) -> u64 {
        self.receive_errors
    }

    /// Parses every datagram waiting on the socket into `out`; returns the number of events
    /// appended. Never blocks.
    pub fn poll(&mut self, out: &mut Vec<ControlEvent>) -> usize {
        let before = out.len();
        // Bounded so a flood cannot keep the caller here forever.
        for _ in 0..1024 {
            match self.socket.recv_from(&mut self.buf) {
                Ok((n, from)) => {
                    self.datagrams += 1;
                    if !self.allow.is_empty() && !self.allow.contains(&from.ip()) {
                        self.refused_sources += 1;
                        continue;
                    }
                    self.parser.parse(&self.buf[..n], out);
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(_) => self.receive_errors += 1,
            }
        }
        out.len() - before
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rosc::{OscMessage, OscPacket, OscType};
    use std::time::Duration;

    #[test]
    fn drains_pending_datagrams_into_events() {
        let mut rx = ControlReceiver::localhost(0).unwrap();
        let addr = rx.local_addr().unwrap();
        let mut out = Vec::new();
        assert_eq!(rx.poll(&mut out), 0, "nothing pending: returns at once");
        let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
        let send = |addr_: &str, args| {
            let bytes = rosc::encoder::encode(&OscPacket::Message(OscMessage {
                addr: addr_.into(),
                args,
            }))
            .unwrap();
            tx.send_to(&bytes, addr).unwrap();
        };
        send("/danced/control/temperature", vec![OscType::Float(0.5)]);
        send("/danced/control/pause", vec![]);
        tx.send_to(b"garbage", addr).unwrap();
        testkit::wait_until(Duration::from_secs(20), || {
            rx.poll(&mut out);
            rx.datagrams() >= 3
        });
        assert_eq!(
            out,
            vec![ControlEvent::Temperature(0.5), ControlEvent::Pause]
        );
        assert_eq!(rx.datagrams(), 3);
        assert_eq!(rx.parser().malformed(), 1);
        assert_eq!(rx.parser().accepted(), 2);
    }

    #[test]
    fn sources_outside_the_allowlist_are_refused_and_counted() {
        let mut rx = ControlReceiver::localhost(0).unwrap();
        let addr = rx.local_addr().unwrap();
        rx.set_allowed_sources(vec!["127.0.0.2".parse().unwrap()]);
        let bytes = rosc::encoder::encode(&OscPacket::Message(OscMessage {
            addr: "/danced/control/pause".into(),
            args: vec![],
        }))
        .unwrap();
        let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
        tx.send_to(&bytes, addr).unwrap();
        let mut out = Vec::new();
        testkit::wait_until(Duration::from_secs(20), || {
            rx.poll(&mut out);
            rx.datagrams() >= 1
        });
        assert_eq!((out.len(), rx.refused_sources()), (0, 1));
        rx.set_allowed_sources(vec!["127.0.0.1".parse().unwrap()]);
        tx.send_to(&bytes, addr).unwrap();
        testkit::wait_until(Duration::from_secs(20), || {
            rx.poll(&mut out);
            !out.is_empty()
        });
        assert_eq!(out, vec![ControlEvent::Pause]);
    }

    #[test]
    fn binding_a_taken_port_is_a_clear_error() {
        let rx = ControlReceiver::localhost(0).unwrap();
        let port = rx.local_addr().unwrap().port();
        let e = ControlReceiver::localhost(port).unwrap_err().to_string();
        assert!(e.contains(&format!("127.0.0.1:{port}")), "{e}");
    }
}
