//! The wire protocols: OSC datagrams and serial frames (COBS, CRC-16).

// ---- OSC datagrams ----

#[cfg(feature = "osc")]
pub(super) fn run_osc(data: &[u8]) {
    use crate::engine::event::Event;
    use crate::io::osc::OscDecoder;
    let decoder = OscDecoder::new(vec!["gravel".into(), "sand".into()], 2)
        .expect("two channels and two materials");
    decoder.decode(data, &mut |event| match event {
        Ok(Event::Force { channel, .. }) => assert!(channel < 2, "force on channel {channel}"),
        Ok(Event::Step { channel, intensity }) => {
            assert!(channel < 2, "step on channel {channel}");
            assert!(intensity.is_finite(), "step intensity {intensity}");
        }
        Ok(Event::Material { channel, slot }) => {
            assert!(
                channel < 2 && slot < 2,
                "material {slot} on channel {channel}"
            );
        }
        _ => {}
    });
}

#[cfg(feature = "osc")]
pub(super) fn seeds_osc() -> Vec<Vec<u8>> {
    use crate::io::osc::{FORCE_ADDRESS, MATERIAL_ADDRESS, STEP_ADDRESS};
    use rosc::{OscBundle, OscMessage, OscPacket, OscTime, OscType, encoder};
    let message = |addr: &str, args: Vec<OscType>| {
        OscPacket::Message(OscMessage {
            addr: addr.to_owned(),
            args,
        })
    };
    let force = message(
        FORCE_ADDRESS,
        vec![OscType::Int(0), OscType::Float(300.0), OscType::Float(20.0)],
    );
    let step = message(STEP_ADDRESS, vec![OscType::Int(1), OscType::Float(0.8)]);
    let material = message(
        MATERIAL_ADDRESS,
        vec![OscType::Int(0), OscType::String("sand".into())],
    );
    let bundle = OscPacket::Bundle(OscBundle {
        timetag: OscTime::from((0, 1)),
        content: vec![force.clone(), step.clone(), material.clone()],
    });
    [force, step, material, bundle]
        .iter()
        .map(|p| encoder::encode(p).expect("a small packet encodes"))
        .collect()
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
