//! A map device's whole grid, fetched as every driver that plans or
//! localizes on a map fetches it at setup: `info`, then one tile of every
//! cell.

use troupe_msgs::{map, Device};

use crate::{Ctx, NodeError, Reply, RequestId, Result};

/// A fetch under way.
#[derive(Debug)]
pub struct MapFetch {
    device: Device,
    asked: Asked,
}

#[derive(Debug, Clone, Copy)]
enum Asked {
    Info(RequestId),
    Cells(RequestId, map::Info),
    Done,
}

impl MapFetch {
    /// Asks `device` for its info.
    ///
    /// # Errors
    ///
    /// The request could not be sent.
    pub fn start(ctx: &mut Ctx, device: Device) -> Result<Self> {
        let id = ctx.request(&device, &map::GetInfo)?;
        Ok(MapFetch {
            device,
            asked: Asked::Info(id),
        })
    }

    /// The map device.
    pub fn device(&self) -> Device {
        self.device
    }

    /// Takes a reply: the info and every cell once both are in, `None` for
    /// the info (the cells are asked then) or a reply to anything else.
    ///
    /// # Errors
    ///
    /// The map refused or answered something else: a configuration error
    /// of `driver`, naming the map.
    pub fn on_reply(
        &mut self,
        ctx: &mut Ctx,
        r: &Reply,
        driver: &str,
    ) -> Result<Option<(map::Info, map::Data)>> {
        let fail = |what: &str, e: NodeError| {
            NodeError::config(driver, format!("map {} gave no {what}: {e}", self.device))
        };
        match self.asked {
            Asked::Info(id) if id == r.id => {
                let info = r.decode::<map::Info>().map_err(|e| fail("info", e))?;
                let q = map::GetData {
                    col: 0,
                    row: 0,
                    width: info.width,
                    height: info.height,
                };
                self.asked = Asked::Cells(ctx.request(&self.device, &q)?, info);
                Ok(None)
            }
            Asked::Cells(id, info) if id == r.id => {
                let cells = r.decode::<map::Data>().map_err(|e| fail("data", e))?;
                self.asked = Asked::Done;
                Ok(Some((info, cells)))
            }
            _ => Ok(None),
        }
    }
}
