//! Player's `rangertolaser`: republishes a ranger device as a laser device.
//!
//! ```text
//! driver ( name "rangertolaser" requires ["ranger:0"] provides ["laser:0"] )
//! ```
//!
//! | | |
//! |---|---|
//! | requires | one `ranger` |
//! | provides | one `laser` |
//! | options | none |
//!
//! # Behavior
//!
//! - On setup it subscribes to the ranger and asks for its configuration;
//!   angles, resolution and maximum range of every scan come from it.
//!   Until that answer arrives, range samples are dropped (Player would
//!   publish them with zeroed angles); if the ranger refuses, scans go out with
//!   zeroed angles as Player's did, and a warning says why.
//! - As Player's, every ranger message makes a [`laser::Scan`] (numbered 0):
//!   the ranges with the latest intensities when their count matches, then,
//!   when the step's intensities come, the same ranges with them.
//! - Laser requests map to ranger requests: `geom` → ranger `geom`,
//!   `get_config` → the cached configuration, `set_config` → ranger
//!   `set_config`, `power` → ranger `power`. The laser request is answered
//!   when the ranger answers, with the ranger's NACK reason if it refuses.

use std::collections::HashMap;

use troupe_msgs::{common, laser, ranger, Device, Interface};
use troupe_node::{Ctx, Driver, Event, NoOptions, RequestId, Responder, Result, Section};

/// The rangertolaser driver.
pub struct RangerToLaser {
    input: Device,
    output: Device,
    config: ConfigState,
    config_request: Option<RequestId>,
    intensities: Vec<f64>,
    /// The latest ranges (once the configuration is known).
    ranges: Vec<f64>,
    /// Laser requests waiting for the ranger's answer.
    pending: HashMap<RequestId, Pending>,
}

enum ConfigState {
    Waiting,
    Known(laser::Config),
    Refused,
}

enum Pending {
    Geom(Responder),
    Config(Responder),
    Power(Responder),
}

fn to_laser(c: &ranger::Config) -> laser::Config {
    laser::Config {
        min_angle: c.min_angle as f32,
        max_angle: c.max_angle as f32,
        resolution: c.angular_res as f32,
        max_range: c.max_range as f32,
        range_res: c.range_res as f32,
        intensity: false,
        scanning_frequency: c.frequency as f32,
    }
}

fn to_ranger(c: &laser::Config) -> ranger::Config {
    ranger::Config {
        min_angle: c.min_angle.into(),
        max_angle: c.max_angle.into(),
        angular_res: c.resolution.into(),
        min_range: 0.0,
        max_range: c.max_range.into(),
        range_res: c.range_res.into(),
        frequency: c.scanning_frequency.into(),
    }
}

impl Driver for RangerToLaser {
    const NAME: &'static str = "rangertolaser";
    type Options = NoOptions;

