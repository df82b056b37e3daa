//! `danced devices`: the audio inputs cpal can see and the MIDI input ports midir can see.

use cpal::traits::HostTrait;

use super::capture::{choose_config, device_name};
use super::input_mix::InputMix;

/// One line per audio input ("name — the format `run` opens"), or a single "no audio inputs"
/// line.
pub fn list_inputs() -> Vec<String> {
    let host = cpal::default_host();
    let default = host.default_input_device().map(|d| device_name(&d));
    let devices: Vec<cpal::Device> = match host.input_devices() {
        Ok(d) => d.collect(),
        Err(e) => return vec![format!("no audio inputs ({e})")],
    };
    if devices.is_empty() {
        return vec!["no audio inputs".to_string()];
    }
    devices
        .iter()
        .map(|d| {
            let name = device_name(d);
            let mark = if default.as_deref() == Some(name.as_str()) {
                " (default)"
            } else {
                ""
            };
            // Exactly what `run` would open, and which inputs it would hear by default.
            let format = match choose_config(d) {
                Ok(c) => {
                    let heard = InputMix::new(c.channels(), None)
                        .map(|m| {
                            let ch: Vec<String> = m.heard().map(|c| c.to_string()).collect();
                            format!("; run hears input {}", ch.join("+"))
                        })
                        .unwrap_or_default();
                    format!(
                        "{} Hz, {} ch, {:?}{heard}",
                        c.sample_rate(),
                        c.channels(),
                        c.sample_format()
                    )
                }
                Err(e) => format!("unusable: {e}"),
            };
            format!("{name}{mark} — {format}")
        })
        .collect()
}

/// One line per MIDI input port, or a single "no MIDI inputs" line.
pub fn list_midi() -> Vec<String> {
    let ports = protocols::MidiInputs::list_ports();
    if ports.is_empty() {
        vec!["no MIDI inputs".to_string()]
    } else {
        ports
    }
}
