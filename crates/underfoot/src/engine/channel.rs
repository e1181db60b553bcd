//! One channel: force in, a material's voice, vibration out.
//!
//! A step detected in the force (or announced) starts the material's excitation
//! ([`crate::excitation::Generator`]): its heel impulse at the strike's sample, then its
//! train on a clock driven by `|dF/dt|` of the same interpolated force the drives see. The
//! IIR voice filters that excitation (the `impulse` drive) and the physical model is struck
//! by it, whatever the drive; the `force` and `force-rate` drives feed the voice the force
//! itself instead.

use super::{EngineConfig, Telemetry};
use crate::excitation::clock::speed_per_newton_per_second;
use crate::excitation::{Generator, Tables};
use crate::force::SensorReading;
use crate::force::condition::ForceConditioner;
use crate::force::drive::{DriveKind, Polarity};
use crate::force::steps::{ReadingTime, StepDetector};
use crate::physical::Ground;
use crate::safety::peak_abs;
use crate::signal::noise::SplitMix64;
use crate::synthesis::{Lane, PreparedMaterial, Voice};
use crate::units::Seconds;

/// A channel's state. All buffers are sized at construction; rendering never allocates.
pub(super) struct Channel {
    /// Its index in the engine: which meter of the telemetry it counts on.
    index: usize,
    conditioner: ForceConditioner,
    detector: StepDetector,
    rng: SplitMix64,
    drive: DriveKind,
    polarity: Polarity,
    weight: f64,
    rate_hz: f64,
    /// The perturbation every material gets, when the configuration fixes one.
    sigma_override: Option<f32>,
    /// The current material's perturbation.
    sigma: f32,
    /// The step's excitation, and the current material's tables for it.
    excitation: Generator,
    tables: Tables,
    /// `|ΔF|` per sample (N) to the excitation clock's speed: `f_s / (W ḡ)`.
    speed_per_newton: f32,
    /// The voice playing now, and the one fading out after a material change.
    voices: [Voice; 2],
    /// The same for materials played by their physical model (when the bank has them),
    /// and which of the two each slot plays.
    grounds: Option<[Ground; 2]>,
    physical: [bool; 2],
    current: usize,
    slot: Option<u16>,
    fade_left: u32,
    fade_len: u32,
    pending_impulse: f32,
    /// The intensity of a strike (or step) taken since [`Channel::take_struck`] was last
    /// called: the engine logs it ([`super::StrikeRecord`]).
    struck: Option<f32>,
    previous_total: f32,
    last_drive: f32,
    /// The largest absolute drive sample of the last block rendered, for the meter.
    drive_peak: f32,
    drive_buf: Vec<f32>,
    /// The excitation of the block: the drive of the `impulse` voice and of physical models.
    excitation_buf: Vec<f32>,
    out_a: Vec<f32>,
    out_b: Vec<f32>,
}

