//! Decoding of audio files (WAV, FLAC, MP3, Ogg Vorbis, AAC/M4A) to interleaved `f32` PCM.
//!
//! Built on symphonia 0.6. The probe picks the container by content; the extension is only
//! passed as a hint (symphonia 0.6's probe does not actually consult it). Encoder delay and
//! padding (e.g. the LAME tag of an MP3) are trimmed by the decoder because symphonia 0.6 enables
//! gapless decoding by default.

use std::fs::File;
use std::io;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use symphonia::core::codecs::audio::{AudioDecoder, AudioDecoderOptions};
use symphonia::core::errors::Error as SymphoniaError;
use symphonia::core::formats::probe::Hint;
use symphonia::core::formats::{FormatOptions, FormatReader, TrackType};
use symphonia::core::io::MediaSourceStream;
use symphonia::core::meta::MetadataOptions;

use crate::error::OfflineError;

/// A whole decoded audio file: interleaved `f32` samples (nominally in [-1, 1]) and their format.
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedAudio {
    /// Interleaved samples: frame `i`, channel `c` is at `i * channels + c`.
    pub samples: Vec<f32>,
    /// Sample rate in Hz.
    pub sample_rate: u32,
    /// Number of interleaved channels (at least 1).
    pub channels: u16,
    /// Packets that failed to decode and were left out of `samples`.
    pub skipped_packets: usize,
}

impl DecodedAudio {
    /// Length of the audio in seconds.
    pub fn duration_s(&self) -> f64 {
        if self.sample_rate == 0 {
            return 0.0;
        }
        self.frames() as f64 / f64::from(self.sample_rate)
    }

    /// Number of frames (samples per channel).
    pub fn frames(&self) -> usize {
        self.samples.len() / usize::from(self.channels.max(1))
    }
}

/// Mono mix (the channels' mean) of interleaved `samples` of `channels` channels.
pub fn mono_mix(samples: &[f32], channels: u16) -> Vec<f32> {
    let ch = usize::from(channels.max(1));
    samples
        .chunks_exact(ch)
        .map(|f| f.iter().sum::<f32>() / ch as f32)
        .collect()
}

/// Streaming decoder for one file: yields the default audio track one packet at a time.
pub struct AudioFileReader {
    path: PathBuf,
    format: Box<dyn FormatReader>,
    decoder: Box<dyn AudioDecoder>,
    track_id: u32,
    sample_rate: u32,
    channels: u16,
    total_frames: Option<u64>,
    /// The first block is decoded by `open` (to learn the real output format), then handed out
    /// by the first `read_block`.
    pending: Option<Vec<f32>>,
    skipped_packets: usize,
    finished: bool,
    truncated: bool,
    /// Last complaint from symphonia, kept so `open` can explain a file that yields no audio.
    last_error: Option<SymphoniaError>,
    /// Set when symphonia panicked: its state is then unknown, so it is never called again.
    panicked: bool,
}

impl std::fmt::Debug for AudioFileReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AudioFileReader")
            .field("path", &self.path)
            .field("sample_rate", &self.sample_rate)
            .field("channels", &self.channels)
            .field("total_frames", &self.total_frames)
            .field("skipped_packets", &self.skipped_packets)
            .field("finished", &self.finished)
            .finish_non_exhaustive()
    }
}

impl AudioFileReader {
    /// Opens a file, probes its format and decodes the first block so the output format is known.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, OfflineError> {
        let path = path.as_ref().to_path_buf();
        let file = open_file(&path)?;

        let mss = MediaSourceStream::new(Box::new(file), Default::default());
        let mut hint = Hint::new();
        if let Some(ext) = path.extension().and_then(|e| e.to_str()) {
            hint.with_extension(ext);
        }
        let probed = guarded(|| {
            symphonia::default::get_probe().probe(
                &hint,
                mss,
                FormatOptions::default(),
                MetadataOptions::default(),
            )
        });
        let format = match probed {
            Some(Ok(format)) => format,
            Some(Err(err)) => return Err(classify_setup_error(&path, err)),
            None => return Err(panic_error(&path)),
        };

