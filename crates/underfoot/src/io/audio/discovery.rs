//! The host and its devices: which device a name means, and what each offers.
//!
//! The device is [`AudioConfig::device`], matched in this order against the host's
//! devices of the stream's direction: the exact device id (`null`, `hw:CARD=1,DEV=0`),
//! the id in ALSA's short form (`hw:1` means `hw:CARD=1,DEV=0`), the exact description,
//! then the first id or description that contains it (case-insensitive). [`list_devices`]
//! shows the candidates.
//!
//! Opening a device asks it for its configurations and hands them to the pure
//! [`choose_config`].

use std::str::FromStr;

use cpal::traits::{DeviceTrait, HostTrait};
use cpal::{SupportedBufferSize, SupportedStreamConfigRange};

use super::choose::{Chosen, Refusal, check_request, choose_config};
use super::{AudioConfig, AudioHost, Direction, SampleFormat};
use crate::io::IoError;
use crate::units::SampleRate;

/// Rates listed by [`list_devices`] when a device offers a continuous range.
const STANDARD_RATES: [u32; 11] = [
    8_000, 11_025, 16_000, 22_050, 32_000, 44_100, 48_000, 88_200, 96_000, 176_400, 192_000,
];

/// One output device, for `--list-devices`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceInfo {
    /// The id to pass as [`AudioConfig::device`] (`"hw:CARD=0,DEV=0"`, `"null"`).
    pub name: String,
    /// What the host calls it (`"HDA Intel PCH, ALC892 Analog"`).
    pub description: String,
    /// The most output channels of any configuration.
    pub max_channels: u16,
    /// Rates it accepts: the standard rates inside its ranges, and any single-rate
    /// configuration (a JACK server's rate).
    pub rates: Vec<SampleRate>,
    /// Smallest and largest buffer in frames, if the host says.
    pub buffer_frames: Option<(u32, u32)>,
    /// Sample formats it offers.
    pub formats: Vec<SampleFormat>,
    /// Why its configurations could not be read (busy, no permission); the other fields
    /// are then empty.
    pub problem: Option<String>,
}

/// Lists the output devices of `host` with what each offers.
///
/// A device whose configurations cannot be read (busy, no permission) is listed with
/// [`DeviceInfo::problem`] set rather than failing the whole list.
///
/// # Errors
/// [`IoError::Open`] if the host is unavailable or cannot enumerate its devices.
pub fn list_devices(host: AudioHost) -> Result<Vec<DeviceInfo>, IoError> {
    let (host, kind) = open_host(host)?;
    let devices = output_devices(&host).map_err(|e| IoError::Open {
        device: kind.to_string(),
        reason: format!("cannot list output devices: {e}"),
    })?;
    Ok(devices.iter().map(describe_device).collect())
}

/// The host's output devices. cpal's own filter keeps JACK's input device, whose
/// configurations it lists for both directions; its description knows better.
fn output_devices(host: &cpal::Host) -> Result<Vec<cpal::Device>, cpal::Error> {
    Ok(host.output_devices()?.filter(is_output).collect())
}

fn is_output(device: &cpal::Device) -> bool {
    device.supports_output()
        && !matches!(device.description(), Ok(d) if d.direction() == cpal::DeviceDirection::Input)
}

fn describe_device(device: &cpal::Device) -> DeviceInfo {
    let mut info = DeviceInfo {
        name: device_id(device),
        description: device_description(device),
        max_channels: 0,
        rates: Vec::new(),
        buffer_frames: None,
        formats: Vec::new(),
        problem: None,
    };
    let ranges: Vec<SupportedStreamConfigRange> = match device.supported_output_configs() {
        Ok(r) => r.filter(|r| !r.sample_format().is_dsd()).collect(),
        Err(e) => {
            info.problem = Some(e.to_string());
            return info;
        }
    };
    info.max_channels = ranges.iter().map(|r| r.channels()).max().unwrap_or(0);
    let mut rates: Vec<u32> = STANDARD_RATES
        .into_iter()
        .filter(|&rate| ranges.iter().any(|r| r.contains_rate(rate)))
        .chain(
            ranges
                .iter()
                .filter(|r| r.min_sample_rate() == r.max_sample_rate())
                .map(|r| r.min_sample_rate()),
        )
        .collect();
    rates.sort_unstable();
    rates.dedup();
    info.rates = rates.into_iter().map(SampleRate).collect();
    info.buffer_frames = ranges
        .iter()
        .filter_map(|r| match *r.buffer_size() {
            SupportedBufferSize::Range { min, max } => Some((min, max)),
            SupportedBufferSize::Unknown => None,
        })
        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)));
    for r in &ranges {
        if !info.formats.contains(&r.sample_format()) {
            info.formats.push(r.sample_format());
        }
    }
    info
}

/// Resolves the host; `Default` becomes the concrete host so that
/// [`StreamInfo`](super::StreamInfo) says what was used.
fn open_host(kind: AudioHost) -> Result<(cpal::Host, AudioHost), IoError> {
    let (id, kind) = match kind {
        // cpal::default_host() panics when ALSA cannot be initialised; going through the
        // id gives an error instead. Without the pipewire/pulseaudio features (not
        // enabled here) ALSA is exactly what default_host() would pick on Linux.
        AudioHost::Default | AudioHost::Alsa => (alsa_host_id()?, AudioHost::Alsa),
        #[cfg(feature = "jack")]
        AudioHost::Jack => (cpal::HostId::Jack, AudioHost::Jack),
    };
    let host = cpal::host_from_id(id).map_err(|e| IoError::Open {
        device: kind.to_string(),
        reason: format!("audio host unavailable: {e}"),
    })?;
    Ok((host, kind))
}

