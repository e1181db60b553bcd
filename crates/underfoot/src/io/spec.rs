//! The command line's spec strings and bounded numbers, parsed in one place.
//!
//! Every parser here is a pure `fn(&str) -> Result<T, SpecError>`: no file is opened and
//! no device touched, so each can be fuzzed on arbitrary text, and each error names the
//! text it refused. Every number comes out finite and inside a documented range, so that
//! nothing downstream turns a duration into a frame count that overflows, a band into a
//! matrix of non-finite values, or a rate into an allocation of gigabytes.
//!
//! | spec | form | bounds |
//! |---|---|---|
//! | [`InputSpec`] | `replay:FILE[@SPEED]`, `gait:SPEC`, `serial:PORT`, `osc:HOST:PORT` | speed [`MIN_SPEED`]..=[`MAX_SPEED`]; gait keys as [`GaitConfig::validate`] |
//! | [`OutputSpec`] | `audio[:DEVICE]`, `wav:FILE`, `null` | |
//! | [`Band`] | `LO:HI` (or `LO,HI`) in Hz | [`MIN_BAND_EDGE`] <= LO < HI <= [`MAX_BAND_EDGE`] |
//! | [`parse_seconds`], [`parse_number`] | seconds, a number | finite, in the caller's range |
//! | [`parse_session_duration`] | seconds | 0..=[`MAX_SESSION`] |
//! | [`parse_rate`] | whole Hz | in the caller's range |
//! | [`parse_count`] | a whole number | in the caller's range |

use std::path::PathBuf;
use std::str::FromStr;

use crate::force::gait::GaitConfig;
use crate::units::{Band, BandError, SampleRate, Seconds, clipped};

/// Slowest replay: a thousandth of real time.
pub const MIN_SPEED: f64 = 1e-3;
/// Fastest replay: a thousand times real time.
pub const MAX_SPEED: f64 = 1e3;
/// Lowest band edge: [`Band::MIN_EDGE`], 0.1 Hz.
pub const MIN_BAND_EDGE: f64 = Band::MIN_EDGE;
/// Highest band edge: [`Band::MAX_EDGE`], 100 kHz.
pub const MAX_BAND_EDGE: f64 = Band::MAX_EDGE;
/// Longest live session: 30 days.
pub const MAX_SESSION: Seconds = Seconds(30.0 * 86_400.0);

/// A spec string or number that was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SpecError {
    /// The text does not parse, or its value is out of range.
    #[error("{what} {input:?}: {reason}")]
    Invalid {
        /// What was being parsed, e.g. `--input` or `duration`.
        what: &'static str,
        /// The text as given.
        input: String,
        /// What is wrong, and what is expected.
        reason: String,
    },
}

fn invalid(what: &'static str, input: &str, reason: impl Into<String>) -> SpecError {
    SpecError::Invalid {
        what,
        input: clipped(input),
        reason: reason.into(),
    }
}

impl From<BandError> for SpecError {
    fn from(e: BandError) -> Self {
        invalid("band", e.input(), e.reason())
    }
}

/// Where force comes from (`underfoot run --input`).
#[derive(Debug, Clone, PartialEq)]
pub enum InputSpec {
    /// `replay:FILE[@SPEED]`: a force track at `speed` times real time (1 without `@`).
    Replay {
        /// The track's file.
        file: PathBuf,
        /// Times real time, [`MIN_SPEED`]..=[`MAX_SPEED`].
        speed: f64,
    },
    /// `gait:SPEC`: a generated walk ([`GaitConfig::from_spec`], validated).
    Gait(Box<GaitConfig>),
    /// `serial:PORT`: a microcontroller on a serial port.
    Serial {
        /// The port, e.g. `/dev/ttyACM0`.
        port: String,
    },
    /// `osc:HOST:PORT`: OSC messages over UDP.
    Osc {
        /// The address to listen on, `HOST:PORT`.
        addr: String,
    },
}

