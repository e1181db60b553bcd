//! The C anchors (`anchors/anchors.c`): plain C loops of the same work as the Rust code
//! they are timed against, built by `build.rs` with the system C compiler at `-O3` (the
//! anchor of the ratios) and at `-O3 -march=native` (reported beside it). Safe wrappers
//! own the C state; a build without a C compiler has no [`Flavour`] available and the
//! benches say so ([`skipped`]).

use std::ffi::{c_int, c_long, c_void};

/// The table of one build's functions (see `anchors.c` for what each does).
#[derive(Debug)]
pub struct Api {
    voices_new: unsafe extern "C" fn(c_int, *const f32) -> *mut c_void,
    voices_free: unsafe extern "C" fn(*mut c_void),
    voices_process: unsafe extern "C" fn(*mut c_void, c_int, *const f32, *mut f32, c_int),
    bank_new: unsafe extern "C" fn(c_int, *const f64, *const f64, *const f64, f64) -> *mut c_void,
    bank_free: unsafe extern "C" fn(*mut c_void),
    bank_process: unsafe extern "C" fn(*mut c_void, *const f64, *mut f32, c_int),
    impact_new: unsafe extern "C" fn(
        c_int,
        *const f64,
        *const f64,
        *const f64,
        f64,
        f64,
        f64,
        f64,
        f64,
    ) -> *mut c_void,
    impact_free: unsafe extern "C" fn(*mut c_void),
    impact_strike: unsafe extern "C" fn(*mut c_void, f64),
    impact_process: unsafe extern "C" fn(*mut c_void, *mut f32, c_int),
    crumpling_new: unsafe extern "C" fn(
        c_int,
        *const f64,
        *const f64,
        *const f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        c_int,
        u64,
    ) -> *mut c_void,
    crumpling_free: unsafe extern "C" fn(*mut c_void),
    crumpling_events: unsafe extern "C" fn(*const c_void) -> c_long,
    crumpling_process: unsafe extern "C" fn(*mut c_void, *const f32, *mut f32, c_int),
}

macro_rules! api {
    ($cfg:ident, $module:ident, $prefix:literal) => {
        #[cfg($cfg)]
        mod $module {
            use std::ffi::{c_int, c_long, c_void};
            unsafe extern "C" {
                #[link_name = concat!($prefix, "voices_new")]
                pub fn voices_new(voices: c_int, coefs: *const f32) -> *mut c_void;
                #[link_name = concat!($prefix, "voices_free")]
                pub fn voices_free(p: *mut c_void);
                #[link_name = concat!($prefix, "voices_process")]
                pub fn voices_process(
                    p: *mut c_void,
                    voices: c_int,
                    input: *const f32,
                    out: *mut f32,
                    frames: c_int,
                );
                #[link_name = concat!($prefix, "bank_new")]
                pub fn bank_new(
                    modes: c_int,
                    freq: *const f64,
                    decay: *const f64,
                    gain: *const f64,
                    rate: f64,
                ) -> *mut c_void;
                #[link_name = concat!($prefix, "bank_free")]
                pub fn bank_free(p: *mut c_void);
                #[link_name = concat!($prefix, "bank_process")]
                pub fn bank_process(p: *mut c_void, input: *const f64, out: *mut f32, n: c_int);
                #[link_name = concat!($prefix, "impact_new")]
                pub fn impact_new(
                    modes: c_int,
                    freq: *const f64,
                    decay: *const f64,
                    gain: *const f64,
                    rate: f64,
                    mass: f64,
                    k: f64,
                    alpha: f64,
                    lambda: f64,
                ) -> *mut c_void;
                #[link_name = concat!($prefix, "impact_free")]
                pub fn impact_free(p: *mut c_void);
                #[link_name = concat!($prefix, "impact_strike")]
                pub fn impact_strike(p: *mut c_void, velocity: f64);
                #[link_name = concat!($prefix, "impact_process")]
                pub fn impact_process(p: *mut c_void, out: *mut f32, n: c_int);
                #[link_name = concat!($prefix, "crumpling_new")]
                pub fn crumpling_new(
                    modes: c_int,
                    freq: *const f64,
                    decay: *const f64,
                    gain: *const f64,
                    rate: f64,
                    mass: f64,
                    k: f64,
                    alpha: f64,
                    lambda: f64,
                    rms_speed: f64,
                    spread: f64,
                    slots: c_int,
                    seed: u64,
                ) -> *mut c_void;
                #[link_name = concat!($prefix, "crumpling_free")]
                pub fn crumpling_free(p: *mut c_void);
                #[link_name = concat!($prefix, "crumpling_events")]
                pub fn crumpling_events(p: *const c_void) -> c_long;
                #[link_name = concat!($prefix, "crumpling_process")]
                pub fn crumpling_process(p: *mut c_void, rate: *const f32, out: *mut f32, n: c_int);
            }
            pub static API: super::Api = super::Api {
                voices_new,
                voices_free,
                voices_process,
                bank_new,
                bank_free,
                bank_process,
                impact_new,
                impact_free,
                impact_strike,
                impact_process,
                crumpling_new,
                crumpling_free,
                crumpling_events,
                crumpling_process,
            };
        }
    };
}

