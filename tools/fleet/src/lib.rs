//! Fleets: what it takes to run a plan on many hosts or in containers.
//!
//! - [`docker`]: `troupe image` (the one `FROM scratch` image) and
//!   `troupe compose` (a compose file running a plan, one container per host);
//! - [`orchestrate`]: `troupe compose --swarm` and `--k8s` (the same
//!   services as a Docker Swarm stack or Kubernetes manifests, a router
//!   beside each host);
//! - [`keys`]: `troupe fleet-keys` (one authority, a certificate and a Zenoh
//!   config per member, and the access rules the router enforces).
//!
//! Depends on the launcher for plans; nothing depends on it but the binary
//! and the benchmarks.

pub mod docker;
pub mod keys;
pub mod orchestrate;
