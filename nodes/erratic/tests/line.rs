//! The driver's line thread against the emulated Erratic over a real
//! pseudo-terminal: line faults, a mute robot, an unplugged one.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

mod common;

use std::sync::mpsc::Receiver;
use std::time::Duration;

use common::{emulate, settings};
use troupe_erratic::device::{self, Order, Update};
use troupe_erratic::packet::Motor;
use troupe_node::Waker;
use troupe_serial::{recv_where, Faults};

fn wait_for(rx: &Receiver<Update>, secs: u64, want: impl FnMut(&Update) -> bool) -> Update {
    recv_where(rx, Duration::from_secs(secs), want)
        .unwrap_or_else(|e| panic!("no matching update within {secs} s: {e}"))
}

/// The motor packet in an update, if it is one.
fn motor(u: &Update) -> Option<Motor> {
    match u {
        Update::Packet(p) if matches!(p.first(), Some(0x80..=0x8F)) => Motor::decode(p).ok(),
        _ => None,
    }
}

#[test]
fn line_faults_are_survived_and_the_robot_still_drives() {
    let faults = Faults {
        noise: 0.2,
        corrupt: 0.1,
        truncate: 0.05,
        drop: 0.001,
        ..Faults::default()
    };
    let emu = emulate("noisy", faults, None);
    let line = device::spawn(settings(emu.link()), Waker::none()).unwrap();
    let rx = line.updates();
    wait_for(rx, 60, |u| matches!(u, Update::Ready { .. }));
    // Every motor packet that gets through is whole: it decodes.
    let mut packets = 0;
    wait_for(rx, 60, |u| {
        if let Update::Packet(p) = u {
            if matches!(p.first(), Some(0x80..=0x8F)) {
                assert!(Motor::decode(p).is_ok(), "{p:02X?}");
                packets += 1;
            }
        }
        packets >= 30
    });
    assert!(line.send(Order::Enable(true)));
    assert!(line.send(Order::Vel {
        speed: 300,
        turn: 0
    }));
    // 0.3 m at 0.930 mm per tick: the robot moved through the noise.
    wait_for(rx, 30, |u| {
        motor(u).is_some_and(|m| (200..2000).contains(&m.x))
    });
    line.stop(Order::Stop);
    let stats = emu.stop().unwrap();
    assert!(stats.motor >= 30, "{stats:?}");
}

#[test]
fn a_mute_robot_is_reported_and_an_unplugged_one_reconnects() {
    let mute = emulate("mute", Faults::mute(), None);
    let line = device::spawn(settings(mute.link()), Waker::none()).unwrap();
    let rx = line.updates();
    let Update::Lost(why) = wait_for(rx, 30, |u| matches!(u, Update::Lost(_))) else {
        unreachable!()
    };
    assert!(why.contains("no configuration reply"), "{why}");
    line.stop(Order::Stop);
    mute.stop().unwrap();

    let unplug = emulate(
        "unplug",
        Faults::unplug(Duration::from_secs(3), Duration::from_secs(1)),
        None,
    );
    let line = device::spawn(settings(unplug.link()), Waker::none()).unwrap();
    let rx = line.updates();
    wait_for(rx, 20, |u| matches!(u, Update::Ready { .. }));
    let Update::Lost(why) = wait_for(rx, 20, |u| matches!(u, Update::Lost(_))) else {
        unreachable!()
    };
    assert!(
        why.contains("lost") || why.contains("no motor packet"),
        "{why}"
    );
    // Plugged back in and powered up afresh: configured and open again.
    wait_for(rx, 30, |u| matches!(u, Update::Ready { .. }));
    wait_for(rx, 10, |u| motor(u).is_some());
    line.stop(Order::Stop);
    unplug.stop().unwrap();
}
