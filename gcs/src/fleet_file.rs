//! The fleet file of `gcs fly --config`: which vehicles, how each is reached, where its camera
//! streams from. Every error names the vehicle and the field.
//!
//! ```toml
//! [[vehicle]]
//! name = "alpha"                       # optional; "drone K" otherwise
//! protocol = "mavlink"                 # or "shield"
//! address = "tcpout:127.0.0.1:5760"    # as everywhere: serial:, tcpout:, tcpin:, udpin:, udpout:
//! camera = "tcpout:127.0.0.1:5900"     # the TCP frame stream carrying its camera
//! camera_id = 0                        # its vehicle id in that stream (default: its order there)
//! start = [1.0, 7.5, 0.0]              # x, y (metres), yaw (radians) in the map, if known
//! altitude = 0.9                       # its altitude band, metres, 0.25–2.0 (default 0.6 + 0.15·K)
//! channels = "ardupilot"               # or "thesis" (the thesis's reversed Naza wiring)
//! signing_key = "alpha"                # MAVLink only: sign with this key (`gcs key list`) and
//!                                      # refuse anything not signed with it
//! ```

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, bail};
use link::{Address, ChannelMap};
use serde::Deserialize;

use crate::fleet::{LOWEST_BAND_M, LinkKind, altitude_band, band_limits};

/// The fleet file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FleetFile {
    #[serde(default)]
    vehicle: Vec<VehicleEntry>,
}

/// One `[[vehicle]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct VehicleEntry {
    name: Option<String>,
    protocol: String,
    address: String,
    camera: String,
    camera_id: Option<u8>,
    start: Option<[f64; 3]>,
    altitude: Option<f64>,
    channels: Option<String>,
    signing_key: Option<String>,
}

/// A vehicle of the fleet, checked.
#[derive(Debug, Clone)]
pub struct Vehicle {
    /// Its name for the operator.
    pub name: String,
    /// The protocol its link speaks.
    pub kind: LinkKind,
    /// Where its link is reached.
    pub address: String,
    /// The TCP frame stream carrying its camera.
    pub camera: Address,
    /// Its vehicle id in that stream.
    pub camera_id: u8,
    /// Its start in the map (x, y, yaw), if known.
    pub start: Option<[f64; 3]>,
    /// Its altitude band, metres.
    pub altitude: f64,
    /// Its RC wiring, if not the protocol's default.
    pub channels: Option<ChannelMap>,
    /// The MAVLink signing key it uses: a name in the key store or a key file's path.
    pub signing_key: Option<String>,
}

/// Reads and checks a fleet file; every error names the vehicle and the field.
pub fn load(path: &Path) -> anyhow::Result<Vec<Vehicle>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the fleet file {}", path.display()))?;
    parse(&text, &path.display().to_string())
}

