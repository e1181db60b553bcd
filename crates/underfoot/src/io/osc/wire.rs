//! The OSC 1.0 wire format: what a datagram holds, read without copying and written for
//! senders and tests.
//!
//! A packet is a message or a bundle. Every item is a multiple of 4 bytes, big-endian:
//!
//! - an **OSC-string** is UTF-8 bytes, a NUL, and NULs up to the next multiple of 4 (so
//!   `"/a"` is `2f 61 00 00`, and a 4-byte string takes 8);
//! - a **message** is its address (an OSC-string starting with `/`), its type tags (an
//!   OSC-string starting with `,`, one letter per argument), then the arguments;
//! - a **bundle** is the OSC-string `#bundle`, an 8-byte time tag, then elements, each a
//!   32-bit size (a multiple of 4) and that many bytes holding a message or a bundle.
//!
//! Arguments by tag: `i` int32, `f` float32, `h` int64, `d` float64, `s`/`S` string or
//! symbol, `b` blob (int32 size, bytes, NULs to a multiple of 4), `t` time tag (8 bytes),
//! `c`, `r`, `m` (4 bytes: char, colour, MIDI), and `T`, `F`, `N`, `I`, `[`, `]` with no
//! bytes. The decoder needs only the numbers and strings; the others are read so that a
//! message carrying them is well-formed (and refused by its address's rules, not as
//! garbage). An unknown tag, a missing NUL, bad padding, invalid UTF-8, a size past the end
//! or bytes left over make the whole packet malformed. A message without type tags (OSC
//! 1.0 allows senders of its time to omit them) has no arguments.
//!
//! Parsing checks the whole packet before it yields a message, so a malformed packet
//! yields none: a bundle is applied whole or not at all.

/// One argument of a message.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum Arg<'a> {
    /// `i`: a 32-bit integer.
    Int(i32),
    /// `h`: a 64-bit integer.
    Long(i64),
    /// `f`: a 32-bit float.
    Float(f32),
    /// `d`: a 64-bit float.
    Double(f64),
    /// `s` (or `S`, a symbol): a string.
    Str(&'a str),
    /// Any other type, by its tag letter (`b`, `t`, `c`, `r`, `m`, `T`, `F`, `N`, `I`, `[`,
    /// `]`).
    Other(u8),
}

/// A message: its address and arguments.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Message<'a> {
    /// The address pattern, e.g. `/underfoot/step`.
    pub address: &'a str,
    /// The arguments, in order.
    pub args: Vec<Arg<'a>>,
}

/// Why a datagram is not an OSC packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Malformed {
    /// Not OSC: see the module doc for what is checked.
    Bytes,
    /// Bundles nested deeper than the limit given.
    TooDeep,
}

const BUNDLE_TAG: &[u8] = b"#bundle\0";

/// Every message of `packet`, in order, after checking all of it; bundles may nest up to
/// `max_depth` levels.
pub(super) fn parse(packet: &[u8], max_depth: usize) -> Result<Vec<Message<'_>>, Malformed> {
    let mut messages = Vec::new();
    element(packet, max_depth, &mut messages)?;
    Ok(messages)
}

fn element<'a>(
    bytes: &'a [u8],
    depth_left: usize,
    out: &mut Vec<Message<'a>>,
) -> Result<(), Malformed> {
    if bytes.starts_with(BUNDLE_TAG) {
        let depth_left = depth_left.checked_sub(1).ok_or(Malformed::TooDeep)?;
        let mut rest = bytes.get(BUNDLE_TAG.len() + 8..).ok_or(Malformed::Bytes)?;
        while !rest.is_empty() {
            let (size, after) = rest.split_first_chunk::<4>().ok_or(Malformed::Bytes)?;
            let size = u32::from_be_bytes(*size) as usize;
            if !size.is_multiple_of(4) {
                return Err(Malformed::Bytes);
            }
            let content = after.get(..size).ok_or(Malformed::Bytes)?;
            element(content, depth_left, out)?;
            rest = &after[size..];
        }
        Ok(())
    } else {
        out.push(message(bytes)?);
        Ok(())
    }
}

