//! The driver's line thread against the emulated 914 over a real
//! pseudo-terminal at 416666 baud: set-up, polling, driving, the digital
//! outputs, line faults and a mute board.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

use std::path::Path;
use std::sync::mpsc::Receiver;
use std::time::Duration;

use troupe_node::Waker;
use troupe_serial::{recv_where, Emulator, Faults, LineOptions};
use troupe_wbr914::device::{self, Order, Sample, Settings, Update};
use troupe_wbr914::emulator::{self, EmulatorOptions, EmulatorStats};
use troupe_wbr914::robot;

fn emulate(name: &str, faults: Faults) -> Emulator<EmulatorStats> {
    Emulator::spawn(&format!("wbr914-{name}"), move |link, stop, linked| {
        let opts = EmulatorOptions {
            line: LineOptions {
                link,
                faults,
                seed: 5,
                capture: None,
            },
        };
        emulator::run_with(&opts, &mut emulator::room(), stop, linked)
    })
    .expect("the emulator links its line")
}

/// Everything polled, for the robot at `link`.
fn settings(link: &Path) -> Settings {
    Settings {
        port: link.to_owned(),
        torque: 75,
        position: true,
        ir: true,
        aio: true,
        dio: true,
        debug: false,
    }
}

fn wait_for(rx: &Receiver<Update>, secs: u64, want: impl FnMut(&Update) -> bool) -> Update {
    recv_where(rx, Duration::from_secs(secs), want)
        .unwrap_or_else(|e| panic!("no matching update within {secs} s: {e}"))
}

fn sample(u: &Update) -> Option<&Sample> {
    match u {
        Update::Sample(s) => Some(s),
        _ => None,
    }
}

#[test]
fn the_driver_sets_up_polls_and_drives_the_emulated_914() {
    let emu = emulate("drive", Faults::default());
    let line = device::spawn(settings(emu.link()), Waker::none()).unwrap();
    let rx = line.updates();
    let Update::Ready { versions, cycle_us } =
        wait_for(rx, 30, |u| matches!(u, Update::Ready { .. }))
    else {
        unreachable!()
    };
    assert_eq!(versions, (emulator::VERSION, emulator::VERSION));
    assert_eq!(cycle_us, emulator::CYCLE_US);
    let Update::Sample(s) = wait_for(rx, 10, |u| sample(u).is_some()) else {
        unreachable!()
    };
    let m = s.motion.expect("wheels polled");
    assert_eq!((m.pose.x, m.speed), (0.0, 0.0));
    // IR 2 looks at a wall 3.79 m off: out of reach, the 80-count floor.
    let ir = s.ir.expect("IR polled");
    assert_eq!(ir[2], robot::ir_counts(2, 0.8));
    assert_eq!(s.aio, Some([0, 128, 256, 384, 512, 640, 768, 896]));
    assert_eq!(s.dio, Some(0));

    // Motors are off: a velocity alone moves nothing.
    line.send(Order::Vel(0.2, 0.0));
    for _ in 0..5 {
        wait_for(rx, 10, |u| sample(u).is_some());
    }
    let Update::Sample(s) = wait_for(rx, 10, |u| sample(u).is_some()) else {
        unreachable!()
    };
    assert_eq!(s.motion.unwrap().pose.x, 0.0);

    line.send(Order::Enable(true));
    line.send(Order::Vel(0.2, 0.5));
    let Update::Sample(s) = wait_for(rx, 30, |u| {
        sample(u).is_some_and(|s| s.motion.is_some_and(|m| m.pose.x > 0.2))
    }) else {
        unreachable!()
    };
    let m = s.motion.unwrap();
    assert!(m.pose.yaw > 0.05, "a left turn raises the heading: {m:?}");
    assert!(
        (m.speed - 0.2).abs() < 0.01 && (m.turn - 0.5).abs() < 0.02,
        "{m:?}"
    );

    // The low byte of the outputs, looped back to the inputs.
    line.send(Order::Dio(8, 0xA5));
    wait_for(rx, 10, |u| sample(u).is_some_and(|s| s.dio == Some(0xA500)));
    line.send(Order::ResetOdom);
    line.send(Order::Vel(0.0, 0.0));
    wait_for(rx, 10, |u| {
        sample(u).is_some_and(|s| s.motion.is_some_and(|m| m.pose.x.abs() < 0.05))
    });
    line.stop(Order::Stop);
    let stats = emu.stop().unwrap();
    assert_eq!((stats.refused, stats.digital_writes), (0, 1), "{stats:?}");
}

#[test]
fn line_noise_is_survived_and_a_mute_board_is_reported() {
    let noisy = emulate(
        "noisy",
        Faults {
            noise: 0.1,
            corrupt: 0.05,
            ..Faults::default()
        },
    );
    let line = device::spawn(settings(noisy.link()), Waker::none()).unwrap();
    let rx = line.updates();
    wait_for(rx, 60, |u| matches!(u, Update::Ready { .. }));
    line.send(Order::Enable(true));
    let mut polls = 0;
    wait_for(rx, 60, |u| {
        if sample(u).is_some() {
            polls += 1;
            line.send(Order::Vel(0.2, 0.0));
        }
        sample(u).is_some_and(|s| s.motion.is_some_and(|m| m.pose.x > 0.1))
    });
    assert!(polls > 1);
    line.stop(Order::Stop);
    noisy.stop().unwrap();

    let mute = emulate("mute", Faults::mute());
    let line = device::spawn(settings(mute.link()), Waker::none()).unwrap();
    let Update::Lost(why) = wait_for(line.updates(), 30, |u| matches!(u, Update::Lost(_))) else {
        unreachable!()
    };
    assert!(why.contains("did not answer GETVERSION"), "{why}");
    line.stop(Order::Stop);
    mute.stop().unwrap();
}
