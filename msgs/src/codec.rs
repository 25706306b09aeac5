//! The wire format of every Troupe payload.
//!
//! Postcard is compact but not self-describing: bytes of one type decode as
//! garbage of another. Every payload therefore starts with its schema tag:
//!
//! ```text
//! u8 tag length | tag (UTF-8, e.g. "laser/scan@1") | f64 LE timestamp | postcard body
//! ```
//!
//! The timestamp is the sample's time on the sender's clock (simulation time
//! under Stage), in seconds, as in Player's message header.

use serde::{de::DeserializeOwned, Deserialize, Serialize};

/// A typed message with a schema tag. Implemented by every message in this crate.
pub trait Message: Serialize + DeserializeOwned + Clone + std::fmt::Debug + Send + 'static {
    /// `interface/name@version`; bump the version when the layout changes.
    const SCHEMA: &'static str;
    /// Where the message is sent when it is a command or a request (see
    /// [`Command`], [`Request`]); `None` for data and replies.
    const ROUTE: Option<Route> = None;
}

/// How a message reaches a device: the last chunk of its key.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    /// A command, put on `…/cmd/<name>`.
    Command(&'static str),
    /// A request, a get on `…/req/<name>`.
    Request(&'static str),
}

/// A message sent to a device as a command (put on `…/cmd/<NAME>`).
pub trait Command: Message {
    /// The last key chunk: `vel`, `pos`, `goal`…
    const NAME: &'static str;
}

/// A message sent to a device as a request (get on `…/req/<NAME>`).
pub trait Request: Message {
    /// The last key chunk: `geom`, `info`, `set_pose`…
    const NAME: &'static str;
    /// What an acknowledging device answers.
    type Reply: Message;
}

/// Why a payload could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The payload is shorter than its header.
    #[error("payload of {len} bytes is too short for a Troupe header")]
    Truncated {
        /// Bytes received.
        len: usize,
    },
    /// The schema tag is not UTF-8.
    #[error("payload schema tag is not UTF-8")]
    BadTag,
    /// The payload holds another message type.
    #[error("payload is `{got}`, expected `{expected}`")]
    SchemaMismatch {
        /// The schema the receiver asked for.
        expected: &'static str,
        /// The schema the payload carries.
        got: String,
    },
    /// The body does not decode as its schema says.
    #[error("payload `{schema}` is malformed: {reason}")]
    Body {
        /// The schema tag of the payload.
        schema: String,
        /// Postcard's reason.
        reason: String,
    },
    /// No message type with this schema is known to this build.
    #[error("unknown schema `{0}`")]
    UnknownSchema(String),
}

/// A decoded message with the timestamp of its payload.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Stamped<M> {
    /// Seconds, on the sender's clock.
    pub stamp: f64,
    /// The message.
    pub msg: M,
}

/// Encodes `msg` with its schema tag and `stamp`.
///
/// The payload is allocated once at its exact size (postcard measures the
/// body first) and byte runs are copied whole: a 1 MB camera frame is one
/// allocation and one copy, not a vector grown twenty times and filled a
/// byte at a time.
pub fn encode<M: Message>(msg: &M, stamp: f64) -> Vec<u8> {
    encode_sized(msg, stamp, encoded_len(msg))
}

/// [`encode`] for a caller that has measured the payload already: `len` is
/// its [`encoded_len`], the capacity allocated.
pub fn encode_sized<M: Message>(msg: &M, stamp: f64, len: usize) -> Vec<u8> {
    let tag = M::SCHEMA.as_bytes();
    let mut out = Vec::with_capacity(len);
    // INVARIANT: schema tags are short literals in this crate (checked by a test).
    out.push(tag.len() as u8);
    out.extend_from_slice(tag);
    out.extend_from_slice(&stamp.to_le_bytes());
    match postcard::serialize_with_flavor(msg, Whole(out)) {
        Ok(out) => out,
        Err(e) => unreachable!("postcard into Vec failed: {e}"),
    }
}

/// The length of `msg`'s payload, as [`encode`] makes it.
pub fn encoded_len<M: Message>(msg: &M) -> usize {
    // Serialising the plain data types of this crate cannot fail.
    let body =
        postcard::serialize_with_flavor(msg, postcard::ser_flavors::Size::default()).unwrap_or(0);
    1 + M::SCHEMA.len() + 8 + body
}

