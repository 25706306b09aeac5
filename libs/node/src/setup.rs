//! What a Player client asks a device once, when it subscribes: tools that
//! join a running stack (the recorder, the Foxglove server) ask the same of
//! each device as it comes.

use std::time::Duration;

use troupe_msgs::{codec, keys, Device};
use zenoh::Session;

/// The answers (payloads as they travelled) of the requests a Player client
/// makes once of a device of `dev`'s interface: a map's info and whole grid,
/// a sensor's geometry (and a ranger's configuration), a simulator's world
/// (a Troupe extension, for viewers); the latest sample of
/// a device that publishes on change. A device that does not answer is left
/// as it is.
pub fn setup_answers(session: &Session, dev: &Device) -> Vec<Vec<u8>> {
    use troupe_msgs::{ir, laser, map, ranger, simulation, sonar, Interface, Request};
    use zenoh::Wait;
    fn ask<R: Request>(session: &Session, dev: &Device, req: &R) -> Option<Vec<u8>> {
        let key = keys::req(dev, R::NAME);
        let replies = crate::ask(session, &key, Duration::from_secs(2))
            .payload(codec::encode(req, 0.0))
            .wait()
            .ok()?;
        let reply = replies.recv().ok()?.into_result().ok()?;
        Some(reply.payload().to_bytes().into_owned())
    }
    let answers = match dev.interface {
        Interface::Map => {
            let Some(info) = ask(session, dev, &map::GetInfo) else {
                return vec![];
            };
            let data = codec::decode::<map::Info>(&info).ok().and_then(|i| {
                let whole = map::GetData {
                    col: 0,
                    row: 0,
                    width: i.msg.width,
                    height: i.msg.height,
                };
                ask(session, dev, &whole)
            });
            vec![Some(info), data]
        }
        Interface::Laser => vec![ask(session, dev, &laser::GetGeom)],
        Interface::Ranger => vec![
            ask(session, dev, &ranger::GetGeom),
            ask(session, dev, &ranger::GetConfig),
        ],
        Interface::Sonar => vec![ask(session, dev, &sonar::GetGeom)],
        Interface::Ir => vec![ask(session, dev, &ir::GetGeom)],
        // What a viewer draws: every model's body, colour and place.
        Interface::Simulation => vec![ask(session, dev, &simulation::GetWorld)],
        // Devices that publish on change: their latest sample, as the
        // bridge gives a client that subscribes (a localizer's estimate
        // while the robot stands still).
        Interface::Localize | Interface::Planner => {
            let latest = session
                .get(keys::data(dev))
                .timeout(Duration::from_secs(1))
                .wait();
            return latest.map_or_else(
                |_| vec![],
                |replies| {
                    replies
                        .iter()
                        .filter_map(|r| r.into_result().ok())
                        .map(|s| s.payload().to_bytes().into_owned())
                        .collect()
                },
            );
        }
        _ => vec![],
    };
    answers.into_iter().flatten().collect()
}
