//! Choosing the stream: from what a device offers and what was asked to the
//! configuration opened, or a refusal that lists what the device can do.
//!
//! Among the device's configurations with the requested channels and rate, 32-bit float
//! is preferred; otherwise the best remaining PCM format, ranked by resolution. A
//! requested buffer size must lie in the device's range; without one the host's default
//! is used. Anything the device cannot do is a [`Refusal`], which
//! [`AudioOutput::start`](super::AudioOutput::start) reports as an
//! [`IoError::Unsupported`](crate::io::IoError::Unsupported) naming the device.
//!
//! [`choose_config`] is pure: the offers are cpal's plain
//! [`SupportedStreamConfigRange`]s, as the device lists them
//! ([`discovery`](super::discovery) asks it), so the rules are tested without a device.

use cpal::{BufferSize, StreamConfig, SupportedBufferSize, SupportedStreamConfigRange};

use super::{AudioConfig, Direction, SampleFormat};
use crate::units::SampleRate;

/// The largest scratch buffer, in frames, allocated for a non-float device whose buffer
/// size was not requested. Bigger device buffers are rendered in chunks of this size.
pub const MAX_SCRATCH_FRAMES: u32 = 8192;

/// The PCM formats, best first: 32-bit float, then by resolution. Anything else (DSD)
/// cannot carry the engine's samples.
const PREFERENCE: [SampleFormat; 12] = {
    use SampleFormat as F;
    [
        F::F32,
        F::F64,
        F::I32,
        F::U32,
        F::I24,
        F::U24,
        F::I16,
        F::U16,
        F::I64,
        F::U64,
        F::I8,
        F::U8,
    ]
};

/// The configuration picked for a device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Chosen {
    /// Channels, rate and buffer size to open the stream with.
    pub stream: StreamConfig,
    /// The device's sample format; anything but `F32` is converted.
    pub format: SampleFormat,
    /// Frames of `f32` scratch for converting formats: the requested buffer, else the
    /// device's largest (at most [`MAX_SCRATCH_FRAMES`]); at least 1.
    pub scratch_frames: usize,
}

/// Why a device cannot be opened as asked; the message lists what it offers instead.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Refusal {
    /// No channels asked for.
    #[error("zero channels requested")]
    ZeroChannels,
    /// A rate of 0 Hz asked for.
    #[error("a sample rate of 0 Hz requested")]
    ZeroRate,
    /// A buffer of 0 frames asked for.
    #[error("a buffer of 0 frames requested")]
    ZeroBuffer,
    /// The device offers nothing in a PCM format in this direction.
    #[error("it offers no PCM {direction} configuration")]
    NoPcm {
        /// The direction asked for.
        direction: Direction,
    },
    /// No configuration with the channel count asked for.
    #[error("{wanted} channels not supported; it offers {} channels", channel_spans(.offered))]
    Channels {
        /// Channels asked for.
        wanted: u16,
        /// The channel counts of the device's PCM configurations.
        offered: Vec<u16>,
    },
    /// No configuration with those channels at the rate asked for.
    #[error("{rate} not supported with {channels} channels; it offers {}", rate_spans(.offered))]
    Rate {
        /// The rate asked for.
        rate: SampleRate,
        /// The channels asked for.
        channels: u16,
        /// Lowest and highest rate of each configuration with those channels.
        offered: Vec<(u32, u32)>,
    },
    /// No configuration with those channels and rate takes the buffer size asked for.
    #[error(
        "a buffer of {frames} frames not supported at {rate} with {channels} channels; it offers {} frames",
        buffer_spans(.offered)
    )]
    Buffer {
        /// The buffer asked for, in frames.
        frames: u32,
        /// The rate asked for.
        rate: SampleRate,
        /// The channels asked for.
        channels: u16,
        /// Smallest and largest buffer of each configuration that says.
        offered: Vec<(u32, u32)>,
    },
}

/// Refuses a request no device could meet (zero channels, rate or buffer), before any
/// device is asked what it offers.
///
/// # Errors
/// [`Refusal::ZeroChannels`], [`Refusal::ZeroRate`] or [`Refusal::ZeroBuffer`].
pub fn check_request(config: &AudioConfig) -> Result<(), Refusal> {
    if config.channels == 0 {
        return Err(Refusal::ZeroChannels);
    }
    if config.rate.0 == 0 {
        return Err(Refusal::ZeroRate);
    }
    if config.buffer_frames == Some(0) {
        return Err(Refusal::ZeroBuffer);
    }
    Ok(())
}

