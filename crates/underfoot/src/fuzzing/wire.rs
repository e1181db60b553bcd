//! The wire protocols: OSC datagrams and serial frames (COBS, CRC-16).

// ---- OSC datagrams ----

#[cfg(feature = "osc")]
pub(super) fn run_osc(data: &[u8]) {
    use crate::engine::event::Event;
    use crate::io::osc::{Decoded, OscDecoder};
    let decoder = OscDecoder::new(vec!["gravel".into(), "sand".into()], 2)
        .expect("two channels and two materials");
    decoder.decode(data, &mut |event| match event {
        Ok(Decoded::Event(Event::Force { channel, .. })) => {
            assert!(channel < 2, "force on channel {channel}")
        }
        Ok(Decoded::Event(Event::Step { channel, intensity })) => {
            assert!(channel < 2, "step on channel {channel}");
            assert!(intensity.is_finite(), "step intensity {intensity}");
        }
        Ok(Decoded::Event(Event::Material { channel, slot })) => {
            assert!(
                channel < 2 && slot < 2,
                "material {slot} on channel {channel}"
            );
        }
        Ok(Decoded::Marker(m)) => assert!(m.check().is_ok(), "marker {m:?}"),
        Err(_) => {}
    });
}

#[cfg(feature = "osc")]
pub(super) fn seeds_osc() -> Vec<Vec<u8>> {
    use crate::io::osc::wire::{Arg, encode_bundle, encode_message};
    use crate::io::osc::{FORCE_ADDRESS, MARKER_ADDRESS, MATERIAL_ADDRESS, STEP_ADDRESS};
    // Channels count from 1.
    let force = encode_message(
        FORCE_ADDRESS,
        &[Arg::Int(1), Arg::Float(300.0), Arg::Float(20.0)],
    );
    let step = encode_message(STEP_ADDRESS, &[Arg::Int(2), Arg::Float(0.8)]);
    let material = encode_message(MATERIAL_ADDRESS, &[Arg::Int(1), Arg::Str("sand")]);
    let marker = encode_message(
        MARKER_ADDRESS,
        &[Arg::Str("trial 1"), Arg::Int(1), Arg::Str("P01")],
    );
    let bundle = encode_bundle(&[force.clone(), step.clone(), material.clone()]);
    vec![force, step, material, marker, bundle]
}

// ---- serial frames (COBS, CRC-16) ----

#[cfg(feature = "serial")]
pub(super) fn run_serial(data: &[u8]) {
    use crate::io::serial::{Frame, FrameDecoder, encode_frame, encode_servo_frame};
    let mut decoder = FrameDecoder::new();
    let mut frames = Vec::new();
    decoder.push(data, |f| frames.push(f));
    // A frame decoded is one that encodes back to itself.
    let mut bytes = Vec::new();
    for frame in &frames {
        match frame {
            Frame::Force(f) => encode_frame(f, &mut bytes),
            Frame::Servo(s) => encode_servo_frame(s, &mut bytes),
        }
    }
    let mut again = Vec::new();
    FrameDecoder::new().push(&bytes, |f| again.push(f));
    assert_eq!(frames, again, "decoded frames do not survive re-encoding");
}

#[cfg(feature = "serial")]
pub(super) fn seeds_serial() -> Vec<Vec<u8>> {
    use crate::io::serial::{FrameData, ServoFrame, encode_frame, encode_servo_frame};
    let mut out = Vec::new();
    encode_frame(
        &FrameData::new(1, &[512, 0, 1023]).expect("three counts"),
        &mut out,
    );
    encode_servo_frame(
        &ServoFrame::new(2, &[1500, 1000]).expect("two targets"),
        &mut out,
    );
    encode_frame(&FrameData::new(3, &[7]).expect("one count"), &mut out);
    vec![out]
}
