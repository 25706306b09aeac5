//! The driver's line thread against the emulated scanner, over a real
//! pseudo-terminal: Player's whole connection sequence, then scans.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

mod common;

use std::sync::mpsc::Receiver;
use std::time::Duration;

use common::{emulate, settings};
use troupe_geom::{Room, Scene};
use troupe_node::Waker;
use troupe_serial::{recv_where, Faults};
use troupe_sicklms200::device::{self, Order, Update};
use troupe_sicklms200::emulator;

/// Waits for an update matching `want`, for at most `secs`.
fn wait_for(rx: &Receiver<Update>, secs: u64, want: impl FnMut(&Update) -> bool) -> Update {
    recv_where(rx, Duration::from_secs(secs), want)
        .unwrap_or_else(|e| panic!("no matching update within {secs} s: {e}"))
}

#[test]
fn connects_at_9600_switches_to_500000_and_streams_room_scans() {
    let emu = emulate("fast", Faults::default(), None);
    let t = device::spawn(settings(emu.link(), 50, 500000), Waker::none()).unwrap();
    let rx = t.updates();
    let ready = wait_for(rx, 20, |u| matches!(u, Update::Ready { .. }));
    let Update::Ready { kind, baud } = ready else {
        unreachable!()
    };
    assert_eq!((kind.as_str(), baud), (emulator::KIND, 500000));

    let Update::Scan(raw, config) = wait_for(rx, 10, |u| matches!(u, Update::Scan(..))) else {
        unreachable!()
    };
    assert_eq!(raw.values.len(), 361);
    assert_eq!(config.res, 50);
    let scan = troupe_sicklms200::to_scan(&raw, &config, false, 0);
    // Straight ahead: the pillar (2 m ahead, radius 0.3, drifting sideways) or
    // the far wall 6 m away; straight left/right: the side walls 3 m away.
    let angles: Vec<f64> = (0..361)
        .map(|i| (-90.0 + 0.5 * f64::from(i)).to_radians())
        .collect();
    let truth = Room.ranges(0.0, &angles);
    assert!(
        (scan.ranges[0] - 3.0).abs() < 0.002,
        "right wall {}",
        scan.ranges[0]
    );
    assert!(
        (scan.ranges[360] - 3.0).abs() < 0.002,
        "left wall {}",
        scan.ranges[360]
    );
    assert!((scan.ranges[180] - 1.7).abs() < 0.31 || (scan.ranges[180] - 6.0).abs() < 0.01);
    assert_eq!(truth.len(), scan.ranges.len());
    assert!(
        scan.intensity.iter().all(|&i| i == 0),
        "nothing within 1 m reflects"
    );

    // A new configuration is taken up: 1° gives 181 values.
    let mut c = config;
    c.res = 100;
    assert!(t.send(Order::Configure(c)));
    let Update::Configured(done) = wait_for(rx, 20, |u| matches!(u, Update::Configured(..))) else {
        unreachable!()
    };
    assert_eq!(done, Ok(c));
    wait_for(
        rx,
        10,
        |u| matches!(u, Update::Scan(r, _) if r.values.len() == 181),
    );

    t.stop(Order::Stop);
    let stats = emu.stop().unwrap();
    assert!(stats.scans >= 2 && stats.requests >= 8, "{stats:?}");
    assert_eq!(stats.refused, 0);
}

#[test]
fn survives_noise_bad_checksums_truncation_and_dropped_bytes() {
    let faults = Faults {
        noise: 0.2,
        corrupt: 0.1,
        truncate: 0.1,
        drop: 0.0005,
        ..Faults::default()
    };
    let emu = emulate("noisy", faults, None);
    let t = device::spawn(settings(emu.link(), 100, 500000), Waker::none()).unwrap();
    let rx = t.updates();
    // Whatever the faults did to the handshake, the driver gets through it
    // (reconnecting if it must) and good scans come out: every one whole.
    let mut good = 0;
    wait_for(rx, 60, |u| {
        if let Update::Scan(raw, _) = u {
            assert_eq!(raw.values.len(), 181);
            good += 1;
        }
        good >= 30
    });
    t.stop(Order::Stop);
    emu.stop().unwrap();
}

#[test]
fn a_mute_device_is_reported_and_an_unplugged_one_reconnects() {
    let mute = emulate("mute", Faults::mute(), None);
    let mut s = settings(mute.link(), 100, 38400);
    s.connect_rates = vec![9600];
    let t = device::spawn(s, Waker::none()).unwrap();
    let rx = t.updates();
    let Update::Lost(why) = wait_for(rx, 20, |u| matches!(u, Update::Lost(_))) else {
        unreachable!()
    };
    assert!(
        why.contains("no reply to stop streaming at 9600 baud"),
        "{why}"
    );
    t.stop(Order::Stop);
    mute.stop().unwrap();

    let unplug = emulate(
        "unplug",
        Faults::unplug(Duration::from_secs(3), Duration::from_secs(1)),
        None,
    );
    let t = device::spawn(settings(unplug.link(), 100, 38400), Waker::none()).unwrap();
    let rx = t.updates();
    wait_for(rx, 20, |u| matches!(u, Update::Ready { .. }));
    let Update::Lost(why) = wait_for(rx, 20, |u| matches!(u, Update::Lost(_))) else {
        unreachable!()
    };
    assert!(why.contains("lost") || why.contains("no scan"), "{why}");
    // Plugged back in, powered up afresh at 9600: the whole sequence again.
    wait_for(rx, 30, |u| matches!(u, Update::Ready { .. }));
    wait_for(rx, 10, |u| matches!(u, Update::Scan(..)));
    t.stop(Order::Stop);
    unplug.stop().unwrap();
}
