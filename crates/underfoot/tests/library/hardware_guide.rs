//! The hardware guide's worked frame is what the encoder sends: firmware authors copy
//! those bytes, so the document is checked like code.
#![cfg(feature = "serial")]

use std::path::Path;

use underfoot::io::serial::{
    FrameData, ServoFrame, crc16_ccitt_false, encode_frame, encode_servo_frame,
};

/// The hardware guide's text.
fn guide() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/hardware.md");
    std::fs::read_to_string(&path).expect("docs/hardware.md")
}

/// The hex bytes on the guide's line that starts with `label`.
fn bytes_after(guide: &str, label: &str) -> Vec<u8> {
    let line = guide
        .lines()
        .find(|l| l.starts_with(label))
        .unwrap_or_else(|| panic!("no line starting with {label:?} in the guide"));
    line[label.len()..]
        .split_whitespace()
        .map_while(|w| u8::from_str_radix(w, 16).ok())
        .collect()
}

#[test]
fn the_worked_force_frame_is_what_the_encoder_sends() {
    let guide = guide();
    let payload = bytes_after(&guide, "payload");
    let wire = bytes_after(&guide, "wire");

    let frame = FrameData::new(258, &[812, 0, 405, 96]).unwrap();
    let mut sent = Vec::new();
    encode_frame(&frame, &mut sent);
    assert_eq!(wire, sent, "the guide's wire bytes");
    assert_eq!(wire.len(), 9 + 2 * 4, "the guide's frame length");

    let (body, crc) = payload.split_at(payload.len() - 2);
    assert_eq!(
        crc16_ccitt_false(body),
        u16::from_le_bytes([crc[0], crc[1]]),
        "the guide's payload checksum"
    );
    assert!(guide.contains(&format!("CRC 0x{:04X}", crc16_ccitt_false(body))));
}

#[test]
fn the_worked_servo_frame_is_what_the_host_sends() {
    let guide = guide();
    let payload = bytes_after(&guide, "servo payload");
    let wire = bytes_after(&guide, "servo wire");

    let frame = ServoFrame::new(7, &[1500, 1720, 1000]).unwrap();
    let mut sent = Vec::new();
    encode_servo_frame(&frame, &mut sent);
    assert_eq!(wire, sent, "the guide's servo wire bytes");

    let (body, crc) = payload.split_at(payload.len() - 2);
    let expected = crc16_ccitt_false(body);
    assert_eq!(expected, u16::from_le_bytes([crc[0], crc[1]]));
    assert!(guide.contains(&format!("CRC 0x{expected:04X}")));
}
