use proptest::prelude::*;

use super::protocol::cobs_encode;
use super::source::check_config;
use super::*;
use crate::force::scale::CountScale;
use crate::io::IoError;

/// The CRC straight from its definition, one bit at a time.
fn crc_bitwise(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

fn encoded(seq: u16, counts: &[u16]) -> Vec<u8> {
    let mut v = Vec::new();
    encode_frame(&FrameData::new(seq, counts).unwrap(), &mut v);
    v
}

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

#[test]
fn crc_check_value() {
    assert_eq!(crc16_ccitt_false(b"123456789"), 0x29B1);
    assert_eq!(crc_bitwise(b"123456789"), 0x29B1);
    assert_eq!(crc16_ccitt_false(b""), 0xFFFF);
}

#[test]
fn layout_of_a_frame() {
    // Two sensors, 0x0102 and 0x0000: the zeros in the payload are stuffed away.
    let wire = encoded(0x0304, &[0x0102, 0x0000]);
    let payload = [0x01, 0x04, 0x03, 0x02, 0x02, 0x01, 0x00, 0x00];
    let crc = crc16_ccitt_false(&payload).to_le_bytes();
    let mut expected = vec![0x00, 0x07, 0x01, 0x04, 0x03, 0x02, 0x02, 0x01, 0x01];
    // The CRC bytes, stuffed by hand: a zero closes the block.
    let mut block = vec![];
    for b in crc {
        if b == 0 {
            expected.push(block.len() as u8 + 1);
            expected.append(&mut block);
        } else {
            block.push(b);
        }
    }
    expected.push(block.len() as u8 + 1);
    expected.append(&mut block);
    expected.push(0x00);
    assert_eq!(wire, expected);
    assert_eq!(wire.len(), 9 + 2 * 2);
    assert!(!wire[1..wire.len() - 1].contains(&0));
}

#[test]
fn round_trip_with_zeros_and_full_blocks() {
    for counts in [
        vec![0u16],
        vec![0; MAX_FRAME_SENSORS],
        vec![0xFFFF; MAX_FRAME_SENSORS],
        (0..MAX_FRAME_SENSORS as u16).map(|i| i * 1000).collect(),
    ] {
        let (frames, stats) = decode_all(&encoded(9, &counts));
        assert_eq!(frames.len(), 1);
        assert_eq!(frames[0].counts(), &counts[..]);
        assert_eq!(frames[0].seq, 9);
        assert_eq!(stats.rejected, 0);
    }
}

#[test]
fn cobs_blocks_longer_than_254_round_trip() {
    // Frames never get this long, but the stuffing must still be COBS; decoded here by
    // the textbook rule rather than the decoder's length-limited state machine.
    for payload in [
        (0..600u32).map(|i| (i % 251 + 1) as u8).collect::<Vec<_>>(),
        vec![7; 254],
        vec![0; 3],
    ] {
        let mut wire = Vec::new();
        cobs_encode(&payload, &mut wire);
        assert!(!wire.contains(&0));
        let mut out = Vec::new();
        let mut at = 0;
        while at < wire.len() {
            let code = usize::from(wire[at]);
            out.extend(&wire[at + 1..at + code]);
            at += code;
            if code != 0xFF && at < wire.len() {
                out.push(0);
            }
        }
        assert_eq!(out, payload);
    }
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
fn every_rejection_is_named_and_counted() {
    let check = |bytes: Vec<u8>, want: FrameError| {
        let mut d = FrameDecoder::new();
        let results: Vec<_> = bytes.iter().filter_map(|&b| d.push_byte(b)).collect();
        assert_eq!(results, vec![Err(want)], "{bytes:02x?}");
        assert_eq!(d.stats().rejected, 1);
        assert_eq!(d.stats().frames, 0);
        assert_eq!(
            d.stats().bad_checksums,
            u64::from(matches!(want, FrameError::Checksum { .. }))
        );
    };
    let good = encoded(1, &[10, 20]);
    // A bit flipped in a value (byte 6 is the low byte of 10).
    let mut flipped = good.clone();
    flipped[6] ^= 0x10;
    let crc = crc16_ccitt_false(&[1, 1, 0, 2, 10, 0, 20, 0]);
    check(
        flipped,
        FrameError::Checksum {
            computed: crc16_ccitt_false(&[1, 1, 0, 2, 0x1A, 0, 20, 0]),
            received: crc,
        },
    );
    // Cut short inside a block.
    let mut cut = good[..5].to_vec();
    cut.push(0);
    check(cut, FrameError::Stuffing);
    // Stuffing intact but too short.
    check(vec![0, 3, 1, 2, 0], FrameError::TooShort { len: 2 });
    // Garbage longer than any frame.
    let mut long = vec![0];
    long.extend(std::iter::repeat_n(0x55, 1000));
    long.push(0);
    check(long, FrameError::TooLong);
    // Sound frames with a bad header, checksum and all.
    check(frame_of(&[3, 0, 0, 1, 5, 0]), FrameError::UnknownType(3));
    check(frame_of(&[1, 0, 0, 0]), FrameError::SensorCount(0));
    check(frame_of(&[1, 0, 0, 65, 0, 0]), FrameError::SensorCount(65));
    check(
        frame_of(&[1, 0, 0, 3, 5, 0, 6, 0]),
        FrameError::Length {
            sensors: 3,
            len: 10,
        },
    );
}

#[test]
fn resynchronises_after_garbage_with_and_without_zeros() {
    let mut stream = Vec::new();
    stream.extend([0x13, 0x00, 0x55, 0x00, 0x00, 0x41]); // junk, including zeros
    stream.extend(encoded(0, &[1, 2]));
    stream.extend(std::iter::repeat_n(0xAA, 5000)); // a long burst, no zero
    stream.extend(encoded(1, &[3, 4]));
    let (frames, stats) = decode_all(&stream);
    let counts: Vec<_> = frames.iter().map(|f| f.counts().to_vec()).collect();
    assert_eq!(counts, vec![vec![1, 2], vec![3, 4]]);
    // "13", "55", "41" and the burst; the empty chunks between zeros are idle line.
    assert_eq!(stats.rejected, 4);
    assert_eq!(stats.skipped_bytes, 3 + 5000);
    assert_eq!(stats.lost, 0);
}

#[test]
fn lost_frames_are_counted_across_the_wrap() {
    let mut stream = Vec::new();
    for seq in [65533u16, 65534, 1, 2, 6] {
        stream.extend(encoded(seq, &[7]));
    }
    let (frames, stats) = decode_all(&stream);
    assert_eq!(frames.len(), 5);
    // 65535 and 0 between 65534 and 1, then 3, 4 and 5.
    assert_eq!(stats.lost, 5);
}

#[test]
fn layout_of_a_servo_frame() {
    let mut wire = Vec::new();
    encode_servo_frame(
        &ServoFrame::new(0x0102, &[1500, 0x0A0B]).unwrap(),
        &mut wire,
    );
    let payload = [0x02, 0x02, 0x01, 0x02, 0xDC, 0x05, 0x0B, 0x0A];
    let mut want = vec![0];
    let mut p = payload.to_vec();
    p.extend(crc16_ccitt_false(&payload).to_le_bytes());
    cobs_encode(&p, &mut want);
    want.push(0);
    assert_eq!(wire, want);
    assert_eq!(wire.len(), 9 + 2 * 2);
    assert!(ServoFrame::new(0, &[]).is_none());
    assert!(ServoFrame::new(0, &[1; MAX_FRAME_SERVOS + 1]).is_none());
}

#[test]
fn both_frame_types_share_a_stream_and_unknown_types_are_counted() {
    let mut stream = Vec::new();
    for i in 0..5u16 {
        stream.extend(encoded(i, &[i, 2 * i]));
        encode_servo_frame(&ServoFrame::new(i * 3, &[1000 + i]).unwrap(), &mut stream);
        // A sound frame of a type nobody knows, between them.
        stream.extend(frame_of(&[0x7F, 0, 0, 1, 5, 0]));
    }
    let mut d = FrameDecoder::new();
    let mut got = Vec::new();
    d.push(&stream, |f| got.push(f));
    assert_eq!(got.len(), 10);
    for (i, pair) in got.chunks(2).enumerate() {
        let i = i as u16;
        assert_eq!(
            pair[0],
            Frame::Force(FrameData::new(i, &[i, 2 * i]).unwrap())
        );
        assert_eq!(
            pair[1],
            Frame::Servo(ServoFrame::new(i * 3, &[1000 + i]).unwrap())
        );
        assert_eq!(pair[1].type_byte(), SERVO_FRAME);
    }
    let stats = d.stats();
    assert_eq!((stats.rejected, stats.unknown_type), (5, 5));
    // Gaps per type: force frames are consecutive, servo frames skip two each time.
    assert_eq!(stats.lost, 4 * 2);
    // A servo frame may carry at most 16 targets.
    let mut d = FrameDecoder::new();
    let mut p = vec![SERVO_FRAME, 0, 0, 17];
    p.extend([1u8; 34]);
    let results: Vec<_> = frame_of(&p)
        .iter()
        .filter_map(|&b| d.push_byte(b))
        .collect();
    assert_eq!(results, vec![Err(FrameError::SensorCount(17))]);
}

#[test]
fn bad_configs_are_refused() {
    let config = |layout: Vec<usize>, npc: f32| SerialConfig {
        port: "/dev/null".into(),
        baud: 115_200,
        layout,
        scale: CountScale::Uniform {
            newtons_per_count: npc,
        },
    };
    assert!(check_config(&config(vec![2, 2], 0.1)).is_ok());
    assert!(check_config(&config(vec![], 0.1)).is_err());
    assert!(check_config(&config(vec![0], 0.1)).is_err());
    assert!(check_config(&config(vec![9], 0.1)).is_err());
    assert!(check_config(&config(vec![8; 9], 0.1)).is_err());
    assert!(check_config(&config(vec![1], f32::NAN)).is_err());
    assert!(check_config(&config(vec![1], -1.0)).is_err());
    assert!(matches!(
        SerialSource::open(&config(vec![], 1.0)),
        Err(IoError::Unsupported { .. })
    ));
    assert!(matches!(
        SerialSource::open(&SerialConfig {
            port: "/nonexistent/tty".into(),
            ..config(vec![1], 1.0)
        }),
        Err(IoError::Open { .. })
    ));
}

/// How a valid frame's bytes get damaged on the line.
#[derive(Debug, Clone)]
enum Damage {
    None,
    Flip { at: usize, bit: u8 },
    Truncate { keep: usize },
    Drop { at: usize },
    Insert { at: usize, bytes: Vec<u8> },
    GarbageBefore(Vec<u8>),
}

fn damage() -> impl Strategy<Value = Damage> {
    prop_oneof![
        4 => Just(Damage::None),
        1 => (any::<usize>(), 0u8..8).prop_map(|(at, bit)| Damage::Flip { at, bit }),
        1 => any::<usize>().prop_map(|keep| Damage::Truncate { keep }),
        1 => any::<usize>().prop_map(|at| Damage::Drop { at }),
        1 => (any::<usize>(), proptest::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(at, bytes)| Damage::Insert { at, bytes }),
        1 => proptest::collection::vec(any::<u8>(), 0..300).prop_map(Damage::GarbageBefore),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_bytes_never_panic(
        bytes in proptest::collection::vec(any::<u8>(), 0..4000),
        cuts in proptest::collection::vec(any::<usize>(), 0..20),
    ) {
        let mut d = FrameDecoder::new();
        let mut frames = 0u64;
        let mut rest = &bytes[..];
        for cut in cuts {
            let (now, later) = rest.split_at(cut % (rest.len() + 1));
            d.push(now, |_| frames += 1);
            rest = later;
        }
        d.push(rest, |_| frames += 1);
        let s = d.stats();
        prop_assert_eq!(s.frames, frames);
        prop_assert!(s.skipped_bytes <= bytes.len() as u64);
        prop_assert!(s.bad_checksums <= s.rejected);
    }

    #[test]
    fn damaged_frames_never_take_good_ones_down(
        frames in proptest::collection::vec(
            (proptest::collection::vec(any::<u16>(), 1..=MAX_FRAME_SENSORS), damage()),
            1..40,
        ),
        chunk in 1usize..64,
    ) {
        let mut stream = Vec::new();
        let mut intact = Vec::new();
        for (seq, (counts, damage)) in frames.iter().enumerate() {
            let seq = seq as u16;
            let mut wire = encoded(seq, counts);
            let n = wire.len();
            match damage {
                Damage::None => intact.push((seq, counts.clone())),
                Damage::Flip { at, bit } => wire[at % n] ^= 1 << bit,
                Damage::Truncate { keep } => wire.truncate(keep % n),
                Damage::Drop { at } => {
                    wire.remove(at % n);
                }
                Damage::Insert { at, bytes } => {
                    wire.splice(at % n..at % n, bytes.iter().copied());
                }
                Damage::GarbageBefore(bytes) => {
                    stream.extend(bytes);
                    intact.push((seq, counts.clone()));
                }
            }
            stream.extend(wire);
        }
        let mut d = FrameDecoder::new();
        let mut got = Vec::new();
        for piece in stream.chunks(chunk) {
            d.push(piece, |f| {
                if let Frame::Force(f) = f {
                    got.push((f.seq, f.counts().to_vec()));
                }
            });
        }
        // Every intact frame arrives, in order; a damaged frame that happens to pass the
        // CRC (one in 65536) may show up between them.
        let mut next = got.iter();
        for want in &intact {
            prop_assert!(next.any(|g| g == want), "lost {:?}", want);
        }
        prop_assert_eq!(d.stats().frames, got.len() as u64);
    }
}
