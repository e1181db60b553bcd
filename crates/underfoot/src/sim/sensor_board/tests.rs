use std::io::Write;
use std::time::Duration;

use super::*;
use crate::io::serial::protocol::cobs_encode;
use crate::io::serial::{DecoderStats, FRAME_VERSION, Frame, FrameDecoder, crc16_ccitt_false};

/// The force frames in `bytes` (a servo frame fails the test).
fn decode_all(bytes: &[u8]) -> (Vec<FrameData>, DecoderStats) {
    let mut d = FrameDecoder::new();
    let mut frames = Vec::new();
    d.push(bytes, |f| match f {
        Frame::Force(f) => frames.push(f),
        Frame::Servo(f) => panic!("unexpected {f:?}"),
    });
    (frames, d.stats())
}

/// A delimited frame of `payload` and its correct checksum.
fn frame_of(payload: &[u8]) -> Vec<u8> {
    let mut p = payload.to_vec();
    p.extend(crc16_ccitt_false(payload).to_le_bytes());
    let mut wire = vec![0];
    cobs_encode(&p, &mut wire);
    wire.push(0);
    wire
}

#[test]
fn reference_sender_quantises_like_an_adc() {
    let mut s = ReferenceSender::new(Vec::new());
    s.send_newtons(&[1.26, -3.0, 1e9], 0.5).unwrap();
    assert!(s.send_newtons(&[f32::NAN], 0.5).is_err());
    assert!(s.send_newtons(&[1.0], 0.0).is_err());
    assert!(s.send_counts(&[]).is_err());
    assert!(s.send_newtons(&[1.0; MAX_FRAME_SENSORS + 1], 1.0).is_err());
    let (frames, _) = decode_all(&s.into_inner());
    assert_eq!(frames.len(), 1);
    assert_eq!(frames[0].counts(), &[3, 0, 65535]);
}

#[test]
fn reference_sender_sends_a_track() {
    use crate::force::track::ChannelSensors;
    use crate::units::Seconds;
    let channel = |name: &str, names: &[&str]| ChannelSensors {
        name: name.into(),
        sensors: names.iter().map(|s| (*s).to_string()).collect(),
    };
    let track = ForceTrack {
        channels: vec![
            channel("left", &["heel", "toe"]),
            channel("right", &["heel", "toe"]),
        ],
        rows: (0..3)
            .map(|i| ForceRow {
                time: Seconds(f64::from(i) * 0.01),
                readings: vec![
                    SensorReading::new(&[i as f32, 1.0]).unwrap(),
                    SensorReading::new(&[2.0, 3.0]).unwrap(),
                ],
            })
            .collect(),
    };
    let mut s = ReferenceSender::new(Vec::new());
    assert_eq!(s.send_track(&track, 0.25).unwrap(), 3);
    let (frames, stats) = decode_all(&s.into_inner());
    assert_eq!(stats.frames, 3);
    assert_eq!(frames[2].seq, 2);
    assert_eq!(frames[2].counts(), &[8, 4, 8, 12]);
}

#[cfg(unix)]
mod pty {
    use std::time::Instant;

    use serialport::{SerialPort, TTYPort};

    use super::*;
    use crate::engine::Event;
    use crate::force::scale::CountScale;
    use crate::io::serial::{SerialConfig, SerialSource};
    use crate::io::{EventSource, IoError, SourceState};

    const GOOD: usize = 200;
    const NPC: f32 = 0.5;
    const LAYOUT: [usize; 2] = [2, 2];

    /// The counts of good frame `i`, recognisable at the other end.
    fn counts_of(i: usize) -> [u16; 4] {
        let i = i as u16;
        [i, 1000 + i, 2000 + i, 3000 + i]
    }

    /// Bad frames, cycling through the ways a frame goes wrong. Each is written between
    /// two good frames, so it forms exactly one chunk and one rejection.
    fn write_bad<W: Write>(kind: usize, s: &mut ReferenceSender<W>) -> io::Result<()> {
        let mut wire = Vec::new();
        match kind {
            0 => {
                // A flipped bit in a value, the checksum as sent. The frame took a
                // sequence number, so it also counts as lost.
                let seq = s.next_frame(&[0]).unwrap().seq.to_le_bytes();
                let mut p = vec![FRAME_VERSION, seq[0], seq[1], 4, 1, 0, 2, 0, 3, 0, 4, 0];
                let crc = crc16_ccitt_false(&p).to_le_bytes();
                p[6] ^= 0x40;
                p.extend(crc);
                wire.push(0);
                cobs_encode(&p, &mut wire);
                wire.push(0);
            }
            1 => {
                // Cut short: the sender reset mid-frame.
                let f = s.next_frame(&[1, 2, 3, 4]).unwrap();
                encode_frame(&f, &mut wire);
                wire.truncate(7);
            }
            2 => {
                // Line noise, no zero in it.
                wire.extend((0..23u8).map(|i| i.wrapping_mul(37) | 1));
            }
            3 => {
                // Four sensors declared, three sent, checksum correct.
                let seq = s.next_frame(&[0]).unwrap().seq.to_le_bytes();
                wire = frame_of(&[FRAME_VERSION, seq[0], seq[1], 4, 1, 0, 2, 0, 3, 0]);
            }
            _ => {
                // A sound frame from firmware wired for three sensors: the source, not the
                // decoder, refuses it.
                let f = s.next_frame(&[1, 2, 3]).unwrap();
                encode_frame(&f, &mut wire);
            }
        }
        s.get_mut().write_all(&wire)
    }

