//! WAV streams decoded piece by piece: [`WavStreamDecoder`] turns the bytes of a WAV stream
//! (a header, then PCM to the end of the stream, as `arecord` or `ffmpeg -f wav -` write to
//! a pipe) into mono samples the same way [`read_wav`](crate::audio::read_wav) decodes a
//! file. [`crate::audio_stream::FeatureStream`] makes the features from them.

/// Sample encodings a WAV stream may carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    /// Integer PCM of this many bits (8 is unsigned, as in WAV files).
    Int(u16),
    /// 32-bit IEEE float.
    Float32,
}

/// The format of a WAV stream, from its header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WavStreamFormat {
    pub sample_rate: u32,
    pub channels: u16,
    pub bits_per_sample: u16,
    pub float: bool,
}

/// Decodes a WAV stream piece by piece: [`WavStreamDecoder::push`] takes bytes as they
/// arrive and returns the mono samples they complete. A `data` chunk whose declared size is
/// 0 or at least 2^31 - 1 bytes (what tools writing to a pipe put there) runs to the end
/// of the stream; otherwise the declared size is honoured.
#[derive(Debug, Default)]
pub struct WavStreamDecoder {
    pending: Vec<u8>,
    format: Option<(WavStreamFormat, Encoding)>,
    /// Bytes of sample data still expected (`None`: to the end of the stream).
    data_left: Option<u64>,
    in_data: bool,
    bytes_seen: u64,
}

/// A data chunk at least this long is taken as "to the end of the stream".
const STREAMING_DATA_SIZE: u32 = 0x7fff_ffff;

impl WavStreamDecoder {
    /// A decoder waiting for the header.
    pub fn new() -> WavStreamDecoder {
        WavStreamDecoder::default()
    }

    /// The format, once the header has been read.
    pub fn format(&self) -> Option<WavStreamFormat> {
        self.format.map(|(f, _)| f)
    }

    /// Takes the next bytes of the stream; returns the mono samples they complete (averaged
    /// over channels, integers scaled to [-1, 1)). A malformed header or a non-finite sample
    /// is an error; the message does not name the stream.
    pub fn push(&mut self, bytes: &[u8]) -> std::result::Result<Vec<f32>, String> {
        self.bytes_seen += bytes.len() as u64;
        self.pending.extend_from_slice(bytes);
        if !self.in_data {
            self.parse_header()?;
            if !self.in_data {
                return Ok(Vec::new());
            }
        }
        let (format, encoding) = self.format.ok_or("no fmt chunk before the data")?;
        let width = (format.bits_per_sample as usize).div_ceil(8);
        let frame = width * format.channels as usize;
        let mut usable = self.pending.len() - self.pending.len() % frame;
        if let Some(left) = self.data_left {
            usable = usable.min(left as usize - left as usize % frame);
        }
        let mut out = Vec::with_capacity(usable / frame);
        for chunk in self.pending[..usable].chunks_exact(frame) {
            let mut sum = 0.0f32;
            for c in chunk.chunks_exact(width) {
                let v = decode_sample(c, encoding);
                if !v.is_finite() {
                    return Err("a sample is not finite".into());
                }
                sum += v;
            }
            out.push(sum / format.channels as f32);
        }
        self.pending.drain(..usable);
        if let Some(left) = &mut self.data_left {
            *left -= usable as u64;
            if *left < frame as u64 {
                // The declared data is complete; whatever follows is other chunks.
                *left = 0;
                self.pending.clear();
            }
        }
        Ok(out)
    }

    /// Checks the end of the stream: an error when no sample data began or when it stops
    /// inside a sample frame.
    pub fn finish(&self) -> std::result::Result<(), String> {
        if self.bytes_seen == 0 {
            return Err("empty stream, not a WAV stream".into());
        }
        if !self.in_data {
            return Err("the stream ended inside the WAV header".into());
        }
        if !self.pending.is_empty() && self.data_left != Some(0) {
            return Err("sample data ends inside a frame (truncated)".into());
        }
        Ok(())
    }