api!(uf_c_anchor_o3, o3, "uf_o3_");
api!(uf_c_anchor_native, native, "uf_native_");

/// One build of the anchors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flavour {
    /// `-O3`: the anchor the ratios are taken against.
    O3,
    /// `-O3 -march=native`: the same source for this machine's instruction set, reported
    /// beside it.
    Native,
}

impl Flavour {
    /// A short label for printed figures: `C -O3`, `C -O3 -march=native`.
    #[must_use]
    pub fn label(self) -> &'static str {
        match self {
            Self::O3 => "C -O3",
            Self::Native => "C -O3 -march=native",
        }
    }

    /// The build's functions, `None` when it was not built.
    #[must_use]
    pub fn api(self) -> Option<&'static Api> {
        match self {
            Self::O3 => {
                #[cfg(uf_c_anchor_o3)]
                return Some(&o3::API);
                #[cfg(not(uf_c_anchor_o3))]
                None
            }
            Self::Native => {
                #[cfg(uf_c_anchor_native)]
                return Some(&native::API);
                #[cfg(not(uf_c_anchor_native))]
                None
            }
        }
    }

    /// The compiler and flags it was built with (from `build.rs`).
    #[must_use]
    pub fn compiler(self) -> Option<&'static str> {
        match self {
            Self::O3 => option_env!("UF_C_ANCHOR_O3"),
            Self::Native => option_env!("UF_C_ANCHOR_NATIVE"),
        }
    }
}

/// The builds available, `-O3` first.
#[must_use]
pub fn available() -> Vec<(Flavour, &'static Api)> {
    [Flavour::O3, Flavour::Native]
        .into_iter()
        .filter_map(|f| f.api().map(|a| (f, a)))
        .collect()
}

/// Prints, once per bench, which anchors run, or the line saying they were skipped.
pub fn announce() {
    for f in [Flavour::O3, Flavour::Native] {
        match f.compiler() {
            Some(cc) => println!("C anchor {}: {cc}", f.label()),
            None => println!("{}", skipped(f)),
        }
    }
}

/// The line a bench prints when an anchor was not built.
#[must_use]
pub fn skipped(f: Flavour) -> String {
    let why = match f {
        Flavour::O3 => option_env!("UF_C_ANCHOR_O3_SKIPPED"),
        Flavour::Native => option_env!("UF_C_ANCHOR_NATIVE_SKIPPED"),
    };
    format!(
        "C anchor skipped: no C compiler ({}: {})",
        f.label(),
        why.unwrap_or("not built")
    )
}

fn len(n: usize) -> c_int {
    c_int::try_from(n).expect("a block length that fits a C int")
}

/// The modes of a bank, as three arrays (frequency Hz, decay s, gain m/(N·s)).
#[derive(Debug, Clone, Default)]
pub struct Modes {
    /// Frequencies, Hz.
    pub frequency: Vec<f64>,
    /// Decay times, s.
    pub decay: Vec<f64>,
    /// Gains, m/(N·s).
    pub gain: Vec<f64>,
}

impl Modes {
    fn check(&self) -> c_int {
        assert!(self.frequency.len() == self.decay.len() && self.decay.len() == self.gain.len());
        assert!((1..=32).contains(&self.frequency.len()), "1 to 32 modes");
        len(self.frequency.len())
    }
}

/// A hammer: mass kg, stiffness, exponent, Hunt-Crossley damping.
#[derive(Debug, Clone, Copy)]
pub struct Hammer {
    /// kg.
    pub mass: f64,
    /// N/m^α.
    pub stiffness: f64,
    /// α.
    pub alpha: f64,
    /// λ, N·s/m^(α+1).
    pub damping: f64,
}

macro_rules! owned {
    ($name:ident, $free:ident, $doc:literal) => {
        #[doc = $doc]
        #[derive(Debug)]
        pub struct $name {
            api: &'static Api,
            ptr: *mut c_void,
        }
        impl Drop for $name {
            fn drop(&mut self) {
                // SAFETY: `ptr` came from the matching `_new` of the same build and is
                // freed once.
                unsafe { (self.api.$free)(self.ptr) }
            }
        }
    };
}

owned!(
    Voices,
    voices_free,
    "C voices: 8 parallel biquads then 3 in series, f32."
);
owned!(Bank, bank_free, "A C resonator bank (f64).");
owned!(
    CImpact,
    impact_free,
    "A C hammer on a C resonator bank, explicit Hunt-Crossley contact."
);
owned!(
    Crumpling,
    crumpling_free,
    "A C crumpling loop: Poisson impacts into a pool of C impacts."
);