impl InputSpec {
    /// Parses an input spec; see the [module docs](self).
    ///
    /// # Errors
    /// [`SpecError::Invalid`] naming the text.
    pub fn parse(s: &str) -> Result<Self, SpecError> {
        const WHAT: &str = "--input";
        let Some((kind, rest)) = s.split_once(':') else {
            return Err(invalid(
                WHAT,
                s,
                "expected replay:FILE[@SPEED], gait:SPEC, serial:PORT or osc:HOST:PORT",
            ));
        };
        match kind {
            "replay" => {
                let (file, speed) = match rest.rsplit_once('@') {
                    Some((file, speed)) => (file, parse_speed(speed)?),
                    None => (rest, 1.0),
                };
                if file.is_empty() || file.contains('\0') {
                    return Err(invalid(WHAT, s, "replay: needs a file"));
                }
                Ok(Self::Replay {
                    file: PathBuf::from(file),
                    speed,
                })
            }
            "gait" => GaitConfig::from_spec(rest)
                .map(|g| Self::Gait(Box::new(g)))
                .map_err(|e| invalid(WHAT, s, e.to_string())),
            "serial" => {
                if rest.trim().is_empty() || rest.contains('\0') {
                    return Err(invalid(WHAT, s, "serial: needs a port, e.g. /dev/ttyACM0"));
                }
                Ok(Self::Serial {
                    port: rest.to_owned(),
                })
            }
            "osc" => {
                let bad = || invalid(WHAT, s, "osc: needs HOST:PORT, e.g. 0.0.0.0:9000");
                let (host, port) = rest.rsplit_once(':').ok_or_else(bad)?;
                if host.is_empty() || host.contains('\0') || port.parse::<u16>().is_err() {
                    return Err(bad());
                }
                Ok(Self::Osc {
                    addr: rest.to_owned(),
                })
            }
            _ => Err(invalid(
                WHAT,
                s,
                format!("unknown kind {kind:?} (replay, gait, serial, osc)"),
            )),
        }
    }
}

impl FromStr for InputSpec {
    type Err = SpecError;
    fn from_str(s: &str) -> Result<Self, SpecError> {
        Self::parse(s)
    }
}

/// A replay speed: finite, [`MIN_SPEED`]..=[`MAX_SPEED`].
///
/// # Errors
/// [`SpecError::Invalid`] naming the text.
pub fn parse_speed(s: &str) -> Result<f64, SpecError> {
    let reason = format!("expected a speed from {MIN_SPEED} to {MAX_SPEED} times real time");
    match s.trim().parse::<f64>() {
        Ok(v) if (MIN_SPEED..=MAX_SPEED).contains(&v) => Ok(v),
        _ => Err(invalid("replay speed", s, reason)),
    }
}

/// Where vibration goes (`underfoot run --output`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OutputSpec {
    /// `audio` or `audio:DEVICE`: a sound card (the host's default without a device).
    Audio {
        /// The device's id or description, if named.
        device: Option<String>,
    },
    /// `wav:FILE`: a WAV file, paced like a device.
    Wav {
        /// The file.
        path: PathBuf,
    },
    /// `null`: nowhere, paced like a device.
    Null,
}

impl OutputSpec {
    /// Parses an output spec; see the [module docs](self).
    ///
    /// # Errors
    /// [`SpecError::Invalid`] naming the text.
    pub fn parse(s: &str) -> Result<Self, SpecError> {
        const WHAT: &str = "--output";
        let (kind, rest) = match s.split_once(':') {
            Some((kind, rest)) => (kind, Some(rest)),
            None => (s, None),
        };
        if s.contains('\0') {
            return Err(invalid(WHAT, s, "contains a NUL character"));
        }
        match (kind, rest) {
            ("audio", None) => Ok(Self::Audio { device: None }),
            ("audio", Some(d)) if !d.is_empty() => Ok(Self::Audio {
                device: Some(d.to_owned()),
            }),
            ("wav", Some(f)) if !f.is_empty() => Ok(Self::Wav {
                path: PathBuf::from(f),
            }),
            ("wav", _) => Err(invalid(WHAT, s, "wav:FILE needs a file")),
            ("null", None) => Ok(Self::Null),
            _ => Err(invalid(
                WHAT,
                s,
                "expected audio[:DEVICE], wav:FILE or null",
            )),
        }
    }
}

