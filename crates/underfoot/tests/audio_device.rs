//! Audio output against real cpal hosts.
//!
//! Without a sound card these tests skip (with a message) rather than fail:
//! - ALSA's `null` device, if the ALSA configuration has one: a smoke test. It is not
//!   paced (it consumes audio as fast as it is rendered), so only counts are checked.
//! - A JACK server, with `--features jack` and `UNDERFOOT_JACK=1`, which makes it
//!   mandatory: a correctly paced device even on a machine without audio hardware
//!   (`jackd --no-realtime -d dummy -r 48000 -p 64`, started by `.ci/audio-setup`).
//! - A sweep through a JACK loopback, with `UNDERFOOT_JACK_LOOPBACK=1` and a server with
//!   large periods (see the test).
//!
//! A counting allocator checks that the whole audio-thread path (cpal, the conversion
//! and metering here, the render callback) does not allocate once running.
#![cfg(feature = "audio")]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use underfoot::io::IoError;
use underfoot::io::audio::{AudioConfig, AudioHost, AudioOutput, list_devices};
use underfoot::units::SampleRate;

struct CountingAlloc;

thread_local! {
    /// Set by the render callback on its first call, so that allocations on audio
    /// threads (and only there) are counted from then on.
    static ON_AUDIO_THREAD: Cell<bool> = const { Cell::new(false) };
}
static AUDIO_THREAD_ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

