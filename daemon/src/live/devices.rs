//! `danced devices`: the audio inputs cpal can see and the MIDI input ports midir can see.

use cpal::traits::HostTrait;

use super::capture::{choose_config, device_name};

/// One line per audio input ("name — default format"), or a single "no audio inputs" line.
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
            let format = match choose_config(d) {
                Ok(c) => format!(
                    "{} Hz, {} ch, {:?}",
                    c.sample_rate(),
                    c.channels(),
                    c.sample_format()
                ),
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
