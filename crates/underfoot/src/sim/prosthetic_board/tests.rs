//! The simulated board and the host, over pseudo-terminals: the frames both ways, the
//! servos' return to rest, and a whole simulated walk.

use std::io::{Read, Write};
use std::path::Path;
use std::sync::Arc;

use serialport::SerialPort;

use super::*;
use crate::engine::Event;
use crate::interface::config::{InterfaceConfig, Link};
use crate::io::prosthetic::ProstheticHost;
use crate::io::serial::{ServoFrame, crc16_ccitt_false, encode_servo_frame};
use crate::io::{EventSource, SourceState};
use crate::sim::ReferenceSender;

fn sim_config(servo_rate: u32, gait: &str) -> InterfaceConfig {
    let text = format!(
        r#"
[link]
port = "simulated"
servo_rate_hz = {servo_rate}
insole_timeout_s = 0.1

[insole]
newtons_per_count = 0.5

[[sensor]]
name = "heel"
index = 0
[[sensor]]
name = "midfoot"
index = 1
[[sensor]]
name = "toe"
index = 2

{servos}

[[channel]]
name = "disc"
sensors = ["heel", "midfoot", "toe"]

[simulated]
gait = "{gait}"
newtons_per_count = 0.5
slew_us_per_s = 4000
"#,
        servos = ["heel", "midfoot", "toe"]
            .iter()
            .enumerate()
            .map(|(i, s)| format!(
                "[[servo]]\nid = {i}\nsensors = [\"{s}\"]\nrange_us = [1000, 2000]\n\
                 rest_us = 1000\nfull_us = 2000\nthreshold_n = 20\nfull_force_n = 500\n\
                 dead_band_us = 4\nrate_us_per_s = 6000\n"
            ))
            .collect::<Vec<_>>()
            .join("\n"),
    );
    InterfaceConfig::parse(&text, Path::new("test.toml"), |_| unreachable!()).unwrap()
}

#[test]
fn heel_midfoot_toe_share_the_force_and_roll_over() {
    let c = sim_config(50, "steps=1,rate=500,lead_in=0,tail=0");
    let Link::Simulated(sim) = &c.link else {
        unreachable!()
    };
    let foot = SimulatedFoot::new(sim, 3, &[1000; 3]).unwrap();
    let g = gait::generate(&sim.gait).unwrap();
    let mut peaks = [(0.0f32, 0usize); 3];
    for (i, row) in g.track.rows.iter().enumerate() {
        let hmt = foot.heel_midfoot_toe(i);
        let total = row.readings[0].total();
        assert!((hmt.iter().sum::<f32>() - total).abs() <= 1e-3 * total.max(1.0));
        assert!(hmt.iter().all(|&f| f >= 0.0));
        for (p, &f) in peaks.iter_mut().zip(&hmt) {
            if f > p.0 {
                *p = (f, i);
            }
        }
    }
    assert!(peaks.iter().all(|p| p.0 > 100.0), "{peaks:?}");
    assert!(
        peaks[0].1 < peaks[1].1 && peaks[1].1 < peaks[2].1,
        "heel, midfoot, toe peak in order: {peaks:?}"
    );
}

