//! Player's `dummy` driver: publishes fixed data at a fixed rate on any
//! interface it supports, takes every command, refuses every request.
//!
//! ```text
//! driver ( name "dummy" provides ["laser:0"] rate 75 )
//! ```
//!
//! | | |
//! |---|---|
//! | provides | any number of `laser`, `ranger`, `position2d`, `ptz`, `blobfinder`, `power`, `fiducial`, `dio`, `aio`, `camera`, `wsn` devices |
//! | requires | nothing |
//! | option `rate` | float, Hz, default 10 |
//! | option `image_size` | `[width height]` of the camera's images, pixels, default `[320 240]` (Player's; not an option of Player's dummy) |
//! | option `panic_in` | for testing supervision: `setup`, `tick`, `request` or `command`, the hook that panics (a request's hook runs on Zenoh's thread) |
//!
//! The data are Player's: a 361-beam laser scan at 8 m over ±90°, 361 ranger
//! ranges of 8 m, a position2d at (1, 1, 1) moving at (1, 1, 1), a 320 x 240
//! (or `image_size`) RGB image whose every byte is the count of images sent before it (modulo
//! 256: it fades from black to white and again), and so on.
//! Useful to test clients, tools and pipelines without a robot.

use std::time::Duration;

use serde::Deserialize;
use troupe_msgs::{
    aio, blobfinder, camera, dio, fiducial, laser, position2d, power, ptz, ranger, wsn,
};
use troupe_msgs::{Device, Interface, Pose2d, Pose3d};
use troupe_node::{Ctx, Driver, Event, NodeError, Result, Section};

/// The interfaces `dummy` can provide.
pub const INTERFACES: &[Interface] = &[
    Interface::Laser,
    Interface::Ranger,
    Interface::Position2d,
    Interface::Ptz,
    Interface::Blobfinder,
    Interface::Power,
    Interface::Fiducial,
    Interface::Dio,
    Interface::Aio,
    Interface::Camera,
    Interface::Wsn,
];

/// Options of the dummy driver.
#[derive(Debug, Clone, Deserialize)]
#[serde(default)]
pub struct Options {
    /// Data rate, Hz.
    pub rate: f64,
    /// The hook that panics, to test supervision.
    pub panic_in: Option<Hook>,
    /// The camera's images, `[width, height]` in pixels.
    pub image_size: [u32; 2],
}

impl Default for Options {
    fn default() -> Self {
        Options {
            rate: 10.0,
            panic_in: None,
            image_size: [320, 240],
        }
    }
}

/// The largest image `image_size` may ask for: 64 MB of RGB.
const MAX_IMAGE_BYTES: u64 = 64 << 20;

/// A hook of the driver (`panic_in`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Hook {
    /// `setup`, before the devices are announced.
    Setup,
    /// Each tick, when data are published.
    Tick,
    /// A request (answered on Zenoh's thread while the driver is idle).
    Request,
    /// A command.
    Command,
}

/// The dummy driver.
pub struct Dummy {
    devices: Vec<Device>,
    period: Duration,
    /// Ticks so far, modulo 256: the grey of the next camera image.
    ticks: u8,
    /// The camera's images, `[width, height]`.
    image_size: [u32; 2],
    panic_in: Option<Hook>,
}

impl Dummy {
    fn hook(&self, hook: Hook) {
        assert!(
            self.panic_in != Some(hook),
            "dummy: panicking in its {hook:?} hook, as its options asked (panic_in)"
        );
    }
}

impl Driver for Dummy {
    const NAME: &'static str = "dummy";
    type Options = Options;

