//! Key expressions: the only place in Troupe where keys are spelled.
//!
//! ```text
//! robot/<port>/<interface>/<index>               data samples (put)
//! robot/<port>/<interface>/<index>/cmd/<name>    commands (put)
//! robot/<port>/<interface>/<index>/req/<name>    requests (queryable/get)
//! robot/<port>/<interface>/<index>/driver/<name> liveliness token of the provider
//! sim/clock                                      simulation time
//! ```
//!
//! A fleet or a test isolates itself with Zenoh's namespace option, never by
//! renaming these keys.

use crate::addr::{AddrError, Device, Interface};

/// Where the simulator publishes its clock.
pub const SIM_CLOCK: &str = "sim/clock";

const ROOT: &str = "robot";

/// `troupe bench latency`: the pinger publishes here…
pub const BENCH_PING: &str = "bench/ping";
/// …the ponger answers here…
pub const BENCH_PONG: &str = "bench/pong";
/// …serves requests here…
pub const BENCH_REQ: &str = "bench/req";
/// …and announces itself with this liveliness token.
pub const BENCH_READY: &str = "bench/ready";

/// The data key of `dev`: `robot/6665/laser/0`.
pub fn data(dev: &Device) -> String {
    format!("{ROOT}/{}/{}/{}", dev.robot, dev.interface, dev.index)
}

/// The key of command `name` to `dev`: `robot/6665/position2d/0/cmd/vel`.
pub fn cmd(dev: &Device, name: &str) -> String {
    format!("{}/cmd/{name}", data(dev))
}

/// All command keys of `dev`: `robot/6665/position2d/0/cmd/*`.
pub fn cmd_any(dev: &Device) -> String {
    format!("{}/cmd/*", data(dev))
}

/// The key of request `name` to `dev`: `robot/6665/map/0/req/data`.
pub fn req(dev: &Device, name: &str) -> String {
    format!("{}/req/{name}", data(dev))
}

/// All request keys of `dev`: `robot/6665/map/0/req/*`.
pub fn req_any(dev: &Device) -> String {
    format!("{}/req/*", data(dev))
}

/// The liveliness token declaring that `driver` provides `dev`.
pub fn token(dev: &Device, driver: &str) -> String {
    token_at(&data(dev), driver)
}

/// The liveliness token declaring that `driver` provides the device whose
/// data key is `key`, a key already spelled (remapped, say):
/// `robot/6665/laser/0/driver/play`.
pub fn token_at(key: &str, driver: &str) -> String {
    format!("{key}/driver/{driver}")
}

/// Liveliness selector for the token of `dev`, whichever driver provides it.
pub fn token_any(dev: &Device) -> String {
    format!("{}/driver/*", data(dev))
}

/// Selector for the data of every device: `robot/*/*/*`.
pub fn data_all() -> String {
    format!("{ROOT}/*/*/*")
}

/// Selector for every key of every robot: data, commands, requests and
/// liveliness tokens: `robot/**`.
pub fn all() -> String {
    format!("{ROOT}/**")
}

/// The prefix of every key of robot `robot`: `robot/6665/` (what a port
/// remapping replaces).
pub fn robot_prefix(robot: u32) -> String {
    format!("{ROOT}/{robot}/")
}

/// Selector for the data of every device of `interface`, on every robot:
/// `robot/*/laser/*`.
pub fn data_of(interface: Interface) -> String {
    format!("{ROOT}/*/{interface}/*")
}

/// Liveliness selector for every device token, or those of one robot.
pub fn tokens(robot: Option<u32>) -> String {
    match robot {
        Some(r) => format!("{ROOT}/{r}/*/*/driver/*"),
        None => format!("{ROOT}/*/*/*/driver/*"),
    }
}

