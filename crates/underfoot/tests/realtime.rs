//! The audio path never allocates: a counting allocator watches every render call.
//!
//! Everything that happens on the audio thread is exercised: all three drives, force
//! readings, steps, material switches mid-walk (crossfades), a material replaced in the
//! bank, non-finite input, the limiter working, the watchdog fading out (after the
//! compensation, in the output stage) and the shut-down fade. Each step's excitation: the
//! fitted trains of micro-impacts of the built-ins through the IIR voice and the physical
//! models, struck mid-block, on explicit steps and across material changes, and the
//! generator alone at its cap of draws a sample. The physical aggregate model too: Poisson
//! events, retuned slots, stolen slots, explicit strikes and resets. And the paced
//! pseudo-device of a live session's `null` output (`live::PacedDevice`), whose render
//! stands in for a device's callback: the engine inside it and its clock, on time, late
//! and stalled.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};

use underfoot::compensation::chain::Compensation;
use underfoot::compensation::equalizer::{EqualizerConfig, Realisation, SpectralWeights};
use underfoot::engine::offline::track_events;
use underfoot::engine::{self, EngineConfig, Event, MaterialBank, TimedEvent};
use underfoot::excitation::clock::nominal_speeds;
use underfoot::excitation::{ExcitationModel, Generator, Tables};
use underfoot::force::SensorReading;
use underfoot::force::gait::{GaitConfig, generate, nominal_step};
use underfoot::material::builtin::builtin;
use underfoot::physical::{Aggregate, AggregateParams, SurfaceMode};
use underfoot::signal::butterworth;
use underfoot::synthesis::{PreparedMaterial, SynthModel, VoiceConfig};
use underfoot::units::{Decibels, Hz, Newtons, SampleRate, Seconds};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    static WATCHING: Cell<bool> = const { Cell::new(false) };
}

// SAFETY: forwards to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if WATCHING.with(Cell::get) {
            ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        }
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if WATCHING.with(Cell::get) {
            ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        }
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if WATCHING.with(Cell::get) {
            ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations and frees made by `f` on this thread.
fn allocations_in(f: impl FnOnce()) -> usize {
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    WATCHING.with(|w| w.set(true));
    f();
    WATCHING.with(|w| w.set(false));
    ALLOCATIONS.load(Ordering::SeqCst) - before
}

#[test]
fn the_counter_sees_allocations() {
    assert!(allocations_in(|| drop(std::hint::black_box(vec![1u8; 64]))) >= 2);
}

/// The built-in library prepared for the IIR voice and for the physical models, with
/// the excitations fitted to each material. Preparing a bank (a modal fit per material) is
/// most of these tests' time, and it happens before any engine exists: once for all of
/// them, cloned for each case.
fn banks() -> &'static (MaterialBank, MaterialBank) {
    static BANKS: OnceLock<(MaterialBank, MaterialBank)> = OnceLock::new();
    BANKS.get_or_init(|| {
        let rate = SampleRate(48_000);
        let step = nominal_step(70.0, 1.8, rate.hz());
        let bank_for = |model| {
            let voice = VoiceConfig {
                model,
                ..VoiceConfig::default()
            };
            MaterialBank::prepare(builtin(), rate, &voice, &step, Newtons::weight_of(70.0)).unwrap()
        };
        (bank_for(SynthModel::Iir), bank_for(SynthModel::Physical))
    })
}

