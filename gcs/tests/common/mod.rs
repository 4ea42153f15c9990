//! Shared by the CLI tests: run the `gcs` binary built for this test run.

use std::process::{Command, Output};

/// Runs `gcs` with `args` and returns what it did.
pub fn gcs(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gcs"))
        .args(args)
        .output()
        .expect("run gcs")
}