fn alsa_host_id() -> Result<cpal::HostId, IoError> {
    cpal::HostId::from_str("alsa").map_err(|_| IoError::Open {
        device: AudioHost::Alsa.to_string(),
        reason: "ALSA is not available on this platform".into(),
    })
}

fn device_id(device: &cpal::Device) -> String {
    match device.id() {
        Ok(id) => id.id().to_string(),
        Err(_) => device_description(device),
    }
}

fn device_description(device: &cpal::Device) -> String {
    device
        .description()
        .map(|d| d.name().to_string())
        .unwrap_or_default()
}

/// The host's devices in `direction`.
fn devices_in(host: &cpal::Host, direction: Direction) -> Result<Vec<cpal::Device>, cpal::Error> {
    match direction {
        Direction::Output => output_devices(host),
        Direction::Input => Ok(host
            .input_devices()?
            .filter(|d| goes(d, Direction::Input))
            .collect()),
    }
}

/// Whether `device` carries audio in `direction`. cpal lists JACK's synthetic devices
/// under both directions; their description says which one each really is.
fn goes(device: &cpal::Device, direction: Direction) -> bool {
    match direction {
        Direction::Output => is_output(device),
        Direction::Input => {
            device.supports_input()
                && !matches!(device.description(), Ok(d) if d.direction() == cpal::DeviceDirection::Output)
        }
    }
}

fn default_device(host: &cpal::Host, direction: Direction) -> Option<cpal::Device> {
    match direction {
        Direction::Output => host.default_output_device(),
        Direction::Input => host.default_input_device(),
    }
}

fn find_device(
    host: &cpal::Host,
    kind: AudioHost,
    wanted: Option<&str>,
    direction: Direction,
) -> Result<cpal::Device, IoError> {
    let no_device = |reason: String| IoError::Open {
        device: match wanted {
            Some(w) => format!("{kind} device \"{w}\""),
            None => format!("{kind} default {direction} device"),
        },
        reason,
    };
    let server_hint = match kind {
        #[cfg(feature = "jack")]
        AudioHost::Jack => " (is a JACK server running? cpal does not start one)",
        _ => "",
    };
    let Some(wanted) = wanted else {
        return default_device(host, direction)
            .ok_or_else(|| no_device(format!("the host has no {direction} device{server_hint}")));
    };

    let devices = devices_in(host, direction)
        .map_err(|e| no_device(format!("cannot list {direction} devices: {e}")))?;
    let ids: Vec<String> = devices.iter().map(device_id).collect();
    let descriptions: Vec<String> = devices.iter().map(device_description).collect();

    if let Some(i) = ids.iter().position(|id| id == wanted) {
        return Ok(devices[i].clone());
    }
    // ALSA's "default" is not always among the enumerated devices, but always opens.
    if let Some(device) = default_device(host, direction)
        && device_id(&device) == wanted
    {
        return Ok(device);
    }
    // ALSA ids are canonicalised by the host ("hw:1" -> "hw:CARD=1,DEV=0").
    if let Some(device) = host.device_by_id(&cpal::DeviceId::new(host.id(), wanted))
        && goes(&device, direction)
    {
        return Ok(device);
    }
    if let Some(i) = descriptions
        .iter()
        .position(|d| d.eq_ignore_ascii_case(wanted))
    {
        return Ok(devices[i].clone());
    }
    let needle = wanted.to_lowercase();
    if let Some(i) = (0..devices.len()).find(|&i| {
        ids[i].to_lowercase().contains(&needle) || descriptions[i].to_lowercase().contains(&needle)
    }) {
        return Ok(devices[i].clone());
    }
    let available = if ids.is_empty() {
        format!("the host has no {direction} device{server_hint}")
    } else {
        format!("no such {direction} device; available: {}", ids.join(", "))
    };
    Err(no_device(available))
}

/// A device found and configured for one direction, not yet streaming.
pub(super) struct Opened {
    pub(super) device: cpal::Device,
    pub(super) host_kind: AudioHost,
    /// The device id.
    pub(super) name: String,
    /// Host and id, for messages.
    pub(super) label: String,
    pub(super) chosen: Chosen,
}

/// Finds the device `config` names among the host's devices in `direction` and chooses
/// its stream configuration.
pub(super) fn open_device(config: &AudioConfig, direction: Direction) -> Result<Opened, IoError> {
    let (host, host_kind) = open_host(config.host)?;
    let device = find_device(&host, host_kind, config.device.as_deref(), direction)?;
    let name = device_id(&device);
    let label = format!("{host_kind} device \"{name}\"");
    let chosen = configure(&device, &label, config, direction)?;
    Ok(Opened {
        device,
        host_kind,
        name,
        label,
        chosen,
    })
}

/// Asks `device` what it offers in `direction` and chooses among it. A request no device
/// could meet is refused before the device is asked.
fn configure(
    device: &cpal::Device,
    label: &str,
    config: &AudioConfig,
    direction: Direction,
) -> Result<Chosen, IoError> {
    let unsupported = |refusal: Refusal| IoError::Unsupported {
        device: label.to_string(),
        reason: refusal.to_string(),
    };
    check_request(config).map_err(unsupported)?;
    let cannot_read = |e: cpal::Error| IoError::Open {
        device: label.to_string(),
        reason: format!("cannot read its {direction} configurations: {e}"),
    };
    let offers: Vec<SupportedStreamConfigRange> = match direction {
        Direction::Output => device
            .supported_output_configs()
            .map_err(cannot_read)?
            .collect(),
        Direction::Input => device
            .supported_input_configs()
            .map_err(cannot_read)?
            .collect(),
    };
    choose_config(&offers, config, direction).map_err(unsupported)
}