impl FromStr for OutputSpec {
    type Err = SpecError;
    fn from_str(s: &str) -> Result<Self, SpecError> {
        Self::parse(s)
    }
}

/// The spec as it parses: `audio`, `audio:DEVICE`, `wav:FILE` or `null`.
impl std::fmt::Display for OutputSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Audio { device: None } => f.write_str("audio"),
            Self::Audio {
                device: Some(device),
            } => write!(f, "audio:{device}"),
            Self::Wav { path } => write!(f, "wav:{}", path.display()),
            Self::Null => f.write_str("null"),
        }
    }
}

/// A band `LO:HI` in Hz (`LO,HI` is accepted too), as [`Band`]'s `FromStr` parses it:
/// finite, with [`MIN_BAND_EDGE`] <= LO < HI <= [`MAX_BAND_EDGE`]. Whether it fits below
/// a rate's Nyquist frequency is for the caller, who knows the rate ([`Band::fits`]).
///
/// # Errors
/// [`SpecError::Invalid`] naming the text.
pub fn parse_band(s: &str) -> Result<Band, SpecError> {
    Ok(s.parse::<Band>()?)
}

/// A duration in seconds, finite and within `lo..=hi`; `what` names it in errors.
///
/// # Errors
/// [`SpecError::Invalid`] naming the text and the range.
pub fn parse_seconds(s: &str, what: &'static str, lo: f64, hi: f64) -> Result<Seconds, SpecError> {
    parse_within(s, what, lo, hi, "seconds").map(Seconds)
}

/// A finite number within `lo..=hi` (a level in dB, a gain); `what` names it, with its
/// unit, in errors.
///
/// # Errors
/// [`SpecError::Invalid`] naming the text and the range.
pub fn parse_number(s: &str, what: &'static str, lo: f64, hi: f64) -> Result<f64, SpecError> {
    parse_within(s, what, lo, hi, "a number")
}

/// The length of a live session: seconds from 0 to [`MAX_SESSION`] (30 days).
///
/// # Errors
/// [`SpecError::Invalid`] naming the text.
pub fn parse_session_duration(s: &str) -> Result<Seconds, SpecError> {
    parse_seconds(s, "duration", 0.0, MAX_SESSION.0)
}

/// A sample rate in whole Hz within `lo..=hi`; `what` names it in errors.
///
/// # Errors
/// [`SpecError::Invalid`] naming the text and the range.
pub fn parse_rate(s: &str, what: &'static str, lo: u32, hi: u32) -> Result<SampleRate, SpecError> {
    parse_within(s, what, lo, hi, "a whole number of Hz").map(SampleRate)
}

/// A whole number within `lo..=hi`; `what` names it in errors.
///
/// # Errors
/// [`SpecError::Invalid`] naming the text and the range.
pub fn parse_count(s: &str, what: &'static str, lo: usize, hi: usize) -> Result<usize, SpecError> {
    parse_within(s, what, lo, hi, "a whole number")
}

/// A channel as a person numbers it, from 1 (as audio tools number ports, and as the
/// status, the panel and OSC do), returned as the engine's index, from 0.
///
/// # Errors
/// [`SpecError`] naming `what` for anything but a whole number from 1 to 65536; 0 says
/// that channels count from 1.
pub fn parse_channel_number(s: &str, what: &'static str) -> Result<u16, SpecError> {
    match s.trim().parse::<u32>() {
        Ok(0) => Err(invalid(
            what,
            s,
            "channels count from 1 (the first channel is 1)".to_owned(),
        )),
        Ok(n) if n <= u32::from(u16::MAX) + 1 => Ok((n - 1) as u16),
        _ => Err(invalid(
            what,
            s,
            "expected a channel number from 1".to_owned(),
        )),
    }
}

