use super::*;
use crate::signal::noise::SplitMix64;
use Arg::Int;
use proptest::prelude::*;
use std::time::Instant;
use wire::{encode_bundle, encode_message};

// Datagrams are built by `wire`'s encoder, which its own tests check against the
// specification's bytes.
fn msg(addr: &str, args: Vec<Arg<'_>>) -> Vec<u8> {
    encode_message(addr, &args)
}

fn bundle(content: Vec<Vec<u8>>) -> Vec<u8> {
    encode_bundle(&content)
}

fn names() -> Vec<String> {
    ["gravel", "snow", "wood"].map(String::from).to_vec()
}

/// The events (and rejections) of a datagram; a marker is a test failure here.
fn decoded(d: &OscDecoder, datagram: &[u8]) -> Vec<Result<Event, OscReject>> {
    let mut v = Vec::new();
    d.decode(datagram, &mut |r| {
        v.push(r.map(|d| match d {
            Decoded::Event(e) => e,
            Decoded::Marker(m) => panic!("a marker: {m:?}"),
        }));
    });
    v
}

fn decoded_markers(d: &OscDecoder, datagram: &[u8]) -> Vec<Result<Marker, OscReject>> {
    let mut v = Vec::new();
    d.decode(datagram, &mut |r| {
        v.push(r.map(|d| match d {
            Decoded::Marker(m) => m,
            Decoded::Event(e) => panic!("an event: {e:?}"),
        }));
    });
    v
}

fn force(channel: u16, newtons: &[f32]) -> Event {
    Event::Force {
        channel,
        reading: SensorReading::new(newtons).unwrap(),
    }
}

/// Good packets and the events they should make.
fn good() -> Vec<(Vec<u8>, Vec<Event>)> {
    use Arg::{Double, Float, Int, Long, Str};
    vec![
        (
            msg(FORCE_ADDRESS, vec![Int(2), Float(612.5)]),
            vec![force(1, &[612.5])],
        ),
        (
            msg(FORCE_ADDRESS, vec![Float(1.0), Int(300), Double(2.5)]),
            vec![force(0, &[300.0, 2.5])],
        ),
        (
            msg(STEP_ADDRESS, vec![Int(2)]),
            vec![Event::Step {
                channel: 1,
                intensity: 1.0,
            }],
        ),
        (
            msg(STEP_ADDRESS, vec![Long(1), Int(2)]),
            vec![Event::Step {
                channel: 0,
                intensity: 2.0,
            }],
        ),
        (
            msg(MATERIAL_ADDRESS, vec![Int(2), Str("wood")]),
            vec![Event::Material {
                channel: 1,
                slot: 2,
            }],
        ),
        (
            bundle(vec![
                msg(MATERIAL_ADDRESS, vec![Int(1), Str("snow")]),
                bundle(vec![msg(STEP_ADDRESS, vec![Int(1), Float(0.5)])]),
                msg(FORCE_ADDRESS, vec![Int(1), Float(1.0), Float(2.0)]),
            ]),
            vec![
                Event::Material {
                    channel: 0,
                    slot: 1,
                },
                Event::Step {
                    channel: 0,
                    intensity: 0.5,
                },
                force(0, &[1.0, 2.0]),
            ],
        ),
    ]
}

fn nested(levels: usize) -> Vec<u8> {
    let mut p = msg(STEP_ADDRESS, vec![Int(1)]);
    for _ in 0..levels {
        p = bundle(vec![p]);
    }
    p
}