/// Splits a key into the device and what follows it (`""`, `cmd/vel`, …).
fn split<'a>(key: &'a str, rest: &'static str) -> Result<(Device, Vec<&'a str>), AddrError> {
    let bad = || AddrError::NotADeviceKey {
        text: key.to_owned(),
        rest,
    };
    let mut parts = key.split('/');
    if parts.next() != Some(ROOT) {
        return Err(bad());
    }
    let robot = parts.next().and_then(|p| p.parse().ok()).ok_or_else(bad)?;
    let interface = parts
        .next()
        .and_then(Interface::from_name)
        .ok_or_else(bad)?;
    let index = parts.next().and_then(|p| p.parse().ok()).ok_or_else(bad)?;
    Ok((Device::new(robot, interface, index), parts.collect()))
}

/// The device of a data key (`robot/6665/laser/0`).
pub fn parse_data(key: &str) -> Result<Device, AddrError> {
    match split(key, "")? {
        (dev, rest) if rest.is_empty() => Ok(dev),
        _ => Err(AddrError::NotADeviceKey {
            text: key.to_owned(),
            rest: "",
        }),
    }
}

/// The device and driver name of a liveliness token key.
pub fn parse_token(key: &str) -> Result<(Device, String), AddrError> {
    const REST: &str = "/driver/<name>";
    match split(key, REST)? {
        (dev, rest) if rest.len() == 2 && rest[0] == "driver" => Ok((dev, rest[1].to_owned())),
        _ => Err(AddrError::NotADeviceKey {
            text: key.to_owned(),
            rest: REST,
        }),
    }
}

/// The device and name of a command or request key (`…/cmd/vel`, `…/req/geom`).
pub fn parse_named(key: &str, kind: &'static str) -> Result<(Device, String), AddrError> {
    let rest = if kind == "cmd" {
        "/cmd/<name>"
    } else {
        "/req/<name>"
    };
    match split(key, rest)? {
        (dev, r) if r.len() == 2 && r[0] == kind => Ok((dev, r[1].to_owned())),
        _ => Err(AddrError::NotADeviceKey {
            text: key.to_owned(),
            rest,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_round_trip() {
        let d = Device::new(6665, Interface::Laser, 0);
        assert_eq!(data(&d), "robot/6665/laser/0");
        assert_eq!(parse_data(&data(&d)).unwrap(), d);
        assert_eq!(cmd(&d, "vel"), "robot/6665/laser/0/cmd/vel");
        assert_eq!(
            parse_named(&cmd(&d, "vel"), "cmd").unwrap(),
            (d, "vel".into())
        );
        assert_eq!(
            parse_named(&req(&d, "geom"), "req").unwrap(),
            (d, "geom".into())
        );
        let t = token(&d, "stage");
        assert_eq!(parse_token(&t).unwrap(), (d, "stage".to_owned()));
        assert_eq!(tokens(Some(6665)), "robot/6665/*/*/driver/*");
    }

    #[test]
    fn selectors_and_prefixes_are_spelled_under_the_root() {
        let d = Device::new(6665, Interface::Laser, 0);
        assert_eq!(data_all(), "robot/*/*/*");
        assert_eq!(all(), "robot/**");
        assert_eq!(robot_prefix(6665), "robot/6665/");
        assert!(data(&d).starts_with(&robot_prefix(6665)));
        assert!(!data(&d).starts_with(&robot_prefix(666)));
        assert_eq!(
            token_at(&data(&d), "play"),
            "robot/6665/laser/0/driver/play"
        );
        assert_eq!(token_at(&data(&d), "stage"), token(&d, "stage"));
    }

    #[test]
    fn non_device_keys_are_rejected_with_the_key_quoted() {
        for k in [
            "sim/clock",
            "robot/x/laser/0",
            "robot/6665/lazer/0",
            "robot/6665/laser",
            "robot/6665/laser/0/cmd/vel",
        ] {
            let e = parse_data(k).unwrap_err();
            assert!(e.to_string().contains(k), "{e}");
        }
        assert!(parse_token("robot/6665/laser/0").is_err());
        assert!(parse_named("robot/6665/laser/0/req/geom", "cmd").is_err());
    }
}
