//! The real-time engine: N channels, force in, vibration out.
//!
//! [`build`] splits the engine in two halves that talk only through lock-free
//! single-producer single-consumer queues ([`rtrb`]) and atomics:
//!
//! - the [`Engine`] lives on the audio thread. [`Engine::process`] renders into the buffer
//!   it is given and never allocates, locks, blocks or panics;
//! - the [`Controller`] lives anywhere else. It sends [`TimedEvent`]s (force readings,
//!   steps, material changes) and new materials, reads [`Telemetry`], and frees the
//!   materials the engine has retired, so that no deallocation happens on the audio
//!   thread either.
//!
//! Every material of the bank is prepared before the engine starts; changing a channel's
//! material is a slot index, and the voice copies the coefficients into its own fixed
//! arrays. A replaced material goes back over the retire queue. A material prepared while
//! the engine runs (a fit made from a control panel) goes into one of the spare slots
//! reserved at build ([`EngineConfig::spare_slots`]): the audio thread pushes its pointer
//! into room that is already there. A channel's trim ([`Controller::set_trim`]) lowers
//! its output below the configured gain, smoothly, before the limiter; it can never raise
//! it.
//!
//! A block is rendered in three passes over the channels: each channel's force and
//! excitation; then the IIR voices of all channels, eight at a time, one per SIMD lane
//! ([`VoiceLanes`], which gives each voice the same bits as running it alone); then
//! each channel's physical model or fading voice, and its output stage. The output
//! stage takes a live, settled stretch with nothing near the ceiling as one vector
//! loop ([`OutputStage::process`]), the same products it forms sample by sample.
//!
//! The [`Telemetry`] has a meter per channel that the audio thread writes once per block
//! with relaxed atomics and a reader takes at its own pace: the last reading's force per
//! sensor, strikes, the output's peak and its RMS over exactly the reader's interval, the
//! drive's peak, the limiter's smallest gain, the watchdog's state, the slot and the trim.
//!
//! # Timing
//!
//! An event with a frame (`TimedEvent::at`) takes effect at exactly that sample, whatever
//! the block size: the block is split there. So an offline render is identical for every
//! block size.
//!
//! A force reading without a frame but with its sensor time ([`SensorReading::at`](crate::force::SensorReading::at); a
//! replay or a generated walk stamps every reading) is given a frame by the engine's
//! sensor clock ([`clock`], which states the rule): the first one anchors sensor time `t_A`
//! at frame `A = F + B + M` (drained at the start of a call at frame `F` of `B` frames,
//! `M` = [`EngineConfig::sensor_latency`]), and every one applies at
//! `frame(t) = A + round((t − t_A) · fs)`, exactly, like a timed event. A step's onset is
//! then `frame(t_s)`, `t_s` the sensor time of the reading that crosses the threshold, and
//! its intensity comes from the readings' sensor times ([`crate::force::steps`]): a live
//! session plays what an offline render of the same track plays, shifted by a constant,
//! for every block size (tested for 16 to 1024 frames). The price is a fixed latency of
//! one block plus `M`.
//!
//! Any other event without a frame (an explicit step, a material change, a reading that
//! knows no sensor time) takes effect at the start of the next block: its impulse reaches
//! the output in the first block rendered after it arrives.
//!
//! # Output
//!
//! Channel `c` goes to device channel `c`; device channels beyond the engine's are zero.
//! Each channel's synthesis leaves through its own [`OutputStage`], the one place where
//! the engine's samples become output: the configured compensation (the device equalizer
//! and the limb filter, [`EngineConfig::compensation`]), then the watchdog, the output
//! gain and the [`Fader`] (which ramps everything in at start and out at
//! [`Controller::stop`]), then the non-finite guard and the limiter's ceiling. Nothing
//! runs after it, so the safety stages hold for every model kind and every compensation
//! ([`crate::safety`]). A channel without a device channel runs its stage too, so its
//! state stays in time.
//!
//! # Files
//!
//! | file | what |
//! |---|---|
//! | `config.rs` | [`EngineConfig`] and [`EngineError`] |
//! | `bank.rs` | [`MaterialBank`]: the materials, prepared off the audio thread |
//! | `controller.rs` | [`Controller`], the control half |
//! | `audio.rs` | [`Engine`], the audio half: events at their frame, the render loop |
//! | `channel.rs` | one channel: force in, a material's voice, vibration out |
//! | [`clock`] | the sensor clock: readings placed by their own time |
//! | [`event`] | what reaches the audio thread |
//! | `output.rs` | [`OutputStage`]: compensation, then every safety stage |
//! | `telemetry.rs` | [`Telemetry`]: the counters the audio half publishes |
//! | [`offline`] | the engine run as fast as it goes, on timed events |

mod audio;
mod bank;
mod channel;
pub mod clock;
mod config;
mod controller;
pub mod event;
pub mod offline;
mod output;
pub mod settings;
mod telemetry;

use std::sync::Arc;

pub use clock::ClockAnchor;
pub use event::{Event, StrikeRecord, TimedEvent};

