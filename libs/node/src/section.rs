//! A driver's section: what a `driver ( … )` block of a Player `.cfg` says.
//!
//! The launcher hands each node its section as JSON:
//!
//! ```json
//! {"name": "rangertolaser", "provides": ["laser:0"], "requires": ["ranger:0"],
//!  "robot": 6665, "options": {"rate": 10}}
//! ```
//!
//! `robot` is the default robot field (Player's `-p PORT`) for addresses that
//! give none. Options keep Player's names; unknown ones are warned about, as
//! Player warned about unused options.

use std::sync::{Mutex, PoisonError};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use troupe_msgs::{DevAddr, Device, Interface, DEFAULT_ROBOT};

use crate::error::{NodeError, Result};

/// A driver's section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Section {
    /// The driver's Player name (`name "sicklms200"`).
    pub name: String,
    /// Devices this driver provides.
    #[serde(default)]
    pub provides: Vec<DevAddr>,
    /// Devices this driver requires.
    #[serde(default)]
    pub requires: Vec<DevAddr>,
    /// Robot field for addresses that give none.
    #[serde(default = "default_robot")]
    pub robot: u32,
    /// Driver-specific options, by Player's names.
    #[serde(default)]
    pub options: serde_json::Map<String, serde_json::Value>,
    /// Which `requires` entries the driver has looked up.
    #[serde(skip)]
    claims: Claims,
}

/// The indices of the `requires` entries a driver looked up
/// ([`Section::required_one`], [`Section::required_where`]): the others
/// are not used. Not part of the section's value: copies start afresh and
/// compare equal.
#[derive(Default)]
struct Claims(Mutex<Vec<usize>>);

impl Claims {
    fn add(&self, i: usize) {
        let mut v = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        if !v.contains(&i) {
            v.push(i);
        }
    }

    fn has(&self, i: usize) -> bool {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .contains(&i)
    }
}

impl Clone for Claims {
    fn clone(&self) -> Self {
        Claims::default()
    }
}

impl PartialEq for Claims {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl std::fmt::Debug for Claims {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Claims")
    }
}

fn default_robot() -> u32 {
    DEFAULT_ROBOT
}

/// A device named in `provides` or `requires`, resolved.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Slot {
    /// Its key (`odometry`, `input`, …) if the cfg gave one.
    pub key: Option<String>,
    /// The concrete device.
    pub device: Device,
}

impl Section {
    /// A section for `name` with no devices or options.
    pub fn new(name: &str) -> Self {
        Section {
            name: name.to_owned(),
            provides: Vec::new(),
            requires: Vec::new(),
            robot: DEFAULT_ROBOT,
            options: Default::default(),
            claims: Claims::default(),
        }
    }

    /// Parses a section from JSON.
    ///
    /// # Errors
    ///
    /// [`NodeError::Config`] quoting serde's reason (line and column included).
    pub fn from_json(text: &str) -> Result<Self> {
        serde_json::from_str(text).map_err(|e| NodeError::config("?", format!("section JSON: {e}")))
    }

    /// The provided devices, resolved against the section's robot.
    pub fn provided(&self) -> Vec<Slot> {
        self.slots(&self.provides)
    }

    /// The required devices, resolved against the section's robot.
    pub fn required(&self) -> Vec<Slot> {
        self.slots(&self.requires)
    }

    fn slots(&self, list: &[DevAddr]) -> Vec<Slot> {
        list.iter()
            .map(|a| Slot {
                key: a.key.clone(),
                device: a.device(self.robot),
            })
            .collect()
    }

    /// The one provided device of `interface` (with `key`, if given).
    ///
    /// # Errors
    ///
    /// [`NodeError::Config`] when there is none, or more than one.
    pub fn provided_one(&self, interface: Interface, key: Option<&str>) -> Result<Device> {
        self.one(&self.provided(), "provides", interface, key)
    }

    /// The one required device of `interface` (with `key`, if given),
    /// which the driver then uses.
    ///
    /// # Errors
    ///
    /// [`NodeError::Config`] when there is none, or more than one.
    pub fn required_one(&self, interface: Interface, key: Option<&str>) -> Result<Device> {
        let slots = self.required();
        let d = self.one(&slots, "requires", interface, key)?;
        self.claim(&slots, |s| s.device == d);
        Ok(d)
    }

    /// The required devices of the interfaces `want` accepts, which the
    /// driver then uses.
    pub fn required_where(&self, want: impl Fn(Interface) -> bool) -> Vec<Device> {
        let slots = self.required();
        self.claim(&slots, |s| want(s.device.interface));
        slots
            .into_iter()
            .map(|s| s.device)
            .filter(|d| want(d.interface))
            .collect()
    }

    /// Marks the `requires` entries (`slots`, as [`Section::required`]
    /// makes them) that `used` picks as looked up.
    fn claim(&self, slots: &[Slot], used: impl Fn(&Slot) -> bool) {
        for (i, s) in slots.iter().enumerate() {
            if used(s) {
                self.claims.add(i);
            }
        }
    }

