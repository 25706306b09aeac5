//! Stage's gripper: paddles that close on what they touch, break beams,
//! and what a gripper holds carried with it.

use super::*;

/// Where a gripper's paddles are going, as Stage's gripper keeps them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Paddles {
    /// Fully open.
    #[default]
    Open,
    /// Closed as far as they go (on what they hold, if anything).
    Closed,
    /// On their way open.
    Opening,
    /// On their way closed.
    Closing,
}

/// A gripper's state: Stage's gripper model with its default paddles (0.66
/// of the gripper's length, 0.1 of its width each).
///
/// # Behavior
///
/// Every 100 ms of simulated time (Stage's update interval) the paddles
/// move a twentieth of their travel towards the last command. Two break
/// beams cross the gap between them (3/4 and 1/4 of the paddles' length
/// from their tips) and two contact rays run along their inner faces, at
/// the gripper's height; they meet models with `gripper_return`. Closing
/// paddles that touch something take it: it moves to the gripper's centre
/// and goes with it, and the paddles close no further than its width
/// lets them. Opening lets go of it where it is.
#[derive(Debug, Clone, PartialEq)]
pub struct GripperState {
    /// The paddles.
    pub paddles: Paddles,
    /// How far closed: 0 open, 1 closed.
    pub position: f64,
    /// Where closing stops: 1, or less on a held object.
    pub(super) close_limit: f64,
    /// The last command, kept as Stage keeps it: close (`true`) or open.
    pub(super) command: Option<bool>,
    /// The model it holds, and that model's pose in the gripper's frame.
    pub held: Option<(usize, Pose)>,
    /// Break beams as Stage's Player plugin reports them: 0x04 the inner
    /// beam, 0x08 the outer one.
    pub beams: u32,
    /// Simulated seconds since the paddles last moved.
    pub(super) since: f64,
}

impl Default for GripperState {
    fn default() -> Self {
        GripperState {
            paddles: Paddles::Open,
            position: 0.0,
            close_limit: 1.0,
            command: None,
            held: None,
            beams: 0,
            since: 0.0,
        }
    }
}

/// Stage's gripper: paddles' share of the gripper's length and width,
/// where the beams cross them (from the paddles' base), and how far the
/// paddles move per update.
pub(super) const PADDLE_X: f64 = 0.66;
pub(super) const PADDLE_Y: f64 = 0.1;
pub(super) const BEAM_INSET: [f64; 2] = [0.75 * PADDLE_X, 0.25 * PADDLE_X];
pub(super) const PADDLE_STEP: f64 = 0.05;
pub(super) const GRIPPER_INTERVAL: f64 = 0.1;

impl Sim {
    /// Model `m`'s pose as Stage's `GET_POSE2D` reports it: on its parent,
    /// and, while a gripper holds it, on that gripper (Stage makes the
    /// gripper its parent, at 0 0 0).
    pub fn reported_pose(&self, m: usize) -> Pose {
        let held = self
            .grippers
            .iter()
            .flatten()
            .any(|g| g.held.is_some_and(|(k, _)| k == m));
        if held {
            Pose::default()
        } else {
            self.poses[m]
        }
    }

    /// Gives gripper `g` Stage's command: close (`true`) or open. The
    /// paddles move at its next updates.
    pub fn grip(&mut self, g: usize, close: bool) {
        if let Some(st) = &mut self.grippers[g] {
            st.command = Some(close);
        }
    }

    /// The first model with `gripper_return`, other than gripper `g`, on
    /// the ray from `(x, y)` (in `g`'s frame) along `yaw` for `len` metres,
    /// at the gripper's height.
    pub(super) fn gripper_ray(
        &self,
        g: usize,
        (x, y, yaw): (f64, f64, f64),
        len: f64,
    ) -> Option<usize> {
        if len <= 0.0 {
            return None;
        }
        let (at, z) = self.global_z(g);
        let o = at.compose(&self.world.models[g].origin).apply(x, y);
        let accept = |id: u16| {
            let k = usize::from(id) - 1;
            k != g && self.world.models[k].gripper_return && self.spans(k, z)
        };
        let d = unit(at.yaw + yaw);
        self.cast(o, d, (0.0, len), Some(z), accept, 0)
            .map(|h| usize::from(h.id) - 1)
    }

