//! Troupe's Player TCP bridge: legacy Player clients (libplayerc,
//! libplayerc++, playerv, the Python bindings) talk to Troupe's devices
//! unchanged.
//!
//! One TCP listener per robot port speaks Player 3 TCP/XDR byte for byte:
//! the banner, the `player` meta-device (DEVLIST from liveliness, DRIVERINFO,
//! DEV open/close, PUSH/PULL data modes, replace rules), and every interface
//! of troupe-msgs translated both ways ([`codec`]). Each client has its own
//! bounded queue with Player's semantics ([`queue`]), so a slow client never
//! stalls the others or the robot.
//!
//! - [`xdr`]: XDR as Player's generator writes it;
//! - [`wire`]: banner, header, framing;
//! - [`codec`]: Player bodies ↔ Troupe messages;
//! - [`queue`]: a client's queue (PUSH/PULL, SYNCH, replace rules, overflow);
//! - [`Bridge`]: listeners, connections, Zenoh subscriptions and requests;
//! - [`import`]: the other way round, a Player server's devices on Troupe.
//! - [`command`]: `troupe bridge`, the bridge as a process of its own.
#![warn(missing_docs)]

pub mod codec;
pub mod command;
pub mod import;
pub mod queue;
mod server;
pub mod wire;
pub mod xdr;

pub use server::{
    parse_network, Bridge, BridgeError, Config, IpNetwork, Limits, NetworkError, Port,
    DEFAULT_MAX_CLIENTS, MAX_PENDING_REQUESTS, MAX_UNREAD_ANSWERS,
};
