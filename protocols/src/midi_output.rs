//! MIDI output ports through midir, for the MIDI clock danced leads.

use crate::error::ProtocolError;

/// Client name shown to other MIDI software.
const CLIENT_NAME: &str = "danced";

/// An open MIDI output; messages go out until it is dropped.
pub struct MidiOutConnection {
    connection: midir::MidiOutputConnection,
    port_name: String,
}

impl std::fmt::Debug for MidiOutConnection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MidiOutConnection")
            .field("port_name", &self.port_name)
            .finish_non_exhaustive()
    }
}

impl MidiOutConnection {
    /// Connects to the first output port whose name contains `port_name_substring`
    /// (case-insensitive).
    pub fn connect(port_name_substring: &str) -> Result<Self, ProtocolError> {
        let output = midir::MidiOutput::new(CLIENT_NAME)
            .map_err(|e| ProtocolError::MidiUnavailable(e.to_string()))?;
        let (port, port_name) = crate::midi_input::port_matching(&output, port_name_substring)?;
        let connection =
            output
                .connect(&port, "danced-clock")
                .map_err(|e| ProtocolError::MidiConnect {
                    port: port_name.clone(),
                    reason: e.to_string(),
                })?;
        Ok(Self {
            connection,
            port_name,
        })
    }

    /// The full name of the connected port.
    pub fn port_name(&self) -> &str {
        &self.port_name
    }

    /// Sends one message; false when the driver refused it.
    pub fn send(&mut self, bytes: &[u8]) -> bool {
        self.connection.send(bytes).is_ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn connecting_without_midi_or_the_port_is_a_clear_error() {
        match MidiOutConnection::connect("no such port, surely 51c0") {
            Err(ProtocolError::MidiUnavailable(_) | ProtocolError::MidiPortNotFound { .. }) => {}
            other => panic!("unexpected: {other:?}"),
        }
    }
}