/// Malformed datagrams, each to be rejected once, and the reason.
fn malformed() -> Vec<(&'static str, Vec<u8>, OscReject)> {
    use Arg::{Float, Int, Str};
    let mut noise = SplitMix64::new(7);
    let random: Vec<u8> = (0..97).map(|_| noise.next_u64() as u8).collect();
    let mut truncated = msg(FORCE_ADDRESS, vec![Int(1), Float(1.0)]);
    truncated.truncate(truncated.len() - 3);
    vec![
        ("random bytes", random, OscReject::NotOsc),
        ("empty", vec![], OscReject::NotOsc),
        ("truncated", truncated, OscReject::NotOsc),
        (
            "unknown address",
            msg("/underfoot/jump", vec![Int(0)]),
            OscReject::UnknownAddress,
        ),
        (
            "force as a string",
            msg(FORCE_ADDRESS, vec![Int(1), Str("heavy")]),
            OscReject::Arguments,
        ),
        (
            "force without a value",
            msg(FORCE_ADDRESS, vec![Int(1)]),
            OscReject::Arguments,
        ),
        (
            "nine sensors",
            msg(
                FORCE_ADDRESS,
                std::iter::once(Int(1))
                    .chain(std::iter::repeat_n(Float(1.0), 9))
                    .collect(),
            ),
            OscReject::Arguments,
        ),
        (
            "channel as a string",
            msg(STEP_ADDRESS, vec![Str("0")]),
            OscReject::Arguments,
        ),
        (
            "fractional channel",
            msg(STEP_ADDRESS, vec![Float(0.5)]),
            OscReject::Arguments,
        ),
        (
            "channel too high",
            msg(STEP_ADDRESS, vec![Int(3)]),
            OscReject::Channel(3),
        ),
        (
            "channel 0 (channels count from 1)",
            msg(FORCE_ADDRESS, vec![Int(0), Float(1.0)]),
            OscReject::Channel(0),
        ),
        (
            "a protocol-1 address",
            msg("/underfoot/force", vec![Int(0), Float(1.0)]),
            OscReject::OldProtocol,
        ),
        (
            "a protocol-1 step without arguments",
            msg("/underfoot/step", vec![]),
            OscReject::OldProtocol,
        ),
        (
            "negative channel",
            msg(FORCE_ADDRESS, vec![Int(-1), Float(1.0)]),
            OscReject::Channel(-1),
        ),
        (
            "unknown material",
            msg(MATERIAL_ADDRESS, vec![Int(1), Str("lava")]),
            OscReject::UnknownMaterial,
        ),
        (
            "material as a slot number",
            msg(MATERIAL_ADDRESS, vec![Int(1), Int(1)]),
            OscReject::Arguments,
        ),
        (
            "NaN force",
            msg(FORCE_ADDRESS, vec![Int(1), Float(1.0), Float(f32::NAN)]),
            OscReject::Value,
        ),
        (
            "infinite force",
            msg(FORCE_ADDRESS, vec![Int(1), Arg::Double(1e300)]),
            OscReject::Value,
        ),
        (
            "negative intensity",
            msg(STEP_ADDRESS, vec![Int(1), Float(-1.0)]),
            OscReject::Value,
        ),
        ("bundles too deep", nested(20), OscReject::TooDeep),
    ]
}

#[test]
fn good_packets_make_the_right_events() {
    let d = OscDecoder::new(names(), 2).unwrap();
    for (packet, want) in good() {
        let got = decoded(&d, &packet);
        assert_eq!(
            got,
            want.into_iter().map(Ok).collect::<Vec<_>>(),
            "{packet:?}"
        );
    }
    assert_eq!(decoded(&d, &nested(MAX_BUNDLE_DEPTH)).len(), 1);
}

#[test]
fn malformed_packets_say_why() {
    let d = OscDecoder::new(names(), 2).unwrap();
    for (what, datagram, why) in malformed() {
        assert_eq!(decoded(&d, &datagram), vec![Err(why)], "{what}");
    }
    // A bad message in a bundle costs only itself.
    let mixed = bundle(vec![
        msg(STEP_ADDRESS, vec![Int(6)]),
        msg(STEP_ADDRESS, vec![Int(2)]),
    ]);
    let got = decoded(&d, &mixed);
    assert_eq!(got[0], Err(OscReject::Channel(6)));
    assert!(got[1].is_ok());
    // Bytes after a message make the packet suspect.
    let mut trailing = msg(STEP_ADDRESS, vec![Int(2)]);
    trailing.extend([0, 0, 0, 0]);
    assert_eq!(decoded(&d, &trailing), vec![Err(OscReject::NotOsc)]);
}

#[test]
fn markers_carry_their_trial_fields_and_bad_ones_say_why() {
    use Arg::{Int, Str};
    let d = OscDecoder::new(names(), 2).unwrap();
    let got = decoded_markers(
        &d,
        &msg(
            MARKER_ADDRESS,
            vec![
                Str("trial 3 starts"),
                Int(3),
                Str("P07"),
                Str("gravel first"),
            ],
        ),
    );
    assert_eq!(
        got,
        vec![Ok(Marker {
            trial: Some(3),
            participant: Some("P07".into()),
            condition: Some("gravel first".into()),
            ..Marker::new("trial 3 starts")
        })]
    );
    assert_eq!(
        decoded_markers(&d, &msg(MARKER_ADDRESS, vec![Str("note")])),
        vec![Ok(Marker::new("note"))]
    );
    for (what, args, why) in [
        ("no text", vec![Int(1)], OscReject::Arguments),
        (
            "a negative trial",
            vec![Str("x"), Int(-1)],
            OscReject::Arguments,
        ),
        ("a line break", vec![Str("a\nb")], OscReject::Marker),
        ("empty", vec![Str(" ")], OscReject::Marker),
        (
            "five arguments",
            vec![Str("x"), Int(1), Str("p"), Str("c"), Str("?")],
            OscReject::Arguments,
        ),
    ] {
        assert_eq!(
            decoded_markers(&d, &msg(MARKER_ADDRESS, args)),
            vec![Err(why)],
            "{what}"
        );
    }
}