#[test]
fn rendering_never_allocates_or_frees() {
    let rate = SampleRate(48_000);
    // The last case runs every channel through a low-delay equalizer and a limb filter.
    let mut weights = SpectralWeights::flat(EqualizerConfig::default(), rate).unwrap();
    weights.add_in_band(|f| 6.0 * (-((f.0 - 300.0) / 80.0).powi(2)).exp());
    let compensation = Compensation {
        equalizer: Some((weights, Realisation::LowDelay { taps: 512 })),
        limb: Some(butterworth::lowpass(2, Hz(1500.0), rate).unwrap()),
    };
    let voice_for = |model| VoiceConfig {
        model,
        ..VoiceConfig::default()
    };
    let (iir_bank, physical_bank) = banks();
    for (drive, model, compensated) in [
        ("impulse", SynthModel::Iir, false),
        ("force", SynthModel::Iir, false),
        ("force-rate", SynthModel::Iir, false),
        ("impulse", SynthModel::Physical, false),
        ("force-rate", SynthModel::Iir, true),
        ("force-rate", SynthModel::Physical, true),
    ] {
        let voice = voice_for(model);
        let config = EngineConfig {
            channels: 4,
            drive: drive.parse().unwrap(),
            gain: Decibels(30.0), // so that the limiter works too
            // Room for materials added while it plays (a panel's fits).
            spare_slots: 2,
            compensation: if compensated {
                compensation.clone()
            } else {
                Compensation::default()
            },
            ..EngineConfig::default()
        };
        let bank = match model {
            SynthModel::Iir => iir_bank.clone(),
            SynthModel::Physical => physical_bank.clone(),
        };
        let slots: Vec<u16> = (0..4).map(|c| c as u16).collect();
        let replacement =
            PreparedMaterial::prepare(builtin().get("snow").unwrap(), rate, &voice).unwrap();
        let (mut ctl, mut eng) = engine::build(&config, bank, &slots).unwrap();
        let mut out = vec![0.0f32; 512 * 6];
        let mut replacement = Some(replacement);
        let mut added = vec![
            PreparedMaterial::prepare(builtin().get("sand").unwrap(), rate, &voice).unwrap(),
            PreparedMaterial::prepare(builtin().get("wood").unwrap(), rate, &voice).unwrap(),
        ];
        let mut frame = 0u64;
        for block in 0..400u64 {
            // The control side, outside the watched region: readings at 500 Hz, with a
            // gap of some 0.4 s in which every channel's output stage fades out.
            let readings = if (200..240).contains(&block) { 0 } else { 5 };
            for k in 0..readings {
                let t = (frame + k * 96) as f32 / 48_000.0;
                let f = (700.0 * (t * std::f32::consts::TAU * 0.9).sin()).max(0.0);
                for c in 0..4u16 {
                    let reading = SensorReading::new(&[0.5 * f, 0.5 * f]).unwrap();
                    // Channel 0's readings carry their sensor time and no frame: the
                    // sensor clock schedules them on the audio thread.
                    let event = if c == 0 {
                        TimedEvent::now(Event::Force {
                            channel: c,
                            reading: reading.at(Seconds(f64::from(t))),
                        })
                    } else {
                        TimedEvent::at(
                            frame + k * 96,
                            Event::Force {
                                channel: c,
                                reading,
                            },
                        )
                    };
                    ctl.send(event).unwrap();
                }
            }
            if block % 50 == 7 {
                let slot = (block / 50 % 11) as u16;
                ctl.send(TimedEvent::now(Event::Material { channel: 1, slot }))
                    .unwrap();
                ctl.send(TimedEvent::now(Event::Step {
                    channel: 2,
                    intensity: 1.5,
                }))
                .unwrap();
                ctl.send(TimedEvent::now(Event::Force {
                    channel: 3,
                    reading: SensorReading::single(f32::NAN),
                }))
                .unwrap();
            }
            if block == 100
                && let Some(m) = replacement.take()
            {
                ctl.replace_material(3, m).unwrap();
            }
            // Materials added into the spare slots and played at once; a third is
            // refused on the control side (the bank is full), never on the audio thread.
            if (block == 120 || block == 160)
                && let Some(m) = added.pop()
            {
                let slot = ctl.add_material(m).unwrap();
                assert_eq!(usize::from(slot), 11 + (block as usize - 120) / 40);
                ctl.send(TimedEvent::now(Event::Material { channel: 0, slot }))
                    .unwrap();
            }
            if block == 170 {
                let m =
                    PreparedMaterial::prepare(builtin().get("ice").unwrap(), rate, &voice).unwrap();
                assert!(matches!(
                    ctl.add_material(m),
                    Err(engine::EngineError::BankFull { capacity: 13 })
                ));
            }
            // Trims on two channels, one of them non-finite (refused on the control side),
            // one past 0 dB (clamped).
            if block % 60 == 13 {
                ctl.set_trim(2, Decibels(-(block as f64) / 20.0)).unwrap();
                ctl.set_trim(1, Decibels(6.0)).unwrap();
                assert!(ctl.set_trim(1, Decibels(f64::NAN)).is_err());
            }
            if block == 390 {
                ctl.stop().unwrap();
            }
            // Odd block sizes too: 480 frames, into 6 device channels.
            let frames = if block % 3 == 0 { 480 } else { 256 };
            let buf = &mut out[..frames * 6];
            let n = allocations_in(|| eng.process(buf, 6));
            assert_eq!(n, 0, "{drive}/{model:?}: block {block} allocated {n} times");
            frame += frames as u64;
            ctl.collect();
        }
        let t = ctl.telemetry();
        assert!(
            t.strikes > 0 && t.limited > 0 && t.rejected > 0 && t.stopped && t.watchdog_trips > 0,
            "{t:?}"
        );
    }
}

