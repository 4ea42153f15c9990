//! Helpers for the integration tests: real third-party peers (pymavlink in a virtual
//! environment), free loopback ports, pseudo-terminal pairs, and a fault-injecting proxy.

pub mod faults;

use std::io::Read;
use std::net::{TcpListener, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// The repository root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The Python interpreter of the test environment, with pymavlink installed (made on first use by
/// `tests/python/setup.sh`, under a file lock so parallel test binaries do it once).
pub fn python() -> PathBuf {
    static READY: OnceLock<PathBuf> = OnceLock::new();
    READY
        .get_or_init(|| {
            let venv = std::env::var_os("GCS_PYENV")
                .map_or_else(|| root().join("target/pyenv"), PathBuf::from);
            std::fs::create_dir_all(root().join("target")).expect("create target/");
            let lock = std::fs::File::create(root().join("target/pyenv.lock"))
                .expect("create the pyenv lock file");
            lock.lock().expect("lock target/pyenv.lock");
            let status = Command::new("bash")
                .arg(root().join("tests/python/setup.sh"))
                .env("GCS_PYENV", &venv)
                .status()
                .expect("run tests/python/setup.sh");
            assert!(
                status.success(),
                "tests/python/setup.sh failed: pymavlink could not be installed from PyPI"
            );
            venv.join("bin/python")
        })
        .clone()
}

/// A free loopback UDP port (bound and released; a race with other programs is possible but rare).
pub fn free_udp_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("bind a UDP port")
        .port()
}

/// A free loopback TCP port.
pub fn free_tcp_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("bind a TCP port")
        .port()
}

/// A pymavlink vehicle process (`tests/python/vehicle.py`).
pub struct PyVehicle {
    child: Child,
}

impl PyVehicle {
    /// Starts the vehicle; `connect` is a pymavlink address, `extra` more flags.
    pub fn spawn(connect: &str, extra: &[&str]) -> Self {
        let child = Command::new(python())
            .arg(root().join("tests/python/vehicle.py"))
            .args(["--connect", connect])
            .args(extra)
            .stdout(Stdio::piped())
            .spawn()
            .expect("start tests/python/vehicle.py");
        Self { child }
    }

    /// Waits (at most `limit`) for the vehicle to exit and returns its JSON report.
    pub fn report(mut self, limit: Duration) -> serde_json::Value {
        let until = Instant::now() + limit;
        loop {
            if let Some(status) = self.child.try_wait().expect("wait for the vehicle") {
                assert!(status.success(), "vehicle.py failed: {status}");
                break;
            }
            assert!(
                Instant::now() < until,
                "vehicle.py did not finish within {limit:?}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        let mut out = String::new();
        if let Some(mut s) = self.child.stdout.take() {
            s.read_to_string(&mut out)
                .expect("read the vehicle's report");
        }
        serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("vehicle report {out:?}: {e}"))
    }

    /// Kills the vehicle (a crash, as far as the station can tell).
    pub fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for PyVehicle {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Polls `ok` every 20 ms until it holds or `limit` passes; returns whether it held.
pub fn eventually(limit: Duration, mut ok: impl FnMut() -> bool) -> bool {
    let until = Instant::now() + limit;
    loop {
        if ok() {
            return true;
        }
        if Instant::now() >= until {
            return false;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A pseudo-terminal pair: the returned path is the "device" a link opens; the connection is the
/// other end, for an emulator. Keep the returned port alive for as long as the pair is used.
pub fn pty_pair() -> (String, link::Connection, serialport::TTYPort) {
    let (mut master, slave) = serialport::TTYPort::pair().expect("open a pseudo-terminal pair");
    serialport::SerialPort::set_timeout(&mut master, link::transport::READ_POLL)
        .expect("set pty timeout");
    let path = serialport::SerialPort::name(&slave).expect("pseudo-terminal has a name");
    let reader = master.try_clone_native().expect("clone the pty master");
    let conn = link::Connection::from_parts(Box::new(reader), Box::new(master), path.clone());
    (path, conn, slave)
}