        let Some(track) = format.default_track(TrackType::Audio) else {
            return Err(OfflineError::Unsupported {
                path,
                reason: "no audio track".into(),
            });
        };
        let track_id = track.id;
        let total_frames = track.num_frames;
        let Some(params) = track.codec_params.as_ref().and_then(|p| p.audio()) else {
            return Err(OfflineError::Unsupported {
                path,
                reason: "audio track without codec parameters".into(),
            });
        };
        let made = guarded(|| {
            symphonia::default::get_codecs()
                .make_audio_decoder(params, &AudioDecoderOptions::default())
        });
        let decoder = match made {
            Some(Ok(decoder)) => decoder,
            Some(Err(err)) => return Err(classify_setup_error(&path, err)),
            None => return Err(panic_error(&path)),
        };

        let mut reader = AudioFileReader {
            path,
            format,
            decoder,
            track_id,
            // Placeholders: the real values come from the first decoded buffer, because
            // container headers may omit them (ADTS) or disagree with what the decoder outputs.
            sample_rate: 0,
            channels: 0,
            total_frames,
            pending: None,
            skipped_packets: 0,
            finished: false,
            truncated: false,
            last_error: None,
            panicked: false,
        };

        let mut first = Vec::new();
        if reader.next_block(&mut first) == 0 {
            return Err(reader.no_audio_error());
        }
        reader.pending = Some(first);
        Ok(reader)
    }

    /// The file being decoded.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Sample rate of the decoded audio in Hz.
    pub fn sample_rate(&self) -> u32 {
        self.sample_rate
    }

    /// Number of interleaved channels in every block.
    pub fn channels(&self) -> u16 {
        self.channels
    }

    /// Frame count declared by the container, if any (may overstate a truncated file).
    pub fn total_frames(&self) -> Option<u64> {
        self.total_frames
    }

    /// Packets skipped so far because they failed to decode.
    pub fn skipped_packets(&self) -> usize {
        self.skipped_packets
    }

    /// Whether decoding stopped early because the demuxer hit damaged or missing data.
    pub fn truncated(&self) -> bool {
        self.truncated
    }

    /// Replaces `out`'s contents with the next decoded packet; returns its frame count (0 at end).
    // Damaged packets are skipped and a stream that stops early just ends (see `skipped_packets`
    // and `truncated`), so after a successful `open` this currently never returns `Err`; the
    // `Result` leaves room for errors a later version may want to surface.
    pub fn read_block(&mut self, out: &mut Vec<f32>) -> Result<usize, OfflineError> {
        if let Some(mut first) = self.pending.take() {
            std::mem::swap(out, &mut first);
            return Ok(out.len() / usize::from(self.channels));
        }
        Ok(self.next_block(out))
    }

    /// Decodes packets until one yields audio; returns its frame count, or 0 once the stream ends.
    fn next_block(&mut self, out: &mut Vec<f32>) -> usize {
        out.clear();
        while !self.finished {
            let packet = match guarded(|| self.format.next_packet()) {
                Some(Ok(Some(packet))) => packet,
                Some(Ok(None)) => {
                    self.finished = true;
                    break;
                }
                // The demuxer's errors are unrecoverable by contract; for a chained Ogg stream
                // (`ResetRequired`) the next link may differ in format, so it is not followed.
                Some(Err(err)) => {
                    self.finished = true;
                    self.truncated = true;
                    self.last_error = Some(err);
                    break;
                }
                None => {
                    self.finished = true;
                    self.truncated = true;
                    self.panicked = true;
                    break;
                }
            };
            if packet.track_id != self.track_id {
                continue;
            }
            let decoded = guarded(|| match self.decoder.decode(&packet) {
                Ok(buf) => {
                    let rate = buf.spec().rate();
                    let channels = buf.spec().channels().count();
                    let frames = buf.frames();
                    if frames > 0 {
                        buf.copy_to_vec_interleaved::<f32>(out);
                    }
                    Ok((rate, channels, frames))
                }
                Err(err) => Err(err),
            });
            match decoded {
                Some(Ok((_, _, 0))) => {
                    // Fully trimmed (encoder delay) or header-only packets carry no frames.
                }
                Some(Ok((rate, channels, frames))) => {
                    if self.channels == 0 {
                        match u16::try_from(channels) {
                            Ok(c) if c > 0 && rate > 0 => {
                                self.sample_rate = rate;
                                self.channels = c;
                            }
                            _ => {
                                self.skipped_packets += 1;
                                self.last_error = Some(SymphoniaError::Unsupported(
                                    "sample rate or channel count",
                                ));
                                out.clear();
                                continue;
                            }
                        }
                    }
                    // Interleaved output has one fixed layout, so a packet in another format
                    // (rare: e.g. an MP3 switching from stereo to mono) cannot be placed in it.
                    if rate != self.sample_rate || channels != usize::from(self.channels) {
                        self.skipped_packets += 1;
                        out.clear();
                        continue;
                    }
                    return frames;
                }
                Some(Err(err)) => {
                    self.skipped_packets += 1;
                    self.last_error = Some(err);
                }
                None => {
                    self.finished = true;
                    self.truncated = true;
                    self.panicked = true;
                    out.clear();
                    break;
                }
            }
        }
        0
    }

    /// Explains why `open` saw no audio at all.
    fn no_audio_error(self) -> OfflineError {
        let path = self.path;
        if self.panicked {
            return panic_error(&path);
        }
        match self.last_error {
            None => OfflineError::Empty { path },
            Some(SymphoniaError::Unsupported(what)) => OfflineError::Unsupported {
                path,
                reason: what.to_string(),
            },
            Some(err) => OfflineError::Corrupt {
                path,
                reason: err.to_string(),
            },
        }
    }
}

