//! The documented size limits of everything read from outside, and a bounded file reader.
//!
//! Every input file is read with a cap on its size, so that a huge file, a device node that
//! never ends (`/dev/zero`) or a FIFO fed forever is refused with a message instead of
//! growing memory until the kernel kills the process. The caps are far above any real
//! input of the kind:
//!
//! | input | cap |
//! |---|---|
//! | a recording (WAV, FLAC, Ogg, CSV) | [`MAX_RECORDING_BYTES`] on disk, [`MAX_RECORDING_FRAMES`] decoded |
//! | a force track (CSV) | [`MAX_TRACK_BYTES`]; rows at most [`MAX_TRACK_GAP`] apart |
//! | a library (JSON) | [`MAX_LIBRARY_BYTES`] |
//! | a calibration, compensation file or interface configuration | [`MAX_DOCUMENT_BYTES`] |
//!
//! A file is checked twice: its size from its metadata (a regular file too large is
//! refused before one byte is read), and the bytes actually read (a device or pipe, whose
//! metadata says nothing, is cut off at the cap plus one byte and refused).
//!
//! The reader also notes which files it read ([`reads`]), in a program that asks for it,
//! so that the output policy ([`crate::atomic_file`]) can refuse to replace them.

use std::io::Read;
use std::path::Path;

pub mod reads;

use crate::units::Seconds;

/// Largest recording file read: 256 MiB (about 23 minutes of 48 kHz stereo 24-bit WAV).
pub const MAX_RECORDING_BYTES: u64 = 256 << 20;

/// Most frames a recording may decode to: 30 minutes at 48 kHz (7.5 minutes at 192 kHz).
/// Decoded samples are `f64`, so this caps a recording at 660 MiB in memory.
pub const MAX_RECORDING_FRAMES: usize = 30 * 60 * 48_000;

/// Largest force-track file read: 64 MiB (over an hour of a 4-sensor track at 500 Hz).
/// A track is held in memory whole, at about three times its size in text.
pub const MAX_TRACK_BYTES: u64 = 64 << 20;

/// Largest gap between two consecutive rows of a force track. A longer silence of the
/// sensors is a logger restart or a typo, and an offline render of it would be mostly
/// silence held in memory.
pub const MAX_TRACK_GAP: Seconds = Seconds(10.0);

/// Largest library file read: 64 MiB (a library of a few materials is a few hundred kB).
pub const MAX_LIBRARY_BYTES: u64 = 64 << 20;

/// Largest settings document read (sensor calibrations, compensation files, interface
/// configurations): 16 MiB, a thousand times the largest real one.
pub const MAX_DOCUMENT_BYTES: u64 = 16 << 20;

/// Reads the whole file at `path`, refusing one larger than `cap` bytes.
///
/// # Errors
/// The error of opening or reading the file, or an error of kind
/// [`std::io::ErrorKind::FileTooLarge`] naming the cap when the file (or, for a device
/// or pipe, what it yields) is larger.
pub fn read_capped(path: &Path, cap: u64) -> std::io::Result<Vec<u8>> {
    let file = std::fs::File::open(path)?;
    let too_large = || {
        std::io::Error::new(
            std::io::ErrorKind::FileTooLarge,
            format!(
                "larger than the limit of {} MiB for this kind of file",
                cap >> 20
            ),
        )
    };
    let meta = file.metadata()?;
    // Noted before the bytes are read: an output must not replace a file the command
    // started to read, even one it then refused.
    reads::note_read(&meta);
    let declared = meta.is_file().then_some(meta.len());
    if declared.is_some_and(|n| n > cap) {
        return Err(too_large());
    }
    let mut bytes = Vec::with_capacity(declared.unwrap_or(0).min(cap) as usize);
    file.take(cap.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(too_large());
    }
    Ok(bytes)
}

/// [`read_capped`] for a text file: the bytes must be UTF-8.
///
/// # Errors
/// As [`read_capped`], or an error of kind [`std::io::ErrorKind::InvalidData`].
pub fn read_to_string_capped(path: &Path, cap: u64) -> std::io::Result<String> {
    String::from_utf8(read_capped(path, cap)?).map_err(|_| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            "stream did not contain valid UTF-8",
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_above_the_cap_are_refused() {
        let dir = std::env::temp_dir().join(format!("underfoot-limits-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("f");
        std::fs::write(&path, [7u8; 100]).unwrap();
        assert_eq!(read_capped(&path, 100).unwrap().len(), 100);
        let e = read_capped(&path, 99).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::FileTooLarge);
        assert!(e.to_string().contains("limit"), "{e}");
        std::fs::write(&path, b"\xff\xfe").unwrap();
        assert_eq!(
            read_to_string_capped(&path, 10).unwrap_err().kind(),
            std::io::ErrorKind::InvalidData
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn an_endless_device_is_cut_off_at_the_cap() {
        let start = std::time::Instant::now();
        let e = read_capped(Path::new("/dev/zero"), 1 << 20).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::FileTooLarge);
        assert!(start.elapsed() < std::time::Duration::from_secs(5));
    }
}
