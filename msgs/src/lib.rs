//! Troupe's messages: Player's interfaces as typed Rust values.
//!
//! - [`addr`]: Player device addresses (`key:host:robot:interface:index`) and
//!   interface codes;
//! - [`keys`]: the Zenoh key expressions, the only place keys are spelled;
//! - [`codec`]: the postcard codec, whose payloads carry a schema tag;
//! - [`protocol`]: Player's message types and subtypes, each named once;
//! - one module per interface (`position2d`, `laser`, `map`, …) with its data,
//!   commands and requests, in SI units and radians, with Player's meaning;
//! - [`decode_any`]: decodes any payload by its tag, for tools like `troupe echo`.
//!
//! This crate depends on serde, postcard and thiserror only: never on Zenoh or tokio.
#![warn(missing_docs)]

pub mod addr;
pub mod codec;
pub mod keys;
pub mod protocol;

mod any;
mod bytes;
mod geometry;
mod iface;

pub use addr::{AddrError, DevAddr, Device, Interface, DEFAULT_ROBOT};
pub use any::{decode_any, default_of, encode_from, routed, schema_for, AnyMsg, SCHEMAS};
pub use codec::{decode, encode, Command, DecodeError, Message, Request, Route, Stamped};
pub use geometry::{Color, Pose2d, Pose3d, Size2d, Size3d};
pub use iface::*;

/// Implements [`Message`] (and optionally [`Command`] or [`Request`]) for a type.
macro_rules! message {
    ($ty:ty, $schema:literal) => {
        impl $crate::codec::Message for $ty {
            const SCHEMA: &'static str = $schema;
        }
    };
    ($ty:ty, $schema:literal, cmd $name:literal) => {
        impl $crate::codec::Message for $ty {
            const SCHEMA: &'static str = $schema;
            const ROUTE: Option<$crate::codec::Route> = Some($crate::codec::Route::Command($name));
        }
        impl $crate::codec::Command for $ty {
            const NAME: &'static str = $name;
        }
    };
    ($ty:ty, $schema:literal, req $name:literal -> $reply:ty) => {
        impl $crate::codec::Message for $ty {
            const SCHEMA: &'static str = $schema;
            const ROUTE: Option<$crate::codec::Route> = Some($crate::codec::Route::Request($name));
        }
        impl $crate::codec::Request for $ty {
            const NAME: &'static str = $name;
            type Reply = $reply;
        }
    };
}
pub(crate) use message;
