//! Any bytes, cut into chunks chosen by the input itself, through the stream decoder of both directions and of
//! a tiny buffer. Beyond "no panic": the counters must agree with what the callback reported, and every message
//! the decoder accepts must survive a re-encode unchanged.
#![no_main]

use libfuzzer_sys::fuzz_target;
use nusense_protocol::framing::{self, FrameDecoder, WireError, MAX_FRAME_LEN};
use nusense_protocol::{BoardMessage, LinkCounters, Request};
use serde::{de::DeserializeOwned, Serialize};

fn check<T, const N: usize>(chunk_sizes: &[u8], stream: &[u8])
where
    T: DeserializeOwned + Serialize + PartialEq + core::fmt::Debug,
{
    let mut decoder = FrameDecoder::<N>::new();
    let mut seen = LinkCounters::default();
    let mut rest = stream;
    let mut sizes = chunk_sizes.iter().map(|&s| usize::from(s).max(1)).cycle();
    while !rest.is_empty() {
        let size = sizes.next().unwrap_or(rest.len()).min(rest.len());
        let (chunk, tail) = rest.split_at(size);
        decoder.feed::<T>(chunk, |result| match result {
            Ok(message) => {
                seen.frames_ok += 1;
                let mut buf = [0u8; MAX_FRAME_LEN];
                let frame = framing::encode(&message, &mut buf).expect("an accepted message re-encodes");
                let mut body = frame[..frame.len() - 1].to_vec();
                assert_eq!(framing::decode_frame::<T>(&mut body).as_ref(), Ok(&message));
            }
            Err(WireError::BadCobs) => seen.bad_cobs += 1,
            Err(WireError::BadCrc) => seen.bad_crc += 1,
            Err(WireError::Oversize) => seen.oversize += 1,
            Err(WireError::UnknownTag) => seen.unknown_tag += 1,
        });
        rest = tail;
    }
    assert_eq!(decoder.counters(), seen);
}

fuzz_target!(|data: &[u8]| {
    // First byte: how many of the following bytes are chunk sizes; the rest is the stream.
    let (chunk_sizes, stream) = match data.split_first() {
        Some((&n, rest)) => rest.split_at(usize::from(n % 8).min(rest.len())),
        None => (&[][..], data),
    };
    check::<BoardMessage, MAX_FRAME_LEN>(chunk_sizes, stream);
    check::<Request, MAX_FRAME_LEN>(chunk_sizes, stream);
    check::<Request, 5>(chunk_sizes, stream);

    let mut whole = stream.to_vec();
    let _ = framing::decode_frame::<BoardMessage>(&mut whole);
});