    /// Run-time calibration: each sensor's counts go through its own curve from a
    /// `SensorCalibration`, clamped to the fitted range, instead of one factor.
    #[test]
    fn per_sensor_calibration_scales_each_sensor() {
        use crate::force::calibration::{CurveModel, SensorCalibration, SensorCurve};
        let curve = |name: &str, a: f64, b: f64| SensorCurve {
            name: name.into(),
            model: CurveModel::Power { a, b, r0: 100.0 },
            raw_range: [100.0, 4000.0],
            drift: 0.0,
        };
        let calibration = SensorCalibration {
            sensors: vec![curve("heel", 0.5, 1.0), curve("toe", 0.01, 1.5)],
        };
        let (mut master, slave) = TTYPort::pair().expect("pseudo-terminal pair");
        master.set_timeout(Duration::from_secs(5)).unwrap();
        let config = SerialConfig {
            port: slave.name().expect("the slave end has a path"),
            baud: 115_200,
            layout: vec![2],
            scale: CountScale::calibrated(&calibration),
        };
        let mut source = SerialSource::open(&config).expect("open the slave end");
        // A calibration for three sensors does not fit a two-sensor layout.
        let mut wrong = config.clone();
        wrong.layout = vec![3];
        assert!(matches!(
            SerialSource::open(&wrong),
            Err(IoError::Unsupported { .. })
        ));
        let rows: [[u16; 2]; 4] = [[100, 100], [300, 500], [2100, 1700], [9000, 50]];
        let mut s = ReferenceSender::new(master);
        for r in rows {
            s.send_counts(&r).unwrap();
        }
        let mut events = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(10);
        while events.len() < rows.len() && Instant::now() < deadline {
            source
                .poll(Duration::from_millis(20), &mut |e| events.push(e))
                .unwrap();
        }
        assert_eq!(events.len(), rows.len());
        for (e, r) in events.iter().zip(rows) {
            let want: Vec<f32> = calibration
                .sensors
                .iter()
                .zip(r)
                .map(|(c, raw)| c.force(f64::from(raw)).unwrap().0.0 as f32)
                .collect();
            let Event::Force {
                channel: 0,
                reading,
            } = e
            else {
                panic!("{e:?}")
            };
            assert_eq!(reading.as_slice(), &want[..]);
        }
        // The heel at 300 counts is 0.5 N per count above 100; the last row is
        // clamped above the heel's range and below the toe's.
        let Event::Force { reading, .. } = events[1] else {
            unreachable!()
        };
        assert_eq!(reading.as_slice()[0], 100.0);
        let stats = source.scaling_stats();
        assert_eq!((stats.above_range, stats.below_range), (1, 1));
        drop(s);
    }

    #[test]
    fn good_frames_survive_a_bad_line() {
        let (mut master, slave) = TTYPort::pair().expect("pseudo-terminal pair");
        master.set_timeout(Duration::from_secs(5)).unwrap();
        let slave_name = slave.name().expect("the slave end has a path");
        let config = SerialConfig {
            port: slave_name,
            baud: 115_200,
            layout: LAYOUT.to_vec(),
            scale: CountScale::Uniform {
                newtons_per_count: NPC,
            },
        };
        // Opened by path as a real port would be, 8N1 and raw, next to the pair's own
        // handle (kept open so that the terminal does not hang up between the two).
        let mut source = SerialSource::open(&config).expect("open the slave end");

        let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
        let writer = std::thread::spawn(move || -> io::Result<usize> {
            let mut s = ReferenceSender::new(master);
            let mut bad = 0;
            for i in 0..GOOD {
                s.send_counts(&counts_of(i))?;
                if i % 4 == 1 {
                    write_bad(bad % 5, &mut s)?;
                    bad += 1;
                }
            }
            // Keep the master open until the reader is done: a hang-up could cut off
            // bytes still in the terminal's buffer.
            let _ = done_rx.recv_timeout(Duration::from_secs(20));
            Ok(bad)
        });

        let mut events = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(15);
        while events.len() < GOOD * LAYOUT.len() && Instant::now() < deadline {
            let state = source
                .poll(Duration::from_millis(20), &mut |e| events.push(e))
                .unwrap();
            assert_eq!(state, SourceState::Open);
        }
        // Anything straggling (a duplicate would show here).
        source
            .poll(Duration::from_millis(50), &mut |e| events.push(e))
            .unwrap();
        done_tx.send(()).unwrap();
        let bad = writer.join().unwrap().unwrap();
        drop(slave);

        assert_eq!(events.len(), GOOD * LAYOUT.len(), "events");
        for (i, pair) in events.chunks(2).enumerate() {
            let c = counts_of(i).map(|c| f32::from(c) * NPC);
            let want = [
                Event::Force {
                    channel: 0,
                    reading: SensorReading::new(&c[..2]).unwrap(),
                },
                Event::Force {
                    channel: 1,
                    reading: SensorReading::new(&c[2..]).unwrap(),
                },
            ];
            assert_eq!(pair, want, "frame {i}");
        }
        let stats = source.stats();
        let decoder = source.decoder_stats();
        eprintln!(
            "pty: {GOOD} good + {bad} bad frames sent; {} decoded, {} events, \
             {} rejected ({} bad checksums), {} bytes skipped, {} lost",
            decoder.frames,
            stats.events,
            stats.rejected,
            decoder.bad_checksums,
            stats.skipped_bytes,
            decoder.lost,
        );
        assert_eq!(bad, 50);
        assert_eq!(stats.events, (GOOD * LAYOUT.len()) as u64);
        assert_eq!(stats.rejected, bad as u64);
        // Of each five bad frames, the flipped, the cut-short and the misdeclared one
        // took a sequence number and never arrived whole.
        assert_eq!(decoder.lost, 3 * bad as u64 / 5);
        assert_eq!(decoder.bad_checksums, bad as u64 / 5);
        assert!(stats.skipped_bytes > 0);
    }
}
