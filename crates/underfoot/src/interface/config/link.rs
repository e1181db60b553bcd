//! `[link]` and `[simulated]`: where the interface is, how often servo frames go out,
//! and how long the insole may stay silent.
//!
//! `port = "simulated"` names no port but a simulated board, configured by the
//! `[simulated]` table: a walk on one foot, its ADC's scale, its servos' speed, and the
//! sensors it presses, found by name (`heel`, `midfoot`, `toe`).

use std::ops::Range;

use toml::Spanned;

use super::raw::{RawLink, RawSimulated};
use super::sensors::Insole;
use super::{ConfigError, Source, factor_ok};
use crate::force::gait::GaitConfig;
use crate::units::{Hz, Seconds};

/// Where the interface is.
#[derive(Debug, Clone, PartialEq)]
pub enum Link {
    /// A serial port.
    Serial {
        /// The port: `/dev/ttyACM0`, `COM3`.
        port: String,
        /// Line speed.
        baud: u32,
    },
    /// The simulated foot (see `sim::SimulatedFoot`).
    Simulated(SimulatedConfig),
}

/// The simulated foot's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulatedConfig {
    /// The walk, one foot.
    pub gait: GaitConfig,
    /// Newtons per count of the simulated ADC.
    pub newtons_per_count: f32,
    /// How fast the simulated servos move, µs per second.
    pub slew: f64,
    /// Frame indices of the heel, midfoot and toe sensors.
    pub heel_midfoot_toe: [usize; 3],
}

/// Checks `[link]`'s numbers and port; returns the servo rate and the insole timeout.
pub(super) fn check(
    link: &RawLink,
    span: &Range<usize>,
    at: &Source<'_>,
) -> Result<(Hz, Seconds), ConfigError> {
    let servo_rate = link.servo_rate_hz;
    if !(servo_rate.is_finite() && (1.0..=500.0).contains(&servo_rate)) {
        return Err(at.invalid(
            "link.servo_rate_hz",
            span,
            format!("{servo_rate}: need 1 to 500"),
        ));
    }
    let timeout = link.insole_timeout_s;
    if !(timeout.is_finite() && (0.01..=10.0).contains(&timeout)) {
        return Err(at.invalid(
            "link.insole_timeout_s",
            span,
            format!("{timeout}: need 0.01 to 10 seconds"),
        ));
    }
    if link.baud == 0 {
        return Err(at.invalid("link.baud", span, "0 baud".into()));
    }
    if link.port.trim().is_empty() {
        return Err(at.invalid(
            "link.port",
            span,
            "empty: a serial port, or \"simulated\"".into(),
        ));
    }
    Ok((Hz(servo_rate), Seconds(timeout)))
}

/// The link `[link]` names: its port, or the simulated board of `[simulated]`, whose
/// sensors are found among `insole`'s by name.
pub(super) fn resolve(
    link: RawLink,
    simulated: Option<&Spanned<RawSimulated>>,
    link_span: Range<usize>,
    insole: &Insole,
    at: &Source<'_>,
) -> Result<Link, ConfigError> {
    if link.port != "simulated" {
        return Ok(Link::Serial {
            port: link.port,
            baud: link.baud,
        });
    }
    let (sim, span) = match simulated {
        Some(s) => (s.get_ref(), s.span()),
        None => {
            return Err(at.invalid(
                "simulated",
                &link_span,
                "port = \"simulated\" needs a [simulated] table".into(),
            ));
        }
    };
    let mut gait = GaitConfig::from_spec(&sim.gait)
        .map_err(|e| at.invalid("simulated.gait", &span, e.to_string()))?;
    // One prosthetic foot.
    gait.channels = 1;
    gait.validate()
        .map_err(|e| at.invalid("simulated.gait", &span, e.to_string()))?;
    if !factor_ok(sim.newtons_per_count) {
        return Err(at.invalid(
            "simulated.newtons_per_count",
            &span,
            format!("{}: need a positive finite factor", sim.newtons_per_count),
        ));
    }
    if !(sim.slew_us_per_s.is_finite() && sim.slew_us_per_s > 0.0) {
        return Err(at.invalid(
            "simulated.slew_us_per_s",
            &span,
            format!("{}: need a positive finite rate", sim.slew_us_per_s),
        ));
    }
    let mut roles = [0; 3];
    for (r, name) in roles.iter_mut().zip(["heel", "midfoot", "toe"]) {
        *r = insole.index_of(name).ok_or_else(|| {
            at.invalid(
                "simulated",
                &span,
                format!("the simulated foot needs a [[sensor]] named {name:?}"),
            )
        })?;
    }
    Ok(Link::Simulated(SimulatedConfig {
        gait,
        newtons_per_count: sim.newtons_per_count,
        slew: sim.slew_us_per_s,
        heel_midfoot_toe: roles,
    }))
}
