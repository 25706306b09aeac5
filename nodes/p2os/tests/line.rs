//! The driver's line thread against the emulated Pioneer over a real
//! pseudo-terminal: the handshake, SIPs, driving, faults.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

mod common;

use std::sync::mpsc::Receiver;
use std::time::Duration;

use common::{emulate, settings};
use troupe_node::Waker;
use troupe_p2os::device::{self, Order, Settings, Update};
use troupe_serial::{recv_where, Faults};

fn wait_for(rx: &Receiver<Update>, secs: u64, want: impl FnMut(&Update) -> bool) -> Update {
    recv_where(rx, Duration::from_secs(secs), want)
        .unwrap_or_else(|e| panic!("no matching update within {secs} s: {e}"))
}

fn sip(u: &Update) -> Option<&troupe_p2os::packet::Sip> {
    match u {
        Update::Sip(s) => Some(s),
        _ => None,
    }
}

#[test]
fn handshake_sips_sonar_and_driving() {
    let emu = emulate("drive", Faults::default(), None);
    let line = device::spawn(settings(emu.link()), Waker::none()).unwrap();
    let rx = line.updates();
    let Update::Ready { name, params, baud } =
        wait_for(rx, 20, |u| matches!(u, Update::Ready { .. }))
    else {
        unreachable!()
    };
    assert_eq!(
        (name.0.as_str(), name.1.as_str(), name.2.as_str()),
        ("Troupe", "Pioneer", "p3dx-sh")
    );
    assert_eq!((params.subclass, baud), ("p3dx-sh", 9600));
    // Sonars on: all 16 ranges; the front right one, 166 mm ahead and aimed
    // 10° left, sees the wall 4 m ahead at 3.834 m / cos 10°.
    let u = wait_for(rx, 5, |u| sip(u).is_some_and(|s| s.sonars.len() == 16));
    let s = sip(&u).unwrap();
    let want = (4000.0 - 166.0) / 10f64.to_radians().cos();
    assert!(
        (f64::from(s.sonars[3].1) - want).abs() <= 2.0,
        "{:?}",
        s.sonars
    );
    assert_eq!(s.flags & 1, 0, "motors start off");

    assert!(line.send(Order::Enable(true)));
    assert!(line.send(Order::Vel {
        speed: 300,
        turn: 0,
    }));
    let u = wait_for(rx, 5, |u| sip(u).is_some_and(|s| s.xpos >= 600));
    let s = sip(&u).unwrap();
    assert_eq!((s.kind, s.flags & 1), (0x33, 1));
    assert!(
        (i32::from(s.lvel) - 300).abs() <= 20 && (i32::from(s.rvel) - 300).abs() <= 20,
        "{s:?}"
    );
    assert!(line.send(Order::Vel { speed: 0, turn: 0 }));
    wait_for(rx, 5, |u| sip(u).is_some_and(|s| s.kind == 0x32));
    line.stop(Order::Stop);
    let stats = emu.stop().unwrap();
    assert!(stats.sips >= 10, "{stats:?}");
}

#[test]
fn faults_are_survived_and_a_mute_robot_is_reported() {
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
    let mut sips = 0;
    wait_for(rx, 60, |u| {
        if sip(u).is_some() {
            sips += 1;
        }
        sips >= 30
    });
    line.stop(Order::Stop);
    emu.stop().unwrap();

    let mute = emulate("mute", Faults::mute(), None);
    let line = device::spawn(settings(mute.link()), Waker::none()).unwrap();
    let rx = line.updates();
    let Update::Lost(why) = wait_for(rx, 30, |u| matches!(u, Update::Lost(_))) else {
        unreachable!()
    };
    assert!(why.contains("no answer to SYNC0"), "{why}");
    line.stop(Order::Stop);
    mute.stop().unwrap();
}

#[test]
fn the_gripper_and_the_gyro_answer() {
    let emu = emulate("gripper", Faults::default(), None);
    let line = device::spawn(
        Settings {
            gyro: true,
            ..settings(emu.link())
        },
        Waker::none(),
    )
    .unwrap();
    let rx = line.updates();
    wait_for(rx, 20, |u| matches!(u, Update::Ready { .. }));
    // Still: the gyro reads its middle value.
    wait_for(rx, 5, |u| matches!(u, Update::Gyro(512)));
    assert!(line.send(Order::Gripper(troupe_p2os::packet::grip::CLOSE)));
    // Player reads the paddles in the timer word's high byte: moving, then closed.
    wait_for(rx, 5, |u| sip(u).is_some_and(|s| s.anport == 0x04));
    wait_for(rx, 5, |u| sip(u).is_some_and(|s| s.anport == 0x02));
    // Turning counter-clockwise at 30°/s reads under 512.
    assert!(line.send(Order::Enable(true)));
    assert!(line.send(Order::Vel { speed: 0, turn: 30 }));
    wait_for(rx, 5, |u| matches!(u, Update::Gyro(r) if *r < 500));
    line.stop(Order::Stop);
    emu.stop().unwrap();
}

#[test]
fn an_unplugged_robot_is_lost_then_back() {
    let emu = emulate(
        "unplug",
        Faults::unplug(Duration::from_secs(3), Duration::from_secs(1)),
        None,
    );
    let line = device::spawn(settings(emu.link()), Waker::none()).unwrap();
    let rx = line.updates();
    wait_for(rx, 20, |u| matches!(u, Update::Ready { .. }));
    let Update::Lost(why) = wait_for(rx, 20, |u| matches!(u, Update::Lost(_))) else {
        unreachable!()
    };
    assert!(why.contains("lost") || why.contains("no SIP"), "{why}");
    // Powered up afresh: the whole handshake again, then SIPs.
    wait_for(rx, 30, |u| matches!(u, Update::Ready { .. }));
    wait_for(rx, 10, |u| sip(u).is_some());
    line.stop(Order::Stop);
    emu.stop().unwrap();
}
