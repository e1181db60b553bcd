//! Lab Streaming Layer: a session's force, strikes and markers as LSL streams, so that a
//! lab's LabRecorder records them beside its EEG or motion capture, on LSL's clock.
//!
//! # Streams
//!
//! | name | type | channels | rate | sample |
//! |---|---|---|---|---|
//! | `underfoot force` | `Force` | one per engine channel (newtons, the sum of its sensors) | the sensor rate | `double64` |
//! | `underfoot strikes` | `Markers` | 1 | irregular | a JSON object: `channel` (from 1), `intensity`, `material`, `frame` |
//! | `underfoot markers` | `Markers` | 1 | irregular | a JSON object: `text`, and `trial`, `participant`, `condition` when given |
//!
//! Every sample is stamped on LSL's clock (`lsl_local_clock`, the monotonic clock on
//! Linux): a reading and a marker at the moment the session took it, a strike at the
//! moment its impulse left the engine (`frame / rate` after the output's start). A
//! session's record ([`crate::live::record`]) gives the same moments as `t` since its
//! start, whose monotonic time its manifest holds, so the two line up.
//!
//! # Why liblsl is loaded at run time
//! The `lsl` crate builds the liblsl it bundles (a 2019 release) from source, and that
//! source no longer compiles with current C libraries. LSL's C API is small and stable,
//! so this module calls it directly: it loads `liblsl.so` when a session asks for LSL,
//! from `UNDERFOOT_LIBLSL` (a path) or the system's library path, the liblsl that a lab's
//! LSL installation (or `pip install pylsl`, which carries one) provides. A build with
//! the `lsl` feature then runs where there is no liblsl until LSL is asked for, and says
//! where it looked.
//!
//! Nothing here runs on the audio thread: the session's own thread pushes.

use std::ffi::{CString, c_char, c_double, c_int, c_void};

use super::IoError;

/// The environment variable naming the liblsl shared library to load.
pub const LIBLSL_VARIABLE: &str = "UNDERFOOT_LIBLSL";

/// liblsl's channel formats (`lsl_channel_format_t`).
const CFT_DOUBLE64: c_int = 2;
const CFT_STRING: c_int = 3;
/// `LSL_IRREGULAR_RATE`.
const IRREGULAR: c_double = 0.0;

type CreateInfo = unsafe extern "C" fn(
    *const c_char,
    *const c_char,
    c_int,
    c_double,
    c_int,
    *const c_char,
) -> *mut c_void;
type DestroyInfo = unsafe extern "C" fn(*mut c_void);
type CreateOutlet = unsafe extern "C" fn(*mut c_void, c_int, c_int) -> *mut c_void;
type DestroyOutlet = unsafe extern "C" fn(*mut c_void);
type PushDoubles = unsafe extern "C" fn(*mut c_void, *const c_double, c_double, c_int) -> c_int;
type PushStrings =
    unsafe extern "C" fn(*mut c_void, *const *const c_char, c_double, c_int) -> c_int;
type LocalClock = unsafe extern "C" fn() -> c_double;

/// The functions of liblsl used here, resolved once.
struct Api {
    create_info: CreateInfo,
    destroy_info: DestroyInfo,
    create_outlet: CreateOutlet,
    destroy_outlet: DestroyOutlet,
    push_doubles: PushDoubles,
    push_strings: PushStrings,
    local_clock: LocalClock,
    // Last: the functions above point into it.
    _library: libloading::Library,
}

fn unavailable(reason: String) -> IoError {
    IoError::Open {
        device: "liblsl".into(),
        reason,
    }
}

impl Api {
    fn load() -> Result<Self, IoError> {
        let candidates: Vec<std::ffi::OsString> = match std::env::var_os(LIBLSL_VARIABLE) {
            Some(path) => vec![path],
            None => vec!["liblsl.so".into(), "liblsl.so.2".into()],
        };
        let mut tried = Vec::new();
        for name in &candidates {
            // SAFETY: loading a shared library runs its initialisers; liblsl's set up its
            // own state and nothing else. The path is the user's (or the system's).
            match unsafe { libloading::Library::new(name) } {
                Ok(library) => return Self::resolve(library),
                Err(e) => tried.push(format!("{}: {e}", name.to_string_lossy())),
            }
        }
        Err(unavailable(format!(
            "cannot load liblsl ({}); install LSL, or `pip install pylsl` and set {LIBLSL_VARIABLE} \
             to the liblsl.so it carries (site-packages/pylsl/lib/liblsl.so)",
            tried.join("; ")
        )))
    }

    fn resolve(library: libloading::Library) -> Result<Self, IoError> {
        fn get<T: Copy>(library: &libloading::Library, name: &[u8]) -> Result<T, IoError> {
            // SAFETY: each name is looked up with the signature of liblsl's C API
            // (lsl_c.h), which has been stable since liblsl 1.0.
            unsafe { library.get::<T>(name) }.map(|s| *s).map_err(|e| {
                unavailable(format!(
                    "liblsl lacks {}: {e}",
                    String::from_utf8_lossy(&name[..name.len() - 1])
                ))
            })
        }
        Ok(Self {
            create_info: get(&library, b"lsl_create_streaminfo\0")?,
            destroy_info: get(&library, b"lsl_destroy_streaminfo\0")?,
            create_outlet: get(&library, b"lsl_create_outlet\0")?,
            destroy_outlet: get(&library, b"lsl_destroy_outlet\0")?,
            push_doubles: get(&library, b"lsl_push_sample_dtp\0")?,
            push_strings: get(&library, b"lsl_push_sample_strtp\0")?,
            local_clock: get(&library, b"lsl_local_clock\0")?,
            _library: library,
        })
    }