#[test]
fn the_paced_pseudo_device_never_allocates_or_frees() {
    use std::time::Duration;
    use underfoot::live::PacedDevice;
    use underfoot::live::record::OutputTap;

    let rate = SampleRate(48_000);
    let bank = banks().0.clone();
    let config = EngineConfig {
        channels: 2,
        ..EngineConfig::default()
    };
    let (mut ctl, eng) = engine::build(&config, bank, &[0, 1]).unwrap();
    let block = 256;
    let period = Duration::from_secs_f64(block as f64 / rate.hz());
    // With a session record's tap: every buffer copied into its ring too.
    let (tap, mut reader) = OutputTap::pair(2, rate);
    let mut device = PacedDevice::new(eng, None, 2, rate, block).with_record(tap);
    let mut recorded = Vec::new();
    let mut strikes = 0;
    for n in 0..300u64 {
        // The control side, outside the watched region: readings at about 500 Hz.
        let t = (n * 256) as f32 / 48_000.0;
        let f = (700.0 * (t * std::f32::consts::TAU * 0.9).sin()).max(0.0);
        for channel in 0..2u16 {
            let reading = SensorReading::new(&[0.5 * f, 0.5 * f]).unwrap();
            ctl.send(TimedEvent::now(Event::Force { channel, reading }))
                .unwrap();
        }
        if n == 290 {
            ctl.stop().unwrap();
        }
        let mut wait = Duration::ZERO;
        let allocated = allocations_in(|| wait = device.render().unwrap());
        assert_eq!(allocated, 0, "buffer {n} allocated {allocated} times");
        // Fall behind by two buffers once, then stall for over a second: the clock
        // catches up, then starts afresh.
        if n == 100 {
            std::thread::sleep(wait + 2 * period);
        } else if n == 200 {
            std::thread::sleep(wait + Duration::from_millis(1100));
        }
        ctl.collect();
        reader.take(&mut recorded);
        strikes += ctl.take_strikes(|_| {});
    }
    let report = device.finish().unwrap();
    assert_eq!(report.blocks, 300);
    assert_eq!(recorded.len(), 300 * 256 * 2);
    assert_eq!(reader.dropped(), 0);
    // Two late wake-ups made here; a loaded machine may add its own.
    assert!(report.late >= 2, "{report:?}");
    let t = ctl.telemetry();
    assert!(t.strikes > 0 && t.stopped, "{t:?}");
    // Every strike reached the log, from inside the watched calls.
    assert_eq!(strikes as u64, t.strikes);
}

