//! `deard`: the DEAR service. Reads frames from a capture back end, aligns and refines the depth
//! with `dear-pipeline`, and publishes it to any number of clients through iceoryx2 shared
//! memory.
//!
//! Data flows one way: [`capture`] → [`queue`] → [`processing`] → [`publish`]. [`config`] is
//! the TOML configuration, [`stats`] the live statistics, [`run`] the daemon's life cycle,
//! [`shared_memory`] what a stream needs of it.

pub mod calibration_state;
pub mod capture;
pub mod config;
pub mod iceoryx_log;
pub mod processing;
pub mod publish;
pub mod queue;
pub mod record;
pub mod run;
pub mod shared_memory;
pub mod stats;
pub mod transport_guard;
