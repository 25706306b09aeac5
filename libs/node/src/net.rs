//! What every Troupe program asks of the network: a request's get, and
//! waiting for a device to go live.

use std::time::{Duration, Instant};

use troupe_msgs::{keys, Device};
use zenoh::handlers::DefaultHandler;
use zenoh::query::ConsolidationMode;
use zenoh::session::SessionGetBuilder;
use zenoh::{Session, Wait};

use crate::error::{z, NodeError, Result};

/// A get on request key `key` as every Troupe requester asks (drivers, the
/// client, the bridge): each answer taken as it arrives, not held until the
/// query closes as Zenoh's default consolidation does, within `timeout`.
pub fn ask<'a>(
    session: &'a Session,
    key: &'a str,
    timeout: Duration,
) -> SessionGetBuilder<'a, 'a, DefaultHandler> {
    session
        .get(key)
        .timeout(timeout)
        .consolidation(ConsolidationMode::None)
}

/// Waits until some driver announces `dev` (its liveliness token), at most
/// `timeout`.
///
/// # Errors
///
/// [`NodeError::RequiresTimeout`] when it does not appear in time, or the
/// Zenoh error of watching for it.
pub fn wait_live(session: &Session, dev: &Device, timeout: Duration) -> Result<()> {
    let key = keys::token_any(dev);
    let sub = session
        .liveliness()
        .declare_subscriber(&key)
        .history(true)
        .wait()
        .map_err(z(|| format!("watching liveliness of {dev}")))?;
    let deadline = Instant::now() + timeout;
    loop {
        match sub.recv_deadline(deadline) {
            Ok(Some(s)) if s.kind() == zenoh::sample::SampleKind::Put => return Ok(()),
            Ok(Some(_)) => continue,
            Ok(None) | Err(_) => {
                return Err(NodeError::RequiresTimeout {
                    device: *dev,
                    waited: timeout,
                })
            }
        }
    }
}