fn message(bytes: &[u8]) -> Result<Message<'_>, Malformed> {
    let mut r = Reader(bytes);
    let address = r.string()?;
    if !address.starts_with('/') {
        return Err(Malformed::Bytes);
    }
    let mut args = Vec::new();
    if !r.0.is_empty() {
        let tags = r.string()?;
        let tags = tags.strip_prefix(',').ok_or(Malformed::Bytes)?;
        for tag in tags.bytes() {
            args.push(match tag {
                b'i' => Arg::Int(i32::from_be_bytes(r.take()?)),
                b'f' => Arg::Float(f32::from_be_bytes(r.take()?)),
                b'h' => Arg::Long(i64::from_be_bytes(r.take()?)),
                b'd' => Arg::Double(f64::from_be_bytes(r.take()?)),
                b's' | b'S' => Arg::Str(r.string()?),
                b'b' => {
                    let size = u32::from_be_bytes(r.take()?) as usize;
                    r.skip(size.checked_next_multiple_of(4).ok_or(Malformed::Bytes)?)?;
                    Arg::Other(tag)
                }
                b't' => {
                    r.take::<8>()?;
                    Arg::Other(tag)
                }
                b'c' | b'r' | b'm' => {
                    r.take::<4>()?;
                    Arg::Other(tag)
                }
                b'T' | b'F' | b'N' | b'I' | b'[' | b']' => Arg::Other(tag),
                _ => return Err(Malformed::Bytes),
            });
        }
    }
    if r.0.is_empty() {
        Ok(Message { address, args })
    } else {
        Err(Malformed::Bytes)
    }
}

/// The unread rest of a message.
struct Reader<'a>(&'a [u8]);

impl<'a> Reader<'a> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], Malformed> {
        let (head, rest) = self.0.split_first_chunk::<N>().ok_or(Malformed::Bytes)?;
        self.0 = rest;
        Ok(*head)
    }

    fn skip(&mut self, n: usize) -> Result<(), Malformed> {
        self.0 = self.0.get(n..).ok_or(Malformed::Bytes)?;
        Ok(())
    }

    /// An OSC-string: the text up to its NUL, then NULs to a multiple of 4.
    fn string(&mut self) -> Result<&'a str, Malformed> {
        let len = self
            .0
            .iter()
            .position(|&b| b == 0)
            .ok_or(Malformed::Bytes)?;
        let padded = (len + 1).next_multiple_of(4);
        let field = self.0.get(..padded).ok_or(Malformed::Bytes)?;
        if field[len..].iter().any(|&b| b != 0) {
            return Err(Malformed::Bytes);
        }
        let text = std::str::from_utf8(&field[..len]).map_err(|_| Malformed::Bytes)?;
        self.0 = &self.0[padded..];
        Ok(text)
    }
}

