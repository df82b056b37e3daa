//! The weight files of the analysis' learned parts: little-endian, a four-byte magic, a layout
//! version, then `u32` sizes and `f32` values. Reading checks every size and value, so a
//! truncated, padded or corrupted file is a named error and never a panic or a NaN.

use crate::DspError;

/// Reads a weight file front to back.
pub struct NetFileReader<'a> {
    bytes: &'a [u8],
    at: usize,
    kind: &'static str,
}

impl<'a> NetFileReader<'a> {
    /// Checks the magic and version of `bytes`, a weight file of `kind`.
    pub fn open(
        bytes: &'a [u8],
        kind: &'static str,
        magic: &[u8; 4],
        version: u32,
    ) -> Result<Self, DspError> {
        if bytes.len() < 4 || &bytes[..4] != magic {
            return Err(DspError::NetFileMagic { kind });
        }
        let mut r = Self { bytes, at: 4, kind };
        let found = r.u32()? as u32;
        if found != version {
            return Err(DspError::NetFileVersion {
                kind,
                found,
                supported: version,
            });
        }
        Ok(r)
    }

    /// A malformed-file error naming `reason`.
    pub fn malformed(&self, reason: impl Into<String>) -> DspError {
        DspError::NetFileMalformed {
            kind: self.kind,
            reason: reason.into(),
        }
    }

    /// The next `u32`.
    pub fn u32(&mut self) -> Result<usize, DspError> {
        let s = self
            .bytes
            .get(self.at..self.at + 4)
            .ok_or_else(|| self.malformed("truncated header"))?;
        self.at += 4;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as usize)
    }

    /// The next `u32`, which must lie in `range` (`what` names it in the error).
    pub fn u32_in(
        &mut self,
        range: std::ops::RangeInclusive<usize>,
        what: &str,
    ) -> Result<usize, DspError> {
        let v = self.u32()?;
        if range.contains(&v) {
            Ok(v)
        } else {
            Err(self.malformed(format!("implausible {what}: {v}")))
        }
    }

    /// The next `n` values, all finite.
    pub fn floats(&mut self, n: usize) -> Result<Vec<f32>, DspError> {
        let raw = self
            .bytes
            .get(self.at..self.at.saturating_add(n.saturating_mul(4)))
            .ok_or_else(|| self.malformed("truncated weights"))?;
        self.at += 4 * n;
        let v: Vec<f32> = raw
            .chunks_exact(4)
            .map(|s| f32::from_le_bytes([s[0], s[1], s[2], s[3]]))
            .collect();
        if v.iter().all(|x| x.is_finite()) {
            Ok(v)
        } else {
            Err(self.malformed("non-finite weight"))
        }
    }

    /// Checks that nothing follows what was read.
    pub fn finish(self) -> Result<(), DspError> {
        if self.at == self.bytes.len() {
            Ok(())
        } else {
            Err(self.malformed(format!(
                "{} bytes after the last network",
                self.bytes.len() - self.at
            )))
        }
    }
}

/// Writes a weight file front to back.
pub struct NetFileWriter {
    bytes: Vec<u8>,
}

impl NetFileWriter {
    /// A file starting with `magic` and `version`.
    pub fn new(magic: &[u8; 4], version: u32) -> Self {
        let mut w = Self {
            bytes: magic.to_vec(),
        };
        w.u32(version as usize);
        w
    }

    /// Appends a `u32`.
    pub fn u32(&mut self, v: usize) {
        self.bytes.extend_from_slice(&(v as u32).to_le_bytes());
    }

    /// Appends values.
    pub fn floats(&mut self, xs: &[f32]) {
        xs.iter()
            .for_each(|x| self.bytes.extend_from_slice(&x.to_le_bytes()));
    }

    /// The file's bytes.
    pub fn into_bytes(self) -> Vec<u8> {
        self.bytes
    }
}