    /// One update of gripper `g`, as Stage's gripper model makes it.
    pub(super) fn update_gripper(&mut self, g: usize) {
        let Some(mut st) = self.grippers[g].clone() else {
            return;
        };
        match st.command {
            Some(true) if st.paddles != Paddles::Closed => st.paddles = Paddles::Closing,
            Some(false) if st.paddles != Paddles::Open => st.paddles = Paddles::Opening,
            _ => {}
        }
        match st.paddles {
            Paddles::Opening => {
                st.position -= PADDLE_STEP;
                if st.position < 0.0 {
                    st.position = 0.0;
                    st.paddles = Paddles::Open;
                }
                if st.position == 0.0 || st.position < st.close_limit {
                    if let Some((k, _)) = st.held.take() {
                        // Let go where it is (Stage puts it at the
                        // gripper's pose: it is there already).
                        for t in self.trees[k].clone() {
                            self.looks[t].root = self.world.root(t) as u32;
                        }
                    }
                    st.close_limit = 1.0;
                }
            }
            Paddles::Closing => {
                st.position += PADDLE_STEP;
                if st.position > st.close_limit {
                    st.position = st.close_limit;
                    st.paddles = Paddles::Closed;
                }
            }
            Paddles::Open | Paddles::Closed => {}
        }
        let [sx, sy, _] = self.world.models[g].size;
        // The paddles' inner faces, from the centre line.
        let face = (1.0 - st.position) * (sy / 2.0 - sy * PADDLE_Y);
        let gap = (1.0 - st.position) * (sy - 2.0 * sy * PADDLE_Y);
        st.beams = 0;
        for (bit, inset) in [0x04, 0x08].into_iter().zip(BEAM_INSET) {
            let x = sx * (1.0 - inset) - sx / 2.0;
            if self
                .gripper_ray(g, (x, face, -std::f64::consts::FRAC_PI_2), gap)
                .is_some()
            {
                st.beams |= bit;
            }
        }
        let base = sx * (1.0 - PADDLE_X) - sx / 2.0;
        let touched = [face, -face]
            .into_iter()
            .find_map(|y| self.gripper_ray(g, (base, y, 0.0), PADDLE_X * sx));
        if let (Some(k), Paddles::Closing, None) = (touched, st.paddles, st.held) {
            // Taken: to the gripper's centre, and along with it from now on.
            st.held = Some((k, Pose::default()));
            st.close_limit = (1.0 - self.world.models[k].size[1] / (sy - PADDLE_Y / 2.0)).max(0.0);
            self.looks[k].root = self.looks[g].root;
            if !self.movable[k] {
                for t in self.trees[k].clone() {
                    self.unplace(t);
                    self.movable[t] = true;
                    self.place(t);
                }
            }
        }
        self.grippers[g] = Some(st);
    }

    /// Updates the grippers every 100 ms of simulated time, and moves
    /// what they hold with them.
    pub(super) fn carry(&mut self, dt: f64) {
        for g in 0..self.grippers.len() {
            let Some(st) = &mut self.grippers[g] else {
                continue;
            };
            st.since += dt;
            // (Less a hair: steps of 0.1 s add up to a little less.)
            if st.since >= GRIPPER_INTERVAL - 1e-9 {
                st.since -= GRIPPER_INTERVAL;
                self.update_gripper(g);
            }
            if let Some((k, rel)) = self.grippers[g].as_ref().and_then(|s| s.held) {
                let to = self.global(g).compose(&rel);
                self.set_pose(k, to);
            }
        }
    }
}
