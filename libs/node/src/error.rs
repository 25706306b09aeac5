//! The runtime's error type.

use std::time::Duration;

use troupe_msgs::{AddrError, DecodeError, Device};

/// A boxed error from Zenoh or from a driver's own code.
pub type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// What can go wrong in a node; every variant names the thing at fault.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// The driver's section or options are wrong; fix the cfg.
    #[error("configuration of driver `{driver}`: {reason}")]
    Config {
        /// The driver.
        driver: String,
        /// What is wrong and what is expected.
        reason: String,
    },
    /// Nothing answers where the session was told to connect.
    #[error(
        "no Zenoh router answers at {endpoints}: start one (`troupe launch FILE` runs one \
         inside, `troupe router` runs one alone) or point --connect at one"
    )]
    NoRouter {
        /// The endpoints tried.
        endpoints: String,
    },
    /// The router's endpoint is wrong from here (a name that does not
    /// resolve, a TLS router dialled over plain TCP): what to do.
    #[error("{0}")]
    Unreachable(String),
    /// A TLS link could not be made: no router, or certificates that do not match.
    #[error(
        "no Zenoh router accepted a TLS link at {endpoints}: none runs there, or it refused \
         this host (this host's config and the router's must come from the same `troupe \
         fleet-keys` authority, the name connected to must be the router's, and this host's \
         user and password must be in the router's `passwords`; with `--log info` Zenoh's \
         warning says which: a close \"in response to an OpenSyn\" is the password){hint}"
    )]
    TlsRefused {
        /// The endpoints tried.
        endpoints: String,
        /// What else to check.
        hint: &'static str,
    },
    /// Zenoh refused an operation.
    #[error("zenoh: {what}")]
    Zenoh {
        /// What the node was doing.
        what: String,
        /// Zenoh's error.
        #[source]
        source: BoxError,
    },
    /// A required device never came up.
    #[error("required device {device} did not come up within {waited:?}; is its driver running and connected to the same router?")]
    RequiresTimeout {
        /// The device waited for.
        device: Device,
        /// How long.
        waited: Duration,
    },
    /// A sample or request payload did not decode.
    #[error("malformed payload on `{key}`: {source}")]
    Decode {
        /// The key it arrived on.
        key: String,
        /// Why.
        #[source]
        source: DecodeError,
    },
    /// A bad device address or key.
    #[error(transparent)]
    Addr(#[from] AddrError),
    /// A driver published on a device its section does not provide.
    #[error("driver `{driver}` published on {device}, which its section does not provide")]
    NotProvided {
        /// The driver.
        driver: String,
        /// The device.
        device: Device,
    },
    /// A request the driver sent got no usable answer.
    #[error("request failed: {0}")]
    Request(#[from] RequestError),
    /// The driver failed; the node stops and the supervisor may restart it.
    #[error("driver failed: {0}")]
    Driver(BoxError),
}

impl NodeError {
    /// A [`NodeError::Config`] for `driver`.
    pub fn config(driver: &str, reason: impl Into<String>) -> Self {
        NodeError::Config {
            driver: driver.to_owned(),
            reason: reason.into(),
        }
    }

    /// A [`NodeError::Zenoh`] saying what was being done.
    pub fn zenoh(what: impl Into<String>, source: BoxError) -> Self {
        NodeError::Zenoh {
            what: what.into(),
            source,
        }
    }
}

/// Turns Zenoh's error into a [`NodeError::Zenoh`] saying what was being
/// done (`.map_err(z(|| format!("declaring {key}")))`).
pub(crate) fn z(what: impl FnOnce() -> String) -> impl FnOnce(zenoh::Error) -> NodeError {
    move |e| NodeError::zenoh(what(), e)
}

/// The runtime's result type.
pub type Result<T, E = NodeError> = std::result::Result<T, E>;

/// Why a request got no usable answer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RequestError {
    /// The device refused (Player's RESP_NACK).
    #[error("refused: {0}")]
    Nack(String),
    /// Nothing answered within the deadline.
    #[error("no answer within {0:?}")]
    Timeout(Duration),
    /// No device serves this request.
    #[error("no device answers this request")]
    NoReplier,
    /// The answer did not decode.
    #[error("malformed answer: {0}")]
    Decode(DecodeError),
}
