//! The file's shape, as serde reads it: every table and key, their types and defaults,
//! unknown keys refused. Nothing here checks a value; the sibling modules do.

use serde::Deserialize;
use toml::Spanned;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawFile {
    pub(super) link: Spanned<RawLink>,
    #[serde(default)]
    pub(super) insole: Option<Spanned<RawInsole>>,
    #[serde(default)]
    pub(super) sensor: Vec<Spanned<RawSensor>>,
    #[serde(default)]
    pub(super) servo: Vec<Spanned<RawServo>>,
    #[serde(default)]
    pub(super) channel: Vec<Spanned<RawChannel>>,
    #[serde(default)]
    pub(super) simulated: Option<Spanned<RawSimulated>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLink {
    pub(super) port: String,
    #[serde(default = "default_baud")]
    pub(super) baud: u32,
    #[serde(default = "default_servo_rate")]
    pub(super) servo_rate_hz: f64,
    #[serde(default = "default_timeout")]
    pub(super) insole_timeout_s: f64,
}

fn default_baud() -> u32 {
    115_200
}
fn default_servo_rate() -> f64 {
    50.0
}
fn default_timeout() -> f64 {
    0.2
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(super) struct RawInsole {
    pub(super) newtons_per_count: Option<f32>,
    pub(super) calibration: Option<String>,
    pub(super) frame_sensors: Option<usize>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSensor {
    pub(super) name: String,
    pub(super) index: usize,
    pub(super) curve: Option<String>,
    pub(super) newtons_per_count: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawServo {
    pub(super) id: u8,
    pub(super) sensors: Vec<String>,
    pub(super) weights: Option<Vec<f64>>,
    pub(super) range_us: [u16; 2],
    pub(super) rest_us: u16,
    pub(super) full_us: u16,
    pub(super) threshold_n: f64,
    pub(super) full_force_n: f64,
    pub(super) dead_band_us: f64,
    pub(super) rate_us_per_s: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawChannel {
    pub(super) name: String,
    pub(super) sensors: Vec<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSimulated {
    #[serde(default)]
    pub(super) gait: String,
    #[serde(default = "default_sim_npc")]
    pub(super) newtons_per_count: f32,
    #[serde(default = "default_sim_slew")]
    pub(super) slew_us_per_s: f64,
}

fn default_sim_npc() -> f32 {
    0.5
}
fn default_sim_slew() -> f64 {
    3000.0
}