/// The firmware end of a pty sends insole frames with bad ones between, the host end
/// sends servo frames with bad ones between; each end must get every good frame intact,
/// count the bad ones and resynchronise.
#[cfg(unix)]
#[test]
fn pty_round_trip_both_directions_survives_a_bad_line() {
    use serialport::TTYPort;
    const GOOD: u16 = 150;
    /// Bad chunks of either direction, each a single rejection.
    fn bad(kind: u16, seq: u16, type_byte: u8) -> Vec<u8> {
        let mut w = Vec::new();
        match kind % 4 {
            0 => {
                // A flipped bit.
                encode_servo_or_force(type_byte, seq, &mut w);
                let n = w.len();
                w[n / 2] ^= 0x10;
                if w[n / 2] == 0 {
                    w[n / 2] = 0x33;
                }
            }
            1 => {
                encode_servo_or_force(type_byte, seq, &mut w);
                w.truncate(6);
            }
            2 => w.extend((1..=19u8).map(|i| i.wrapping_mul(29) | 1)),
            _ => {
                // Sound, but of an unknown type.
                let p = [0x09, 0, 0, 1, 7, 0];
                let mut payload = p.to_vec();
                payload.extend(crc16_ccitt_false(&p).to_le_bytes());
                w.push(0);
                cobs(&payload, &mut w);
                w.push(0);
            }
        }
        w
    }
    fn cobs(p: &[u8], out: &mut Vec<u8>) {
        // Plain COBS for short payloads (< 254 bytes).
        let mut code_at = out.len();
        out.push(0);
        let mut code = 1u8;
        for &b in p {
            if b == 0 {
                out[code_at] = code;
                code_at = out.len();
                out.push(0);
                code = 1;
            } else {
                out.push(b);
                code += 1;
            }
        }
        out[code_at] = code;
    }
    fn encode_servo_or_force(type_byte: u8, seq: u16, w: &mut Vec<u8>) {
        if type_byte == 0x02 {
            encode_servo_frame(&ServoFrame::new(seq, &[1500, 1600, 1700]).unwrap(), w);
        } else {
            encode_frame(&FrameData::new(seq, &[1, 2, 3]).unwrap(), w);
        }
    }
    fn servo_targets(i: u16) -> [u16; 3] {
        [1000 + i, 1200 + i, 1400 + i]
    }
    fn insole_counts(i: u16) -> [u16; 3] {
        [i, 500 + i, 1000 + i]
    }

    let (mut device, mut host) = TTYPort::pair().expect("pseudo-terminal pair");
    device.set_timeout(Duration::from_millis(5)).unwrap();
    host.set_timeout(Duration::from_millis(5)).unwrap();
    let device_thread = thread::spawn(move || -> (Vec<ServoFrame>, u64, u64) {
        let mut sender = ReferenceSender::new(device);
        let mut decoder = FrameDecoder::new();
        let mut got = Vec::new();
        let mut buf = [0u8; 256];
        let deadline = Instant::now() + Duration::from_secs(15);
        let mut sent = 0u16;
        while (got.len() < usize::from(GOOD) || sent < GOOD) && Instant::now() < deadline {
            if sent < GOOD {
                sender.send_counts(&insole_counts(sent)).unwrap();
                if sent % 3 == 1 {
                    let junk = bad(sent / 3, sent, 0x01);
                    sender.get_mut().write_all(&junk).unwrap();
                }
                sent += 1;
            }
            if let Ok(n) = sender.get_mut().read(&mut buf) {
                decoder.push(&buf[..n], |f| {
                    if let Frame::Servo(s) = f {
                        got.push(s);
                    }
                });
            }
        }
        let s = decoder.stats();
        (got, s.rejected, s.unknown_type)
    });

    let mut decoder = FrameDecoder::new();
    let mut got: Vec<FrameData> = Vec::new();
    let mut buf = [0u8; 256];
    let mut wire = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(15);
    let mut sent = 0u16;
    while (got.len() < usize::from(GOOD) || sent < GOOD) && Instant::now() < deadline {
        if sent < GOOD {
            wire.clear();
            encode_servo_frame(
                &ServoFrame::new(sent, &servo_targets(sent)).unwrap(),
                &mut wire,
            );
            if sent % 3 == 1 {
                wire.extend(bad(sent / 3, sent, 0x02));
            }
            host.write_all(&wire).unwrap();
            sent += 1;
        }
        if let Ok(n) = host.read(&mut buf) {
            decoder.push(&buf[..n], |f| {
                if let Frame::Force(f) = f {
                    got.push(f);
                }
            });
        }
    }
    let (servo_got, servo_rejected, servo_unknown) = device_thread.join().unwrap();
    let bad_count = u64::from(GOOD.div_ceil(3));
    // Host side: every insole frame, intact and in order.
    assert_eq!(got.len(), usize::from(GOOD));
    for (i, f) in got.iter().enumerate() {
        let i = i as u16;
        assert_eq!((f.seq, f.counts()), (i, &insole_counts(i)[..]));
    }
    let s = decoder.stats();
    assert_eq!(s.rejected, bad_count, "{s:?}");
    assert_eq!(s.unknown_type, bad_count / 4);
    assert_eq!(s.lost, 0);
    // Device side: every servo frame.
    assert_eq!(servo_got.len(), usize::from(GOOD));
    for (i, f) in servo_got.iter().enumerate() {
        let i = i as u16;
        assert_eq!((f.seq, f.targets()), (i, &servo_targets(i)[..]));
    }
    assert_eq!(servo_rejected, bad_count);
    assert_eq!(servo_unknown, bad_count / 4);
}

