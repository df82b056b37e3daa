//! A minimal OSC 1.0 byte writer for the real-time sender.
//!
//! Hand-written rather than rosc's encoder because rosc encodes an `OscPacket` tree: every
//! message needs an owned `String` address and a `Vec<OscType>` of arguments (an `OscType::String`
//! owns its text too), and a bundle a `Vec` of its messages, so one frame to all layouts cost
//! about 600 allocator calls per tick on the 60 Hz real-time thread (measured with
//! `tests/no_alloc.rs`). This writes the same bytes straight into a caller's `Vec<u8>`, which
//! allocates only while its capacity grows during the first frames. rosc still decodes (control
//! input, tests), and the tests check these bytes against rosc's.

use rosc::OscTime;

/// Bytes of a bundle before its elements: "#bundle\0" and the timetag.
pub const BUNDLE_HEADER_BYTES: usize = 16;
/// Bytes in front of each element of a bundle: its size.
pub const ELEMENT_HEADER_BYTES: usize = 4;

/// Encoded size of an OSC string made of `parts` run together: its bytes, then 1 to 4 NULs up to
/// a multiple of 4.
pub fn string_len(parts: &[&str]) -> usize {
    let n: usize = parts.iter().map(|p| p.len()).sum();
    (n + 4) & !3
}

/// Where an unfinished bundle element starts, for [`OscWriter::end_element`].
#[derive(Debug)]
#[must_use = "an element's size is only written by end_element"]
pub struct ElementStart(usize);

/// Appends OSC to a byte buffer; never clears it, so bundles are written element by element.
#[derive(Debug)]
pub struct OscWriter<'a> {
    buf: &'a mut Vec<u8>,
}

impl<'a> OscWriter<'a> {
    /// A writer appending to `buf`.
    pub fn new(buf: &'a mut Vec<u8>) -> Self {
        Self { buf }
    }

    /// An OSC string made of `parts` run together (an address from prefix and name, a type tag
    /// string, a string argument): no intermediate `String` is built.
    pub fn string(&mut self, parts: &[&str]) -> &mut Self {
        let mut n = 0;
        for p in parts {
            self.buf.extend_from_slice(p.as_bytes());
            n += p.len();
        }
        let pad = 4 - n % 4;
        self.buf.extend_from_slice(&[0u8; 4][..pad]);
        self
    }

    /// An `i` argument.
    pub fn int(&mut self, x: i32) -> &mut Self {
        self.buf.extend_from_slice(&x.to_be_bytes());
        self
    }

    /// An `f` argument.
    pub fn float(&mut self, x: f32) -> &mut Self {
        self.buf.extend_from_slice(&x.to_be_bytes());
        self
    }

    /// Several `f` arguments.
    pub fn floats(&mut self, xs: &[f32]) -> &mut Self {
        for &x in xs {
            self.float(x);
        }
        self
    }

    /// A bundle's header: "#bundle\0" and the NTP timetag.
    pub fn bundle_header(&mut self, timetag: OscTime) -> &mut Self {
        self.buf.extend_from_slice(b"#bundle\0");
        self.buf.extend_from_slice(&timetag.seconds.to_be_bytes());
        self.buf
            .extend_from_slice(&timetag.fractional.to_be_bytes());
        self
    }

    /// Starts a bundle element: a size placeholder, filled in by [`Self::end_element`].
    pub fn begin_element(&mut self) -> ElementStart {
        let start = self.buf.len();
        self.buf.extend_from_slice(&[0u8; ELEMENT_HEADER_BYTES]);
        ElementStart(start)
    }

    /// Ends the element begun at `start`, writing its size in front of it.
    pub fn end_element(&mut self, start: ElementStart) {
        let at = start.0;
        let size = self.buf.len() - at - ELEMENT_HEADER_BYTES;
        // An element is part of one UDP datagram, so far below i32::MAX.
        let size = u32::try_from(size).unwrap_or(u32::MAX);
        self.buf[at..at + ELEMENT_HEADER_BYTES].copy_from_slice(&size.to_be_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rosc::{OscBundle, OscMessage, OscPacket, OscType};

    #[test]
    fn writes_what_rosc_writes() {
        for name in ["", "a", "ab", "abc", "abcd", "LeftUpperArm"] {
            let addr = format!("/x/{name}");
            let want = rosc::encoder::encode(&OscPacket::Message(OscMessage {
                addr: addr.clone(),
                args: vec![
                    OscType::String(name.into()),
                    OscType::Int(-7),
                    OscType::Float(1.5),
                ],
            }))
            .unwrap();
            let mut buf = Vec::new();
            OscWriter::new(&mut buf)
                .string(&["/x/", name])
                .string(&[",sif"])
                .string(&[name])
                .int(-7)
                .float(1.5);
            assert_eq!(buf, want, "{name:?}");
            let len = string_len(&["/x/", name]) + string_len(&[",sif"]) + string_len(&[name]) + 8;
            assert_eq!(len, want.len());
        }
    }

    #[test]
    fn bundles_match_rosc() {
        let timetag = OscTime {
            seconds: 0x0102_0304,
            fractional: 0x0506_0708,
        };
        let m = |addr: &str, x: f32| OscMessage {
            addr: addr.into(),
            args: vec![OscType::Float(x)],
        };
        let want = rosc::encoder::encode(&OscPacket::Bundle(OscBundle {
            timetag,
            content: vec![
                OscPacket::Message(m("/a", 1.0)),
                OscPacket::Message(m("/bcde", 2.0)),
            ],
        }))
        .unwrap();
        let mut buf = Vec::new();
        let mut w = OscWriter::new(&mut buf);
        w.bundle_header(timetag);
        for (addr, x) in [("/a", 1.0), ("/bcde", 2.0)] {
            let e = w.begin_element();
            w.string(&[addr]).string(&[",f"]).float(x);
            w.end_element(e);
        }
        assert_eq!(buf, want);
        assert_eq!(BUNDLE_HEADER_BYTES, 16);
    }
}
