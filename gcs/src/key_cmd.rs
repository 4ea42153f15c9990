//! `gcs key`: MAVLink 2 signing keys — make them, list them, give one to a vehicle with
//! `SETUP_SIGNING` and check that the vehicle then signs with it, or turn signing off.

use std::time::Duration;

use anyhow::{Context, bail};
use clap::Subcommand;
use link::mavlink::keys::{disable_signing, setup_signing};
use link::mavlink::{KeyStore, MavlinkConfig, MavlinkLink, SigningKey};
use link::{Address, LinkState, VehicleLink};

/// What to do with keys.
#[derive(Subcommand)]
pub enum KeyCommand {
    /// Make a new random key in the key store (owner-only: the directory 700, the file 600).
    New {
        /// The key's name (letters, digits, '-', '_').
        name: String,
    },
    /// List the keys in the key store.
    List,
    /// Give a key to a vehicle (SETUP_SIGNING), then check that it signs with it. Do this over a
    /// link you trust (USB, a cable): an unsigned vehicle takes a key from anyone.
    Setup {
        /// The key: a name in the key store or a key file's path.
        key: String,
        /// The vehicle's link: serial:PATH:BAUD, tcpout:HOST:PORT, udpin:ADDR:PORT, …
        #[arg(long)]
        address: String,
        /// The vehicle's system id (default: the first vehicle heard).
        #[arg(long)]
        sysid: Option<u8>,
        /// The key the vehicle signs with now, if any (only its holder may change it).
        #[arg(long, value_name = "KEY")]
        current: Option<String>,
    },
    /// Turn signing off on a vehicle (SETUP_SIGNING with an all-zero key, signed with its key).
    Off {
        /// The key the vehicle signs with now.
        #[arg(long, value_name = "KEY")]
        current: String,
        /// The vehicle's link.
        #[arg(long)]
        address: String,
        /// The vehicle's system id (default: the first vehicle heard).
        #[arg(long)]
        sysid: Option<u8>,
    },
}

/// How long to wait for a vehicle's heartbeat.
const WAIT: Duration = Duration::from_secs(10);

/// Runs a `gcs key` command.
pub fn run(command: &KeyCommand) -> anyhow::Result<()> {
    let store = KeyStore::user()?;
    match command {
        KeyCommand::New { name } => {
            let path = store.create(name)?;
            println!("made signing key {name:?}: {}", path.display());
            println!("give it to a vehicle with: gcs key setup {name} --address ADDRESS");
        }
        KeyCommand::List => {
            let names = store.list()?;
            if names.is_empty() {
                println!(
                    "no keys in {} (make one with: gcs key new NAME)",
                    store.dir().display()
                );
            }
            for name in names {
                println!("{name}\t{}", store.path(&name)?.display());
            }
        }
        KeyCommand::Setup {
            key,
            address,
            sysid,
            current,
        } => {
            let new = store.load(key)?;
            let current = current.as_deref().map(|k| store.load(k)).transpose()?;
            let (link, id) = open(address, current, *sysid)?;
            link.send(setup_signing(&new, id));
            // Let the message go out before the link closes.
            std::thread::sleep(Duration::from_millis(500));
            drop(link);
            let (link, _) = open(address, Some(new), Some(id)).with_context(|| {
                format!(
                    "vehicle {id} did not answer signed with key {key:?}: it may not support \
                     signing, or it signs with another key already (give it with --current)"
                )
            })?;
            if link.rejected_signatures() > 0 {
                tracing::warn!(
                    "{} frames with other signatures were refused after the change",
                    link.rejected_signatures()
                );
            }
            println!(
                "vehicle {id} at {address} now signs with key {key:?}; it refuses unsigned and \
                 wrongly signed commands"
            );
        }
        KeyCommand::Off {
            current,
            address,
            sysid,
        } => {
            let current = store.load(current)?;
            let (link, id) = open(address, Some(current), *sysid)?;
            link.send(disable_signing(id));
            std::thread::sleep(Duration::from_millis(500));
            drop(link);
            open(address, None, Some(id)).with_context(|| {
                format!("vehicle {id} did not answer unsigned: signing may still be on")
            })?;
            println!(
                "vehicle {id} at {address} no longer signs: anyone on its link may command it"
            );
        }
    }
    Ok(())
}

/// Opens a link to one vehicle, signed with `key` (and refusing anything else) if given, waits
/// for its heartbeat and returns the link and the vehicle's system id. (The link closes when it
/// is dropped: no vehicle handle outlives this function.)
fn open(
    address: &str,
    key: Option<SigningKey>,
    sysid: Option<u8>,
) -> anyhow::Result<(MavlinkLink, u8)> {
    let parsed: Address = address.parse()?;
    let link = MavlinkLink::connect(
        &parsed,
        MavlinkConfig {
            signing: key,
            ..MavlinkConfig::default()
        },
    )?;
    let vehicle = match sysid {
        Some(id) => link.vehicle(id),
        None => link
            .wait_for_vehicle(WAIT)
            .with_context(|| format!("no vehicle heard at {address} within {WAIT:?}"))?,
    };
    let until = std::time::Instant::now() + WAIT;
    while vehicle.status().state != LinkState::Connected {
        if std::time::Instant::now() > until {
            bail!(
                "vehicle {} at {address}: no heartbeat within {WAIT:?} ({} frames refused for \
                 their signature)",
                vehicle.system_id(),
                link.rejected_signatures()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let id = vehicle.system_id();
    Ok((link, id))
}