    /// Reads the RIFF header and chunks up to the start of `data`, as far as the pending
    /// bytes go.
    fn parse_header(&mut self) -> std::result::Result<(), String> {
        let mut at = 0usize;
        let p = &self.pending;
        if p.len() < 12 {
            if !b"RIFF".starts_with(&p[..p.len().min(4)]) {
                return Err("not a WAV stream (no RIFF header)".into());
            }
            return Ok(());
        }
        if &p[0..4] != b"RIFF" || &p[8..12] != b"WAVE" {
            return Err("not a WAV stream (no RIFF/WAVE header)".into());
        }
        at += 12;
        let mut format = self.format;
        loop {
            if p.len() < at + 8 {
                return Ok(());
            }
            let id = &p[at..at + 4];
            let size = u32::from_le_bytes([p[at + 4], p[at + 5], p[at + 6], p[at + 7]]);
            if id == b"data" {
                let (f, _) = format.ok_or("no fmt chunk before the data")?;
                self.format = format;
                self.data_left = (size != 0 && size < STREAMING_DATA_SIZE).then_some(size as u64);
                self.in_data = true;
                self.pending.drain(..at + 8);
                if f.channels == 0 {
                    return Err("WAV header declares 0 channels".into());
                }
                return Ok(());
            }
            let padded = size as usize + (size as usize & 1);
            if size >= STREAMING_DATA_SIZE {
                return Err(format!(
                    "chunk `{}` declares {size} bytes",
                    String::from_utf8_lossy(id)
                ));
            }
            if p.len() < at + 8 + padded {
                return Ok(());
            }
            if id == b"fmt " {
                format = Some(parse_fmt(&p[at + 8..at + 8 + size as usize])?);
            }
            at += 8 + padded;
        }
    }
}

/// Reads a `fmt ` chunk: PCM (tag 1), IEEE float (tag 3) or WAVE_FORMAT_EXTENSIBLE holding
/// either.
fn parse_fmt(c: &[u8]) -> std::result::Result<(WavStreamFormat, Encoding), String> {
    if c.len() < 16 {
        return Err("fmt chunk is shorter than 16 bytes".into());
    }
    let u16_at = |i: usize| u16::from_le_bytes([c[i], c[i + 1]]);
    let mut tag = u16_at(0);
    let channels = u16_at(2);
    let sample_rate = u32::from_le_bytes([c[4], c[5], c[6], c[7]]);
    let bits = u16_at(14);
    if tag == 0xfffe {
        if c.len() < 26 {
            return Err("extensible fmt chunk is too short".into());
        }
        tag = u16_at(24);
    }
    if channels == 0 {
        return Err("WAV header declares 0 channels".into());
    }
    if !(1000..=768_000).contains(&sample_rate) {
        return Err(format!(
            "WAV sample rate {sample_rate} Hz is outside 1000..=768000"
        ));
    }
    let encoding = match (tag, bits) {
        (1, 8 | 16 | 24 | 32) => Encoding::Int(bits),
        (3, 32) => Encoding::Float32,
        (1, b) => return Err(format!("unsupported sample width {b} bits")),
        (3, b) => return Err(format!("unsupported float width {b} bits")),
        (t, _) => return Err(format!("unsupported WAV format tag {t}")),
    };
    Ok((
        WavStreamFormat {
            sample_rate,
            channels,
            bits_per_sample: bits,
            float: encoding == Encoding::Float32,
        },
        encoding,
    ))
}

/// One little-endian sample as [`read_wav`](crate::audio::read_wav) scales it.
fn decode_sample(b: &[u8], encoding: Encoding) -> f32 {
    match encoding {
        Encoding::Float32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        Encoding::Int(bits) => {
            let v: i32 = match bits {
                8 => b[0] as i32 - 128,
                16 => i16::from_le_bytes([b[0], b[1]]) as i32,
                24 => i32::from_le_bytes([0, b[0], b[1], b[2]]) >> 8,
                _ => i32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            };
            let scale = 1.0 / (1u64 << (bits - 1)) as f64;
            (v as f64 * scale) as f32
        }
    }
}