/// Whether `path` names a song by its extension (flac, wav, mp3 or ogg): what a folder of
/// songs is read for.
pub fn is_audio_file(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| ["flac", "wav", "mp3", "ogg"].iter().any(|x| e == *x))
}

/// Decodes the default audio track of a file completely into memory.
pub fn decode_file(path: &Path) -> Result<DecodedAudio, OfflineError> {
    let mut reader = AudioFileReader::open(path)?;
    let channels = usize::from(reader.channels());

    let mut samples = Vec::new();
    if let Some(frames) = reader.total_frames() {
        // The header is untrusted: cap the up-front reservation (an hour of audio) so a lying
        // frame count cannot trigger a huge allocation; the vector still grows past it if needed.
        let cap = 3600 * reader.sample_rate() as usize;
        let wanted = usize::try_from(frames).unwrap_or(usize::MAX).min(cap);
        let _ = samples.try_reserve_exact(wanted.saturating_mul(channels));
    }

    let mut block = Vec::new();
    while reader.read_block(&mut block)? > 0 {
        samples.extend_from_slice(&block);
    }

    Ok(DecodedAudio {
        samples,
        sample_rate: reader.sample_rate(),
        channels: reader.channels(),
        skipped_packets: reader.skipped_packets(),
    })
}

/// Opens the file, mapping the common failures to errors that say which file.
fn open_file(path: &Path) -> Result<File, OfflineError> {
    let io_error = |error: io::Error| {
        if error.kind() == io::ErrorKind::NotFound {
            OfflineError::NotFound {
                path: path.to_path_buf(),
            }
        } else {
            OfflineError::Io {
                path: path.to_path_buf(),
                error,
            }
        }
    };
    let meta = std::fs::metadata(path).map_err(io_error)?;
    // Opening a directory succeeds on Unix and only fails on the first read, deep inside the
    // probe, where the message would be confusing.
    if meta.is_dir() {
        return Err(io_error(io::Error::new(
            io::ErrorKind::IsADirectory,
            "is a directory",
        )));
    }
    if meta.len() == 0 {
        return Err(OfflineError::Empty {
            path: path.to_path_buf(),
        });
    }
    File::open(path).map_err(io_error)
}

/// Maps an error from probing or decoder creation (nothing decoded yet) to a `OfflineError`.
fn classify_setup_error(path: &Path, err: SymphoniaError) -> OfflineError {
    let path = path.to_path_buf();
    match err {
        SymphoniaError::Unsupported(what) => OfflineError::Unsupported {
            path,
            reason: what.to_string(),
        },
        // Running out of bytes while parsing headers means a damaged file, not a read failure.
        SymphoniaError::IoError(error) if error.kind() != io::ErrorKind::UnexpectedEof => {
            OfflineError::Io { path, error }
        }
        other => OfflineError::Corrupt {
            path,
            reason: other.to_string(),
        },
    }
}