#[test]
fn bad_tables_are_refused() {
    assert!(OscDecoder::new(names(), 0).is_err());
    assert!(OscDecoder::new(names(), MAX_INDEX + 1).is_err());
    assert!(OscDecoder::new(vec![String::new(); MAX_INDEX + 1], 1).is_err());
    assert!(matches!(
        OscSource::bind("127.0.0.1:0", names(), 0),
        Err(IoError::Unsupported { .. })
    ));
    assert!(matches!(
        OscSource::bind("not an address", names(), 1),
        Err(IoError::Open { .. })
    ));
}

/// Polls until `n` events arrived or a second passed.
fn receive(source: &mut OscSource, n: usize) -> Vec<Event> {
    let mut events = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(2);
    while events.len() < n && Instant::now() < deadline {
        let state = source
            .poll(Duration::from_millis(20), &mut |e| events.push(e))
            .unwrap();
        assert_eq!(state, SourceState::Open);
    }
    events
}

#[test]
fn udp_round_trip() {
    let mut source = OscSource::bind("127.0.0.1:0", names(), 2).unwrap();
    let to = source.local_addr().unwrap();
    let sender = UdpSocket::bind("127.0.0.1:0").unwrap();

    // Nothing sent: a poll waits about its timeout and returns empty.
    let start = Instant::now();
    let mut none = 0;
    source
        .poll(Duration::from_millis(30), &mut |_| none += 1)
        .unwrap();
    assert_eq!(none, 0);
    assert!(start.elapsed() >= Duration::from_millis(25));
    // A zero timeout does not wait at all.
    source.poll(Duration::ZERO, &mut |_| none += 1).unwrap();
    assert_eq!(none, 0);

    let mut want = Vec::new();
    for (packet, events) in good() {
        sender.send_to(&packet, to).unwrap();
        want.extend(events);
    }
    assert_eq!(receive(&mut source, want.len()), want);
    assert_eq!(source.stats().events, want.len() as u64);
    assert_eq!(source.stats().rejected, 0);

    let bad = malformed();
    for (_, datagram, _) in &bad {
        sender.send_to(datagram, to).unwrap();
    }
    let after = msg(STEP_ADDRESS, vec![Int(2), Arg::Float(0.25)]);
    sender.send_to(&after, to).unwrap();
    let got = receive(&mut source, 1);
    assert_eq!(
        got,
        vec![Event::Step {
            channel: 1,
            intensity: 0.25
        }]
    );
    let stats = source.stats();
    eprintln!(
        "osc: {} good datagrams, {} malformed; {} events, {} rejected",
        good().len() + 1,
        bad.len(),
        stats.events,
        stats.rejected
    );
    assert_eq!(stats.rejected, bad.len() as u64);
    assert_eq!(stats.events, want.len() as u64 + 1);

    // Each reason is counted apart, and the counts are the same total.
    let mut expected = OscRejectCounts::default();
    for (_, _, reason) in &bad {
        expected.record(reason);
    }
    let counts = source.rejections();
    assert_eq!(counts, expected);
    assert_eq!(counts.total(), stats.rejected);
    assert!(counts.not_osc >= 3 && counts.channel >= 2 && counts.arguments >= 5);
    // Localhost UDP keeps order, and the good message after the bad ones leaves the last reason.
    assert_eq!(source.last_reject(), bad.last().map(|(_, _, r)| *r));
}

#[test]
fn rejection_counts_name_each_reason() {
    let mut counts = OscRejectCounts::default();
    counts.record(&OscReject::Channel(2));
    counts.record(&OscReject::Channel(-1));
    counts.record(&OscReject::UnknownAddress);
    assert_eq!(counts.total(), 3);
    let by_reason = counts.by_reason();
    let named = |name: &str| by_reason.iter().find(|(n, _)| *n == name).unwrap().1;
    assert_eq!(named("channel out of range"), 2);
    assert_eq!(named("unknown address"), 1);
    assert_eq!(by_reason.iter().map(|(_, c)| c).sum::<u64>(), 3);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_datagrams_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let d = OscDecoder::new(names(), 2).unwrap();
        d.decode(&bytes, &mut |_| {});
    }

    #[test]
    fn damaged_packets_never_panic(
        which in 0usize..6,
        edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 1..8),
        cut in any::<usize>(),
    ) {
        let d = OscDecoder::new(names(), 2).unwrap();
        let mut datagram = good().swap_remove(which).0;
        for (at, b) in edits {
            let n = datagram.len();
            datagram[at % n] = b;
        }
        datagram.truncate(cut % (datagram.len() + 1));
        let mut events = 0;
        d.decode(&datagram, &mut |r| {
            if let Ok(Decoded::Event(e)) = r {
                events += 1;
                // Whatever got through is within the table.
                assert!(usize::from(e.channel()) < 2);
                if let Event::Force { reading, .. } = e {
                    assert!(reading.is_finite());
                }
            }
        });
        prop_assert!(events <= 3);
    }
}
