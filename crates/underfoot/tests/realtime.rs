//! The audio path never allocates: a counting allocator watches every render call.
//!
//! Everything that happens on the audio thread is exercised: all three drives, force
//! readings, steps, material switches mid-walk (crossfades), a material replaced in the
//! bank, non-finite input, the limiter working, the watchdog fading out and the
//! shut-down fade.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use underfoot::engine::{self, EngineConfig, Event, MaterialBank, TimedEvent};
use underfoot::force::SensorReading;
use underfoot::force::gait::nominal_step;
use underfoot::material::builtin::builtin;
use underfoot::synthesis::{PreparedMaterial, VoiceConfig};
use underfoot::units::{Decibels, Newtons, SampleRate};

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

#[test]
fn rendering_never_allocates_or_frees() {
    let rate = SampleRate(48_000);
    let weight = Newtons::weight_of(70.0);
    let step = nominal_step(70.0, 1.8, rate.hz());
    for drive in ["impulse", "force", "force-rate"] {
        let config = EngineConfig {
            channels: 4,
            drive: drive.parse().unwrap(),
            gain: Decibels(30.0), // so that the limiter works too
            ..EngineConfig::default()
        };
        let bank =
            MaterialBank::prepare(builtin(), rate, &VoiceConfig::default(), &step, weight).unwrap();
        let slots: Vec<u16> = (0..4).map(|c| c as u16).collect();
        let replacement = PreparedMaterial::prepare(
            builtin().get("snow").unwrap(),
            rate,
            &VoiceConfig::default(),
        )
        .unwrap();
        let (mut ctl, mut eng) = engine::build(&config, bank, &slots).unwrap();
        let mut out = vec![0.0f32; 512 * 6];
        let mut replacement = Some(replacement);
        let mut frame = 0u64;
        for block in 0..400u64 {
            // The control side, outside the watched region: readings at 500 Hz.
            for k in 0..5 {
                let t = (frame + k * 96) as f32 / 48_000.0;
                let f = (700.0 * (t * std::f32::consts::TAU * 0.9).sin()).max(0.0);
                for c in 0..4u16 {
                    let reading = SensorReading::new(&[0.5 * f, 0.5 * f]).unwrap();
                    ctl.send(TimedEvent::at(
                        frame + k * 96,
                        Event::Force {
                            channel: c,
                            reading,
                        },
                    ))
                    .unwrap();
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
            if block == 390 {
                ctl.stop().unwrap();
            }
            // Odd block sizes too: 480 frames, into 6 device channels.
            let frames = if block % 3 == 0 { 480 } else { 256 };
            let buf = &mut out[..frames * 6];
            let n = allocations_in(|| eng.process(buf, 6));
            assert_eq!(n, 0, "{drive}: block {block} allocated {n} times");
            frame += frames as u64;
            ctl.collect();
        }
        let t = ctl.telemetry();
        assert!(
            t.strikes > 0 && t.limited > 0 && t.rejected > 0 && t.stopped,
            "{t:?}"
        );
    }
}
