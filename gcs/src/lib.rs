//! The ground control station's library: the mission runtime and what it needs around it
//! (clocks, the simulated fleet, recording, outputs, evaluation). The `gcs` binary is its CLI;
//! the GUI and the tests drive the same runtime.

pub mod clock;
pub mod evaluate;
pub mod fleet;
pub mod fleet_file;
pub mod gui;
pub mod mission_log;
pub mod outputs;
pub mod record;
pub mod runtime;