/// A message as the bytes of a datagram (or of a bundle's element). [`Arg::Other`]
/// arguments are written as their tag alone, which is right for `T`, `F`, `N`, `I`, `[`
/// and `]`; the decoder needs no others, so no sender here writes them.
///
/// # Panics
/// If an [`Arg::Other`] names a tag that carries bytes (`b`, `t`, `c`, `r`, `m`), or a string
/// holds a NUL: neither has an encoding here.
#[must_use]
pub fn encode_message(address: &str, args: &[Arg<'_>]) -> Vec<u8> {
    let mut out = Vec::new();
    put_string(&mut out, address);
    let mut tags = String::from(",");
    for arg in args {
        tags.push(match *arg {
            Arg::Int(_) => 'i',
            Arg::Long(_) => 'h',
            Arg::Float(_) => 'f',
            Arg::Double(_) => 'd',
            Arg::Str(_) => 's',
            Arg::Other(tag @ (b'T' | b'F' | b'N' | b'I' | b'[' | b']')) => char::from(tag),
            Arg::Other(tag) => panic!("no encoding for OSC tag {:?}", char::from(tag)),
        });
    }
    put_string(&mut out, &tags);
    for arg in args {
        match *arg {
            Arg::Int(i) => out.extend(i.to_be_bytes()),
            Arg::Long(h) => out.extend(h.to_be_bytes()),
            Arg::Float(f) => out.extend(f.to_be_bytes()),
            Arg::Double(d) => out.extend(d.to_be_bytes()),
            Arg::Str(s) => put_string(&mut out, s),
            Arg::Other(_) => {}
        }
    }
    out
}

/// A bundle of already-encoded elements (messages or bundles), with the time tag
/// "immediately" (1), as the bytes of a datagram.
#[must_use]
pub fn encode_bundle(elements: &[Vec<u8>]) -> Vec<u8> {
    let mut out = BUNDLE_TAG.to_vec();
    out.extend(1_u64.to_be_bytes());
    for e in elements {
        let size = u32::try_from(e.len()).expect("an element larger than 4 GiB");
        out.extend(size.to_be_bytes());
        out.extend(e);
    }
    out
}

fn put_string(out: &mut Vec<u8>, s: &str) {
    assert!(!s.contains('\0'), "an OSC-string cannot hold a NUL");
    out.extend(s.as_bytes());
    let padded = (s.len() + 1).next_multiple_of(4);
    out.resize(out.len() + padded - s.len(), 0);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The OSC 1.0 specification's own example: `/oscillator/4/frequency` with the float
    /// 440.0, byte for byte as the specification prints it.
    const SPEC_EXAMPLE: [u8; 32] = [
        0x2f, 0x6f, 0x73, 0x63, 0x69, 0x6c, 0x6c, 0x61, 0x74, 0x6f, 0x72, 0x2f, 0x34, 0x2f, 0x66,
        0x72, 0x65, 0x71, 0x75, 0x65, 0x6e, 0x63, 0x79, 0x00, 0x2c, 0x66, 0x00, 0x00, 0x43, 0xdc,
        0x00, 0x00,
    ];

    #[test]
    fn the_specifications_example_both_ways() {
        let messages = parse(&SPEC_EXAMPLE, 1).expect("well-formed");
        assert_eq!(
            messages,
            vec![Message {
                address: "/oscillator/4/frequency",
                args: vec![Arg::Float(440.0)],
            }]
        );
        assert_eq!(
            encode_message("/oscillator/4/frequency", &[Arg::Float(440.0)]),
            SPEC_EXAMPLE
        );
    }

    #[test]
    fn strings_pad_to_four_with_at_least_one_nul() {
        // "/foo" (4 bytes) takes 8; ",iisff" (6) takes 8; "hello" (5) takes 8.
        let m = encode_message(
            "/foo",
            &[
                Arg::Int(1000),
                Arg::Int(-1),
                Arg::Str("hello"),
                Arg::Float(1.234),
                Arg::Float(5.678),
            ],
        );
        let want: Vec<u8> = [
            &b"/foo\0\0\0\0"[..],
            b",iisff\0\0",
            &1000_i32.to_be_bytes(),
            &(-1_i32).to_be_bytes(),
            b"hello\0\0\0",
            &1.234_f32.to_be_bytes(),
            &5.678_f32.to_be_bytes(),
        ]
        .concat();
        assert_eq!(m, want);
    }

    #[test]
    fn every_tag_is_read_and_bundles_keep_their_order() {
        let mut blob_message = b"/x\0\0,ibtcrmTFNI[]hd\0".to_vec();
        blob_message.extend(7_i32.to_be_bytes());
        blob_message.extend(5_u32.to_be_bytes());
        blob_message.extend(b"abcde\0\0\0");
        blob_message.extend([0; 8 + 4 + 4 + 4]);
        blob_message.extend((-3_i64).to_be_bytes());
        blob_message.extend(0.5_f64.to_be_bytes());
        let inner = encode_bundle(&[encode_message("/b", &[Arg::Str("")])]);
        let packet = encode_bundle(&[blob_message, inner, encode_message("/c", &[])]);
        let messages = parse(&packet, 2).expect("well-formed");
        let addresses: Vec<_> = messages.iter().map(|m| m.address).collect();
        assert_eq!(addresses, ["/x", "/b", "/c"]);
        let tags = b"btcrmTFNI[]";
        let mut want = vec![Arg::Int(7)];
        want.extend(tags.iter().map(|&t| Arg::Other(t)));
        want.extend([Arg::Long(-3), Arg::Double(0.5)]);
        assert_eq!(messages[0].args, want);
        assert_eq!(messages[1].args, [Arg::Str("")]);
        assert_eq!(parse(&packet, 1), Err(Malformed::TooDeep));
        // Without type tags: no arguments.
        assert_eq!(
            parse(b"/old", 1).map(|m| m[0].args.len()),
            Err(Malformed::Bytes)
        );
        assert_eq!(parse(b"/old\0\0\0\0", 1).map(|m| m[0].args.len()), Ok(0));
    }

    #[test]
    fn damage_anywhere_makes_the_packet_malformed() {
        let first = encode_message("/a", &[Arg::Int(1), Arg::Str("xyz")]);
        let good = encode_bundle(&[first.clone(), encode_message("/b", &[Arg::Double(2.0)])]);
        assert_eq!(parse(&good, 1).map(|m| m.len()), Ok(2));
        // Cut anywhere short of the end: malformed, unless the cut falls where a bundle may
        // end (after its time tag, or after its first element).
        let bundle_may_end = [16, 16 + 4 + first.len()];
        for cut in 1..good.len() {
            let parsed = parse(&good[..cut], 1);
            assert_eq!(
                parsed.is_ok(),
                bundle_may_end.contains(&cut),
                "cut at {cut}: {parsed:?}"
            );
        }
        let bad: [&[u8]; 8] = [
            b"",
            b"/a\0",                  // padding short
            b"/a\0\x01",              // padding not NUL
            b"a\0\0\0,\0\0\0",        // address without '/'
            b"/a\0\0i\0\0\0",         // tags without ','
            b"/a\0\0,q\0\0",          // unknown tag
            b"/a\0\0,\0\0\0\0\0\0\0", // bytes left over
            b"/\xff\0\0,\0\0\0",      // not UTF-8
        ];
        for b in bad {
            assert_eq!(parse(b, 1), Err(Malformed::Bytes), "{b:?}");
        }
        let mut odd_size = encode_bundle(&[encode_message("/a", &[])]);
        odd_size[19] = 3;
        assert_eq!(parse(&odd_size, 1), Err(Malformed::Bytes));
    }
}