    /// The `requires` entries the driver has not looked up (see
    /// [`Section::required_one`]): once the driver is built, those it does
    /// not use.
    pub fn unused_requires(&self) -> Vec<&DevAddr> {
        (0..self.requires.len())
            .filter(|&i| !self.claims.has(i))
            .map(|i| &self.requires[i])
            .collect()
    }

    fn one(&self, slots: &[Slot], field: &str, i: Interface, key: Option<&str>) -> Result<Device> {
        let found: Vec<&Slot> = slots
            .iter()
            .filter(|s| s.device.interface == i && (key.is_none() || s.key.as_deref() == key))
            .collect();
        let what = match key {
            Some(k) => format!("`{k}:::{i}:N`"),
            None => format!("`{i}:N`"),
        };
        match found.as_slice() {
            [one] => Ok(one.device),
            [] => Err(NodeError::config(
                &self.name,
                format!(
                    "`{field}` needs a {what} device; it has {:?}",
                    self.list(field)
                ),
            )),
            _ => Err(NodeError::config(
                &self.name,
                format!(
                    "`{field}` has more than one {what} device: {:?}",
                    self.list(field)
                ),
            )),
        }
    }

    fn list(&self, field: &str) -> Vec<String> {
        let l = if field == "provides" {
            &self.provides
        } else {
            &self.requires
        };
        l.iter().map(ToString::to_string).collect()
    }

    /// Decodes the options as `O`, returning the names of options `O` does not use.
    ///
    /// # Errors
    ///
    /// [`NodeError::Config`] naming the option with the wrong type.
    pub fn options<O: DeserializeOwned>(&self) -> Result<(O, Vec<String>)> {
        let mut unused = Vec::new();
        let value = serde_json::Value::Object(self.options.clone());
        let o = serde_ignored::deserialize(value, |path| unused.push(path.to_string()))
            .map_err(|e| NodeError::config(&self.name, format!("option {e}")))?;
        Ok((o, unused))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Default, Deserialize, PartialEq)]
    #[serde(default)]
    struct Opts {
        rate: f64,
    }

    #[test]
    fn parses_and_resolves_addresses() {
        let s = Section::from_json(
            r#"{"name":"amcl","robot":7000,
                "provides":["localize:0","6666:position2d:2"],
                "requires":["odometry::position2d:0","laser:0","laser:::map:0"]}"#,
        )
        .unwrap();
        assert_eq!(
            s.provided()[1].device,
            Device::new(6666, Interface::Position2d, 2)
        );
        assert_eq!(
            s.required_one(Interface::Position2d, Some("odometry"))
                .unwrap(),
            Device::new(7000, Interface::Position2d, 0)
        );
        let e = s
            .required_one(Interface::Ranger, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("`requires` needs a `ranger:N` device"), "{e}");
    }

    #[test]
    fn requires_a_driver_never_looks_up_are_unused() {
        let s = Section::from_json(
            r#"{"name":"amcl","requires":["odometry::position2d:0","laser:0","laser:::map:0","sonar:1"]}"#,
        )
        .unwrap();
        assert_eq!(s.unused_requires().len(), 4);
        s.required_one(Interface::Position2d, Some("odometry"))
            .unwrap();
        assert_eq!(
            s.required_where(|i| i == Interface::Laser),
            vec![Device::new(DEFAULT_ROBOT, Interface::Laser, 0)]
        );
        let unused: Vec<String> = s
            .unused_requires()
            .iter()
            .map(ToString::to_string)
            .collect();
        assert_eq!(unused, vec!["laser:::map:0", "sonar:1"]);
        // A copy is the same section, its lookups not yet made.
        let copy = s.clone();
        assert_eq!(copy, s);
        assert_eq!(copy.unused_requires().len(), 4);
    }

    #[test]
    fn unknown_options_are_reported_and_bad_types_named() {
        let mut s = Section::new("dummy");
        s.options.insert("rate".into(), 5.into());
        s.options.insert("colour".into(), "red".into());
        let (o, unused): (Opts, _) = s.options().unwrap();
        assert_eq!(o.rate, 5.0);
        assert_eq!(unused, vec!["colour".to_owned()]);
        s.options.insert("rate".into(), "fast".into());
        let e = s.options::<Opts>().unwrap_err().to_string();
        assert!(e.contains("dummy") && e.contains("fast"), "{e}");
    }

    #[test]
    fn malformed_section_json_is_an_error() {
        assert!(Section::from_json(r#"{"name":"x","provides":["laser:x"]}"#).is_err());
        assert!(Section::from_json(r#"{"name":"x","bogus":1}"#).is_err());
        assert!(Section::from_json("{").is_err());
    }
}

/// A cfg on/off value: `1`, `0`, `yes`, `true`…
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Switch {
    /// `yes`/`no`, `true`/`false`.
    Bool(bool),
    /// `1`/`0`.
    Num(f64),
}

impl Switch {
    /// On: `yes`, `true` or a number other than 0.
    pub fn on(self) -> bool {
        match self {
            Switch::Bool(b) => b,
            Switch::Num(n) => n != 0.0,
        }
    }
}

/// Options of a driver that takes none: every option given is reported unused.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
pub struct NoOptions {}
