//! Byte arrays in one piece: a binary format (postcard) takes them as one
//! run of bytes, a text one (JSON) as a list of numbers.
//!
//! Postcard writes a sequence of `u8` or `i8` as its length and one byte
//! per element, which is exactly how it writes bytes: the wire is the
//! same, but a 500x500 map or a 640x480 image is copied at once instead
//! of element by element through serde (0.5-0.7 ms each way for 250,000
//! cells). `serde_bytes` does this for `u8` only, and this crate keeps to
//! serde, postcard and thiserror.

use std::fmt;

use serde::de::{Deserializer, SeqAccess, Visitor};
use serde::{Deserialize, Serialize, Serializer};

/// `#[serde(with = "crate::bytes::u8s")]` for a `Vec<u8>`.
pub mod u8s {
    use super::*;

    /// Bytes, whatever the format: JSON writes them as a list of numbers
    /// all the same, and Python (pythonize) gets `bytes`, not a list of a
    /// million ints for a VGA frame.
    pub fn serialize<S: Serializer>(v: &[u8], s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(v)
    }

    /// Reads what [`serialize`] writes (in a text format, a list of
    /// numbers).
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<u8>, D::Error> {
        if d.is_human_readable() {
            Vec::deserialize(d)
        } else {
            d.deserialize_bytes(Bytes(|b: &[u8]| b.to_vec()))
        }
    }
}

/// `#[serde(with = "crate::bytes::i8s")]` for a `Vec<i8>`: its two's
/// complement bytes.
pub mod i8s {
    use super::*;

    /// Bytes, or in a text format a list of numbers.
    pub fn serialize<S: Serializer>(v: &[i8], s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            v.serialize(s)
        } else {
            let raw: Vec<u8> = v.iter().map(|&c| c.to_ne_bytes()[0]).collect();
            s.serialize_bytes(&raw)
        }
    }

    /// Reads what [`serialize`] writes.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<i8>, D::Error> {
        if d.is_human_readable() {
            Vec::deserialize(d)
        } else {
            d.deserialize_bytes(Bytes(|b: &[u8]| {
                b.iter().map(|&c| i8::from_ne_bytes([c])).collect()
            }))
        }
    }
}

/// Takes bytes whole, or a sequence of them from a format that has no
/// bytes of its own.
struct Bytes<F>(F);

impl<'de, T, F: FnOnce(&[u8]) -> Vec<T>> Visitor<'de> for Bytes<F>
where
    T: Deserialize<'de>,
{
    type Value = Vec<T>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("bytes")
    }

    fn visit_bytes<E: serde::de::Error>(self, b: &[u8]) -> Result<Vec<T>, E> {
        Ok((self.0)(b))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<T>, A::Error> {
        let mut v = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(1 << 16));
        while let Some(x) = seq.next_element()? {
            v.push(x);
        }
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use serde::{Deserialize, Serialize};

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Seq {
        a: Vec<u8>,
        b: Vec<i8>,
    }

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Whole {
        #[serde(with = "super::u8s")]
        a: Vec<u8>,
        #[serde(with = "super::i8s")]
        b: Vec<i8>,
    }

    #[test]
    fn postcard_writes_bytes_as_it_wrote_the_sequences_and_json_the_same_numbers() {
        let (a, b) = (vec![0, 7, 255, 128], vec![-1, 0, 1, -128, 127]);
        let seq = Seq {
            a: a.clone(),
            b: b.clone(),
        };
        let whole = Whole { a, b };
        let bin = postcard::to_stdvec(&seq).unwrap();
        assert_eq!(postcard::to_stdvec(&whole).unwrap(), bin);
        assert_eq!(postcard::from_bytes::<Whole>(&bin).unwrap(), whole);
        let text = serde_json::to_string(&seq).unwrap();
        assert_eq!(serde_json::to_string(&whole).unwrap(), text);
        assert_eq!(serde_json::from_str::<Whole>(&text).unwrap(), whole);
    }
}
