//! Stage's energy model and its flags, as `fasr` and its `source` and
//! `sink` zones use them (libstage's powerpack.cc and Model::UpdateCharge
//! are the reference).
//!
//! A model with `joules`/`kjoules` has a power pack; its descendants draw
//! on it. Each world update, every running model with a pack uses its
//! watts for Stage's `interval_energy` (100 ms, however long the update:
//! a world of 20 ms updates drains five times as fast, as in Stage). A
//! running model with `give_watts` passes energy to each unrelated model
//! with `take_watts` whose body touches its own, at the lesser of the two
//! rates. Flags are what Stage's models carry and zones hold: here only
//! how many.

use troupe_geom::Pose;

use super::Sim;
use crate::movers::Body;
use crate::world::{Kind, World};

/// Stage's `interval_energy`: the seconds of use each update counts.
const INTERVAL_ENERGY: f64 = 0.1;
/// What a running position model uses, and per kg per m/s (or rad/s).
const POSITION_WATTS: f64 = 1.0;
const WATTS_KGMS: f64 = 10.0;
/// What a running ranger uses per sensor.
const RANGER_WATTS_PER_SENSOR: f64 = 0.2;

/// A power pack (Stage's PowerPack).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pack {
    /// Joules stored; below 0 it never runs out.
    pub stored: f64,
    /// Joules it holds when full.
    pub capacity: f64,
}

impl Pack {
    /// The share of its capacity it holds (Stage's ProportionRemaining).
    pub fn fraction(&self) -> f64 {
        self.stored / self.capacity
    }

    /// Uses `j` joules (no more than it holds).
    fn dissipate(&mut self, j: f64) {
        if self.stored >= 0.0 {
            self.stored -= j.min(self.stored);
        }
    }
}

/// The energy and flags of a world.
#[derive(Debug, Clone, Default)]
pub struct Energy {
    /// Each model's own pack.
    packs: Vec<Option<Pack>>,
    /// Some model has a pack: there is energy to account for.
    powered: bool,
    /// The model whose pack each model draws on (itself or its nearest
    /// ancestor with one).
    pack_of: Vec<Option<usize>>,
    /// Models that give energy, and those that take it.
    givers: Vec<usize>,
    takers: Vec<usize>,
    /// How far each model's body reaches from its pose (givers and
    /// takers): two farther apart than their reaches cannot touch.
    reach: Vec<f64>,
    /// How many flags each model holds.
    pub flags: Vec<u32>,
    /// Source zones and the flags they hold at most.
    pub sources: Vec<(usize, u32)>,
    /// Sink zones.
    pub sinks: Vec<usize>,
}

impl Energy {
    /// The packs, givers and takers of `world`.
    pub fn new(world: &World) -> Energy {
        let n = world.models.len();
        let packs: Vec<Option<Pack>> = world
            .models
            .iter()
            .map(|m| {
                m.energy
                    .pack
                    .map(|(stored, capacity)| Pack { stored, capacity })
            })
            .collect();
        let mut pack_of = vec![None; n];
        // Parents come before their children.
        for m in 0..n {
            pack_of[m] = match (packs[m], world.models[m].parent) {
                (Some(_), _) => Some(m),
                (None, Some(p)) => pack_of[p],
                (None, None) => None,
            };
        }
        let with = |f: fn(&crate::world::Energy) -> f64| -> Vec<usize> {
            (0..n)
                .filter(|&m| pack_of[m].is_some() && f(&world.models[m].energy) > 0.0)
                .collect()
        };
        let reach = world
            .models
            .iter()
            .map(|m| {
                m.blocks
                    .iter()
                    .flatten()
                    .map(|p| p.0.hypot(p.1))
                    .fold(0.0, f64::max)
            })
            .collect();
        Energy {
            powered: packs.iter().any(Option::is_some),
            givers: with(|e| e.give),
            takers: with(|e| e.take),
            reach,
            packs,
            pack_of,
            flags: vec![0; n],
            sources: Vec::new(),
            sinks: Vec::new(),
        }
    }

    /// The pack model `m` draws on.
    pub fn pack(&self, m: usize) -> Option<&Pack> {
        self.pack_of[m].and_then(|p| self.packs[p].as_ref())
    }

    /// Moves a flag from model `from` to model `to`, if `from` has one.
    pub fn pass_flag(&mut self, from: usize, to: usize) {
        if self.flags[from] > 0 {
            self.flags[from] -= 1;
            self.flags[to] += 1;
        }
    }
}