/// Parses and checks a fleet file's text; `origin` names it in errors.
pub fn parse(text: &str, origin: &str) -> anyhow::Result<Vec<Vehicle>> {
    let file: FleetFile =
        toml::from_str(text).with_context(|| format!("{origin} is not a fleet file"))?;
    if file.vehicle.is_empty() || file.vehicle.len() > 8 {
        bail!(
            "{}: {} [[vehicle]] tables; a fleet has 1 to 8",
            origin,
            file.vehicle.len()
        );
    }
    let mut per_camera: BTreeMap<String, u8> = BTreeMap::new();
    file.vehicle
        .into_iter()
        .enumerate()
        .map(|(k, v)| {
            let which = format!("{origin}: vehicle {}", k + 1);
            let kind = match v.protocol.as_str() {
                "mavlink" => LinkKind::Mavlink,
                "shield" => LinkKind::Shield,
                other => bail!("{which}: protocol {other:?} must be \"mavlink\" or \"shield\""),
            };
            v.address
                .parse::<Address>()
                .with_context(|| format!("{which}: address"))?;
            let camera: Address = v
                .camera
                .parse()
                .with_context(|| format!("{which}: camera"))?;
            let order = per_camera.entry(v.camera.clone()).or_insert(0);
            let camera_id = v.camera_id.unwrap_or(*order);
            *order += 1;
            if let Some(s) = v.start
                && !s.iter().all(|x| x.is_finite())
            {
                bail!("{which}: start {s:?} must be finite x, y, yaw");
            }
            let altitude = v.altitude.unwrap_or_else(|| altitude_band(LOWEST_BAND_M, k));
            let (low, high) = band_limits();
            if !(altitude.is_finite() && (low..=high).contains(&altitude)) {
                bail!(
                    "{which}: altitude {altitude} must be {low:.2} to {high:.1} metres, the \
                     heights the map's walls are taken from"
                );
            }
            let channels = match v.channels.as_deref() {
                None => None,
                Some("ardupilot") => Some(ChannelMap::ardupilot()),
                Some("thesis") => Some(ChannelMap::thesis_naza()),
                Some(other) => {
                    bail!("{which}: channels {other:?} must be \"ardupilot\" or \"thesis\"")
                }
            };
            if v.signing_key.is_some() && kind != LinkKind::Mavlink {
                bail!("{which}: signing_key: only MAVLink links are signed (the shield protocol has no signatures)");
            }
            Ok(Vehicle {
                name: v.name.unwrap_or_else(|| format!("drone {}", k + 1)),
                kind,
                address: v.address,
                camera,
                camera_id,
                start: v.start,
                altitude,
                channels,
                signing_key: v.signing_key,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO: &str = r#"
[[vehicle]]
protocol = "mavlink"
address = "tcpout:127.0.0.1:5760"
camera = "tcpout:127.0.0.1:5900"
start = [1.0, 7.5, 0.0]
signing_key = "alpha"

[[vehicle]]
name = "beta"
protocol = "shield"
address = "serial:/dev/ttyUSB0:115200"
camera = "tcpout:127.0.0.1:5900"
channels = "thesis"
"#;

    #[test]
    fn a_fleet_file_reads_with_its_defaults() {
        let fleet = parse(TWO, "fleet.toml").expect("valid");
        assert_eq!(fleet.len(), 2);
        assert_eq!(fleet[0].name, "drone 1");
        assert_eq!(fleet[0].kind, LinkKind::Mavlink);
        assert_eq!((fleet[0].camera_id, fleet[1].camera_id), (0, 1));
        assert_eq!(fleet[1].name, "beta");
        assert_eq!(fleet[1].kind, LinkKind::Shield);
        assert!(fleet[1].channels.is_some() && fleet[0].channels.is_none());
        assert!(fleet[1].altitude > fleet[0].altitude);
        assert_eq!(fleet[0].signing_key.as_deref(), Some("alpha"));
        assert_eq!(fleet[1].signing_key, None);
    }

    #[test]
    fn errors_name_the_file_the_vehicle_and_the_field() {
        let err = |text: &str| format!("{:#}", parse(text, "f.toml").expect_err("refused"));
        let e = err(&TWO.replace("\"shield\"", "\"smoke\""));
        assert!(e.contains("f.toml: vehicle 2: protocol \"smoke\""), "{e}");
        let e = err(&TWO.replace("start = [1.0, 7.5, 0.0]", "altitude = 9.0"));
        assert!(e.contains("vehicle 1: altitude 9"), "{e}");
        let e = err(&TWO.replace("tcpout:127.0.0.1:5760", "carrier-pigeon"));
        assert!(e.contains("vehicle 1: address"), "{e}");
        let e = err(&TWO.replace("channels = \"thesis\"", "signing_key = \"alpha\""));
        assert!(e.contains("vehicle 2: signing_key: only MAVLink"), "{e}");
        let e = err("[[vehicle]]\nprotocol = 3\n");
        assert!(e.contains("f.toml is not a fleet file"), "{e}");
        let e = err("");
        assert!(e.contains("0 [[vehicle]] tables"), "{e}");
    }

    #[test]
    fn every_altitude_lies_where_the_map_takes_walls() {
        let (low, high) = band_limits();
        let with = |altitude: f64| {
            TWO.replace("start = [1.0, 7.5, 0.0]", &format!("altitude = {altitude}"))
        };
        for ok in [low, 1.2, high] {
            assert_eq!(parse(&with(ok), "f.toml").expect("valid")[0].altitude, ok);
        }
        // TOML spells not-a-number `nan`.
        let nan = TWO.replace("start = [1.0, 7.5, 0.0]", "altitude = nan");
        for bad in [with(low - 0.05), with(high + 0.2), nan] {
            let e = format!("{:#}", parse(&bad, "f.toml").expect_err("refused"));
            assert!(
                e.contains("vehicle 1: altitude") && e.contains("must be 0.25 to 2.0 metres"),
                "{e}"
            );
        }
        // Eight vehicles, the most a fleet has, on their default bands.
        let one = "[[vehicle]]\nprotocol = \"mavlink\"\naddress = \"tcpout:127.0.0.1:5760\"\ncamera = \"tcpout:127.0.0.1:5900\"\n";
        let eight = parse(&one.repeat(8), "f.toml").expect("eight fit");
        assert!(eight.iter().all(|v| (low..=high).contains(&v.altitude)));
    }
}