/// Encodes `msg` stamped `stamp` into `out`, as [`encode`] would: for
/// memory the payload is sent from (a shared-memory buffer). `out` must be
/// [`encoded_len`] bytes long; returns whether it was and is now filled.
pub fn encode_into<M: Message>(msg: &M, stamp: f64, out: &mut [u8]) -> bool {
    let tag = M::SCHEMA.as_bytes();
    let Some((head, body)) = out.split_at_mut_checked(1 + tag.len() + 8) else {
        return false;
    };
    // INVARIANT: schema tags are short literals in this crate (checked by a test).
    head[0] = tag.len() as u8;
    head[1..=tag.len()].copy_from_slice(tag);
    head[1 + tag.len()..].copy_from_slice(&stamp.to_le_bytes());
    let want = body.len();
    matches!(postcard::to_slice(msg, body), Ok(b) if b.len() == want)
}

/// Postcard's output into a `Vec`, a run of bytes copied in one piece
/// (postcard's own `to_extend` pushes them one by one).
struct Whole(Vec<u8>);

impl postcard::ser_flavors::Flavor for Whole {
    type Output = Vec<u8>;

    #[inline]
    fn try_extend(&mut self, data: &[u8]) -> postcard::Result<()> {
        // A number's few bytes inline; a run of bytes through memcpy.
        if data.len() <= 16 {
            self.0.extend(data.iter().copied());
        } else {
            self.0.extend_from_slice(data);
        }
        Ok(())
    }

    #[inline]
    fn try_push(&mut self, data: u8) -> postcard::Result<()> {
        self.0.push(data);
        Ok(())
    }

    fn finalize(self) -> postcard::Result<Vec<u8>> {
        Ok(self.0)
    }
}

/// The parts of a payload: schema tag, timestamp, body.
pub fn split(payload: &[u8]) -> Result<(&str, f64, &[u8]), DecodeError> {
    let truncated = || DecodeError::Truncated { len: payload.len() };
    let n = *payload.first().ok_or_else(truncated)? as usize;
    let tag = payload.get(1..1 + n).ok_or_else(truncated)?;
    let tag = std::str::from_utf8(tag).map_err(|_| DecodeError::BadTag)?;
    let stamp = payload.get(1 + n..9 + n).ok_or_else(truncated)?;
    let mut b = [0u8; 8];
    b.copy_from_slice(stamp);
    Ok((tag, f64::from_le_bytes(b), &payload[9 + n..]))
}

/// Rewrites an encoded payload's timestamp in place (an answer kept ready
/// and sent again later is stamped when it is sent).
///
/// # Errors
///
/// [`DecodeError::Truncated`] if `payload` is shorter than its header.
pub fn restamp(payload: &mut [u8], stamp: f64) -> Result<(), DecodeError> {
    let len = payload.len();
    let n = *payload.first().ok_or(DecodeError::Truncated { len })? as usize;
    payload
        .get_mut(1 + n..9 + n)
        .ok_or(DecodeError::Truncated { len })?
        .copy_from_slice(&stamp.to_le_bytes());
    Ok(())
}

/// The schema tag of a payload, without decoding its body.
pub fn schema_of(payload: &[u8]) -> Result<&str, DecodeError> {
    split(payload).map(|(t, _, _)| t)
}

/// Decodes a body known to be of schema `schema` (a [`Message`], or a
/// [`View`] borrowing from `body`).
pub(crate) fn decode_body<'a, M: Deserialize<'a>>(
    schema: &str,
    body: &'a [u8],
) -> Result<M, DecodeError> {
    match postcard::take_from_bytes::<M>(body) {
        Ok((msg, [])) => Ok(msg),
        Ok((_, rest)) => Err(DecodeError::Body {
            schema: schema.to_owned(),
            reason: format!("{} trailing bytes", rest.len()),
        }),
        Err(e) => Err(DecodeError::Body {
            schema: schema.to_owned(),
            reason: e.to_string(),
        }),
    }
}

/// Decodes a payload as `M`, checking its schema tag first.
pub fn decode<M: Message>(payload: &[u8]) -> Result<Stamped<M>, DecodeError> {
    let (tag, stamp, body) = split(payload)?;
    if tag != M::SCHEMA {
        return Err(DecodeError::SchemaMismatch {
            expected: M::SCHEMA,
            got: tag.to_owned(),
        });
    }
    Ok(Stamped {
        stamp,
        msg: decode_body(tag, body)?,
    })
}

/// A message read in place: its byte arrays borrow from the payload
/// instead of being copied out (a camera frame in shared memory is read
/// where it lies). It reads the wire of the [`Message`] it views.
pub trait View<'a>: Deserialize<'a> {
    /// The message whose payloads it reads.
    type Owned: Message;
}

