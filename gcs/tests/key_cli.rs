//! `gcs key` against a simulated ArduCopter over TCP: a key is made, given to the vehicle with
//! SETUP_SIGNING, and then only its holder commands the vehicle.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;
use std::time::Duration;

use link::mavlink::{KeyStore, MavlinkConfig, MavlinkLink, SigningKey};
use link::{Command as VehicleCommand, VehicleLink};
use sitl::{SimConfig, Sitl, SitlConfig, World};

fn gcs_key(keys: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gcs"))
        .arg("key")
        .args(args)
        .env("GCS_KEY_DIR", keys)
        .output()
        .expect("run gcs")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A scratch directory, removed when dropped.
struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn temp_keys() -> (Scratch, PathBuf) {
    let dir = std::env::temp_dir().join(format!("gcs-key-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let keys = dir.join("keys");
    (Scratch(dir), keys)
}

fn link(address: &str, signing: Option<SigningKey>) -> MavlinkLink {
    MavlinkLink::connect(
        &address.parse().expect("address"),
        MavlinkConfig {
            signing,
            command_timeout: Duration::from_millis(400),
            ..MavlinkConfig::default()
        },
    )
    .expect("connect")
}

fn armed(sitl: &Sitl) -> bool {
    sitl.with_sim(|s| s.vehicle(0).state().armed)
}

#[test]
fn a_key_given_with_setup_signing_lets_only_its_holder_command_the_vehicle() {
    let (_scratch, keys) = temp_keys();
    let made = gcs_key(&keys, &["new", "alpha"]);
    assert!(made.status.success(), "{}", text(&made));
    assert!(text(&made).contains("alpha.key"), "{}", text(&made));
    let again = gcs_key(&keys, &["new", "alpha"]);
    assert!(!again.status.success() && text(&again).contains("never overwritten"));
    assert!(gcs_key(&keys, &["new", "intruder"]).status.success());
    let list = gcs_key(&keys, &["list"]);
    assert!(text(&list).contains("alpha") && text(&list).contains("intruder"));
    let store = KeyStore::at(&keys);
    let (alpha, intruder) = (
        store.load("alpha").unwrap(),
        store.load("intruder").unwrap(),
    );

    let sitl = Sitl::start(SitlConfig {
        world: Arc::new(World::load("apartment").expect("built-in world")),
        sim: SimConfig::default(),
        vehicles: vec!["mavlink@tcpin:127.0.0.1:0".parse().expect("endpoint")],
        camera: None,
        speed: 1.0,
        signing_key: None,
    })
    .expect("the simulator starts");
    let port = sitl.endpoint_addrs()[0].expect("a TCP port").port();
    let address = format!("tcpout:127.0.0.1:{port}");

    let setup = gcs_key(&keys, &["setup", "alpha", "--address", &address]);
    assert!(setup.status.success(), "{}", text(&setup));
    assert!(
        text(&setup).contains("now signs with key"),
        "{}",
        text(&setup)
    );

    // A station without a key hears the vehicle but is not obeyed.
    {
        let l = link(&address, None);
        let v = l.wait_for_vehicle(Duration::from_secs(5)).expect("heard");
        assert!(v.command(VehicleCommand::Arm).is_err());
        assert!(!armed(&sitl));
    }
    // A station with another key neither hears it nor is obeyed, and cannot replace its key.
    {
        let l = link(&address, Some(intruder));
        assert!(l.wait_for_vehicle(Duration::from_secs(3)).is_none());
        assert!(l.rejected_signatures() > 0);
        assert!(l.vehicle(1).command(VehicleCommand::Arm).is_err());
    }
    let hijack = gcs_key(&keys, &["setup", "intruder", "--address", &address]);
    assert!(!hijack.status.success(), "{}", text(&hijack));
    assert!(
        text(&hijack).contains("did not answer signed"),
        "{}",
        text(&hijack)
    );
    // The key holder is obeyed.
    {
        let l = link(&address, Some(alpha));
        let v = l.wait_for_vehicle(Duration::from_secs(5)).expect("heard");
        v.command(VehicleCommand::Arm).expect("the key holder arms");
        assert!(armed(&sitl));
        v.command(VehicleCommand::Disarm).expect("and disarms");
    }

    // A key file others may read is refused before anything is sent.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let file = keys.join("alpha.key");
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o644)).unwrap();
        let loose = gcs_key(&keys, &["off", "--current", "alpha", "--address", &address]);
        assert!(
            !loose.status.success() && text(&loose).contains("chmod 600"),
            "{}",
            text(&loose)
        );
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o600)).unwrap();
    }
    // The key holder turns signing off; anyone is obeyed again.
    let off = gcs_key(&keys, &["off", "--current", "alpha", "--address", &address]);
    assert!(off.status.success(), "{}", text(&off));
    let l = link(&address, None);
    let v = l.wait_for_vehicle(Duration::from_secs(5)).expect("heard");
    v.command(VehicleCommand::Arm)
        .expect("unsigned arm after signing is off");
    assert!(armed(&sitl));
}