/// Every built-in but `hard` plays a train of micro-impacts after its heel (thousands a
/// second of step clock on sand and snow). Through the engine, for the IIR voice and for
/// the physical models, with the default `impulse` drive: channel 0 walks (a generated
/// gait, its readings at their frames, so its strikes fall mid-block), channel 1 walks the
/// same readings sent without a frame (the sensor clock places them), channel 2 gets an
/// explicit step every 0.3 s (its trains run on the free clock, one after the other), and
/// every channel changes material 0.1 s after each of its steps, while the train runs;
/// blocks of 1 to 512 frames.
///
/// The drive meter shows that the trains played inside the watched calls: a heel sounds
/// in the call of its strike, so a call without a strike whose drive is not zero played
/// micro-impacts. If the generator allocated for one, this test would fail.
#[test]
fn trains_of_micro_impacts_never_allocate_or_free() {
    let rate = SampleRate(48_000);
    let gait = generate(&GaitConfig {
        steps: 6,
        channels: 1,
        lead_in: Seconds(0.1),
        tail: Seconds(0.3),
        ..GaitConfig::default()
    })
    .unwrap();
    let walk = track_events(&gait.track, rate);
    let frames = walk.last().and_then(|e| e.at).unwrap() + 4800;
    let step_every = 14_400;
    let (iir_bank, physical_bank) = banks();
    for (model, bank) in [
        (SynthModel::Iir, iir_bank),
        (SynthModel::Physical, physical_bank),
    ] {
        let trains: Vec<u16> = (0..bank.materials().len())
            .filter(|&k| bank.materials()[k].excitation.bins() > 0)
            .map(|k| k as u16)
            .collect();
        assert!(trains.len() >= 10, "{model:?}: {trains:?} play trains");
        // The control side's schedule, made before the engine runs: channel 0's readings,
        // channel 2's steps, and the material changes 0.1 s into each step.
        let mut timed: Vec<TimedEvent> = walk.clone();
        let change = |k: usize, channel: u16, at: u64| {
            let slot = trains[(k + usize::from(channel)) % trains.len()];
            TimedEvent::at(at + 4800, Event::Material { channel, slot })
        };
        for (k, strike) in gait.strikes[0].iter().enumerate() {
            let at = (strike.0 * rate.hz()).round() as u64;
            timed.extend([change(k, 0, at), change(k, 1, at)]);
        }
        for (k, at) in (37..frames).step_by(step_every).enumerate() {
            let step = Event::Step {
                channel: 2,
                intensity: 1.0,
            };
            timed.extend([TimedEvent::at(at, step), change(k, 2, at)]);
        }
        timed.sort_by_key(|e| e.at);
        let config = EngineConfig {
            channels: 3,
            ..EngineConfig::default()
        };
        let (mut ctl, mut eng) = engine::build(&config, bank.clone(), &trains[..3]).unwrap();
        let meters = ctl.telemetry_handle();
        let mut out = vec![0.0f32; 512 * 3];
        let (mut next, mut live, mut frame) = (0, 0, 0u64);
        let mut strikes = [0u64; 3];
        let mut train_calls = [0usize; 3];
        let mut calls = 0usize;
        while frame < frames {
            let n = [1, 7, 64, 333, 512, 480][calls % 6];
            let end = frame + n as u64;
            while let Some(e) = timed.get(next).filter(|e| e.at.unwrap() < end) {
                ctl.send(*e).unwrap();
                next += 1;
            }
            // Channel 1's readings, sent in the call their frame falls in, as a live
            // source sends them.
            while let Some(e) = walk.get(live).filter(|e| e.at.unwrap() < end) {
                let Event::Force { reading, .. } = e.event else {
                    unreachable!("the walk is readings")
                };
                ctl.send(TimedEvent::now(Event::Force {
                    channel: 1,
                    reading,
                }))
                .unwrap();
                live += 1;
            }
            let buf = &mut out[..n * 3];
            let allocated = allocations_in(|| eng.process(buf, 3));
            assert_eq!(
                allocated, 0,
                "{model:?}: call {calls} allocated {allocated} times"
            );
            assert!(buf.iter().all(|v| v.is_finite()));
            for (c, (count, trained)) in strikes.iter_mut().zip(&mut train_calls).enumerate() {
                let m = meters.take_channel(c).unwrap();
                if m.strikes == *count && m.drive > 0.0 {
                    *trained += 1;
                }
                *count = m.strikes;
            }
            ctl.collect();
            frame = end;
            calls += 1;
        }
        // Six strikes a walk and a step every 0.3 s; trains in hundreds of calls.
        assert!(
            strikes[0] >= 6 && strikes[1] >= 6 && strikes[2] >= 20,
            "{strikes:?}"
        );
        assert!(
            train_calls.iter().all(|&t| t >= 100),
            "{model:?}: calls with micro-impacts and no strike: {train_calls:?} of {calls}"
        );
        let t = ctl.telemetry();
        assert_eq!(t.rejected, 0, "{t:?}");
        assert!(t.peak > 0.0, "{t:?}");
    }
}