/// Decodes a payload as the view `V`, checking its schema tag first:
/// [`decode`] without copying a byte array.
pub fn decode_view<'a, V: View<'a>>(payload: &'a [u8]) -> Result<Stamped<V>, DecodeError> {
    let (tag, stamp, body) = split(payload)?;
    let expected = <V::Owned as Message>::SCHEMA;
    if tag != expected {
        return Err(DecodeError::SchemaMismatch {
            expected,
            got: tag.to_owned(),
        });
    }
    Ok(Stamped {
        stamp,
        msg: decode_body(tag, body)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{laser, position2d, Pose2d};

    #[test]
    fn a_view_reads_a_frame_where_it_lies_and_checks_what_it_reads() {
        use crate::camera;
        let frame = camera::Data {
            width: 4,
            height: 2,
            bpp: 8,
            format: camera::FORMAT_MONO8,
            image: (0..8).collect(),
            ..Default::default()
        };
        let payload = encode(&frame, 3.5);
        let view = decode_view::<camera::DataView>(&payload).unwrap();
        assert_eq!(view.stamp, 3.5);
        assert_eq!(view.msg.to_data(), frame);
        assert!(
            payload.as_ptr_range().contains(&view.msg.image.as_ptr()),
            "the image is borrowed from the payload, not copied"
        );
        let scan = encode(&laser::Scan::default(), 0.0);
        assert!(matches!(
            decode_view::<camera::DataView>(&scan),
            Err(DecodeError::SchemaMismatch { .. })
        ));
        let cut = &payload[..payload.len() - 1];
        assert!(matches!(
            decode_view::<camera::DataView>(cut),
            Err(DecodeError::Body { .. })
        ));
    }

    #[test]
    fn round_trip_keeps_message_and_stamp() {
        let m = position2d::CmdVel {
            vel: Pose2d::new(0.5, 0.0, 0.1),
            state: true,
        };
        let bytes = encode(&m, 12.5);
        let got = decode::<position2d::CmdVel>(&bytes).unwrap();
        assert_eq!(got.stamp, 12.5);
        assert_eq!(got.msg, m);
        assert_eq!(schema_of(&bytes).unwrap(), "position2d/cmd_vel@1");
    }

    #[test]
    fn encode_into_writes_what_encode_makes_and_refuses_a_wrong_length() {
        let m = crate::camera::Data {
            width: 2,
            height: 1,
            image: vec![1, 2, 3, 4, 5, 6],
            ..Default::default()
        };
        let want = encode(&m, 3.5);
        assert_eq!(encoded_len(&m), want.len());
        let mut out = vec![0; want.len()];
        assert!(encode_into(&m, 3.5, &mut out));
        assert_eq!(out, want);
        for n in [0, 5, want.len() - 1, want.len() + 1] {
            assert!(!encode_into(&m, 3.5, &mut vec![0; n]), "{n} bytes");
        }
    }

    #[test]
    fn restamp_changes_the_stamp_only() {
        let m = laser::Scan {
            ranges: vec![1.0, 2.0],
            ..Default::default()
        };
        let mut bytes = encode(&m, 1.0);
        restamp(&mut bytes, 42.25).unwrap();
        assert_eq!(bytes, encode(&m, 42.25));
        for n in 0..10 {
            assert!(restamp(&mut bytes.clone()[..n], 0.0).is_err(), "prefix {n}");
        }
    }

    #[test]
    fn wrong_schema_is_a_clear_error() {
        let bytes = encode(&laser::Scan::default(), 0.0);
        let e = decode::<position2d::Data>(&bytes).unwrap_err();
        assert_eq!(
            e.to_string(),
            "payload is `laser/scan@1`, expected `position2d/data@1`"
        );
    }

    #[test]
    fn truncated_and_garbage_payloads_never_panic() {
        let bytes = encode(&laser::Scan::default(), 1.0);
        for n in 0..bytes.len() {
            assert!(decode::<laser::Scan>(&bytes[..n]).is_err(), "prefix {n}");
        }
        let mut extra = bytes.clone();
        extra.push(0);
        assert!(matches!(
            decode::<laser::Scan>(&extra),
            Err(DecodeError::Body { .. })
        ));
        assert_eq!(
            decode::<laser::Scan>(&[3, 0xff, 0xfe, 0xfd]).unwrap_err(),
            DecodeError::BadTag
        );
        // Every 1- and 2-byte input, and a pseudo-random sweep.
        for a in 0..=255u8 {
            let _ = crate::decode_any(&[a]);
            for b in 0..=255u8 {
                let _ = crate::decode_any(&[a, b]);
            }
        }
        let mut x: u32 = 0x1234_5678;
        for len in 0..200 {
            let mut v = bytes.clone();
            v.truncate(len % (bytes.len() + 1));
            for byte in v.iter_mut().skip(9) {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                *byte = x as u8;
            }
            let _ = crate::decode_any(&v);
        }
    }
}