/// The error reported when symphonia panicked on this file.
fn panic_error(path: &Path) -> OfflineError {
    OfflineError::Corrupt {
        path: path.to_path_buf(),
        reason: "the decoder crashed on this data".into(),
    }
}

/// Runs symphonia code, turning a panic into `None`: bad input must not take the daemon down.
fn guarded<T>(f: impl FnOnce() -> T) -> Option<T> {
    catch_unwind(AssertUnwindSafe(f)).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Instant;

    /// A file under the temp dir that is deleted when dropped.
    struct TempFile(PathBuf);

    impl TempFile {
        fn new(name: &str, bytes: &[u8]) -> Self {
            static COUNTER: AtomicUsize = AtomicUsize::new(0);
            let n = COUNTER.fetch_add(1, Ordering::Relaxed);
            let path = std::env::temp_dir()
                .join(format!("danced-decode-{}-{n}-{name}", std::process::id()));
            std::fs::write(&path, bytes).expect("write temp file");
            TempFile(path)
        }
    }

    impl Drop for TempFile {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }

    /// A 16-bit PCM WAV file; `data_len` overrides the data chunk's declared size.
    fn wav_bytes(rate: u32, channels: u16, samples: &[i16], data_len: Option<u32>) -> Vec<u8> {
        let data_bytes = (samples.len() * 2) as u32;
        let declared = data_len.unwrap_or(data_bytes);
        let block_align = channels * 2;
        let mut b = Vec::with_capacity(44 + samples.len() * 2);
        b.extend_from_slice(b"RIFF");
        b.extend_from_slice(&(36 + declared).to_le_bytes());
        b.extend_from_slice(b"WAVEfmt ");
        b.extend_from_slice(&16u32.to_le_bytes());
        b.extend_from_slice(&1u16.to_le_bytes()); // PCM
        b.extend_from_slice(&channels.to_le_bytes());
        b.extend_from_slice(&rate.to_le_bytes());
        b.extend_from_slice(&(rate * u32::from(block_align)).to_le_bytes());
        b.extend_from_slice(&block_align.to_le_bytes());
        b.extend_from_slice(&16u16.to_le_bytes());
        b.extend_from_slice(b"data");
        b.extend_from_slice(&declared.to_le_bytes());
        for s in samples {
            b.extend_from_slice(&s.to_le_bytes());
        }
        b
    }

    /// Distinct, full-scale-spanning test values: a sine per channel at different frequencies.
    fn test_signal(rate: u32, channels: u16, frames: usize) -> Vec<i16> {
        let mut out = Vec::with_capacity(frames * usize::from(channels));
        for i in 0..frames {
            for c in 0..channels {
                let f = 440.0 * f64::from(c + 1);
                let v = (2.0 * std::f64::consts::PI * f * i as f64 / f64::from(rate)).sin();
                out.push((v * 32000.0).round() as i16);
            }
        }
        // Exercise the extremes of the sample range too.
        if out.len() >= 2 {
            out[0] = i16::MIN;
            out[1] = i16::MAX;
        }
        out
    }

    fn assert_names_file(err: &OfflineError, path: &Path) {
        let shown = err.to_string();
        let name = path.file_name().unwrap().to_str().unwrap();
        assert!(shown.contains(name), "error {shown:?} does not name {name}");
        assert_eq!(err.path(), Some(path));
    }

    /// Small deterministic PRNG (xorshift64*), so the "random" inputs are reproducible.
    fn pseudo_random_bytes(seed: u64, len: usize) -> Vec<u8> {
        let mut x = seed.max(1);
        (0..len)
            .map(|_| {
                x ^= x >> 12;
                x ^= x << 25;
                x ^= x >> 27;
                (x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 56) as u8
            })
            .collect()
    }

    #[test]
    fn wav_round_trip_mono_and_stereo() {
        for &(rate, channels) in &[(22050u32, 1u16), (22050, 2), (48000, 1), (48000, 2)] {
            // Not a multiple of any packet size, so the last partial packet is exercised.
            let frames = rate as usize / 3 + 7;
            let pcm = test_signal(rate, channels, frames);
            let file = TempFile::new(
                &format!("rt-{rate}-{channels}.wav"),
                &wav_bytes(rate, channels, &pcm, None),
            );

            let audio = decode_file(&file.0).expect("decode");
            assert_eq!(audio.sample_rate, rate);
            assert_eq!(audio.channels, channels);
            assert_eq!(audio.frames(), frames);
            assert_eq!(audio.samples.len(), pcm.len());
            assert_eq!(audio.skipped_packets, 0);
            assert!((audio.duration_s() - frames as f64 / f64::from(rate)).abs() < 1e-9);
            for (i, (&got, &want)) in audio.samples.iter().zip(&pcm).enumerate() {
                let want = f32::from(want) / 32768.0;
                assert!(
                    (got - want).abs() <= 1.0 / 32768.0,
                    "sample {i}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn streaming_reader_matches_decode_file() {
        let pcm = test_signal(48000, 2, 30_000);
        let file = TempFile::new("stream.wav", &wav_bytes(48000, 2, &pcm, None));
        let mut reader = AudioFileReader::open(&file.0).expect("open");
        assert_eq!(reader.sample_rate(), 48000);
        assert_eq!(reader.channels(), 2);
        assert_eq!(reader.total_frames(), Some(30_000));

        let mut all = Vec::new();
        let mut block = Vec::new();
        let mut blocks = 0;
        loop {
            let frames = reader.read_block(&mut block).expect("read");
            if frames == 0 {
                break;
            }
            assert_eq!(block.len(), frames * 2);
            all.extend_from_slice(&block);
            blocks += 1;
        }
        assert!(blocks > 1, "expected several packets, got {blocks}");
        assert_eq!(
            reader.read_block(&mut block).unwrap(),
            0,
            "stays at the end"
        );
        assert!(block.is_empty());
        assert!(!reader.truncated());
        assert_eq!(all, decode_file(&file.0).unwrap().samples);
    }

    #[test]
    fn reader_can_move_to_another_thread() {
        fn assert_send<T: Send>() {}
        assert_send::<AudioFileReader>();
        assert_send::<OfflineError>();
    }

    #[test]
    fn missing_file_is_not_found() {
        let path =
            std::env::temp_dir().join(format!("danced-decode-{}-missing.wav", std::process::id()));
        let err = decode_file(&path).unwrap_err();
        assert!(matches!(err, OfflineError::NotFound { .. }), "{err:?}");
        assert_names_file(&err, &path);
    }

    #[test]
    fn directory_is_io_error() {
        let dir = std::env::temp_dir();
        let err = decode_file(&dir).unwrap_err();
        assert!(matches!(err, OfflineError::Io { .. }), "{err:?}");
        assert!(err.to_string().contains(&*dir.to_string_lossy()));
    }

    #[test]
    fn empty_file_is_empty() {
        let file = TempFile::new("empty.wav", b"");
        let err = decode_file(&file.0).unwrap_err();
        assert!(matches!(err, OfflineError::Empty { .. }), "{err:?}");
        assert_names_file(&err, &file.0);
    }

    #[test]
    fn text_file_named_wav_is_unsupported() {
        let text = "This is not audio, just some notes.\n".repeat(50);
        let file = TempFile::new("notes.wav", text.as_bytes());
        let err = decode_file(&file.0).unwrap_err();
        assert!(matches!(err, OfflineError::Unsupported { .. }), "{err:?}");
        assert_names_file(&err, &file.0);
    }

    /// A WAV cut in the middle of its data chunk (even mid-sample) decodes what is there and
    /// reports no error: the frames before the cut come out intact.
    #[test]
    fn truncated_wav_decodes_what_is_there() {
        let frames = 20_000;
        let pcm = test_signal(44100, 2, frames);
        let mut bytes = wav_bytes(44100, 2, &pcm, None);
        let kept_frames = 12_345;
        bytes.truncate(44 + kept_frames * 4 + 3); // 3 bytes into the next frame
        let file = TempFile::new("truncated.wav", &bytes);

        let audio = decode_file(&file.0).expect("a truncated WAV still decodes");
        assert_eq!(audio.sample_rate, 44100);
        assert_eq!(audio.channels, 2);
        assert_eq!(audio.frames(), kept_frames);
        for (&got, &want) in audio.samples.iter().zip(&pcm) {
            assert!((got - f32::from(want) / 32768.0).abs() <= 1.0 / 32768.0);
        }
        let reader = AudioFileReader::open(&file.0).unwrap();
        assert_eq!(
            reader.total_frames(),
            Some(frames as u64),
            "the header still claims the full length"
        );
    }

    /// A WAV cut before its first whole frame: too short to recognise (4 bytes) is Unsupported,
    /// otherwise Corrupt, including a complete header whose promised data is missing.
    #[test]
    fn wav_cut_before_any_frame_is_an_error_naming_the_file() {
        let bytes = wav_bytes(44100, 1, &[0; 100], None);
        for cut in [4, 12, 20, 30, 40, 44, 45] {
            let file = TempFile::new(&format!("cut{cut}.wav"), &bytes[..cut]);
            let err = decode_file(&file.0).unwrap_err();
            if cut == 4 {
                assert!(
                    matches!(err, OfflineError::Unsupported { .. }),
                    "cut at {cut}: {err:?}"
                );
            } else {
                assert!(
                    matches!(err, OfflineError::Corrupt { .. }),
                    "cut at {cut}: {err:?}"
                );
            }
            assert_names_file(&err, &file.0);
        }
    }

    #[test]
    fn wav_without_frames_is_empty() {
        for channels in [1, 2] {
            let file = TempFile::new("noframes.wav", &wav_bytes(48000, channels, &[], None));
            let err = decode_file(&file.0).unwrap_err();
            assert!(matches!(err, OfflineError::Empty { .. }), "{err:?}");
            assert_names_file(&err, &file.0);
            let err = AudioFileReader::open(&file.0).unwrap_err();
            assert!(matches!(err, OfflineError::Empty { .. }), "{err:?}");
        }
    }

    #[test]
    fn random_bytes_named_mp3_are_rejected() {
        let file = TempFile::new("noise.mp3", &pseudo_random_bytes(0x5eed, 64 * 1024));
        let err = decode_file(&file.0).unwrap_err();
        // The probe scans for frame sync words by content and finds no run of valid MP3 frames.
        assert!(matches!(err, OfflineError::Unsupported { .. }), "{err:?}");
        assert_names_file(&err, &file.0);
    }

    /// CRC-32 as Ogg uses it (polynomial 0x04c11db7, not reflected, no final xor).
    fn ogg_crc(data: &[u8]) -> u32 {
        let mut crc = 0u32;
        for &b in data {
            crc ^= u32::from(b) << 24;
            for _ in 0..8 {
                crc = if crc & 0x8000_0000 != 0 {
                    (crc << 1) ^ 0x04c1_1db7
                } else {
                    crc << 1
                };
            }
        }
        crc
    }

    /// One Ogg page holding one packet (< 255 bytes).
    fn ogg_page(flags: u8, granule: u64, seq: u32, packet: &[u8]) -> Vec<u8> {
        let mut p = Vec::new();
        p.extend_from_slice(b"OggS\0");
        p.push(flags);
        p.extend_from_slice(&granule.to_le_bytes());
        p.extend_from_slice(&0x1234_5678u32.to_le_bytes()); // stream serial
        p.extend_from_slice(&seq.to_le_bytes());
        p.extend_from_slice(&[0; 4]); // CRC, filled in below
        p.push(1);
        p.push(packet.len() as u8);
        p.extend_from_slice(packet);
        let crc = ogg_crc(&p);
        p[22..26].copy_from_slice(&crc.to_le_bytes());
        p
    }

    #[test]
    fn ogg_opus_is_unsupported() {
        let mut head = b"OpusHead".to_vec();
        head.push(1); // version
        head.push(2); // channels
        head.extend_from_slice(&312u16.to_le_bytes()); // pre-skip
        head.extend_from_slice(&48000u32.to_le_bytes());
        head.extend_from_slice(&0i16.to_le_bytes()); // gain
        head.push(0); // channel mapping family
        let mut tags = b"OpusTags".to_vec();
        tags.extend_from_slice(&[0; 8]); // empty vendor string, no comments
        let audio = [0xfc, 0xff, 0xfe]; // a 20 ms CELT frame TOC plus filler
        let mut bytes = ogg_page(0x02, 0, 0, &head);
        bytes.extend(ogg_page(0x00, 0, 1, &tags));
        bytes.extend(ogg_page(0x04, 960, 2, &audio));

        let file = TempFile::new("voice.opus", &bytes);
        let err = decode_file(&file.0).unwrap_err();
        // Found by the Ogg demuxer, rejected for want of an Opus decoder (not by the probe).
        assert!(
            matches!(&err, OfflineError::Unsupported { reason, .. } if reason.contains("codec")),
            "{err:?}"
        );
        assert_names_file(&err, &file.0);
    }

    /// Never panics on arbitrary bytes, under any of the extensions the daemon accepts.
    #[test]
    fn garbage_never_panics() {
        let wav = wav_bytes(22050, 2, &test_signal(22050, 2, 3000), None);
        for seed in 1..60u64 {
            let noise = pseudo_random_bytes(seed, 1 + (seed as usize * 997) % 20_000);
            // Random bytes behind a plausible header reach deeper into the parsers.
            let mut mutated = wav.clone();
            for (k, r) in pseudo_random_bytes(seed * 31, 8).chunks(2).enumerate() {
                let at = (usize::from(r[0]) + k * 13) % 64;
                mutated[at] = r[1];
            }
            for (ext, bytes) in [
                ("mp3", &noise),
                ("wav", &mutated),
                ("flac", &noise),
                ("m4a", &noise),
                ("ogg", &noise),
            ] {
                let file = TempFile::new(&format!("garbage{seed}.{ext}"), bytes);
                if let Err(err) = decode_file(&file.0) {
                    assert_names_file(&err, &file.0);
                }
            }
        }
    }

    /// The shared data's madmom samples, or `None` when absent (the test skips, see `testkit`).
    #[track_caller]
    fn madmom_dir() -> Option<PathBuf> {
        testkit::require_shared("madmom-tests").map(|data| data.join("madmom-tests"))
    }

    fn timed_decode(path: &Path) -> DecodedAudio {
        let t = Instant::now();
        let audio = decode_file(path).unwrap_or_else(|e| panic!("{e}"));
        let secs = t.elapsed().as_secs_f64();
        let mode = if cfg!(debug_assertions) {
            "debug"
        } else {
            "release"
        };
        eprintln!(
            "{}: {} Hz, {} ch, {:.3} s, decoded in {:.1} ms = {:.0}x real time ({mode}), {} skipped",
            path.display(),
            audio.sample_rate,
            audio.channels,
            audio.duration_s(),
            secs * 1e3,
            audio.duration_s() / secs,
            audio.skipped_packets
        );
        audio
    }

    #[test]
    fn madmom_samples() {
        let Some(dir) = madmom_dir() else { return };

        let wav = timed_decode(&dir.join("sample.wav"));
        assert_eq!((wav.sample_rate, wav.channels), (44100, 1));
        assert!(
            (wav.duration_s() - 2.8).abs() < 0.05,
            "{}",
            wav.duration_s()
        );

        let wav22 = timed_decode(&dir.join("sample_22050.wav"));
        assert_eq!((wav22.sample_rate, wav22.channels), (22050, 1));
        assert!((wav22.duration_s() - wav.duration_s()).abs() < 0.05);

        let flac = timed_decode(&dir.join("stereo_sample.flac"));
        assert_eq!((flac.sample_rate, flac.channels), (44100, 2));
        assert_eq!(flac.skipped_packets, 0);

        let m4a = timed_decode(&dir.join("stereo_sample.m4a"));
        assert_eq!((m4a.sample_rate, m4a.channels), (44100, 2));
        assert!(
            (m4a.duration_s() - flac.duration_s()).abs() < 0.05,
            "flac {} s vs m4a {} s",
            flac.duration_s(),
            m4a.duration_s()
        );
        assert_eq!(m4a.skipped_packets, 0);
    }

    #[test]
    fn truncated_flac_returns_the_decoded_part() {
        let Some(dir) = madmom_dir() else { return };
        let bytes = std::fs::read(dir.join("stereo_sample.flac")).unwrap();
        let file = TempFile::new("half.flac", &bytes[..bytes.len() / 2]);
        let audio = decode_file(&file.0).expect("the first half still decodes");
        assert_eq!((audio.sample_rate, audio.channels), (44100, 2));
        assert!(
            audio.duration_s() > 1.0 && audio.duration_s() < 3.0,
            "{}",
            audio.duration_s()
        );
        let mut reader = AudioFileReader::open(&file.0).unwrap();
        let mut block = Vec::new();
        while reader.read_block(&mut block).unwrap() > 0 {}
        assert!(
            reader.truncated(),
            "the FLAC demuxer notices the missing data"
        );
    }

    /// DANCE_C_1 has no audio in the shared copy of the data set; take the first that does (or
    /// `None`: the test skips, see `testkit`).
    #[track_caller]
    fn tang2018_mp3_path() -> Option<PathBuf> {
        let root = testkit::shared_data().join("tang2018");
        let found = ["DANCE_C_1", "DANCE_C_2", "DANCE_C_4", "DANCE_R_2"]
            .iter()
            .map(|d| root.join(d).join("audio.mp3"))
            .find(|p| p.is_file());
        if found.is_none() {
            testkit::skip(format_args!(
                "no tang2018 mp3 under {} (the shared data sets)",
                root.display()
            ));
        }
        found
    }

    /// Damaged MP3 frames are skipped and counted; a cut-off MP3 yields the audio before the cut.
    #[test]
    fn damaged_and_cut_mp3() {
        let Some(path) = tang2018_mp3_path() else {
            return;
        };
        let bytes = std::fs::read(&path).unwrap();
        // About 30 s of audio keeps the test quick in debug builds.
        let prefix = &bytes[..bytes.len().min(500_000)];
        let clean = TempFile::new("prefix.mp3", prefix);
        let clean = decode_file(&clean.0).expect("a cut MP3 decodes up to the cut");
        assert_eq!((clean.sample_rate, clean.channels), (44100, 2));
        assert_eq!(clean.skipped_packets, 0);
        assert!(clean.duration_s() > 20.0, "{}", clean.duration_s());

        let mut damaged = prefix.to_vec();
        let noise = pseudo_random_bytes(7, 16 * 400);
        for (k, chunk) in noise.chunks(400).enumerate() {
            let at = 60_000 + k * 25_000;
            damaged[at..at + 400].copy_from_slice(chunk);
        }
        let damaged = TempFile::new("damaged.mp3", &damaged);
        let audio = decode_file(&damaged.0).expect("damage in the middle is survivable");
        assert_eq!((audio.sample_rate, audio.channels), (44100, 2));
        let lost = clean.duration_s() - audio.duration_s();
        eprintln!(
            "damaged mp3: {} packets skipped, {lost:.3} s lost",
            audio.skipped_packets
        );
        // Most hits decode to noise or make the demuxer resync (dropping frames uncounted); only
        // some make the decoder itself fail.
        assert!(audio.skipped_packets > 0, "expected skipped packets");
        // Each hit costs at most a few 26 ms frames (the bit reservoir spreads the damage).
        assert!((0.0..2.0).contains(&lost), "lost {lost} s");
    }

    #[test]
    fn tang2018_mp3() {
        let Some(path) = tang2018_mp3_path() else {
            return;
        };
        let audio = timed_decode(&path);
        assert_eq!((audio.sample_rate, audio.channels), (44100, 2));
        assert!(audio.duration_s() > 30.0, "{}", audio.duration_s());
        let peak = audio.samples.iter().fold(0f32, |m, s| m.max(s.abs()));
        assert!(peak > 0.1 && peak <= 1.5, "peak {peak}");
        let reader = AudioFileReader::open(&path).unwrap();
        if let Some(total) = reader.total_frames() {
            assert_eq!(
                total as usize,
                audio.frames(),
                "gapless length matches the header"
            );
        }
    }
}