/// The stream to open for `config` on a device that offers `offers` in `direction`.
///
/// # Errors
/// A [`Refusal`]: the request itself ([`check_request`]), or the first of channels, rate,
/// buffer size that no PCM configuration offers.
pub fn choose_config(
    offers: &[SupportedStreamConfigRange],
    config: &AudioConfig,
    direction: Direction,
) -> Result<Chosen, Refusal> {
    check_request(config)?;
    let pcm: Vec<&SupportedStreamConfigRange> = offers
        .iter()
        .filter(|r| format_rank(r.sample_format()).is_some())
        .collect();
    if pcm.is_empty() {
        return Err(Refusal::NoPcm { direction });
    }

    let with_channels: Vec<&SupportedStreamConfigRange> = pcm
        .iter()
        .copied()
        .filter(|r| r.channels() == config.channels)
        .collect();
    if with_channels.is_empty() {
        return Err(Refusal::Channels {
            wanted: config.channels,
            offered: pcm.iter().map(|r| r.channels()).collect(),
        });
    }
    let with_rate: Vec<&SupportedStreamConfigRange> = with_channels
        .iter()
        .copied()
        .filter(|r| r.contains_rate(config.rate.0))
        .collect();
    if with_rate.is_empty() {
        return Err(Refusal::Rate {
            rate: config.rate,
            channels: config.channels,
            offered: with_channels
                .iter()
                .map(|r| (r.min_sample_rate(), r.max_sample_rate()))
                .collect(),
        });
    }
    let fits_buffer =
        |r: &&SupportedStreamConfigRange| match (config.buffer_frames, r.buffer_size()) {
            (None, _) | (Some(_), SupportedBufferSize::Unknown) => true,
            (Some(n), &SupportedBufferSize::Range { min, max }) => (min..=max).contains(&n),
        };
    let Some(best) = with_rate
        .iter()
        .copied()
        .filter(fits_buffer)
        .min_by_key(|r| format_rank(r.sample_format()))
    else {
        return Err(Refusal::Buffer {
            frames: config.buffer_frames.unwrap_or(0),
            rate: config.rate,
            channels: config.channels,
            offered: with_rate
                .iter()
                .filter_map(|r| match *r.buffer_size() {
                    SupportedBufferSize::Range { min, max } => Some((min, max)),
                    SupportedBufferSize::Unknown => None,
                })
                .collect(),
        });
    };

    let buffer_size = match config.buffer_frames {
        Some(n) => BufferSize::Fixed(n),
        None => BufferSize::Default,
    };
    let scratch_frames = match (config.buffer_frames, best.buffer_size()) {
        (Some(n), _) => n,
        (None, &SupportedBufferSize::Range { max, .. }) => max.min(MAX_SCRATCH_FRAMES),
        (None, SupportedBufferSize::Unknown) => MAX_SCRATCH_FRAMES,
    };
    Ok(Chosen {
        stream: StreamConfig {
            channels: config.channels,
            sample_rate: config.rate.0,
            buffer_size,
        },
        format: best.sample_format(),
        scratch_frames: usize::try_from(scratch_frames.max(1)).unwrap_or(1),
    })
}

/// Preference among PCM formats, best first; `None` for formats that cannot carry PCM.
fn format_rank(format: SampleFormat) -> Option<usize> {
    PREFERENCE.iter().position(|&f| f == format)
}

/// `[1, 2, 3, 6]` -> `"1-3, 6"`.
pub(super) fn spans(mut values: Vec<u32>) -> String {
    values.sort_unstable();
    values.dedup();
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < values.len() {
        let mut j = i;
        while j + 1 < values.len() && values[j + 1] == values[j] + 1 {
            j += 1;
        }
        out.push(if i == j {
            values[i].to_string()
        } else {
            format!("{}-{}", values[i], values[j])
        });
        i = j + 1;
    }
    out.join(", ")
}

fn channel_spans(channels: &[u16]) -> String {
    spans(channels.iter().map(|&c| u32::from(c)).collect())
}

fn rate_spans(ranges: &[(u32, u32)]) -> String {
    let items: Vec<String> = ranges
        .iter()
        .map(|&(lo, hi)| {
            if lo == hi {
                format!("{lo} Hz")
            } else {
                format!("{lo}-{hi} Hz")
            }
        })
        .collect();
    dedup_join(items)
}

fn buffer_spans(ranges: &[(u32, u32)]) -> String {
    let items: Vec<String> = ranges
        .iter()
        .map(|&(min, max)| {
            if min == max {
                format!("{min}")
            } else {
                format!("{min}-{max}")
            }
        })
        .collect();
    dedup_join(items)
}

fn dedup_join(mut items: Vec<String>) -> String {
    items.sort();
    items.dedup();
    if items.is_empty() {
        "no size the host will say".into()
    } else {
        items.join(", ")
    }
}