    fn new(section: &Section, options: Options) -> Result<Self> {
        if !(options.rate.is_finite() && options.rate > 0.0 && options.rate <= 10_000.0) {
            return Err(NodeError::config(
                Self::NAME,
                format!(
                    "option `rate` must be in (0, 10000] Hz, got {}",
                    options.rate
                ),
            ));
        }
        let [w, h] = options.image_size;
        if w == 0 || h == 0 || u64::from(w) * u64::from(h) * 3 > MAX_IMAGE_BYTES {
            return Err(NodeError::config(
                Self::NAME,
                format!(
                    "option `image_size` [{w} {h}]: expected a width and a height of at least 1 pixel, at most {} MB of RGB",
                    MAX_IMAGE_BYTES >> 20
                ),
            ));
        }
        let devices: Vec<Device> = section.provided().into_iter().map(|s| s.device).collect();
        if devices.is_empty() {
            return Err(NodeError::config(Self::NAME, "`provides` is empty"));
        }
        if let Some(d) = devices.iter().find(|d| !INTERFACES.contains(&d.interface)) {
            let names: Vec<&str> = INTERFACES.iter().map(|i| i.name()).collect();
            return Err(NodeError::config(
                Self::NAME,
                format!("cannot provide {d}: dummy supports {}", names.join(", ")),
            ));
        }
        Ok(Dummy {
            devices,
            period: Duration::from_secs_f64(1.0 / options.rate),
            ticks: 0,
            panic_in: options.panic_in,
            image_size: options.image_size,
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.hook(Hook::Setup);
        ctx.set_tick(Some(self.period));
        Ok(())
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Tick => {
                self.hook(Hook::Tick);
                for d in &self.devices {
                    publish(ctx, d, self.ticks, self.image_size)?;
                }
                self.ticks = self.ticks.wrapping_add(1);
                Ok(())
            }
            Event::Request(r) => {
                self.hook(Hook::Request);
                r.nack("the dummy driver refuses every request");
                Ok(())
            }
            Event::Command(_) => {
                self.hook(Hook::Command);
                Ok(())
            }
            Event::Data(_) | Event::Reply(_) | Event::Wake => Ok(()),
        }
    }
}

/// Publishes `d`'s fixed data, tick `tick`, images `[width, height]`.
fn publish(ctx: &mut Ctx, d: &Device, tick: u8, [w, h]: [u32; 2]) -> Result<()> {
    match d.interface {
        Interface::Laser => ctx.publish(
            d,
            &laser::Scan {
                min_angle: -std::f32::consts::FRAC_PI_2,
                max_angle: std::f32::consts::FRAC_PI_2,
                resolution: 0.5f32.to_radians(),
                max_range: 8.0,
                ranges: vec![8.0; 361],
                intensity: vec![1; 361],
                id: 1,
            },
        ),
        Interface::Ranger => ctx.publish(
            d,
            &ranger::Ranges {
                ranges: vec![8.0; 361],
            },
        ),
        Interface::Position2d => ctx.publish(
            d,
            &position2d::Data {
                pose: Pose2d::new(1.0, 1.0, 1.0),
                vel: Pose2d::new(1.0, 1.0, 1.0),
                stall: false,
            },
        ),
        Interface::Ptz => ctx.publish(
            d,
            &ptz::Data {
                pan: 1.0,
                tilt: 1.0,
                zoom: 1.0,
                panspeed: 1.0,
                tiltspeed: 1.0,
            },
        ),
        Interface::Blobfinder => ctx.publish(
            d,
            &blobfinder::Data {
                width: 320,
                height: 240,
                blobs: (0..2)
                    .map(|b| blobfinder::Blob {
                        id: b,
                        color: b,
                        area: b,
                        x: b,
                        y: b,
                        left: b,
                        right: b,
                        top: b,
                        bottom: b,
                        range: b as f32,
                    })
                    .collect(),
            },
        ),
        Interface::Power => ctx.publish(
            d,
            &power::Data {
                valid: 0xFF,
                volts: 1.0,
                percent: 1.0,
                joules: 1.0,
                watts: 1.0,
                charging: true,
            },
        ),
        Interface::Fiducial => ctx.publish(
            d,
            &fiducial::Data {
                fiducials: (0..5)
                    .map(|i| {
                        let v = f64::from(i);
                        let p = Pose3d {
                            x: v,
                            y: v,
                            z: v,
                            roll: v,
                            pitch: v,
                            yaw: v,
                        };
                        fiducial::Item {
                            id: i,
                            pose: p,
                            upose: p,
                        }
                    })
                    .collect(),
            },
        ),
        Interface::Dio => ctx.publish(
            d,
            &dio::Data {
                count: 8,
                bits: 0xAA,
            },
        ),
        Interface::Aio => ctx.publish(
            d,
            &aio::Data {
                voltages: (0..5).map(|i| i as f32).collect(),
            },
        ),
        Interface::Camera => ctx.publish(
            d,
            &camera::Data {
                width: w,
                height: h,
                bpp: 24,
                format: camera::FORMAT_RGB888,
                fdiv: 0,
                compression: camera::COMPRESS_RAW,
                image: vec![tick; w as usize * h as usize * 3],
            },
        ),
        Interface::Wsn => ctx.publish(
            d,
            &wsn::Data {
                node_type: 132,
                node_id: 1,
                node_parent_id: 125,
                readings: wsn::Readings {
                    light: 779.0,
                    mic: 495.0,
                    accel_x: 500.0,
                    accel_y: 500.0,
                    accel_z: 500.0,
                    magn_x: 224.0,
                    magn_y: 224.0,
                    magn_z: 224.0,
                    temperature: 500.0,
                    battery: 489.0,
                },
            },
        ),
        // INVARIANT: `new` only accepts devices of INTERFACES.
        other => Err(NodeError::config(
            Dummy::NAME,
            format!("cannot publish {other}"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_node::testing::Harness;

    #[test]
    fn publishes_players_fixed_data_every_tick() {
        let mut h = Harness::<Dummy>::from_json(
            r#"{"name":"dummy","provides":["ranger:0","position2d:1"],"options":{"rate":20}}"#,
        )
        .unwrap();
        assert_eq!(h.tick_period(), Some(Duration::from_millis(50)));
        h.tick().unwrap();
        h.tick().unwrap();
        let r = h.published::<ranger::Ranges>(Device::new(6665, Interface::Ranger, 0));
        assert_eq!(r.len(), 2);
        assert_eq!(r[0].ranges, vec![8.0; 361]);
        let p = h.published::<position2d::Data>(Device::new(6665, Interface::Position2d, 1));
        assert_eq!(p[1].pose, Pose2d::new(1.0, 1.0, 1.0));
    }

    #[test]
    fn camera_images_count_the_ticks_as_players_do() {
        let mut h = Harness::<Dummy>::from_json(
            r#"{"name":"dummy","provides":["camera:0","wsn:0"],"options":{"rate":5}}"#,
        )
        .unwrap();
        for _ in 0..3 {
            h.tick().unwrap();
        }
        let images = h.published::<camera::Data>(Device::new(6665, Interface::Camera, 0));
        assert_eq!(images.len(), 3);
        assert_eq!(
            (images[0].width, images[0].height, images[0].bpp),
            (320, 240, 24)
        );
        assert_eq!(images[2].image.len(), 320 * 240 * 3);
        assert!(images[2].image.iter().all(|&b| b == 2));
        let w = h.published::<wsn::Data>(Device::new(6665, Interface::Wsn, 0));
        assert_eq!((w[0].node_type, w[0].node_parent_id), (132, 125));
        assert_eq!(w[0].readings.battery, 489.0);
    }

    #[test]
    fn refuses_requests_and_takes_commands() {
        let mut h =
            Harness::<Dummy>::from_json(r#"{"name":"dummy","provides":["position2d:0"]}"#).unwrap();
        let d = Device::new(6665, Interface::Position2d, 0);
        h.command(d, &position2d::CmdVel::default()).unwrap();
        let p = h.request(d, &position2d::GetGeom).unwrap();
        assert!(h.reply::<position2d::Geom>(p).unwrap().is_err());
    }

    #[test]
    fn bad_sections_are_refused_with_reasons() {
        let e = |j: &str| Harness::<Dummy>::from_json(j).err().unwrap().to_string();
        assert!(e(r#"{"name":"dummy","provides":["map:0"]}"#).contains("cannot provide 6665:map:0"));
        assert!(
            e(r#"{"name":"dummy","provides":["laser:0"],"options":{"rate":0}}"#).contains("rate")
        );
        assert!(e(r#"{"name":"dummy"}"#).contains("provides"));
        for size in ["[0,240]", "[100000,100000]"] {
            let j = format!(
                r#"{{"name":"dummy","provides":["camera:0"],"options":{{"image_size":{size}}}}}"#
            );
            assert!(e(&j).contains("option `image_size`"), "{size}: {}", e(&j));
        }
    }

    #[test]
    fn image_size_sets_the_camera_s_images() {
        let mut h = Harness::<Dummy>::from_json(
            r#"{"name":"dummy","provides":["camera:0"],"options":{"image_size":[640,480]}}"#,
        )
        .unwrap();
        h.tick().unwrap();
        let images = h.published::<camera::Data>(Device::new(6665, Interface::Camera, 0));
        assert_eq!((images[0].width, images[0].height), (640, 480));
        assert_eq!(images[0].image.len(), 640 * 480 * 3);
    }
}