/// `s` (trimmed) parsed as a `T` within `lo..=hi`, else an error that says it expected
/// `kind` in that range. A NaN is in no range.
fn parse_within<T>(s: &str, what: &'static str, lo: T, hi: T, kind: &str) -> Result<T, SpecError>
where
    T: FromStr + PartialOrd + std::fmt::Display,
{
    match s.trim().parse::<T>() {
        Ok(v) if lo <= v && v <= hi => Ok(v),
        _ => Err(invalid(
            what,
            s,
            format!("expected {kind} from {lo} to {hi}"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn inputs() {
        assert_eq!(
            InputSpec::parse("replay:walk.csv@2").unwrap(),
            InputSpec::Replay {
                file: "walk.csv".into(),
                speed: 2.0
            }
        );
        assert_eq!(
            InputSpec::parse("replay:a@b.csv").unwrap_err().to_string(),
            "replay speed \"b.csv\": expected a speed from 0.001 to 1000 times real time"
        );
        assert!(matches!(
            InputSpec::parse("replay:walk.csv").unwrap(),
            InputSpec::Replay { speed: 1.0, .. }
        ));
        assert!(matches!(
            InputSpec::parse("gait:steps=3").unwrap(),
            InputSpec::Gait(g) if g.steps == 3
        ));
        assert!(matches!(
            InputSpec::parse("osc:0.0.0.0:9000").unwrap(),
            InputSpec::Osc { addr } if addr == "0.0.0.0:9000"
        ));
        assert!(matches!(
            InputSpec::parse("serial:/dev/ttyACM0").unwrap(),
            InputSpec::Serial { port } if port == "/dev/ttyACM0"
        ));
        for bad in [
            "",
            "replay",
            "replay:",
            "replay:x.csv@inf",
            "replay:x.csv@NaN",
            "replay:x.csv@0",
            "replay:x.csv@1e19",
            "replay:x.csv@-1",
            "gait:steps=0",
            "gait:steps=1e19",
            "gait:cadence=inf",
            "serial:",
            "osc:9000",
            "osc::9000",
            "osc:host:99999",
            "tcp:x",
        ] {
            let e = InputSpec::parse(bad).unwrap_err().to_string();
            assert!(!e.is_empty(), "{bad}");
        }
    }

    #[test]
    fn outputs() {
        assert_eq!(
            OutputSpec::parse("audio").unwrap(),
            OutputSpec::Audio { device: None }
        );
        assert_eq!(
            OutputSpec::parse("audio:hw:1").unwrap(),
            OutputSpec::Audio {
                device: Some("hw:1".into())
            }
        );
        assert_eq!(
            OutputSpec::parse("wav:o.wav").unwrap(),
            OutputSpec::Wav {
                path: "o.wav".into()
            }
        );
        assert_eq!(OutputSpec::parse("null").unwrap(), OutputSpec::Null);
        for bad in ["", "wav", "wav:", "null:x", "audio:", "file:x", "wav:a\0b"] {
            assert!(OutputSpec::parse(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn outputs_display_as_they_parse() {
        for s in ["audio", "audio:hw:1", "wav:o.wav", "wav:a:b.wav", "null"] {
            assert_eq!(OutputSpec::parse(s).unwrap().to_string(), s);
        }
    }

    #[test]
    fn bands_are_bounded() {
        assert_eq!("20:900".parse::<Band>().unwrap(), Band::new(20.0, 900.0));
        assert_eq!(parse_band(" 40 , 1024 ").unwrap(), Band::new(40.0, 1024.0));
        // Issue 14: `fit --band 1e-200:900` span forever inside the SVD.
        for bad in [
            "1e-200:900",
            "0:900",
            "-1:900",
            "900:20",
            "20:20",
            "20:inf",
            "NaN:900",
            "20:1e300",
            "20",
            "20:",
            ":900",
        ] {
            let e = parse_band(bad).unwrap_err().to_string();
            assert!(e.contains(&format!("{bad:?}")), "{e}");
        }
    }

    #[test]
    fn numbers_are_bounded() {
        // Issue 14: `run --duration inf` (or 1e19) panicked after opening the device.
        for bad in ["inf", "1e19", "NaN", "-1", "", "2592001"] {
            assert!(parse_session_duration(bad).is_err(), "{bad}");
        }
        assert_eq!(parse_session_duration("2.5").unwrap(), Seconds(2.5));
        assert_eq!(parse_session_duration("0").unwrap(), Seconds(0.0));
        assert_eq!(
            parse_rate("2000", "rate", 100, 192_000).unwrap(),
            SampleRate(2000)
        );
        // Issue 14: `fit --rate 4000000000` aborted on a 34 GB allocation.
        for bad in ["4000000000", "0", "99", "2000.5", "-2000", "x"] {
            assert!(parse_rate(bad, "rate", 100, 192_000).is_err(), "{bad}");
        }
        assert_eq!(parse_count("8", "order", 1, 64).unwrap(), 8);
        for bad in ["0", "65", "18446744073709551616", "1.5"] {
            assert!(parse_count(bad, "order", 1, 64).is_err(), "{bad}");
        }
        let long = "9".repeat(10_000);
        let e = parse_count(&long, "order", 1, 64).unwrap_err().to_string();
        assert!(e.len() < 400, "{}", e.len());
    }

    /// An error names the text it refused (or the part of it at fault, cut at 200 bytes).
    fn check_error(e: &SpecError, input: &str) {
        let SpecError::Invalid {
            input: named,
            reason,
            ..
        } = e;
        let named = named.strip_suffix('…').unwrap_or(named);
        assert!(input.contains(named), "{named:?} is not from {input:?}");
        assert!(!reason.is_empty());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        #[test]
        fn input_specs_never_panic(s in ".{0,64}", kind in prop::sample::select(
            vec!["replay:", "gait:", "serial:", "osc:", "", "gait:steps=", "replay:f@"]
        )) {
            let s = format!("{kind}{s}");
            match InputSpec::parse(&s) {
                Ok(InputSpec::Replay { speed, .. }) => {
                    prop_assert!((MIN_SPEED..=MAX_SPEED).contains(&speed));
                }
                Ok(_) => {}
                Err(e) => check_error(&e, &s),
            }
        }

        #[test]
        fn output_specs_never_panic(s in ".{0,64}", kind in prop::sample::select(
            vec!["audio:", "wav:", "null", ""]
        )) {
            let s = format!("{kind}{s}");
            if let Err(e) = OutputSpec::parse(&s) {
                check_error(&e, &s);
            }
        }

        #[test]
        fn bands_are_finite_and_ordered(
            s in ".{0,40}",
            lo in prop::num::f64::ANY,
            hi in prop::num::f64::ANY,
            sep in prop::sample::select(vec![":", ",", ";"]),
        ) {
            for s in [s, format!("{lo}{sep}{hi}"), format!("{lo:e}{sep}{hi:e}")] {
                match parse_band(&s) {
                    Ok(b) => prop_assert!(
                        b.lo.0 >= MIN_BAND_EDGE && b.lo.0 < b.hi.0 && b.hi.0 <= MAX_BAND_EDGE
                    ),
                    Err(e) => check_error(&e, &s),
                }
            }
        }

        #[test]
        fn numbers_stay_in_range(s in ".{0,40}", x in prop::num::f64::ANY, n in any::<u64>()) {
            for s in [s, x.to_string(), format!("{x:e}"), n.to_string()] {
                if let Ok(d) = parse_session_duration(&s) {
                    prop_assert!(d.0.is_finite() && (0.0..=MAX_SESSION.0).contains(&d.0));
                    // The conversion that panicked on `inf` cannot now.
                    let _ = std::time::Duration::from_secs_f64(d.0);
                }
                if let Ok(r) = parse_rate(&s, "rate", 100, 192_000) {
                    prop_assert!((100..=192_000).contains(&r.0));
                }
                if let Ok(c) = parse_count(&s, "count", 1, 64) {
                    prop_assert!((1..=64).contains(&c));
                }
                if let Ok(v) = parse_number(&s, "gain", -120.0, 60.0) {
                    prop_assert!((-120.0..=60.0).contains(&v));
                }
                if let Ok(v) = parse_speed(&s) {
                    prop_assert!((MIN_SPEED..=MAX_SPEED).contains(&v));
                }
            }
        }
    }
}
