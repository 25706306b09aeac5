//! `cargo +nightly fuzz run decode` (from nodes/bridge): every byte string
//! through the framing and every interface's decoder.
#![no_main]

use libfuzzer_sys::fuzz_target;
use troupe_bridge::{codec, wire};
use troupe_msgs::Interface;

fuzz_target!(|data: &[u8]| {
    if let Ok(Some((h, len))) = wire::frame(data) {
        let body = &data[wire::HEADER_LEN..len];
        let iface = u16::try_from(h.interf).ok().and_then(Interface::from_code);
        if let (Some(iface), Ok(kind), Ok(sub)) =
            (iface, u8::try_from(h.kind), u8::try_from(h.subtype))
        {
            if let Ok(Some(codec::ToDevice::Request { reply, .. })) =
                codec::from_player(iface, kind, sub, body, h.timestamp)
            {
                let _ = reply(body);
            }
        }
    }
});
