//! Property tests: whatever bytes a client sends, the decoders answer with a
//! value or an error, never a panic, and never allocate more than the input
//! can hold. (The cargo-fuzz target in fuzz/ explores the same entry points
//! without a time limit.)

use proptest::prelude::*;
use troupe_bridge::queue::{Out, Queue, Replace, Rule};
use troupe_bridge::{codec, wire};
use troupe_msgs::Interface;

fn decode_everything(bytes: &[u8]) {
    let _ = wire::frame(bytes);
    for &iface in Interface::ALL {
        for kind in [wire::CMD, wire::REQ] {
            for subtype in 0..=12u8 {
                if let Ok(Some(codec::ToDevice::Request { reply, .. })) =
                    codec::from_player(iface, kind, subtype, bytes, 0.0)
                {
                    // A device's reply is untrusted too.
                    let _ = reply(bytes);
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        decode_everything(&bytes);
    }

    #[test]
    fn counts_that_lie_never_panic(
        words in prop::collection::vec(prop_oneof![Just(0u32), Just(1), Just(3), Just(u32::MAX), any::<u32>()], 0..64)
    ) {
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_be_bytes()).collect();
        decode_everything(&bytes);
    }

    #[test]
    fn a_full_queue_keeps_every_response(ops in prop::collection::vec((0u8..4, any::<bool>()), 0..300)) {
        let mut q = Queue::new(8);
        let (mut responses_in, mut responses_out) = (0, 0);
        for (op, flag) in ops {
            match op {
                0 => q.push(msg(wire::DATA, u32::from(flag))),
                1 => { q.push(msg(wire::RESP_ACK, 1)); responses_in += 1; }
                2 => q.set_pull(flag),
                _ => if flag {
                    q.request_data(msg(wire::RESP_ACK, 1));
                    responses_in += 1;
                } else {
                    q.add_rule(Rule { interf: -1, index: -1, kind: 1, subtype: -1, replace: Replace::Replace });
                },
            }
            while let Some(m) = q.pop(std::time::Instant::now()) {
                if m.kind == wire::RESP_ACK { responses_out += 1; }
            }
            prop_assert!(q.len() <= 8 + responses_in - responses_out);
        }
        // Whatever stays queued, no response was dropped.
        q.set_pull(false);
        while let Some(m) = q.pop(std::time::Instant::now()) {
            if m.kind == wire::RESP_ACK { responses_out += 1; }
        }
        prop_assert_eq!(responses_in, responses_out);
    }
}

fn msg(kind: u8, interf: u32) -> Out {
    Out::new(
        wire::Header {
            interf,
            kind: u32::from(kind),
            subtype: 1,
            ..wire::Header::default()
        },
        &[],
    )
}
