//! The servo heartbeat: a thread of its own that writes a servo frame on a fixed deadline,
//! whatever the poll thread is doing (see the [parent module](super), *Heartbeat*).

use std::io::{self, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread;
use std::time::{Duration, Instant};

use serialport::SerialPort;

use crate::interface::servo::ServoBank;
use crate::io::serial::{MAX_FRAME_SERVOS, ServoFrame, describe, encode_servo_frame, is_quiet};
use crate::units::Seconds;

/// What the poll thread and the heartbeat thread share: the servos and the heartbeat's
/// counts. Held for a few microseconds at a time, never while writing to the port.
pub(super) struct Shared {
    pub(super) bank: ServoBank,
    /// When the oldest insole frame not yet reflected in a servo frame was decoded.
    pub(super) pending_since: Option<Instant>,
    /// A reopened port's write handle, for the heartbeat to take.
    pub(super) new_writer: Option<Box<dyn SerialPort>>,
    /// Set by the heartbeat when a write failed: the port is gone.
    pub(super) write_lost: Option<String>,
    pub(super) sent: u64,
    pub(super) delay_sum: f64,
    pub(super) delay_count: u64,
    pub(super) max_delay: f64,
    pub(super) max_gap: f64,
}

pub(super) fn lock(shared: &Mutex<Shared>) -> MutexGuard<'_, Shared> {
    // A panic on the other thread leaves plain counters and servo state, still usable.
    shared.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The heartbeat thread: stopped and joined on drop.
pub(super) struct Heartbeat {
    stop: Arc<AtomicBool>,
    thread: Option<thread::JoinHandle<()>>,
}

impl Drop for Heartbeat {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

impl Heartbeat {
    pub(super) fn start(
        shared: Arc<Mutex<Shared>>,
        writer: Box<dyn SerialPort>,
        period: Duration,
    ) -> Result<Self, io::Error> {
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let stop = Arc::clone(&stop);
            thread::Builder::new()
                .name("servo-heartbeat".into())
                .spawn(move || heartbeat(&shared, &stop, period, writer))?
        };
        Ok(Self {
            stop,
            thread: Some(thread),
        })
    }
}

/// Every `period`, on its own deadline: advances the servos by the real time since the
/// last tick and writes their targets as one servo frame.
fn heartbeat(
    shared: &Mutex<Shared>,
    stop: &AtomicBool,
    period: Duration,
    writer: Box<dyn SerialPort>,
) {
    let mut writer = Some(writer);
    let mut seq: u16 = 0;
    let mut targets = [0u16; MAX_FRAME_SERVOS];
    let mut wire = Vec::with_capacity(64);
    let mut last_update = Instant::now();
    let mut last_sent: Option<Instant> = None;
    let mut next = last_update + period;
    while !stop.load(Ordering::SeqCst) {
        let now = Instant::now();
        if now < next {
            // Unparked early by a stop; a spurious wake-up just goes round again.
            thread::park_timeout(next - now);
            continue;
        }
        // The next frame is due one period after this one was due, not after it went
        // out, so wake-up latency does not accumulate into a slower rate ...
        next += period;
        if next <= now {
            // ... unless the thread was stalled for over a period: resume the cadence
            // from now rather than send a burst of catch-up frames.
            next = now + period;
        }
        let (n, pending) = {
            let mut s = lock(shared);
            if let Some(w) = s.new_writer.take() {
                writer = Some(w);
                last_sent = None;
            }
            s.bank
                .update(Seconds(now.duration_since(last_update).as_secs_f64()));
            last_update = now;
            let n = s.bank.commands(&mut targets);
            let pending = if writer.is_some() {
                s.pending_since.take()
            } else {
                None
            };
            (n, pending)
        };
        let (Some(w), Some(frame)) = (writer.as_mut(), ServoFrame::new(seq, &targets[..n])) else {
            continue; // the port is lost, or no servos are configured
        };
        seq = seq.wrapping_add(1);
        wire.clear();
        encode_servo_frame(&frame, &mut wire);
        let result = w.write_all(&wire);
        let sent = Instant::now();
        let mut s = lock(shared);
        match result {
            Ok(()) => {
                s.sent += 1;
                if let Some(last) = last_sent {
                    s.max_gap = s.max_gap.max(sent.duration_since(last).as_secs_f64());
                }
                last_sent = Some(sent);
                if let Some(since) = pending {
                    let d = sent.duration_since(since).as_secs_f64();
                    s.delay_sum += d;
                    s.delay_count += 1;
                    s.max_delay = s.max_delay.max(d);
                }
            }
            // The line did not take the frame within a period (a board that stopped
            // reading): this frame is dropped, the next one carries the same targets.
            Err(e) if is_quiet(&e) => {}
            Err(e) => {
                writer = None;
                last_sent = None;
                s.write_lost = Some(describe(&e));
            }
        }
    }
}
