//! `aud.npy`, the audio feature windows `[N, 16, F]` as AD-NeRF stores them: NumPy's
//! format read with every header checked (C order, float32 or float64, three dimensions,
//! every value finite) and written atomically.

use std::io::Cursor;
use std::path::Path;

use crate::audio::AudioWindows;
use crate::error::{Error, Result};
use crate::files::write_atomic;

/// Reads `aud.npy`: a C-order float32 (or float64) array of shape `[N, 16, F]`, all finite.
pub fn load_audio_npy(path: &Path) -> Result<AudioWindows> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_audio_npy(path, &bytes)
}

/// The dimensions of a `.npy` file's `shape` entry as written in its header, without
/// multiplying them; `None` when the bytes hold no readable header or no `shape` tuple
/// (the npy reader then says what is wrong). A dimension beyond `u64` reads as `u64::MAX`.
fn npy_header_shape(bytes: &[u8]) -> Option<Vec<u64>> {
    let rest = bytes.strip_prefix(b"\x93NUMPY")?;
    let (&major, rest) = rest.split_first()?;
    let rest = rest.get(1..)?;
    let (len, rest) = if major == 1 {
        (
            u16::from_le_bytes([*rest.first()?, *rest.get(1)?]) as usize,
            rest.get(2..)?,
        )
    } else {
        let b = rest.get(..4)?;
        (
            u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
            rest.get(4..)?,
        )
    };
    let header = String::from_utf8_lossy(rest.get(..len.min(rest.len()))?);
    let after = &header[header.find("shape")? + "shape".len()..];
    let tuple = &after[after.find('(')? + 1..];
    let tuple = &tuple[..tuple.find(')')?];
    tuple
        .split(',')
        .map(str::trim)
        .filter(|d| !d.is_empty())
        .map(|d| {
            let digits = d.trim_end_matches(['L', 'l']);
            digits
                .chars()
                .all(|c| c.is_ascii_digit())
                .then(|| digits.parse::<u64>().unwrap_or(u64::MAX))
        })
        .collect()
}

/// An error when the non-zero dimensions of the header's shape overflow when multiplied.
fn refuse_overflowing_shape(path: &Path, bytes: &[u8]) -> Result<()> {
    // npyz multiplies the header's dimensions unchecked (the size, and the strides from the
    // last dimension back): a shape whose non-zero dimensions overflow when multiplied must
    // be refused before it reads the header, even when another dimension is 0.
    if let Some(shape) = npy_header_shape(bytes)
        && shape
            .iter()
            .filter(|&&d| d != 0)
            .try_fold(1u64, |acc, &d| acc.checked_mul(d))
            .is_none()
    {
        return Err(Error::invalid(
            path,
            format!("shape {shape:?} holds more values than any file can"),
        ));
    }
    Ok(())
}

/// [`load_audio_npy`] on bytes already read; `path` names them in errors.
pub fn parse_audio_npy(path: &Path, bytes: &[u8]) -> Result<AudioWindows> {
    refuse_overflowing_shape(path, bytes)?;
    let npy = npyz::NpyFile::new(Cursor::new(bytes))
        .map_err(|e| Error::invalid(path, format!("not a .npy file: {e}")))?;
    let shape: Vec<u64> = npy.shape().to_vec();
    if shape.len() != 3 || shape[1] != 16 || shape[2] == 0 {
        return Err(Error::invalid(
            path,
            format!("expected shape [N, 16, F], got {shape:?}"),
        ));
    }
    if npy.order() != npyz::Order::C {
        return Err(Error::invalid(
            path,
            "Fortran-ordered arrays are not supported; save with C order",
        ));
    }
    let dtype = npy.dtype().descr();
    let item = match dtype.as_str() {
        "'<f4'" => 4u64,
        "'<f8'" => 8,
        other => {
            return Err(Error::invalid(
                path,
                format!("expected float32 data, got dtype {other}"),
            ));
        }
    };
    // The shape must fit the bytes there are before anything is allocated for it.
    shape
        .iter()
        .try_fold(item, |acc, &d| acc.checked_mul(d))
        .filter(|&n| n <= bytes.len() as u64)
        .ok_or_else(|| {
            Error::invalid(
                path,
                format!(
                    "shape {shape:?} needs more data than the file's {} bytes",
                    bytes.len()
                ),
            )
        })?;
    let data: Vec<f32> = match dtype.as_str() {
        "'<f4'" => npy.into_vec::<f32>(),
        "'<f8'" => npy
            .into_vec::<f64>()
            .map(|v| v.into_iter().map(|x| x as f32).collect()),
        other => {
            return Err(Error::invalid(
                path,
                format!("expected float32 data, got dtype {other}"),
            ));
        }
    }
    .map_err(|e| Error::invalid(path, format!("truncated or unreadable data: {e}")))?;
    let (n, window, f) = (shape[0] as usize, shape[1] as usize, shape[2] as usize);
    if data.len() != n * window * f {
        return Err(Error::invalid(path, "data length does not match its shape"));
    }
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(
            path,
            format!("non-finite value at flat index {i}"),
        ));
    }
    Ok(AudioWindows {
        n_frames: n,
        window,
        n_features: f,
        data,
    })
}

/// Writes audio windows as a C-order float32 `.npy` of shape `[N, window, F]`, atomically.
pub fn save_audio_npy(path: &Path, audio: &AudioWindows) -> Result<()> {
    use npyz::WriterBuilder;
    let mut buf = Vec::new();
    let shape = [
        audio.n_frames as u64,
        audio.window as u64,
        audio.n_features as u64,
    ];
    let fail = |e: std::io::Error| Error::invalid(path, format!("cannot encode .npy: {e}"));
    let mut writer = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&shape)
        .writer(&mut buf)
        .begin_nd()
        .map_err(fail)?;
    writer.extend(audio.data.iter().copied()).map_err(fail)?;
    writer.finish().map_err(fail)?;
    write_atomic(path, &buf)
}