use crate::compensation::CompensationError;
use crate::compensation::chain::CompensationChain;
use crate::safety::Fader;
use crate::synthesis::{LANE_WIDTH, PreparedMaterial, VoiceLanes};
pub use audio::Engine;
pub use bank::MaterialBank;
use channel::Channel;
use clock::SensorClock;
pub use config::{EngineConfig, EngineError};
pub use controller::Controller;
pub use output::OutputStage;
pub use settings::{PlayError, PlaySettings};
pub use telemetry::{ChannelLevels, Telemetry, TelemetrySnapshot};

/// Builds an engine and its controller. `initial` is each channel's starting material
/// (slot in `bank`); a channel without one is silent until it gets a material event.
///
/// # Errors
/// An invalid configuration, or an initial slot beyond the bank.
pub fn build(
    config: &EngineConfig,
    bank: MaterialBank,
    initial: &[u16],
) -> Result<(Controller, Engine), EngineError> {
    if config.channels == 0 || config.channels > usize::from(u16::MAX) {
        return Err(EngineError::InvalidConfig(format!(
            "{} channels: need 1 to 65535",
            config.channels
        )));
    }
    if config.max_block == 0 || config.queue_capacity == 0 {
        return Err(EngineError::InvalidConfig(
            "max_block and queue_capacity must be positive".into(),
        ));
    }
    if !(config.ceiling.0.is_finite() && config.gain.0.is_finite()) || config.ceiling.0 > 0.0 {
        return Err(EngineError::InvalidConfig(format!(
            "ceiling {} and gain {} must be finite, the ceiling at most 0 dB (full scale)",
            config.ceiling, config.gain
        )));
    }
    if !(config.sensor_latency.0.is_finite() && (0.0..=1.0).contains(&config.sensor_latency.0)) {
        return Err(EngineError::InvalidConfig(format!(
            "sensor latency {} must be 0 to 1 s",
            config.sensor_latency
        )));
    }
    if let Some(sigma) = config.perturbation
        && !(sigma.is_finite() && (0.0..=0.5).contains(&sigma))
    {
        return Err(EngineError::InvalidConfig(format!(
            "perturbation {sigma} must be in 0..0.5"
        )));
    }
    if let Some(bad) = initial
        .iter()
        .find(|s| usize::from(**s) >= bank.materials.len())
    {
        return Err(EngineError::InvalidConfig(format!(
            "initial material slot {bad} is beyond the bank of {}",
            bank.materials.len()
        )));
    }
    let names = bank.names();
    let (command_tx, command_rx) = rtrb::RingBuffer::new(config.queue_capacity);
    // Room for every replacement that could be in flight, so the engine never has to
    // drop a retired material on the audio thread.
    let (retire_tx, retire_rx) = rtrb::RingBuffer::new(config.queue_capacity);
    let telemetry = Arc::new(Telemetry::new(config.channels));
    let (strike_tx, strike_rx) = rtrb::RingBuffer::new(event::STRIKE_LOG);
    if config.spare_slots > usize::from(u16::MAX) - bank.materials.len() {
        return Err(EngineError::InvalidConfig(format!(
            "{} spare slots beyond {} materials: at most 65535 slots in all",
            config.spare_slots,
            bank.materials.len()
        )));
    }
    let capacity = bank.materials.len() + config.spare_slots;
    // Reserved now, so that adding a material on the audio thread is a push into room
    // that is already there.
    let mut slots: Vec<Box<PreparedMaterial>> = Vec::with_capacity(capacity);
    slots.extend(bank.materials.into_iter().map(Box::new));
    let bank = slots;
    let prototype = bank.iter().find_map(|m| m.ground.as_ref());
    let mut channels: Vec<Channel> = (0..config.channels)
        .map(|c| Channel::new(config, c, prototype))
        .collect();
    for (ch, slot) in channels.iter_mut().zip(initial) {
        ch.set_material(*slot, &bank[usize::from(*slot)]);
        telemetry.meter_slot(ch.index(), *slot);
    }
    let stages = (0..config.channels)
        .map(|_| {
            let chain = if config.compensation.is_identity() {
                None
            } else {
                Some(CompensationChain::new(
                    &config.compensation,
                    config.rate,
                    64,
                )?)
            };
            Ok(OutputStage::new(
                chain,
                &config.watchdog,
                config.ceiling,
                config.release,
                config.rate,
            ))
        })
        .collect::<Result<Vec<_>, CompensationError>>()?;
    let engine = Engine {
        rate: config.rate,
        stages,
        channels,
        bank,
        fader: Fader::fade_in(config.fade, config.rate),
        gain: config.gain.to_amplitude() as f32,
        frame: 0,
        pending: Vec::with_capacity(config.queue_capacity),
        commands: command_rx,
        retired: retire_tx,
        strike_log: strike_tx,
        telemetry: Arc::clone(&telemetry),
        scratch: vec![0.0; config.max_block],
        lanes: vec![VoiceLanes::new(); config.channels.div_ceil(LANE_WIDTH)],
        peak: 0.0,
        clock: SensorClock::new(config.rate, config.sensor_latency),
    };
    let controller = Controller {
        commands: command_tx,
        retired: retire_rx,
        strike_log: strike_rx,
        telemetry,
        names,
        capacity,
        rate: config.rate,
    };
    Ok((controller, engine))
}
