//! `localize`: pose hypotheses from a localizer such as amcl.

use serde::{Deserialize, Serialize};

use crate::iface::common::Ack;
use crate::{message, Pose2d};

/// One pose hypothesis.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Hypoth {
    /// Mean pose, world frame.
    pub mean: Pose2d,
    /// Covariance in Player's order: xx, yy, yaw-yaw, xy, y-yaw, x-yaw
    /// (m², rad², m·rad), as Player's `cov[6]`.
    pub cov: [f64; 6],
    /// Weight of the hypothesis (Player's `alpha`), 0..=1.
    pub weight: f64,
}

/// The current hypotheses (`PLAYER_LOCALIZE_DATA_HYPOTHS`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Hypoths {
    /// Observations not yet processed.
    pub pending_count: u32,
    /// Time of the oldest pending observation, seconds.
    pub pending_time: f64,
    /// Hypotheses, best first.
    pub hypoths: Vec<Hypoth>,
}
message!(Hypoths, "localize/hypoths@2");

/// Resets the filter around a pose.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SetPose {
    /// Mean pose.
    pub mean: Pose2d,
    /// Covariance in Player's order: xx, yy, yaw-yaw, xy, y-yaw, x-yaw.
    pub cov: [f64; 6],
}
message!(SetPose, "localize/set_pose@2", req "set_pose" -> Ack);

/// One particle.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Particle {
    /// Pose, world frame.
    pub pose: Pose2d,
    /// Weight.
    pub weight: f64,
}

/// The particle set (`PLAYER_LOCALIZE_REQ_GET_PARTICLES`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Particles {
    /// Mean of the set.
    pub mean: Pose2d,
    /// Variance of the set.
    pub variance: f64,
    /// The particles.
    pub particles: Vec<Particle>,
}
message!(Particles, "localize/particles@1");

/// Asks for the [`Particles`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetParticles;
message!(GetParticles, "localize/get_particles@1", req "particles" -> Particles);
