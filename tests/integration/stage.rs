//! Stage's own simple.cfg (read in place from ../shared/compat) launched as
//! processes: r0's devices come up, a client drives r0 towards a wall and the
//! laser sees it approach.

use std::path::Path;
use std::time::Instant;

use troupe_client::{Client, LaserProxy, Position2dProxy, SimulationProxy};
use troupe_tests::DEADLINE;

#[test]
fn simple_cfg_serves_r0_and_the_laser_sees_the_wall_approach() {
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/compat/stage/simple.cfg");
    if !cfg.exists() {
        eprintln!("skipping: ../shared/compat is absent");
        return;
    }
    let ns = troupe_tests::unique_namespace("stage");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let endpoint = launcher.endpoint("troupe launch: router listening on");
    let client = Client::with_session(troupe_tests::client_at(&endpoint, &ns), 6665);
    // The laser comes from rangertolaser, started once Stage's ranger:1 is live.
    let sim = SimulationProxy::new(&client, 0);
    let pp = Position2dProxy::new(&client, 0).unwrap();
    let lp = LaserProxy::new(&client, 0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while lp.count() != 180 {
        assert!(
            Instant::now() < deadline,
            "no 180-beam laser from simple.cfg"
        );
        let _ = client.read_timeout(DEADLINE);
    }
    // Stop r0's wander controller and face it into the cave's south-west corner.
    pp.set_speed(0.0, 0.0).unwrap();
    sim.set_pose2d("r0", -6.5, -6.5, -3.0 * std::f64::consts::FRAC_PI_4)
        .unwrap();
    let at = sim.get_pose2d("r0").unwrap();
    assert!(
        (at.x + 6.5).abs() < 0.5 && (at.y + 6.5).abs() < 0.5,
        "{at:?}"
    );
    let ahead = |lp: &LaserProxy| lp.range(90).unwrap_or(0.0);
    let deadline = Instant::now() + DEADLINE;
    while !(0.5..3.0).contains(&ahead(&lp)) {
        assert!(
            Instant::now() < deadline,
            "no wall ahead of r0: {} m",
            ahead(&lp)
        );
        client.read().unwrap();
    }
    let first = ahead(&lp);
    pp.set_speed(0.3, 0.0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while ahead(&lp) > first - 0.3 {
        assert!(
            Instant::now() < deadline,
            "the wall never came closer than {} m",
            ahead(&lp)
        );
        client.read().unwrap();
    }
    assert!(pp.x_speed() > 0.0, "r0 reports its speed");
    pp.set_speed(0.0, 0.0).unwrap();
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}
