//! MIDI input ports (ALSA sequencer on Linux, CoreMIDI, WinMM) through midir.

use crate::error::ProtocolError;
use crossbeam_channel::Sender;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// One raw MIDI message as midir delivers it: driver timestamp (µs), up to 3 bytes, byte count.
pub type MidiPacket = (u64, [u8; 3], u8);

/// Client name shown to other MIDI software (e.g. in `aconnect -l`).
const CLIENT_NAME: &str = "danced";

/// Entry point to the system's MIDI inputs.
#[derive(Clone, Copy, Debug, Default)]
pub struct MidiInputs;

impl MidiInputs {
    /// Names of the MIDI input ports; empty when the system has no MIDI (e.g. no
    /// /dev/snd/seq in a container), which is not an error for a daemon that may run without.
    pub fn list_ports() -> Vec<String> {
        let Ok(input) = midir::MidiInput::new(CLIENT_NAME) else {
            return Vec::new();
        };
        input
            .ports()
            .iter()
            .filter_map(|p| input.port_name(p).ok())
            .collect()
    }

    /// Connects to the first port whose name contains `port_name_substring` (case-insensitive)
    /// and forwards each message of at most 3 bytes to `sender`.
    ///
    /// The callback runs on midir's thread and never allocates or blocks: longer messages
    /// (system exclusive) are skipped, and messages that find a full (bounded) channel are
    /// dropped; both are counted on the returned connection. Active sensing is filtered out by
    /// the driver; clock is kept.
    pub fn connect(
        port_name_substring: &str,
        sender: Sender<MidiPacket>,
    ) -> Result<MidiConnection, ProtocolError> {
        let mut input = midir::MidiInput::new(CLIENT_NAME)
            .map_err(|e| ProtocolError::MidiUnavailable(e.to_string()))?;
        input.ignore(midir::Ignore::SysexAndActiveSense);
        let (port, port_name) = port_matching(&input, port_name_substring)?;
        let skipped = Arc::new(AtomicU64::new(0));
        let dropped = Arc::new(AtomicU64::new(0));
        let (skipped_cb, dropped_cb) = (Arc::clone(&skipped), Arc::clone(&dropped));
        let callback = move |timestamp_us: u64, bytes: &[u8], _: &mut ()| {
            let Some(packet) = packet(timestamp_us, bytes) else {
                skipped_cb.fetch_add(1, Ordering::Relaxed);
                return;
            };
            if sender.try_send(packet).is_err() {
                dropped_cb.fetch_add(1, Ordering::Relaxed);
            }
        };
        let connection = input
            .connect(&port, "danced-in", callback, ())
            .map_err(|e| ProtocolError::MidiConnect {
                port: port_name.clone(),
                reason: e.to_string(),
            })?;
        Ok(MidiConnection {
            _connection: connection,
            port_name,
            skipped,
            dropped,
        })
    }
}

/// The first port of `io` whose name contains `wanted` (case-insensitive), with its name; the
/// error lists the ports there are.
pub(crate) fn port_matching<IO: midir::MidiIO>(
    io: &IO,
    wanted: &str,
) -> Result<(IO::Port, String), ProtocolError> {
    let lower = wanted.to_lowercase();
    let ports = io.ports();
    let names: Vec<String> = ports
        .iter()
        .map(|p| io.port_name(p).unwrap_or_default())
        .collect();
    match names.iter().position(|n| n.to_lowercase().contains(&lower)) {
        Some(i) => Ok((ports[i].clone(), names[i].clone())),
        None => Err(ProtocolError::MidiPortNotFound {
            wanted: wanted.to_string(),
            available: names,
        }),
    }
}

/// The message as a fixed-size packet, or `None` when it is empty or longer than 3 bytes.
fn packet(timestamp_us: u64, bytes: &[u8]) -> Option<MidiPacket> {
    if bytes.is_empty() || bytes.len() > 3 {
        return None;
    }
    let mut data = [0u8; 3];
    data[..bytes.len()].copy_from_slice(bytes);
    Some((timestamp_us, data, bytes.len() as u8))
}

/// An open MIDI input; messages flow until it is dropped.
pub struct MidiConnection {
    _connection: midir::MidiInputConnection<()>,
    port_name: String,
    skipped: Arc<AtomicU64>,
    dropped: Arc<AtomicU64>,
}

impl std::fmt::Debug for MidiConnection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MidiConnection")
            .field("port_name", &self.port_name)
            .field("skipped", &self.skipped())
            .field("dropped", &self.dropped())
            .finish()
    }
}

impl MidiConnection {
    /// The full name of the connected port.
    pub fn port_name(&self) -> &str {
        &self.port_name
    }

    /// Messages longer than 3 bytes (system exclusive) skipped so far.
    pub fn skipped(&self) -> u64 {
        self.skipped.load(Ordering::Relaxed)
    }

    /// Messages lost because the channel was full (the consumer fell behind).
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packets_copy_up_to_three_bytes() {
        assert_eq!(packet(5, &[0x90, 60, 100]), Some((5, [0x90, 60, 100], 3)));
        assert_eq!(packet(6, &[0xf8]), Some((6, [0xf8, 0, 0], 1)));
        assert_eq!(packet(7, &[]), None);
        assert_eq!(packet(8, &[0xf0, 1, 2, 0xf7]), None);
    }

    #[test]
    fn listing_and_connecting_never_panic_without_midi() {
        let ports = MidiInputs::list_ports();
        let (tx, _rx) = crossbeam_channel::bounded(64);
        match MidiInputs::connect("no such port, surely 8c1f", tx) {
            Err(ProtocolError::MidiUnavailable(_)) => assert!(ports.is_empty()),
            Err(ProtocolError::MidiPortNotFound { available, .. }) => {
                assert_eq!(available.len(), ports.len())
            }
            other => panic!("unexpected: {other:?}"),
        }
    }
}