/// When the insole stops mid-stance, the host keeps sending servo frames and their
/// targets walk back to rest at the rate limit, after the input timeout.
#[cfg(unix)]
#[test]
fn servos_return_to_rest_when_the_insole_stops() {
    use serialport::TTYPort;
    let config = sim_config(100, "steps=1");
    let (mut device, host_end) = TTYPort::pair().expect("pseudo-terminal pair");
    device.set_timeout(Duration::from_millis(5)).unwrap();
    let mut host = ProstheticHost::with_port(Box::new(host_end), "pty", &config).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let board = {
        let stop = Arc::clone(&stop);
        thread::spawn(move || {
            let mut sender = ReferenceSender::new(device);
            let mut decoder = FrameDecoder::new();
            let mut got: Vec<(Instant, Vec<u16>)> = Vec::new();
            let mut buf = [0u8; 256];
            let start = Instant::now();
            while !stop.load(Ordering::SeqCst) {
                // Full force on the heel (1000 counts = 500 N) for 0.4 s, then silence.
                if start.elapsed() < Duration::from_millis(400) {
                    sender.send_counts(&[1000, 0, 0]).unwrap();
                }
                if let Ok(n) = sender.get_mut().read(&mut buf) {
                    decoder.push(&buf[..n], |f| {
                        if let Frame::Servo(f) = f {
                            got.push((Instant::now(), f.targets().to_vec()));
                        }
                    });
                }
            }
            (start, got)
        })
    };
    let until = Instant::now() + Duration::from_millis(1200);
    while Instant::now() < until {
        host.poll(Duration::from_millis(20), &mut |_| {}).unwrap();
    }
    stop.store(true, Ordering::SeqCst);
    let (start, got) = board.join().unwrap();
    let stats = host.stats();
    assert_eq!(stats.input_timeouts, 1, "{stats:?}");
    // The heel servo reached full pressure while the insole was live ...
    let peak = got.iter().map(|(_, t)| t[0]).max().unwrap();
    assert_eq!(peak, 2000);
    // ... and is back at rest at the end, having moved no faster than its rate limit
    // (6000 µs/s) between frames.
    assert_eq!(got.last().unwrap().1[0], 1000);
    for w in got.windows(2) {
        let dt = w[1].0.duration_since(w[0].0).as_secs_f64();
        let moved = (f64::from(w[1].1[0]) - f64::from(w[0].1[0])).abs();
        // Arrival times jitter around the sending times: allow a frame period.
        assert!(
            moved <= 6000.0 * (dt + 0.01) + 1.0,
            "moved {moved} µs in {dt} s"
        );
    }
    // Not before the timeout: full pressure held until 0.4 s + 0.1 s.
    let left_full = got
        .iter()
        .find(|(t, v)| t.duration_since(start) > Duration::from_millis(400) && v[0] < 2000)
        .map(|(t, _)| t.duration_since(start).as_secs_f64())
        .unwrap();
    assert!(left_full >= 0.45, "left full pressure at {left_full} s");
}

/// The host and the simulated board over a pty, in real time: the engine gets force
/// events, the servos follow heel, midfoot, toe in order within each step, and return to
/// rest after the walk.
#[cfg(unix)]
#[test]
#[ignore = "slow tier: paced in real time"]
fn simulated_walk_drives_servos_heel_to_toe() {
    let config = sim_config(
        100,
        "steps=3,cadence=2.5,rate=250,lead_in=0.1,tail=0.4,variation=0",
    );
    let (mut host, sim) = open_interface(&config).unwrap();
    let sim = sim.unwrap();
    let mut events = 0u64;
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline {
        let state = host
            .poll(Duration::from_millis(20), &mut |e| {
                assert!(matches!(e, Event::Force { channel: 0, .. }));
                events += 1;
            })
            .unwrap();
        if state == SourceState::Ended {
            break;
        }
    }
    // Keep serving servo frames while the board lingers, so the return to rest shows.
    let until = Instant::now() + Duration::from_millis(250);
    while Instant::now() < until {
        let _ = host.poll(Duration::from_millis(10), &mut |_| {});
    }
    let hs = host.stats();
    let report = sim.finish().unwrap();
    eprintln!(
        "simulated: {} insole frames sent, host got {} ({} rejected), {} servo frames sent, \
         board got {}; servo delay max {:.1} ms mean {:.1} ms",
        report.insole_frames,
        hs.insole_frames,
        hs.rejected,
        hs.servo_frames_sent,
        report.servo_frames,
        hs.max_servo_delay.0 * 1e3,
        hs.mean_servo_delay.0 * 1e3
    );
    assert_eq!(hs.insole_frames, report.insole_frames);
    assert_eq!(hs.rejected, 0);
    assert_eq!(events, hs.insole_frames);
    assert!(hs.servo_frames_sent > 50);
    assert!(report.servo_frames + 5 >= hs.servo_frames_sent);
    assert_eq!(report.rejected, 0);
    // Within each step (the foot's stance), servo k peaks after servo k - 1.
    let step = 1.0 / 2.5 * 2.0; // one foot: a strike per gait cycle
    for n in 0..3 {
        let (from, to) = (0.1 + step * n as f64, 0.1 + step * (n as f64 + 0.9));
        let mut peak = [(0.0f64, 0.0f64); 3];
        for (t, pos) in &report.positions {
            if t.0 < from || t.0 > to {
                continue;
            }
            for (p, &x) in peak.iter_mut().zip(pos) {
                if x > p.0 {
                    *p = (x, t.0);
                }
            }
        }
        assert!(peak.iter().all(|p| p.0 > 1200.0), "step {n}: {peak:?}");
        assert!(
            peak[0].1 < peak[1].1 && peak[1].1 < peak[2].1,
            "step {n}: heel, midfoot, toe in order: {peak:?}"
        );
    }
    // After the walk, everything back at rest.
    let last = &report.positions.last().unwrap().1;
    assert!(last.iter().all(|&p| (p - 1000.0).abs() < 1.0), "{last:?}");
}
