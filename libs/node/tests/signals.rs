//! `on_stop_signal` catches a signal sent the moment it returns: a script
//! that stops a tool as soon as its first line appears gets a clean stop,
//! not a kill (a handler installed later, on a thread of its own, raced
//! such a SIGTERM and sometimes lost: the process died of it).

use std::sync::mpsc;
use std::time::Duration;

use nix::sys::signal::{raise, Signal};

#[test]
fn a_sigterm_right_after_on_stop_signal_returns_is_caught() {
    let (tx, rx) = mpsc::channel();
    troupe_node::process::on_stop_signal(move || {
        let _ = tx.send(());
    })
    .expect("the handlers");
    // Without a handler up, this kills the test process.
    raise(Signal::SIGTERM).expect("raise");
    assert!(
        rx.recv_timeout(Duration::from_secs(10)).is_ok(),
        "the signal was not handed on"
    );
}