/// The generator alone, over every built-in's excitation: a strike through a nominal step,
/// a free step restruck mid-train at speeds that are zero, not a number, nominal, and fast
/// enough that more micro-impacts are due in a sample than it draws (`MAX_DRAWS`), then a
/// stop.
#[test]
fn the_excitation_generator_never_allocates_or_frees() {
    let rate = SampleRate(48_000);
    let speeds = nominal_speeds(rate);
    let mut out = vec![0.0f32; speeds.len()];
    for m in &builtin().materials {
        let model = m
            .excitation
            .clone()
            .unwrap_or_else(ExcitationModel::heel_only);
        let tables = Tables::new(&model, rate).unwrap();
        let has_train = tables.bins() > 0;
        let mut g = Generator::new(7);
        let allocated = allocations_in(|| {
            g.strike(&tables, 1.0);
            g.process(&tables, &speeds, &mut out);
            g.step(&tables, 0.8);
            for (k, y) in out.iter_mut().enumerate() {
                *y = g.next(&tables, [0.0, f32::NAN, 1.0, 1000.0][k % 4]);
                if k == 5000 {
                    g.strike(&tables, 2.0);
                }
            }
            g.stop();
            g.process(&tables, &speeds, &mut out);
        });
        assert_eq!(allocated, 0, "{}: allocated {allocated} times", m.name);
        assert!(!has_train || g.events() > 100, "{}: {}", m.name, g.events());
    }
}

#[test]
fn the_aggregate_model_never_allocates_or_frees() {
    let rate = SampleRate(48_000);
    let modes: Vec<SurfaceMode> = [
        (180.0, 0.08, 2e-3),
        (640.0, 0.04, 1e-3),
        (2100.0, 0.02, 5e-4),
    ]
    .iter()
    .map(|&(f, tau, gain)| SurfaceMode {
        frequency: Hz(f),
        decay: Seconds(tau),
        gain,
    })
    .collect();
    let params = AggregateParams {
        size_spread: 0.4,
        ..AggregateParams::default()
    };
    let mut agg = Aggregate::new(&modes, &params, rate, 42).unwrap();
    let mut rates = vec![0.0f32; 480];
    let mut out = vec![0.0f32; 480];
    for block in 0..600usize {
        // A footstep-like rise and fall of the rate, floods (slot stealing and the
        // per-sample cap), silences (slots coming to rest) and invalid rates.
        for (n, r) in rates.iter_mut().enumerate() {
            let t = (block * 480 + n) as f32 / 48_000.0;
            *r = match block % 100 {
                0..=39 => 2000.0 * (t * 3.0).sin().max(0.0),
                40..=44 => 1e6,
                45..=49 => [f32::NAN, -3.0, f32::INFINITY][n % 3],
                _ => 0.0,
            };
        }
        let frames = if block % 3 == 0 { 480 } else { 128 };
        let (r, o) = (&rates[..frames], &mut out[..frames]);
        let n = allocations_in(|| {
            agg.process(r, o);
            if block % 37 == 5 {
                agg.strike(2.0);
            }
            if block == 300 {
                agg.reset();
            }
        });
        assert_eq!(n, 0, "block {block} allocated {n} times");
        assert!(out[..frames].iter().all(|v| v.is_finite()));
    }
    assert!(agg.events() > 1000, "{}", agg.events());
}

#[test]
fn the_filter_bank_never_allocates_or_frees() {
    use underfoot::compensation::filterbank::{FilterBank, FilterBankConfig};

    let mut bank = FilterBank::new(FilterBankConfig::default(), SampleRate(48_000)).unwrap();
    let mut gains = vec![1.0f32; bank.bins()];
    let mut input = vec![0.0f32; 512];
    let mut out = vec![0.0f32; 512];
    for block in 0..400usize {
        for (n, x) in input.iter_mut().enumerate() {
            *x = ((block * 512 + n) as f32 * 0.037).sin();
        }
        if block % 50 == 7 {
            input[3] = f32::NAN;
        }
        for (k, g) in gains.iter_mut().enumerate() {
            *g = 1.0 / (1.0 + (k + block % 5) as f32 / 30.0);
        }
        let frames = [1, 7, 64, 512][block % 4];
        let (x, y) = (&input[..frames], &mut out[..frames]);
        let n = allocations_in(|| {
            bank.set_gains(&gains);
            if block % 9 == 0 {
                bank.set_gains_with(|f| if f.0 > 2000.0 { 0.5 } else { 1.0 });
            }
            bank.process(x, y);
            if block == 200 {
                bank.reset();
            }
        });
        assert_eq!(n, 0, "block {block} allocated {n} times");
        assert!(out[..frames].iter().all(|v| v.is_finite()));
    }
    assert!(bank.non_finite_inputs() > 0);
}