    fn new(section: &Section, _: NoOptions) -> Result<Self> {
        Ok(RangerToLaser {
            input: section.required_one(Interface::Ranger, None)?,
            output: section.provided_one(Interface::Laser, None)?,
            config: ConfigState::Waiting,
            config_request: None,
            intensities: Vec::new(),
            ranges: Vec::new(),
            pending: HashMap::new(),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        ctx.subscribe(&self.input)?;
        self.config_request = Some(ctx.request(&self.input, &ranger::GetConfig)?);
        Ok(())
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Data(s) if s.is::<ranger::Ranges>() => {
                let d = s.decode::<ranger::Ranges>()?;
                self.ranges = d.msg.ranges;
                self.publish(ctx, d.stamp)
            }
            // As Player's: every ranger message makes a scan, so the step's
            // intensities go out with its ranges.
            Event::Data(s) if s.is::<ranger::Intensities>() => {
                let d = s.decode::<ranger::Intensities>()?;
                self.intensities = d.msg.intensities;
                self.publish(ctx, d.stamp)
            }
            Event::Data(s) => Err(s.unexpected()),
            Event::Request(r) if r.is::<laser::GetGeom>() => {
                let id = ctx.request(&self.input, &ranger::GetGeom)?;
                self.pending.insert(id, Pending::Geom(r.responder));
                Ok(())
            }
            Event::Request(r) if r.is::<laser::GetConfig>() => {
                match &self.config {
                    ConfigState::Known(c) => r.reply(c),
                    _ => {
                        let id = ctx.request(&self.input, &ranger::GetConfig)?;
                        self.pending.insert(id, Pending::Config(r.responder));
                    }
                }
                Ok(())
            }
            Event::Request(r) if r.is::<laser::SetConfig>() => {
                let want = r.decode::<laser::SetConfig>()?.config;
                let id = ctx.request(
                    &self.input,
                    &ranger::SetConfig {
                        config: to_ranger(&want),
                    },
                )?;
                self.pending.insert(id, Pending::Config(r.responder));
                Ok(())
            }
            Event::Request(r) if r.is::<common::Power>() => {
                let p = r.decode::<common::Power>()?;
                let id = ctx.request(&self.input, &p)?;
                self.pending.insert(id, Pending::Power(r.responder));
                Ok(())
            }
            Event::Request(r) => {
                let why = format!("rangertolaser does not handle request `{}`", r.name);
                r.nack(why);
                Ok(())
            }
            Event::Reply(reply) => {
                if Some(reply.id) == self.config_request {
                    self.config_request = None;
                    self.config = match reply.decode::<ranger::Config>() {
                        Ok(c) => ConfigState::Known(to_laser(&c)),
                        Err(e) => {
                            tracing::warn!("ranger {} gave no configuration ({e}); scans will have zero angles", self.input);
                            ConfigState::Refused
                        }
                    };
                    return Ok(());
                }
                match self.pending.remove(&reply.id) {
                    Some(Pending::Geom(resp)) => match reply.decode::<ranger::Geom>() {
                        Ok(g) => resp.reply(&laser::Geom {
                            pose: g.pose,
                            size: g.size,
                        }),
                        Err(e) => resp.nack(format!("ranger {}: {e}", self.input)),
                    },
                    Some(Pending::Config(resp)) => match reply.decode::<ranger::Config>() {
                        Ok(c) => {
                            let c = to_laser(&c);
                            self.config = ConfigState::Known(c);
                            resp.reply(&c);
                        }
                        Err(e) => resp.nack(format!("ranger {}: {e}", self.input)),
                    },
                    Some(Pending::Power(resp)) => match reply.decode::<common::Ack>() {
                        Ok(a) => resp.reply(&a),
                        Err(e) => resp.nack(format!("ranger {}: {e}", self.input)),
                    },
                    None => {}
                }
                Ok(())
            }
            Event::Command(c) => {
                tracing::debug!("laser takes no commands; ignored `{}`", c.key);
                Ok(())
            }
            Event::Tick | Event::Wake => Ok(()),
        }
    }
}

impl RangerToLaser {
    /// Publishes a scan of the latest ranges, stamped as the ranger message that made it.
    fn publish(&mut self, ctx: &mut Ctx, stamp: f64) -> Result<()> {
        let c = match &self.config {
            ConfigState::Known(c) => *c,
            ConfigState::Refused => laser::Config::default(),
            // Ranges from before the configuration make no scan, later either.
            ConfigState::Waiting => {
                self.ranges.clear();
                return Ok(());
            }
        };
        if self.ranges.is_empty() {
            return Ok(());
        }
        let ranges = &self.ranges;
        let intensity = if self.intensities.len() == ranges.len() {
            self.intensities
                .iter()
                .map(|&i| i.clamp(0.0, 255.0) as u8)
                .collect()
        } else {
            Vec::new()
        };
        let scan = laser::Scan {
            min_angle: c.min_angle,
            max_angle: c.max_angle,
            resolution: c.resolution,
            max_range: c.max_range,
            ranges: ranges.iter().map(|&r| r as f32).collect(),
            intensity,
            // Player's rangertolaser numbers no scan.
            id: 0,
        };
        ctx.publish_at(&self.output, &scan, stamp)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_msgs::codec;
    use troupe_node::testing::Harness;
    use troupe_node::RequestError;

    const RANGER: Device = Device::new(6665, Interface::Ranger, 1);
    const LASER: Device = Device::new(6665, Interface::Laser, 0);

    fn harness() -> Harness<RangerToLaser> {
        Harness::from_json(
            r#"{"name":"rangertolaser","requires":["ranger:1"],"provides":["laser:0"]}"#,
        )
        .unwrap()
    }

    fn config() -> ranger::Config {
        ranger::Config {
            min_angle: -1.5,
            max_angle: 1.5,
            angular_res: 0.5,
            max_range: 8.0,
            ..Default::default()
        }
    }

    #[test]
    fn converts_ranges_with_the_rangers_config() {
        let mut h = harness();
        assert_eq!(h.subscriptions(), vec![RANGER]);
        let req = h.requests_sent();
        assert!(req[0].is::<ranger::GetConfig>() && req[0].device == RANGER);
        // Before the config arrives nothing is published.
        h.input(
            RANGER,
            &ranger::Ranges {
                ranges: vec![1.0; 7],
            },
        )
        .unwrap();
        assert!(h.published::<laser::Scan>(LASER).is_empty());
        h.answer(req[0].id, &config()).unwrap();
        h.input(
            RANGER,
            &ranger::Intensities {
                intensities: vec![300.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            },
        )
        .unwrap();
        h.input(
            RANGER,
            &ranger::Ranges {
                ranges: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0],
            },
        )
        .unwrap();
        // The scan keeps the ranger's stamp, whatever the clock says now.
        h.set_time(20.0);
        h.input_raw(
            RANGER,
            codec::encode(
                &ranger::Ranges {
                    ranges: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0],
                },
                19.9,
            ),
        )
        .unwrap();
        let stamped = h.published_at::<laser::Scan>(LASER);
        assert_eq!(stamped.len(), 2);
        assert_eq!(stamped[1].0, 19.9);
        let scans = h.published::<laser::Scan>(LASER);
        let s = &scans[0];
        assert_eq!(
            (s.min_angle, s.max_angle, s.resolution, s.max_range),
            (-1.5, 1.5, 0.5, 8.0)
        );
        assert_eq!(s.ranges, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
        assert_eq!(s.intensity, vec![255, 2, 0, 0, 0, 0, 1]);
    }

    /// Player's rangertolaser makes a scan of every ranger message: Stage's
    /// ranges with the last intensities, then the same ranges with the
    /// step's intensities, each scan numbered 0.
    #[test]
    fn the_step_s_intensities_make_a_second_scan_of_its_ranges() {
        let mut h = harness();
        let id = h.requests_sent()[0].id;
        h.answer(id, &config()).unwrap();
        h.input(
            RANGER,
            &ranger::Ranges {
                ranges: vec![3.0; 7],
            },
        )
        .unwrap();
        h.input(
            RANGER,
            &ranger::Intensities {
                intensities: vec![1.0; 7],
            },
        )
        .unwrap();
        let scans = h.published::<laser::Scan>(LASER);
        assert_eq!(scans.len(), 2);
        assert_eq!((scans[0].intensity.len(), scans[0].id), (0, 0));
        assert_eq!(scans[1].ranges, vec![3.0; 7]);
        assert_eq!((scans[1].intensity.clone(), scans[1].id), (vec![1; 7], 0));
    }

    #[test]
    fn refused_config_still_publishes_like_player() {
        let mut h = harness();
        let id = h.requests_sent()[0].id;
        h.fail(id, RequestError::Nack("no".into())).unwrap();
        h.input(
            RANGER,
            &ranger::Ranges {
                ranges: vec![2.0; 3],
            },
        )
        .unwrap();
        let scans = h.published::<laser::Scan>(LASER);
        assert_eq!(scans[0].ranges, vec![2.0; 3]);
        assert_eq!(scans[0].max_range, 0.0);
    }

    #[test]
    fn geom_request_is_forwarded_and_answered_later() {
        let mut h = harness();
        let p = h.request(LASER, &laser::GetGeom).unwrap();
        assert!(h.reply::<laser::Geom>(p).is_none());
        let fwd = h.requests_sent().pop().unwrap();
        assert!(fwd.is::<ranger::GetGeom>());
        let g = ranger::Geom {
            pose: troupe_msgs::Pose3d::planar(0.1, 0.0, 0.0),
            ..Default::default()
        };
        h.answer(fwd.id, &g).unwrap();
        assert_eq!(h.reply::<laser::Geom>(p).unwrap().unwrap().pose.x, 0.1);
    }

    #[test]
    fn ranger_nack_reaches_the_laser_client() {
        let mut h = harness();
        let p = h.request(LASER, &laser::SetConfig::default()).unwrap();
        let fwd = h.requests_sent().pop().unwrap();
        assert!(fwd.is::<ranger::SetConfig>());
        h.fail(fwd.id, RequestError::Nack("read-only".into()))
            .unwrap();
        let e = h.reply::<laser::Config>(p).unwrap().unwrap_err();
        assert!(e.contains("read-only"), "{e}");
        let p = h.request(LASER, &troupe_msgs::map::GetInfo).unwrap();
        assert!(h
            .reply::<laser::Config>(p)
            .unwrap()
            .unwrap_err()
            .contains("does not handle"));
    }

    #[test]
    fn malformed_ranger_data_is_dropped_and_counted() {
        let mut h = harness();
        h.input_raw(RANGER, vec![1, 2, 3]).unwrap();
        h.input(RANGER, &laser::Scan::default()).unwrap();
        assert_eq!(h.malformed(), 2);
        assert!(h.published::<laser::Scan>(LASER).is_empty());
    }

    #[test]
    fn section_without_ranger_is_a_config_error() {
        let e = Harness::<RangerToLaser>::from_json(
            r#"{"name":"rangertolaser","provides":["laser:0"]}"#,
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("ranger"), "{e}");
    }
}