impl Channel {
    /// `ground` is any physical model of the bank: the channel keeps two copies to load
    /// the bank's physical models into without allocating.
    pub(super) fn new(config: &EngineConfig, index: usize, ground: Option<&Ground>) -> Self {
        let rate = config.rate;
        Self {
            index,
            conditioner: ForceConditioner::new(rate, config.sensor_rate),
            detector: StepDetector::new(&config.detector, config.sensor_rate),
            // Each channel its own stream: steps on two feet are not the same.
            rng: SplitMix64::new(config.seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)),
            drive: config.drive,
            polarity: config.polarity,
            weight: config.nominal_weight.0.max(1e-9),
            rate_hz: rate.hz(),
            sigma_override: config.perturbation,
            sigma: config.perturbation.unwrap_or(0.0),
            excitation: Generator::new(
                !config.seed ^ (index as u64).wrapping_mul(0xD1B5_4A32_D192_ED03),
            ),
            tables: Tables::heel_only(rate),
            speed_per_newton: (speed_per_newton_per_second(config.nominal_weight) * rate.hz())
                as f32,
            voices: [Voice::new(), Voice::new()],
            grounds: ground.map(|g| [g.clone(), g.clone()]),
            physical: [false; 2],
            current: 0,
            slot: None,
            fade_left: 0,
            fade_len: rate.samples_in(config.crossfade).max(1) as u32,
            pending_impulse: 0.0,
            struck: None,
            previous_total: 0.0,
            last_drive: 0.0,
            drive_peak: 0.0,
            drive_buf: vec![0.0; config.max_block],
            excitation_buf: vec![0.0; config.max_block],
            out_a: vec![0.0; config.max_block],
            out_b: vec![0.0; config.max_block],
        }
    }

    /// The largest absolute drive sample of the last block rendered.
    pub(super) fn drive_peak(&self) -> f32 {
        if self.drive_peak.is_finite() {
            self.drive_peak
        } else {
            f32::MAX
        }
    }

    /// The intensity of the strike the last event started, if it started one.
    pub(super) fn take_struck(&mut self) -> Option<f32> {
        self.struck.take()
    }

    /// The bank slot the channel plays, if it has a material.
    pub(super) fn slot(&self) -> Option<u16> {
        self.slot
    }

    /// Its index in the engine.
    pub(super) fn index(&self) -> usize {
        self.index
    }

    /// Switches to a material; the old voice fades out over the crossfade time.
    pub(super) fn set_material(&mut self, slot: u16, material: &PreparedMaterial) {
        if self.slot == Some(slot) {
            return;
        }
        let next = 1 - self.current;
        self.tables.clone_from(&material.excitation);
        self.sigma = self.sigma_override.unwrap_or(material.perturbation);
        match (&material.ground, &mut self.grounds) {
            (Some(model), Some(grounds)) => {
                grounds[next].assign_from(model);
                self.physical[next] = true;
            }
            _ => {
                self.voices[next].load(material, self.drive);
                self.voices[next].perturb(&mut self.rng, self.sigma);
                self.voices[next].settle(self.last_drive);
                self.physical[next] = false;
            }
        }
        let had_material = self.slot.is_some();
        self.current = next;
        self.slot = Some(slot);
        self.fade_left = if had_material { self.fade_len } else { 0 };
    }

    /// A force reading applied at engine frame `frame`. The detector times it by its
    /// sensor time when it has one, else by the frame. Returns whether it was taken (a
    /// reading that was feeds the channel's watchdog).
    pub(super) fn force(
        &mut self,
        reading: &SensorReading,
        frame: u64,
        telemetry: &Telemetry,
    ) -> bool {
        if !reading.is_finite() {
            telemetry.count_rejected();
            return false;
        }
        self.conditioner.push(reading);
        telemetry.meter_force(self.index, reading);
        let time = reading.time().map_or_else(
            || ReadingTime::Arrival(Seconds(frame as f64 / self.rate_hz)),
            ReadingTime::Sensor,
        );
        if let Some(strike) = self.detector.update(reading.total(), time) {
            self.strike(strike.intensity, telemetry);
        }
        true
    }

    /// An explicit step from a source that detects steps itself. Returns whether it was
    /// taken (a step that was keeps the channel alive for its window).
    pub(super) fn step(&mut self, intensity: f32, telemetry: &Telemetry) -> bool {
        if !intensity.is_finite() {
            telemetry.count_rejected();
            return false;
        }
        let intensity = intensity.clamp(0.0, 4.0);
        telemetry.count_strike(self.index);
        self.struck = Some(intensity);
        self.perturb();
        // No force will follow: the excitation's clock runs at the nominal pace.
        self.excitation.step(&self.tables, intensity);
        // A step event is an impulse whatever the drive: there is no force to follow.
        if self.drive != DriveKind::Impulse {
            self.pending_impulse += intensity;
        }
        true
    }

    fn strike(&mut self, intensity: f32, telemetry: &Telemetry) {
        telemetry.count_strike(self.index);
        self.struck = Some(intensity);
        self.perturb();
        self.excitation.strike(&self.tables, intensity);
    }

    fn perturb(&mut self) {
        for v in &mut self.voices {
            v.perturb(&mut self.rng, self.sigma);
        }
    }

    /// The first part of rendering `n` samples (at most `max_block`): the block's drive
    /// and excitation. Then [`lane`](Self::lane) (the engine runs the IIR voices of all
    /// channels together) and [`finish`](Self::finish).
    pub(super) fn prepare(&mut self, n: usize) {
        let n = n.min(self.drive_buf.len());
        let drive = &mut self.drive_buf[..n];
        let excitation = &mut self.excitation_buf[..n];
        // The clock speeds first, then the whole block of excitation: the generator's
        // state stays in registers through its own loop. The force's state is copied
        // out for the loop for the same reason: written through `self`, it would have
        // to be stored at every sample, as the compiler cannot tell it from the buffers.
        let mut conditioner = self.conditioner.clone();
        let mut previous = self.previous_total;
        let speed_per_newton = self.speed_per_newton;
        if self.drive == DriveKind::Impulse {
            for e in excitation.iter_mut() {
                let total = conditioner.next_total();
                *e = (total - previous).abs() * speed_per_newton;
                previous = total;
            }
        } else {
            for (x, e) in drive.iter_mut().zip(excitation.iter_mut()) {
                let total = conditioner.next_total();
                *e = (total - previous).abs() * speed_per_newton;
                *x = self.drive.sample(
                    f64::from(total),
                    f64::from(previous),
                    self.rate_hz,
                    self.polarity,
                    self.weight,
                ) as f32;
                previous = total;
            }
        }
        self.conditioner = conditioner;
        self.previous_total = previous;
        self.excitation.process_in_place(&self.tables, excitation);
        if self.drive == DriveKind::Impulse {
            drive.copy_from_slice(excitation);
        }
        if let Some(last) = drive.last() {
            // The impulse drive's steady state is rest, whatever the last sample held.
            self.last_drive = if self.drive == DriveKind::Impulse {
                0.0
            } else {
                *last
            };
        }
        if let Some(first) = drive.first_mut() {
            *first += self.pending_impulse;
            self.pending_impulse = 0.0;
        }
        // `max` ignores a NaN, so the meter's bits stay those of a finite value.
        self.drive_peak = peak_abs(drive);
    }

    /// The current voice on the block's drive, when the channel plays a material through
    /// its IIR voice: the engine runs it in a lane beside other channels'.
    pub(super) fn lane(&mut self, n: usize) -> Option<Lane<'_>> {
        let n = n.min(self.drive_buf.len());
        if self.slot.is_none() || self.physical[self.current] {
            return None;
        }
        Some(Lane {
            voice: &mut self.voices[self.current],
            input: &self.drive_buf[..n],
            output: &mut self.out_a[..n],
        })
    }

    /// The rest of the block, once the current voice has run in its [`lane`](Self::lane):
    /// the physical model when the channel plays one, the fading voice and the
    /// crossfade. Returns the block's synthesis and the non-finite resets; the engine's
    /// output stage ([`super::OutputStage`]) takes it from there.
    pub(super) fn finish(&mut self, n: usize) -> (&mut [f32], u32) {
        let n = n.min(self.drive_buf.len());
        let mut resets = 0;
        if self.slot.is_none() {
            self.out_a[..n].fill(0.0);
            return (&mut self.out_a[..n], 0);
        }
        let (cur, old) = (self.current, 1 - self.current);
        let drive = &self.drive_buf[..n];
        let excitation = &self.excitation_buf[..n];
        let [ground_a, ground_b] = match &mut self.grounds {
            Some([a, b]) => [Some(a), Some(b)],
            None => [None, None],
        };
        let (ground_cur, ground_old) = if cur == 0 {
            (ground_a, ground_b)
        } else {
            (ground_b, ground_a)
        };
        let voice_old = &mut self.voices[old];
        if self.physical[cur]
            && let Some(ground) = ground_cur
        {
            resets += ground.process(excitation, &mut self.out_a[..n]);
        }
        if self.fade_left > 0 {
            resets += play(
                voice_old,
                ground_old.filter(|_| self.physical[old]),
                drive,
                excitation,
                &mut self.out_b[..n],
            );
            for i in 0..n {
                // Equal-power crossfade: the two materials' signals are uncorrelated.
                let t = if self.fade_left > 0 {
                    self.fade_left -= 1;
                    self.fade_left as f32 / self.fade_len as f32
                } else {
                    0.0
                };
                let angle = t * std::f32::consts::FRAC_PI_2;
                self.out_a[i] = self.out_a[i] * angle.cos() + self.out_b[i] * angle.sin();
            }
            if self.fade_left == 0 {
                self.voices[old].reset();
                if let Some(grounds) = &mut self.grounds {
                    grounds[old].reset();
                }
            }
        }
        (&mut self.out_a[..n], resets)
    }
}

/// One slot's output: its physical model, struck by the excitation, when it plays one,
/// else its voice on the drive.
fn play(
    voice: &mut Voice,
    ground: Option<&mut Ground>,
    drive: &[f32],
    excitation: &[f32],
    out: &mut [f32],
) -> u32 {
    match ground {
        Some(g) => g.process(excitation, out),
        None => voice.process(drive, out),
    }
}