    fn outlet(
        &self,
        name: &str,
        kind: &str,
        channels: usize,
        rate: f64,
        format: c_int,
    ) -> Result<*mut c_void, IoError> {
        let text = |s: &str| CString::new(s).map_err(|e| unavailable(e.to_string()));
        let (name_c, kind_c) = (text(name)?, text(kind)?);
        let source = text(&format!("underfoot-{}-{name}", std::process::id()))?;
        let channels = c_int::try_from(channels).map_err(|e| unavailable(e.to_string()))?;
        // SAFETY: valid C strings that outlive the call; liblsl copies them.
        let info = unsafe {
            (self.create_info)(
                name_c.as_ptr(),
                kind_c.as_ptr(),
                channels,
                rate,
                format,
                source.as_ptr(),
            )
        };
        if info.is_null() {
            return Err(unavailable(format!("liblsl refused the stream {name:?}")));
        }
        // SAFETY: `info` is the live stream info just made; the outlet copies it, so it is
        // destroyed right after. Chunks of one sample; 360 s of buffer for a slow reader.
        let outlet = unsafe { (self.create_outlet)(info, 0, 360) };
        // SAFETY: made above, used no more.
        unsafe { (self.destroy_info)(info) };
        if outlet.is_null() {
            return Err(unavailable(format!(
                "liblsl could not open the stream {name:?}"
            )));
        }
        Ok(outlet)
    }
}

/// A session's three LSL streams.
pub struct LslOutlets {
    api: Api,
    force: *mut c_void,
    strikes: *mut c_void,
    markers: *mut c_void,
    channels: usize,
    /// The failures of pushes so far (liblsl refused a sample).
    failed: u64,
}

// SAFETY: liblsl's outlets may be used from any thread (lsl_c.h: outlets are thread-safe);
// the pointers are owned here and only this value uses them.
unsafe impl Send for LslOutlets {}

impl std::fmt::Debug for LslOutlets {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LslOutlets")
            .field("channels", &self.channels)
            .field("failed", &self.failed)
            .finish_non_exhaustive()
    }
}

impl LslOutlets {
    /// Loads liblsl and opens the three streams for `channels` channels of force read at
    /// `sensor_rate` hertz.
    ///
    /// # Errors
    /// [`IoError::Open`] naming liblsl, with where it was looked for, or the stream it
    /// could not open.
    pub fn open(channels: usize, sensor_rate: f64) -> Result<Self, IoError> {
        let api = Api::load()?;
        let force = api.outlet(
            "underfoot force",
            "Force",
            channels.max(1),
            sensor_rate,
            CFT_DOUBLE64,
        )?;
        let strikes = api.outlet("underfoot strikes", "Markers", 1, IRREGULAR, CFT_STRING)?;
        let markers = api.outlet("underfoot markers", "Markers", 1, IRREGULAR, CFT_STRING)?;
        Ok(Self {
            api,
            force,
            strikes,
            markers,
            channels: channels.max(1),
            failed: 0,
        })
    }

    /// LSL's clock now, in seconds.
    #[must_use]
    pub fn clock(&self) -> f64 {
        // SAFETY: no arguments, no state.
        unsafe { (self.api.local_clock)() }
    }

    /// Each channel's force (newtons), stamped `at` on LSL's clock. A slice shorter than
    /// the stream's channels is padded with zeros.
    pub fn push_force(&mut self, newtons: &[f64], at: f64) {
        let mut sample = vec![0.0; self.channels];
        for (s, v) in sample.iter_mut().zip(newtons) {
            *s = *v;
        }
        // SAFETY: a sample of exactly the stream's channel count.
        let r = unsafe { (self.api.push_doubles)(self.force, sample.as_ptr(), at, 1) };
        self.count(r);
    }

    /// A strike, as a JSON object, stamped `at`.
    pub fn push_strike(&mut self, json: &str, at: f64) {
        self.push_string(Which::Strikes, json, at);
    }

    /// A marker, as a JSON object, stamped `at`.
    pub fn push_marker(&mut self, json: &str, at: f64) {
        self.push_string(Which::Markers, json, at);
    }

    fn push_string(&mut self, which: Which, text: &str, at: f64) {
        // A JSON text has no NUL; one that somehow did is cut there rather than lost.
        let text = CString::new(text.split('\0').next().unwrap_or_default()).unwrap_or_default();
        let outlet = match which {
            Which::Strikes => self.strikes,
            Which::Markers => self.markers,
        };
        let ptrs = [text.as_ptr()];
        // SAFETY: one C string for a one-channel string stream; liblsl copies it.
        let r = unsafe { (self.api.push_strings)(outlet, ptrs.as_ptr(), at, 1) };
        self.count(r);
    }

    fn count(&mut self, code: c_int) {
        if code != 0 {
            self.failed += 1;
        }
    }

    /// Samples liblsl refused so far.
    #[must_use]
    pub fn failed(&self) -> u64 {
        self.failed
    }
}

enum Which {
    Strikes,
    Markers,
}

impl Drop for LslOutlets {
    fn drop(&mut self) {
        for outlet in [self.force, self.strikes, self.markers] {
            // SAFETY: each was made by `lsl_create_outlet` and is destroyed once, here.
            unsafe { (self.api.destroy_outlet)(outlet) };
        }
    }
}