impl Voices {
    /// `coefs`: per voice, 11 rows `(b0, b1, b2, a1, a2)`, the 8 modes then the 3 post sections.
    #[must_use]
    pub fn new(api: &'static Api, voices: usize, coefs: &[f32]) -> Self {
        assert_eq!(coefs.len(), voices * 11 * 5);
        // SAFETY: `coefs` holds the rows the function reads.
        let ptr = unsafe { (api.voices_new)(len(voices), coefs.as_ptr()) };
        assert!(!ptr.is_null());
        Self { api, ptr }
    }

    /// One block: `input` voice-major (`voices × frames`), `out` interleaved.
    pub fn process(&mut self, voices: usize, input: &[f32], out: &mut [f32]) {
        let frames = input.len() / voices;
        assert!(out.len() >= frames * voices);
        // SAFETY: both buffers hold `voices × frames` samples.
        unsafe {
            (self.api.voices_process)(
                self.ptr,
                len(voices),
                input.as_ptr(),
                out.as_mut_ptr(),
                len(frames),
            );
        }
    }
}

impl Bank {
    /// A bank of `modes` at `rate` Hz, at rest.
    #[must_use]
    pub fn new(api: &'static Api, modes: &Modes, rate: f64) -> Self {
        let k = modes.check();
        // SAFETY: three arrays of `k` modes.
        let ptr = unsafe {
            (api.bank_new)(
                k,
                modes.frequency.as_ptr(),
                modes.decay.as_ptr(),
                modes.gain.as_ptr(),
                rate,
            )
        };
        assert!(!ptr.is_null());
        Self { api, ptr }
    }

    /// Each sample of `input` an impulse; `out` the velocity before it.
    pub fn process(&mut self, input: &[f64], out: &mut [f32]) {
        assert_eq!(input.len(), out.len());
        // SAFETY: both hold `input.len()` samples.
        unsafe {
            (self.api.bank_process)(self.ptr, input.as_ptr(), out.as_mut_ptr(), len(out.len()))
        }
    }
}

impl CImpact {
    /// A hammer over a bank of `modes` at `rate` Hz.
    #[must_use]
    pub fn new(api: &'static Api, modes: &Modes, rate: f64, h: Hammer) -> Self {
        let k = modes.check();
        // SAFETY: three arrays of `k` modes.
        let ptr = unsafe {
            (api.impact_new)(
                k,
                modes.frequency.as_ptr(),
                modes.decay.as_ptr(),
                modes.gain.as_ptr(),
                rate,
                h.mass,
                h.stiffness,
                h.alpha,
                h.damping,
            )
        };
        assert!(!ptr.is_null());
        Self { api, ptr }
    }

    /// Throws the hammer at `velocity` m/s.
    pub fn strike(&mut self, velocity: f64) {
        // SAFETY: a live state.
        unsafe { (self.api.impact_strike)(self.ptr, velocity) }
    }

    /// Runs `out.len()` samples of surface velocity.
    pub fn process(&mut self, out: &mut [f32]) {
        // SAFETY: `out` holds the samples written.
        unsafe { (self.api.impact_process)(self.ptr, out.as_mut_ptr(), len(out.len())) }
    }
}

impl Crumpling {
    /// A pool of `slots` impacts over `modes`, RMS strike speed `rms_speed`, size spread
    /// `spread` (log-uniform in `[1/(1+spread), 1+spread]`).
    #[must_use]
    #[expect(
        clippy::too_many_arguments,
        reason = "the model's parameters, one by one"
    )]
    pub fn new(
        api: &'static Api,
        modes: &Modes,
        rate: f64,
        h: Hammer,
        rms_speed: f64,
        spread: f64,
        slots: usize,
        seed: u64,
    ) -> Self {
        let k = modes.check();
        // SAFETY: three arrays of `k` modes.
        let ptr = unsafe {
            (api.crumpling_new)(
                k,
                modes.frequency.as_ptr(),
                modes.decay.as_ptr(),
                modes.gain.as_ptr(),
                rate,
                h.mass,
                h.stiffness,
                h.alpha,
                h.damping,
                rms_speed,
                spread,
                len(slots),
                seed,
            )
        };
        assert!(!ptr.is_null());
        Self { api, ptr }
    }

    /// Events so far.
    #[must_use]
    pub fn events(&self) -> u64 {
        // SAFETY: a live state.
        u64::try_from(unsafe { (self.api.crumpling_events)(self.ptr) }).unwrap_or(0)
    }

    /// `rate[n]` events/s in, summed surface velocity out.
    pub fn process(&mut self, rate: &[f32], out: &mut [f32]) {
        assert_eq!(rate.len(), out.len());
        // SAFETY: both hold `out.len()` samples.
        unsafe {
            (self.api.crumpling_process)(self.ptr, rate.as_ptr(), out.as_mut_ptr(), len(out.len()))
        }
    }
}