#[test]
fn adapting_the_equalizer_never_allocates_or_frees() {
    use underfoot::compensation::adapt::{AdaptConfig, Adapter};
    use underfoot::compensation::equalizer::{
        EqualizerConfig, EqualizerFilter, Realisation, SpectralWeights,
    };
    use underfoot::safety::{Limiter, LimiterReport};
    use underfoot::signal::noise::SplitMix64;
    use underfoot::sim::{SimulatedTile, TileConfig};

    let rate = SampleRate(48_000);
    let weights = SpectralWeights::flat(EqualizerConfig::default(), rate).unwrap();
    let cfg = AdaptConfig {
        interval: Seconds(0.1),
        min_frames: 4,
        ..AdaptConfig::default()
    };
    for realisation in [Realisation::Bank, Realisation::default()] {
        let mut adapter = Adapter::new(&weights, cfg).unwrap();
        let mut filter = EqualizerFilter::new(adapter.weights(), realisation).unwrap();
        let mut limiter = Limiter::new(Decibels(-6.0), Seconds(0.05), rate);
        let mut report = LimiterReport::default();
        let noise = TileConfig {
            noise: Some(Decibels(-30.0)),
            ..TileConfig::default()
        };
        let mut tile = SimulatedTile::new(&noise, rate).unwrap();
        let mut rng = SplitMix64::new(3);
        let mut input = vec![0.0f32; 512];
        let mut drive = vec![0.0f32; 512];
        let mut applied = 0;
        for block in 0..1500usize {
            let frames = [1, 7, 64, 512][block % 4];
            for x in &mut input[..frames] {
                *x = (0.3 * rng.normal()) as f32;
            }
            if block % 97 == 5 {
                input[0] = f32::NAN;
            }
            let (x, y) = (&input[..frames], &mut drive[..frames]);
            let n = allocations_in(|| {
                filter.process(x, y);
                for v in y.iter_mut() {
                    *v = limiter.tick(*v, &mut report);
                }
            });
            assert_eq!(n, 0, "{realisation:?}: filtering block {block} allocated");
            // The simulated device allocates its output; it is not on the audio path.
            let wide: Vec<f64> = drive[..frames].iter().map(|&v| f64::from(v)).collect();
            let mut accel: Vec<f32> = tile.process(&wide).iter().map(|&v| v as f32).collect();
            if block % 89 == 3 {
                accel[0] = f32::INFINITY;
            }
            let force = Newtons(if block % 300 < 250 { 600.0 } else { 20.0 });
            let d = &drive[..frames];
            let n = allocations_in(|| {
                if let Some(w) = adapter.push(d, &accel, force) {
                    assert!(filter.set_weights(w));
                    applied += 1;
                }
            });
            assert_eq!(n, 0, "{realisation:?}: adapting block {block} allocated");
        }
        assert!(applied >= 5, "{realisation:?}: {applied} updates");
        assert!(adapter.non_finite() > 0);
        assert!(drive.iter().all(|v| v.is_finite()));
    }
}

#[test]
fn applying_a_sensor_calibration_never_allocates_or_frees() {
    use underfoot::force::calibration::{CurveKind, SensorCalibration, fit_sensor};
    let samples: Vec<(f64, Newtons)> = (0..40)
        .map(|i| {
            let load = 25.0 * f64::from(i);
            (200.0 + (load / 0.0119).powf(1.0 / 1.4), Newtons(load))
        })
        .collect();
    let power = fit_sensor("heel", &samples, CurveKind::Power).unwrap().0;
    let piecewise = fit_sensor("toe", &samples, CurveKind::Piecewise).unwrap().0;
    let mut calibration = SensorCalibration {
        sensors: vec![power, piecewise],
    };
    calibration.tare(&[210.0, 205.0, 190.0, 195.0]).unwrap();
    let inputs: [[f32; 2]; 5] = [
        [200.0, 200.0],
        [1500.0, 2500.0],
        [1e9, -1e9],
        [f32::NAN, f32::INFINITY],
        [3000.0, 800.0],
    ];
    let mut out = [0.0_f32; 3];
    let mut non_finite = 0;
    let n = allocations_in(|| {
        for raw in &inputs {
            non_finite += calibration.apply(raw, &mut out).non_finite;
            std::hint::black_box(&out);
        }
        // Fewer readings than outputs is counted, not a panic.
        calibration.apply(&inputs[1][..1], &mut out);
    });
    assert_eq!(n, 0, "apply allocated or freed {n} times");
    assert_eq!(non_finite, 2);
}