impl Sim {
    /// Once the robots have done their part of a step: sources refill,
    /// packs are used and charged.
    pub(super) fn update_energy(&mut self) {
        for k in 0..self.energy.sources.len() {
            let (zone, capacity) = self.energy.sources[k];
            if self.due(zone) && self.energy.flags[zone] < capacity {
                self.energy.flags[zone] += 1;
            }
        }
        if self.energy.powered {
            let running = self.running();
            self.use_energy(&running);
            self.charge(&running);
        }
    }

    /// Which models run (Stage's subscribed or `alwayson`): a base driven
    /// by a controller or a client, a ranger that is sensed, what a
    /// controller reads, a model with a controller.
    fn running(&self) -> Vec<bool> {
        let mut on: Vec<bool> = (0..self.world.models.len())
            .map(|m| {
                let def = &self.world.models[m];
                def.energy.always_on || self.used[m] || (def.kind == Kind::Ranger && self.sensed[m])
            })
            .collect();
        for b in &self.bases {
            on[b.model] |= b.ctrl.is_some() || b.cmd.is_some();
        }
        on
    }

    /// Every running model with a pack uses its watts for an update.
    fn use_energy(&mut self, running: &[bool]) {
        let mut speed = vec![0.0; self.world.models.len()];
        for b in &self.bases {
            speed[b.model] = b.vel.x.abs() + b.vel.y.abs() + b.vel.yaw.abs();
        }
        for m in 0..self.world.models.len() {
            let Some(p) = self.energy.pack_of[m].filter(|_| running[m]) else {
                continue;
            };
            let def = &self.world.models[m];
            let watts = match def.kind {
                Kind::Position => POSITION_WATTS + speed[m] * WATTS_KGMS * def.energy.mass,
                Kind::Ranger => RANGER_WATTS_PER_SENSOR * def.sensors.len() as f64,
                _ => def.energy.watts,
            };
            if let Some(pack) = &mut self.energy.packs[p] {
                pack.dissipate(watts * INTERVAL_ENERGY);
            }
        }
    }

    /// Every running giver passes energy to the takers that touch it.
    fn charge(&mut self, running: &[bool]) {
        let (mut mine, mut his) = (Body::default(), Body::default());
        let takers: Vec<(usize, Pose)> = self
            .energy
            .takers
            .iter()
            .map(|&t| (t, self.global(t)))
            .collect();
        for gi in 0..self.energy.givers.len() {
            let g = self.energy.givers[gi];
            if !running[g] {
                continue;
            }
            let at = self.global(g);
            let mut placed = false;
            for &(t, there) in &takers {
                let reach = self.energy.reach[g] + self.energy.reach[t];
                if self.root(t) == self.root(g) || (at.x - there.x).hypot(at.y - there.y) > reach {
                    continue;
                }
                if !placed {
                    mine.place(&self.world.models[g].blocks, at);
                    placed = true;
                }
                his.place(&self.world.models[t].blocks, there);
                if !mine.overlaps(&his) {
                    continue;
                }
                let rate = self.world.models[g]
                    .energy
                    .give
                    .min(self.world.models[t].energy.take);
                let (Some(from), Some(to)) = (self.energy.pack_of[g], self.energy.pack_of[t])
                else {
                    continue;
                };
                self.transfer(from, to, rate * INTERVAL_ENERGY);
            }
        }
    }

    /// Stage's TransferTo: no more than the giver holds (unless its store
    /// never runs out) nor than the taker has room for.
    fn transfer(&mut self, from: usize, to: usize, amount: f64) {
        let (Some(f), Some(t)) = (self.energy.packs[from], self.energy.packs[to]) else {
            return;
        };
        let mut amount = amount.min(t.capacity - t.stored);
        if f.stored >= 0.0 {
            amount = amount.min(f.stored);
        }
        if amount <= 0.0 {
            return;
        }
        if let Some(f) = &mut self.energy.packs[from] {
            f.dissipate(amount);
        }
        if let Some(t) = &mut self.energy.packs[to] {
            t.stored += amount;
        }
    }

    /// The pack model `m` draws on, if any.
    pub fn pack(&self, m: usize) -> Option<&Pack> {
        self.energy.pack(m)
    }

    /// How many flags model `m` holds.
    pub fn flags(&self, m: usize) -> u32 {
        self.energy.flags[m]
    }

    /// The flags each source and sink holds, as `source 1, sink 17`
    /// (`None` in a world without them).
    pub fn flags_held(&self) -> Option<String> {
        let e = &self.energy;
        let zones: Vec<String> = e
            .sources
            .iter()
            .map(|&(z, _)| z)
            .chain(e.sinks.iter().copied())
            .map(|z| format!("`{}` {}", self.world.models[z].name, e.flags[z]))
            .collect();
        (!zones.is_empty()).then(|| zones.join(", "))
    }
}