fn note_allocation() {
    if ON_AUDIO_THREAD.try_with(Cell::get).unwrap_or(false) {
        AUDIO_THREAD_ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: forwards to the system allocator unchanged; the counting touches only a
// const-initialised thread-local and an atomic, neither of which allocates.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: CountingAlloc = CountingAlloc;

/// One device test at a time: the unpaced ALSA null stream keeps a core busy and would
/// disturb the JACK pacing measurement on a small machine.
static DEVICE: Mutex<()> = Mutex::new(());

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    DEVICE.lock().unwrap_or_else(|e| e.into_inner())
}

/// A render callback: a quiet 100 Hz tone on every channel, and the frames it rendered.
fn tone(rate: SampleRate, rendered: &'static AtomicU64) -> impl FnMut(&mut [f32], usize) + Send {
    let step = std::f32::consts::TAU * 100.0 / rate.0 as f32;
    let mut phase = 0.0_f32;
    move |buffer: &mut [f32], channels: usize| {
        ON_AUDIO_THREAD.with(|f| f.set(true));
        for frame in buffer.chunks_exact_mut(channels) {
            frame.fill(0.1 * phase.sin());
            phase = (phase + step) % std::f32::consts::TAU;
        }
        rendered.fetch_add((buffer.len() / channels) as u64, Ordering::Relaxed);
    }
}

#[test]
fn alsa_null_device_smoke() {
    let _guard = one_at_a_time();
    let devices = match list_devices(AudioHost::Alsa) {
        Ok(d) => d,
        Err(e) => {
            println!("skipped: ALSA unavailable: {e}");
            return;
        }
    };
    if !devices.iter().any(|d| d.name == "null") {
        println!("skipped: the ALSA configuration has no \"null\" device");
        return;
    }

    static RENDERED: AtomicU64 = AtomicU64::new(0);
    let config = AudioConfig {
        host: AudioHost::Alsa,
        device: Some("null".into()),
        channels: 2,
        rate: SampleRate(48_000),
        buffer_frames: None,
    };
    let output = AudioOutput::start(&config, tone(config.rate, &RENDERED)).expect("start null");
    let info = output.info().clone();
    std::thread::sleep(Duration::from_millis(200));
    let stats = output.stop();
    println!("ALSA null: {info:?}\n  {stats:?}");

    assert_eq!(info.host, AudioHost::Alsa);
    assert_eq!(info.device, "null");
    assert_eq!((info.rate, info.channels), (SampleRate(48_000), 2));
    assert!(stats.callbacks > 0, "no callbacks");
    assert_eq!(stats.frames, RENDERED.load(Ordering::Relaxed));
    assert_eq!(stats.stream_errors, 0);
}

#[test]
fn alsa_errors_name_the_device_and_what_it_offers() {
    let _guard = one_at_a_time();
    let Ok(devices) = list_devices(AudioHost::Alsa) else {
        println!("skipped: ALSA unavailable");
        return;
    };
    let missing = AudioConfig {
        host: AudioHost::Alsa,
        device: Some("no-such-device-42".into()),
        ..AudioConfig::default()
    };
    let err = AudioOutput::start(&missing, |b: &mut [f32], _| b.fill(0.0)).expect_err("missing");
    let message = err.to_string();
    assert!(matches!(err, IoError::Open { .. }), "{err:?}");
    assert!(message.contains("no-such-device-42"), "{message}");
    println!("{message}");

    if devices.iter().any(|d| d.name == "null") {
        let zero = AudioConfig {
            host: AudioHost::Alsa,
            device: Some("null".into()),
            channels: 0,
            ..AudioConfig::default()
        };
        let err = AudioOutput::start(&zero, |b: &mut [f32], _| b.fill(0.0)).expect_err("0 ch");
        assert!(matches!(err, IoError::Unsupported { .. }), "{err:?}");
        assert!(err.to_string().contains("null"), "{err}");
    }
}

#[cfg(feature = "jack")]
#[test]
fn jack_dummy_server_is_paced_in_real_time() {
    if std::env::var("UNDERFOOT_JACK").as_deref() != Ok("1") {
        println!(
            "skipped: set UNDERFOOT_JACK=1 with a JACK server running \
             (jackd --no-realtime -d dummy -r 48000 -p 64) to run the JACK test"
        );
        return;
    }
    let _guard = one_at_a_time();
    let devices = list_devices(AudioHost::Jack).expect("JACK devices");
    println!("JACK devices: {devices:?}");
    assert!(
        !devices.is_empty(),
        "UNDERFOOT_JACK=1 but no JACK output device: is the server running? \
         (.ci/audio-setup starts one)"
    );

    let rate = SampleRate(48_000);
    let buffer = 64;
    let config = AudioConfig {
        host: AudioHost::Jack,
        device: None,
        channels: 2,
        rate,
        buffer_frames: Some(buffer),
    };

    // A buffer size the server does not run at is refused, naming what it runs at.
    let wrong = AudioConfig {
        buffer_frames: Some(4 * buffer),
        ..config.clone()
    };
    let err = AudioOutput::start(&wrong, |b: &mut [f32], _| b.fill(0.0)).expect_err("256");
    assert!(matches!(err, IoError::Unsupported { .. }), "{err:?}");
    assert!(err.to_string().contains("64"), "{err}");
    println!("refused as expected: {err}");

    static RENDERED: AtomicU64 = AtomicU64::new(0);
    let output = AudioOutput::start(&config, tone(rate, &RENDERED)).expect("start on JACK");
    let info = output.info().clone();
    println!("JACK stream: {info:?}");
    assert_eq!(info.buffer_frames, Some(buffer));
    assert_eq!(info.sample_format, underfoot::io::audio::SampleFormat::F32);

    // Measured between two snapshots, so that start-up does not count.
    std::thread::sleep(Duration::from_millis(200));
    let (t0, s0) = (Instant::now(), output.stats());
    std::thread::sleep(Duration::from_secs(3));
    let (elapsed, s1) = (t0.elapsed(), output.stats());
    let stats = output.stop();

    let callbacks = s1.callbacks - s0.callbacks;
    let audio_seconds = (callbacks * u64::from(buffer)) as f64 / rate.hz();
    let pace = audio_seconds / elapsed.as_secs_f64();
    let latency = stats
        .latency
        .map_or("none".to_string(), |l| format!("{:.3} ms", l.0 * 1e3));
    println!(
        "JACK: {callbacks} callbacks x {buffer} frames = {audio_seconds:.3} s of audio in \
         {:.3} s: {pace:.4}x real time",
        elapsed.as_secs_f64()
    );
    println!(
        "JACK: output latency {latency}, late callbacks {}, xruns {}, stream errors {}, \
         largest callback {} frames, audio-thread allocations {}",
        stats.late_callbacks,
        stats.xruns,
        stats.stream_errors,
        stats.max_callback_frames,
        AUDIO_THREAD_ALLOCATIONS.load(Ordering::Relaxed)
    );

    assert!((0.9..=1.1).contains(&pace), "paced at {pace:.3}x real time");
    assert_eq!(s1.frames - s0.frames, callbacks * u64::from(buffer));
    assert_eq!(stats.max_callback_frames, u64::from(buffer));
    assert_eq!(stats.frames, RENDERED.load(Ordering::Relaxed));
    assert_eq!(stats.stream_errors, 0, "stream errors: {stats:?}");
    assert!(stats.latency.is_some(), "no latency estimate");
    assert_eq!(
        AUDIO_THREAD_ALLOCATIONS.load(Ordering::Relaxed),
        0,
        "the audio thread allocated"
    );
}

/// End-to-end latency on a paced device: from the moment a force reading crossing the
/// step threshold is handed to the engine, to the moment its first vibration sample
/// leaves the device (the callback's wait, the onset's place in its buffer, and the
/// output latency the host reports).
#[cfg(feature = "jack")]
#[test]
fn jack_latency_from_threshold_crossing_to_first_output_sample() {
    use underfoot::engine::{self, EngineConfig, Event, MaterialBank, TimedEvent};
    use underfoot::force::SensorReading;
    use underfoot::force::gait::nominal_step;
    use underfoot::material::builtin::builtin;
    use underfoot::synthesis::VoiceConfig;
    use underfoot::units::Newtons;

    if std::env::var("UNDERFOOT_JACK").as_deref() != Ok("1") {
        println!("skipped: set UNDERFOOT_JACK=1 with a JACK server running");
        return;
    }
    let _guard = one_at_a_time();
    let rate = SampleRate(48_000);
    let bank = MaterialBank::prepare(
        builtin(),
        rate,
        &VoiceConfig::default(),
        &nominal_step(70.0, 1.8, rate.hz()),
        Newtons::weight_of(70.0),
    )
    .unwrap();
    let slot = bank.slot("hard").unwrap();
    let (mut ctl, mut eng) = engine::build(&EngineConfig::default(), bank, &[slot]).unwrap();

    static BASE: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    static ONSET_CALLBACK_NS: AtomicU64 = AtomicU64::new(u64::MAX);
    static ONSET_FRAME: AtomicU64 = AtomicU64::new(0);
    let base = *BASE.get_or_init(Instant::now);
    let config = AudioConfig {
        host: AudioHost::Jack,
        device: None,
        channels: 2,
        rate,
        buffer_frames: Some(64),
    };
    let output = AudioOutput::start(&config, move |out: &mut [f32], channels: usize| {
        let entered = base.elapsed().as_nanos() as u64;
        eng.process(out, channels);
        if ONSET_CALLBACK_NS.load(Ordering::Relaxed) == u64::MAX
            && let Some(i) = out.iter().position(|v| v.abs() > 1e-7)
        {
            ONSET_FRAME.store((i / channels) as u64, Ordering::Relaxed);
            ONSET_CALLBACK_NS.store(entered, Ordering::Relaxed);
        }
    })
    .expect("start on JACK");
    let idle = |ctl: &mut engine::Controller| {
        ctl.send(TimedEvent::now(Event::Force {
            channel: 0,
            reading: SensorReading::single(0.0),
        }))
        .unwrap();
    };
    for _ in 0..100 {
        idle(&mut ctl);
        std::thread::sleep(Duration::from_millis(2));
    }
    let sent = base.elapsed().as_nanos() as u64;
    ctl.send(TimedEvent::now(Event::Force {
        channel: 0,
        reading: SensorReading::single(700.0),
    }))
    .unwrap();
    std::thread::sleep(Duration::from_millis(200));
    let stats = output.stop();
    let callback = ONSET_CALLBACK_NS.load(Ordering::Relaxed);
    assert_ne!(callback, u64::MAX, "the step never reached the output");
    let wait = callback.saturating_sub(sent) as f64 * 1e-9;
    let in_buffer = ONSET_FRAME.load(Ordering::Relaxed) as f64 / rate.hz();
    let device = stats.latency.map_or(0.0, |l| l.0);
    let total = wait + in_buffer + device;
    println!(
        "latency: {:.2} ms to the callback + {:.2} ms into its buffer + {:.2} ms device = {:.2} ms",
        wait * 1e3,
        in_buffer * 1e3,
        device * 1e3,
        total * 1e3
    );
    assert_eq!(ctl.telemetry().strikes, 1);
    assert!(in_buffer == 0.0, "a live step starts its buffer");
    assert!(total < 0.010, "{:.2} ms", total * 1e3);
}

/// Whether the JACK tests are enabled; prints why not otherwise.
#[cfg(feature = "jack")]
fn jack_enabled() -> bool {
    let on = std::env::var("UNDERFOOT_JACK").as_deref() == Ok("1");
    if !on {
        println!("skipped: set UNDERFOOT_JACK=1 with a JACK server running");
    }
    on
}

#[cfg(feature = "jack")]
fn jack_config(channels: u16) -> AudioConfig {
    AudioConfig {
        host: AudioHost::Jack,
        device: None,
        channels,
        rate: SampleRate(48_000),
        buffer_frames: None,
    }
}

/// The input path on JACK: paced frames arrive in f32, without allocating.
#[cfg(feature = "jack")]
#[test]
fn jack_input_delivers_frames_without_allocating() {
    use underfoot::io::audio::AudioInput;

    if !jack_enabled() {
        return;
    }
    let _guard = one_at_a_time();
    static CAPTURED: AtomicU64 = AtomicU64::new(0);
    let before = AUDIO_THREAD_ALLOCATIONS.load(Ordering::Relaxed);
    let input = AudioInput::start(&jack_config(2), |data: &[f32], channels: usize| {
        ON_AUDIO_THREAD.with(|f| f.set(true));
        CAPTURED.fetch_add((data.len() / channels) as u64, Ordering::Relaxed);
    })
    .expect("start the JACK input");
    let info = input.info().clone();
    std::thread::sleep(Duration::from_millis(500));
    let stats = input.stop();
    println!("JACK input: {info:?}\n  {stats:?}");
    assert_eq!(info.channels, 2);
    assert_eq!(stats.frames, CAPTURED.load(Ordering::Relaxed));
    // 0.5 s is 24000 frames; allow for start-up and a loaded machine.
    assert!(stats.frames > 12_000, "{} frames in 0.5 s", stats.frames);
    assert_eq!(stats.stream_errors, 0);
    assert_eq!(
        AUDIO_THREAD_ALLOCATIONS.load(Ordering::Relaxed),
        before,
        "the input's audio thread allocated"
    );
}

/// A sweep measured through JACK with cpal's output port patched to its input port:
/// a wire, so the response must be flat at 0 dB and the recording aligned to playback.
#[cfg(feature = "jack")]
#[test]
fn jack_loopback_sweep_is_flat_and_aligned() {
    use std::process::Command;
    use underfoot::compensation::CompensationError;
    use underfoot::compensation::sweep::{Device, Sweep, SweepConfig};
    use underfoot::io::audio::{AudioLoop, LoopConfig};
    use underfoot::units::Seconds;

    // A measurement wants no low latency, and on this project's virtual machine a graph of
    // two clients at 64-frame periods (1.33 ms) misses a deadline every few hundred
    // milliseconds, which spoils a whole sweep; at 1024 frames it runs clean. So this test
    // runs against its own server (`UNDERFOOT_JACK_LOOPBACK=1`, with `JACK_DEFAULT_SERVER`
    // naming a dummy server at 1024 frames; `.ci/run` starts one) and is mandatory there.
    if !loopback_enabled() {
        return;
    }
    let _guard = one_at_a_time();

    // A rate the server does not run at is the loop's clear error, naming both.
    let wrong = AudioConfig {
        rate: SampleRate(44_100),
        ..jack_config(2)
    };
    let mut device = AudioLoop::new(LoopConfig::new(wrong.clone(), wrong)).expect("settings");
    let err = device
        .play(&[0.0; 100])
        .expect_err("44.1 kHz on a 48 kHz server");
    println!("refused as expected: {err}");
    assert!(matches!(err, CompensationError::Device { .. }), "{err:?}");
    assert!(err.to_string().contains("44100"), "{err}");
    assert!(err.to_string().contains("48000"), "{err}");
    // Input and output at different rates are refused before anything opens.
    let mismatched = LoopConfig::new(
        jack_config(2),
        AudioConfig {
            rate: SampleRate(44_100),
            ..jack_config(2)
        },
    );
    assert!(matches!(
        AudioLoop::new(mismatched),
        Err(IoError::Unsupported { .. })
    ));

    let rate = SampleRate(48_000);
    let sweep = Sweep::new(SweepConfig {
        duration: Seconds(1.0),
        repeats: 1,
        ..SweepConfig::new(rate)
    })
    .expect("sweep");
    let lead_in = Duration::from_secs(2);
    let mut cfg = LoopConfig::new(jack_config(2), jack_config(2));
    cfg.lead_in = Seconds(lead_in.as_secs_f64());
    // A loaded CI machine makes the dummy server miss deadlines now and then; a recording
    // with an xrun is played again (in the same streams, so the patch holds).
    cfg.attempts = 10;
    let mut device = AudioLoop::new(cfg).expect("loop settings");

    // cpal's JACK clients are `cpal_client_<pid>_out` and `_in`, with ports `out_N` and
    // `in_N`; cpal connects them to the system ports as they start (its option not to is
    // fixed when the host enumerates its devices), so the patch is added here, during
    // the lead-in. The dummy back-end's capture is silent, so it adds nothing.
    let pid = std::process::id();
    let out_port = format!("cpal_client_{pid}_out:out_0");
    let in_port = format!("cpal_client_{pid}_in:in_0");
    let patcher = std::thread::spawn(move || -> Result<Duration, String> {
        let t0 = Instant::now();
        loop {
            let listed = Command::new("jack_lsp")
                .env("JACK_NO_START_SERVER", "1")
                .output()
                .map_err(|e| format!("jack_lsp: {e}"))?;
            let ports = String::from_utf8_lossy(&listed.stdout);
            let has = |p: &str| ports.lines().any(|l| l.trim() == p);
            if has(&out_port) && has(&in_port) {
                break;
            }
            if t0.elapsed() > Duration::from_secs(5) {
                return Err(format!("{out_port} and {in_port} never appeared:\n{ports}"));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let status = Command::new("jack_connect")
            .env("JACK_NO_START_SERVER", "1")
            .args([&out_port, &in_port])
            .status()
            .map_err(|e| format!("jack_connect: {e}"))?;
        if !status.success() {
            return Err(format!("jack_connect {out_port} {in_port}: {status}"));
        }
        Ok(t0.elapsed())
    });

    let excitation = sweep.excitation();
    let played = device.play(excitation);
    let patched = patcher.join().expect("patch thread").expect("patching");
    // On a virtual machine the dummy server can miss deadlines in every 2 s window with
    // two chained clients; the loop then refuses to return a recording with gaps, which
    // is the behaviour wanted, but leaves nothing to check the response of.
    let recorded = played.expect("loopback measurement");
    let report = device.last_report().expect("report").clone();
    println!(
        "JACK loopback: patched {:.0} ms after start (lead-in {} ms); {report:?}",
        patched.as_secs_f64() * 1e3,
        lead_in.as_millis()
    );
    assert!(
        patched + Duration::from_millis(300) < lead_in,
        "patching took {patched:?}, too close to the {lead_in:?} lead-in"
    );

    let tail = rate.samples_in(Seconds(0.5));
    assert_eq!(recorded.len(), excitation.len() + tail);
    assert_eq!(report.recorded_frames, recorded.len());

    // The alignment: where the recording's first sound lies against the excitation's.
    let onset = |x: &[f64]| x.iter().position(|v| v.abs() > 1e-6);
    let sent = onset(excitation).expect("a silent excitation");
    let got = onset(&recorded).expect("the recording is silent: was the patch made?");
    let delay = got as i64 - sent as i64;
    let mismatched = excitation
        .iter()
        .zip(recorded.iter().skip(delay.max(0) as usize))
        .filter(|(x, y)| (f64::from(**x as f32) - **y).abs() > 1e-6)
        .count();
    let copy_error = excitation
        .iter()
        .zip(recorded.iter().skip(delay.max(0) as usize))
        .map(|(x, y)| (f64::from(*x as f32) - y).abs())
        .fold(0.0, f64::max);

    let response = sweep.response(&recorded).expect("response");
    let db = response.magnitude_db();
    let gain = db.iter().map(|d| d.0).sum::<f64>() / db.len() as f64;
    let deviation = response.deviation_from_flat_db().0;
    println!(
        "JACK loopback: delay {delay} samples, largest difference from the excitation \
         {copy_error:.2e} ({mismatched} samples differ), gain {gain:+.4} dB, deviation from flat {deviation:.4} dB, \
         {} attempt(s), output xruns {}, input xruns {} (all attempts and start-up)",
        report.attempts, report.output_stats.xruns, report.input_stats.xruns
    );
    // Patched inside one JACK graph, the output client runs before the input client in
    // each cycle, so the recording should start with the excitation's first sample; a
    // buffer of slack is allowed. An attempt without xruns is an exact copy.
    let buffer = report.output.buffer_frames.unwrap_or(64) as i64;
    assert!(
        (0..=buffer).contains(&delay),
        "recording lags playback by {delay} samples"
    );
    assert_eq!(mismatched, 0, "the loopback is not an exact copy");
    assert!(deviation < 0.1, "deviation from flat {deviation} dB");
    assert!(gain.abs() < 0.1, "gain {gain} dB");
}

/// Live equals offline on a paced device: the walk (`gait:steps=6` on gravel),
/// replayed in real time as `underfoot run` does (stamped readings sent without a frame),
/// played by the JACK dummy server at its 64-frame period, against the offline render of
/// the same walk. Each step's peak within 0.5 dB, its onset within one sample of the
/// sensor clock's rule (`frame(t) = A + round((t - t_A) fs)`, so the offline render shifted
/// by `A - round(t_A fs)`). Mirrors the CLI's `run --output wav:` test
/// (`underfoot-cli/tests/live_offline.rs`).
#[cfg(feature = "jack")]
#[test]
fn jack_live_walk_plays_as_the_offline_render() {
    use std::sync::atomic::AtomicU32;
    use underfoot::engine::offline::{render, track_events};
    use underfoot::engine::{self, EngineConfig, MaterialBank, TimedEvent};
    use underfoot::force::gait::{self, GaitConfig, nominal_step};
    use underfoot::io::replay::ReplaySource;
    use underfoot::io::{EventSource, SourceState};
    use underfoot::material::builtin::builtin;
    use underfoot::synthesis::VoiceConfig;
    use underfoot::units::{Newtons, Seconds};

    if !jack_enabled() {
        return;
    }
    let _guard = one_at_a_time();
    let rate = SampleRate(48_000);
    let bank = || {
        MaterialBank::prepare(
            builtin(),
            rate,
            &VoiceConfig::default(),
            &nominal_step(70.0, 1.8, rate.hz()),
            Newtons::weight_of(70.0),
        )
        .unwrap()
    };
    let slot = bank().slot("gravel").unwrap();
    let config = EngineConfig {
        sensor_latency: Seconds(0.04),
        ..EngineConfig::default()
    };
    let track = gait::generate(&GaitConfig {
        steps: 6,
        channels: 1,
        ..GaitConfig::default()
    })
    .unwrap()
    .track;
    let events = track_events(&track, rate);
    let frames = events.last().and_then(|e| e.at).unwrap() as usize + 48_000;
    let offline = render(&config, bank(), &[slot], &events, frames, 64).unwrap();

    // Channel 0 of every frame the device plays, by engine frame: stored, never allocated.
    const CAPACITY: usize = 48_000 * 12;
    static RECORDED: std::sync::OnceLock<Vec<AtomicU32>> = std::sync::OnceLock::new();
    let recorded = RECORDED.get_or_init(|| (0..CAPACITY).map(|_| AtomicU32::new(0)).collect());
    let (mut ctl, mut eng) = engine::build(&config, bank(), &[slot]).unwrap();
    let output = AudioOutput::start(&jack_config(2), move |out: &mut [f32], channels: usize| {
        let start = eng.frame() as usize;
        eng.process(out, channels);
        for (i, frame) in out.chunks(channels).enumerate() {
            if let Some(slot) = recorded.get(start + i) {
                slot.store(frame[0].to_bits(), Ordering::Relaxed);
            }
        }
    })
    .expect("start on JACK");
    let mut source = ReplaySource::new(track.clone(), 1.0).unwrap();
    let mut full = 0;
    while source
        .poll(Duration::from_millis(20), &mut |e| {
            if ctl.send(TimedEvent::now(e)).is_err() {
                full += 1;
            }
        })
        .unwrap()
        == SourceState::Open
    {}
    std::thread::sleep(Duration::from_millis(1500));
    let stats = output.stop();
    let t = ctl.telemetry();
    println!("JACK live walk: {t:?}, device {stats:?}");
    assert_eq!(full, 0);
    assert_eq!(t.strikes, 6);
    assert_eq!((t.late, t.resyncs), (0, 0), "every reading on its frame");
    let anchor = t.sensor_clock.expect("the sensor clock is anchored");
    let shift = anchor.frame as usize - (anchor.time.0 * rate.hz()).round() as usize;
    let live: Vec<f32> = recorded
        .iter()
        .map(|v| f32::from_bits(v.load(Ordering::Relaxed)))
        .collect();

    // A step starts where the output comes within 30 dB of the offline render's loudest
    // sample: materials play at their recorded loudness (gravel's steps peak near -33
    // dBFS), so the threshold follows the render rather than full scale.
    let loudest = offline.samples.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let threshold = loudest * 10f32.powf(-30.0 / 20.0);
    let steps = |y: &[f32]| {
        // After 0.3 s below the threshold: a step's train of micro-impacts crosses it
        // many times over a few hundred milliseconds.
        let mut onsets: Vec<usize> = Vec::new();
        let mut last: Option<usize> = None;
        for (i, v) in y.iter().enumerate() {
            if v.abs() > threshold {
                if last.is_none_or(|l| i > l + 14_400) {
                    onsets.push(i);
                }
                last = Some(i);
            }
        }
        onsets
            .iter()
            .enumerate()
            .map(|(k, &o)| {
                let end = onsets.get(k + 1).copied().unwrap_or(y.len());
                let peak = y[o..end].iter().fold(0.0f32, |m, v| m.max(v.abs()));
                (o, 20.0 * f64::from(peak).log10())
            })
            .collect::<Vec<_>>()
    };
    let want = steps(&offline.samples);
    let got = steps(&live);
    println!("offline steps {want:?}\nlive steps {got:?} (shift {shift})");
    assert_eq!((want.len(), got.len()), (6, 6));
    for (k, (w, g)) in want.iter().zip(&got).enumerate() {
        assert!(
            (w.1 - g.1).abs() <= 0.5,
            "step {k}: {g:?} live, {w:?} offline"
        );
        assert!(
            (w.0 + shift).abs_diff(g.0) <= 1,
            "step {k}: onset {} live, {} offline + {shift}",
            g.0,
            w.0
        );
    }
}

/// Whether the loopback tests run (`UNDERFOOT_JACK_LOOPBACK=1`); says how when not.
#[cfg(feature = "jack")]
fn loopback_enabled() -> bool {
    let on = std::env::var("UNDERFOOT_JACK_LOOPBACK").as_deref() == Ok("1");
    if !on {
        println!(
            "skipped: set UNDERFOOT_JACK_LOOPBACK=1 and JACK_DEFAULT_SERVER to a JACK server \
             with large periods (jackd -n NAME -d dummy -r 48000 -p 1024) to run the loopback"
        );
    }
    on
}

/// What the adaptation tests start from: one channel on gravel at `rate` through a flat
/// equalizer run as the bank; the engine's settings, the bank, gravel's slot, the weights.
#[cfg(feature = "jack")]
fn flat_equalized_gravel(
    rate: SampleRate,
) -> (
    underfoot::engine::EngineConfig,
    underfoot::engine::MaterialBank,
    u16,
    underfoot::compensation::equalizer::SpectralWeights,
) {
    use underfoot::compensation::chain::Compensation;
    use underfoot::compensation::equalizer::{EqualizerConfig, Realisation, SpectralWeights};
    use underfoot::engine::{EngineConfig, MaterialBank};
    use underfoot::force::gait::nominal_step;
    use underfoot::material::builtin::builtin;
    use underfoot::synthesis::VoiceConfig;
    use underfoot::units::Newtons;

    let weights = SpectralWeights::flat(EqualizerConfig::default(), rate).unwrap();
    let bank = MaterialBank::prepare(
        builtin(),
        rate,
        &VoiceConfig::default(),
        &nominal_step(70.0, 1.8, rate.hz()),
        Newtons::weight_of(70.0),
    )
    .unwrap();
    let slot = bank.slot("gravel").unwrap();
    let config = EngineConfig {
        rate,
        channels: 1,
        compensation: Compensation {
            equalizer: Some((weights.clone(), Realisation::Bank)),
            limb: None,
        },
        ..EngineConfig::default()
    };
    (config, bank, slot, weights)
}

/// The JACK ports that exist now (the server named by `JACK_DEFAULT_SERVER`).
#[cfg(feature = "jack")]
fn jack_ports() -> Vec<String> {
    let listed = std::process::Command::new("jack_lsp")
        .env("JACK_NO_START_SERVER", "1")
        .output()
        .expect("jack_lsp");
    String::from_utf8_lossy(&listed.stdout)
        .lines()
        .map(|l| l.trim().to_owned())
        .collect()
}

/// The port that appeared since `before`, ending in `suffix` (cpal's `out_0` or `in_0`).
#[cfg(feature = "jack")]
fn new_port(before: &[String], suffix: &str) -> String {
    let t0 = Instant::now();
    loop {
        let now = jack_ports();
        if let Some(p) = now
            .iter()
            .find(|p| !before.contains(p) && p.ends_with(suffix))
        {
            return p.clone();
        }
        assert!(
            t0.elapsed() < Duration::from_secs(5),
            "no new port *{suffix} among {now:?}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[cfg(feature = "jack")]
fn jack_connect(from: &str, to: &str) {
    let status = std::process::Command::new("jack_connect")
        .env("JACK_NO_START_SERVER", "1")
        .args([from, to])
        .status()
        .expect("jack_connect");
    assert!(status.success(), "jack_connect {from} {to}: {status}");
}

/// Online adaptation end to end through a JACK server: the engine plays a walk on gravel
/// through a flat equalizer (the device is the server's wire); its output port is patched
/// into a simulated leg, Table 1's mean user (a pair of JACK clients of its own: the limb
/// model's sections between an input and an output port, with sensor noise), whose output
/// is patched back into the accelerometer input.
/// The adaptation loop ([`underfoot::live::adapt`], wired exactly as a session wires it:
/// the drive tap after the engine in the output callback, the sensor tap in the input
/// callback, the loop on this thread with the engine's controller) must find the delay
/// through both streams and the plant, and bring the deviation from flat, measured against
/// the plant's true response, below 1 dB within 30 s of walking; the audio threads
/// allocate nothing. On the large-period server of the loopback sweep (see it).
#[cfg(feature = "jack")]
#[test]
fn jack_loopback_adaptation_flattens_a_simulated_leg_within_30_s() {
    use underfoot::compensation::equalizer::SpectralWeights;
    use underfoot::compensation::limb::{DEFAULT_G2, LimbModel, LimbParams};
    use underfoot::engine::{self, TimedEvent};
    use underfoot::force::gait::{self, GaitConfig};
    use underfoot::io::audio::AudioInput;
    use underfoot::io::replay::ReplaySource;
    use underfoot::io::{EventSource, SourceState};
    use underfoot::live::adapt::{AdaptParts, AdaptSettings};
    use underfoot::signal::noise::SplitMix64;
    use underfoot::sim::SimulatedUser;
    use underfoot::units::Band;

    if !loopback_enabled() {
        return;
    }
    let _guard = one_at_a_time();
    let rate = SampleRate(48_000);
    let (config, bank, slot, weights) = flat_equalized_gravel(rate);
    let (mut ctl, mut eng) = engine::build(&config, bank, &[slot]).unwrap();
    let parts = AdaptParts::new(
        &AdaptSettings::default(),
        &weights,
        rate,
        ctl.telemetry_handle(),
    )
    .unwrap();
    let (mut drive, mut sensor, mut adapt) = (parts.drive, parts.sensor, parts.adapt);
    ctl.set_equalizer_weights(0, &adapt.weights().gains_db)
        .unwrap();

    // The leg, and its true response to measure against.
    let limb = LimbModel::new(LimbParams::TABLE1_MEAN, DEFAULT_G2, 1.0).unwrap();
    let sos = SimulatedUser::limb_sections(&limb, rate).unwrap();
    let truth = sos.clone();
    let deviation = |w: &SpectralWeights| {
        let v: Vec<f64> = Band::new(40.0, 1024.0)
            .log_grid(128)
            .into_iter()
            .map(|f| w.gain_db_at(f) + 20.0 * truth.response(rate.omega(f)).norm().log10())
            .collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
    };
    let initial = deviation(adapt.weights());

    // The session's two streams, their callbacks marked as audio threads.
    let ports = jack_ports();
    let output = AudioOutput::start(&jack_config(1), move |out: &mut [f32], channels: usize| {
        ON_AUDIO_THREAD.with(|f| f.set(true));
        eng.process(out, channels);
        drive.push(out, channels);
    })
    .expect("the engine on JACK");
    let engine_out = new_port(&ports, "out_0");
    let ports = jack_ports();
    let input = AudioInput::start(&jack_config(1), move |samples: &[f32], channels: usize| {
        ON_AUDIO_THREAD.with(|f| f.set(true));
        sensor.push(samples, channels);
    })
    .expect("the accelerometer input on JACK");
    let accel_in = new_port(&ports, "in_0");

    // The plant: what its input port receives goes through the leg's sections, plus
    // sensor noise, out of its output port in the same JACK cycle (the graph runs the
    // input client first), through a ring.
    let (mut leg_tx, mut leg_rx) = rtrb::RingBuffer::<f32>::new(1 << 16);
    let ports = jack_ports();
    let leg_in = AudioInput::start(&jack_config(1), move |samples: &[f32], channels: usize| {
        for frame in samples.chunks_exact(channels) {
            let _ = leg_tx.push(frame[0]);
        }
    })
    .expect("the plant's input");
    let plant_in = new_port(&ports, "in_0");
    let ports = jack_ports();
    let mut state = vec![[0.0f64; 2]; sos.sections.len()];
    let mut wide = vec![0.0f64; 8192];
    let mut rng = SplitMix64::new(3);
    let leg_out = AudioOutput::start(&jack_config(1), move |out: &mut [f32], channels: usize| {
        let frames = (out.len() / channels).min(wide.len());
        for w in &mut wide[..frames] {
            *w = f64::from(leg_rx.pop().unwrap_or(0.0));
        }
        sos.filter_with_state(&mut wide[..frames], &mut state);
        for (frame, w) in out.chunks_exact_mut(channels).zip(&wide[..frames]) {
            // Accelerometer noise about 65 dB under the steps' peaks.
            frame.fill((w + 1e-5 * rng.normal()) as f32);
        }
    })
    .expect("the plant's output");
    let plant_out = new_port(&ports, "out_0");
    jack_connect(&engine_out, &plant_in);
    jack_connect(&plant_out, &accel_in);

    // Walk for 30 s, polling the loop as a session does.
    let track = gait::generate(&GaitConfig {
        steps: 60,
        channels: 1,
        ..GaitConfig::default()
    })
    .unwrap()
    .track;
    let mut source = ReplaySource::new(track, 1.0).unwrap();
    let walking = Instant::now();
    let mut history: Vec<(f64, f64)> = Vec::new();
    let mut full = 0;
    while walking.elapsed() < Duration::from_secs(30) {
        let state = source
            .poll(Duration::from_millis(20), &mut |e| {
                if ctl.send(TimedEvent::now(e)).is_err() {
                    full += 1;
                }
            })
            .unwrap();
        assert_eq!(state, SourceState::Open, "the walk ended early");
        let before = adapt.status().updates;
        adapt.poll(&mut ctl);
        ctl.collect();
        if adapt.status().updates > before {
            history.push((walking.elapsed().as_secs_f64(), deviation(adapt.weights())));
        }
    }
    let allocations = AUDIO_THREAD_ALLOCATIONS.load(Ordering::Relaxed);
    let out_stats = output.stop();
    let in_stats = input.stop();
    leg_in.stop();
    leg_out.stop();
    let status = adapt.status();
    let t = ctl.telemetry();
    let every_5s: Vec<String> = history
        .windows(2)
        .filter(|w| (w[0].0 / 5.0).floor() < (w[1].0 / 5.0).floor())
        .map(|w| format!("{:.1} s: {:.2} dB", w[1].0, w[1].1))
        .collect();
    // From here on below 1 dB.
    let settled = history
        .iter()
        .rposition(|&(_, d)| d >= 1.0)
        .map_or(history.first(), |i| history.get(i + 1))
        .map(|h| h.0);
    println!(
        "JACK adaptation: initial {initial:.2} dB; {every_5s:?}; below 1 dB from {settled:?} s; \
         final {:?}; {status:?}; engine applied {} refused {}; output {out_stats:?}; input \
         {in_stats:?}",
        history.last(),
        t.equalizer_updates,
        t.equalizer_refused
    );
    assert_eq!(full, 0);
    assert!(
        initial > 2.0,
        "the leg must need equalizing: {initial:.2} dB"
    );
    assert!(status.delay.is_some(), "the delay was never found");
    let last = history.last().expect("no update in 30 s").1;
    assert!(last < 1.0, "{last:.2} dB from flat after 30 s of walking");
    assert!(settled.is_some_and(|t| t <= 30.0));
    assert_eq!(t.equalizer_refused, 0);
    // Every update sent was applied (with the starting weights), but for the last one,
    // which may still have been in the queue when the output stopped.
    let sent = status.updates + 1 - status.queue_full;
    assert!(
        (sent - 1..=sent).contains(&t.equalizer_updates),
        "{sent} sent"
    );
    assert_eq!(allocations, 0, "the audio threads allocated");
}

/// The same adaptation wired by a live [`Session`](underfoot::live::Session), as `underfoot
/// run --eq FILE --adapt` runs it, with the session's own output port patched straight
/// into its accelerometer input: a wire, so the delay found is the two streams' start-up
/// offset (the input opens first: a few periods), and the weights, which start flat, must
/// stay flat (the adaptation does not wander on a device that needs nothing).
#[cfg(feature = "jack")]
#[test]
fn jack_loopback_session_adapts_through_its_own_streams() {
    use std::sync::atomic::AtomicBool;
    use underfoot::io::spec::OutputSpec;
    use underfoot::live::adapt::AdaptSettings;
    use underfoot::live::{Session, SessionConfig, SessionInput};
    use underfoot::units::Seconds;

    if !loopback_enabled() {
        return;
    }
    let _guard = one_at_a_time();
    let (engine, bank, slot, _) = flat_equalized_gravel(SampleRate(48_000));
    let config = SessionConfig {
        host: "jack".to_owned(),
        duration: Some(Seconds(14.0)),
        adapt: Some(AdaptSettings::default()),
        ..SessionConfig::new(
            SessionInput::Spec("gait:steps=30,channels=1".parse().unwrap()),
            OutputSpec::Audio { device: None },
        )
    };
    let session = Session::open(&config).unwrap();
    let ports = jack_ports();
    let running = session
        .start(&engine, bank, &[slot])
        .expect("the session on JACK");
    jack_connect(&new_port(&ports, "out_0"), &new_port(&ports, "in_0"));
    let summary = running
        .run(&AtomicBool::new(false), |e| {
            panic!("a walk has no link: {e}")
        })
        .unwrap();
    let (status, adapted) = summary.adapt.expect("the adaptation's report");
    let t = &summary.telemetry;
    let spread = {
        let band = adapted.corrected();
        let g: Vec<f64> = band.map(|k| adapted.gains_db[k]).collect();
        g.iter().fold(0.0f64, |m, v| m.max(v.abs()))
    };
    println!(
        "JACK session adaptation on a wire: {status:?}; weights within ±{spread:.2} dB; \
         engine applied {} refused {}; output {:?}",
        t.equalizer_updates, t.equalizer_refused, summary.output
    );
    let delay = status.delay.expect("the delay was never found");
    // A multiple of the period: the wire adds nothing to the streams' offset.
    assert!(
        (0..=24_000).contains(&delay) && delay % 1024 == 0,
        "a wire delays by {delay} samples"
    );
    assert!(status.updates > 0, "no update in 14 s");
    assert!(
        spread < 0.5,
        "the weights wandered by {spread:.2} dB on a wire"
    );
    assert_eq!(t.equalizer_refused, 0);
    // The session stops the engine after its last poll: every update was applied.
    assert_eq!(t.equalizer_updates, status.updates + 1 - status.queue_full);
}
