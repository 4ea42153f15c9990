//! The one string form that names a vehicle's transport everywhere (CLI, config, tests).

use std::fmt;
use std::net::SocketAddr;
use std::str::FromStr;

/// Where a vehicle is reached: a serial device, a TCP client or server, or a UDP socket.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Address {
    /// `serial:PATH:BAUD`: a serial device (USB adapter, radio, pseudo-terminal).
    Serial {
        /// Device path, e.g. `/dev/ttyUSB0`.
        path: String,
        /// Baud rate, e.g. 115200.
        baud: u32,
    },
    /// `tcpout:HOST:PORT`: connect to a TCP server (e.g. ArduPilot SITL on 5760).
    TcpOut(HostPort),
    /// `tcpin:ADDR:PORT`: listen for one TCP client at a time.
    TcpIn(SocketAddr),
    /// `udpin:ADDR:PORT`: bind and answer whoever sends to us.
    UdpIn(SocketAddr),
    /// `udpout:HOST:PORT`: send to a fixed UDP peer and read its answers.
    UdpOut(HostPort),
}

/// A host name or IP literal with a port, resolved when the transport connects.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HostPort {
    /// Host name or IP address (IPv6 in brackets).
    pub host: String,
    /// TCP or UDP port.
    pub port: u16,
}

impl fmt::Display for HostPort {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.host, self.port)
    }
}

/// Why an address string could not be understood.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "bad link address {input:?}: {reason} (expected serial:PATH:BAUD, tcpout:HOST:PORT, \
     tcpin:ADDR:PORT, udpin:ADDR:PORT or udpout:HOST:PORT)"
)]
pub struct AddressError {
    /// The string as given.
    pub input: String,
    /// What was wrong with it.
    pub reason: String,
}

impl FromStr for Address {
    type Err = AddressError;

    fn from_str(input: &str) -> Result<Self, Self::Err> {
        let fail = |reason: String| AddressError {
            input: input.to_owned(),
            reason,
        };
        let (scheme, rest) = input
            .split_once(':')
            .ok_or_else(|| fail("missing scheme".into()))?;
        match scheme {
            "serial" => {
                let (path, baud) = rest
                    .rsplit_once(':')
                    .ok_or_else(|| fail("missing baud rate after the device path".into()))?;
                if path.is_empty() {
                    return Err(fail("empty device path".into()));
                }
                let baud: u32 = baud
                    .parse()
                    .map_err(|_| fail(format!("baud rate {baud:?} is not a whole number")))?;
                if baud == 0 {
                    return Err(fail("baud rate must be above zero".into()));
                }
                Ok(Address::Serial {
                    path: path.to_owned(),
                    baud,
                })
            }
            "tcpout" => parse_host_port(rest).map(Address::TcpOut).map_err(fail),
            "udpout" => parse_host_port(rest).map(Address::UdpOut).map_err(fail),
            "tcpin" => parse_bind(rest).map(Address::TcpIn).map_err(fail),
            "udpin" => parse_bind(rest).map(Address::UdpIn).map_err(fail),
            other => Err(fail(format!("unknown scheme {other:?}"))),
        }
    }
}

fn parse_host_port(rest: &str) -> Result<HostPort, String> {
    let (host, port) = rest
        .rsplit_once(':')
        .ok_or_else(|| "missing port after the host".to_owned())?;
    if host.is_empty() {
        return Err("empty host".into());
    }
    let port: u16 = port
        .parse()
        .map_err(|_| format!("port {port:?} is not a number from 1 to 65535"))?;
    if port == 0 {
        return Err("port 0 cannot be connected to".into());
    }
    Ok(HostPort {
        host: host.to_owned(),
        port,
    })
}

fn parse_bind(rest: &str) -> Result<SocketAddr, String> {
    rest.parse::<SocketAddr>().map_err(|_| {
        format!(
            "{rest:?} is not an IP address and port to bind, e.g. 127.0.0.1:14550 or [::1]:14550"
        )
    })
}

impl fmt::Display for Address {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Address::Serial { path, baud } => write!(f, "serial:{path}:{baud}"),
            Address::TcpOut(hp) => write!(f, "tcpout:{hp}"),
            Address::TcpIn(a) => write!(f, "tcpin:{a}"),
            Address::UdpIn(a) => write!(f, "udpin:{a}"),
            Address::UdpOut(hp) => write!(f, "udpout:{hp}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_form_round_trips() {
        for s in [
            "serial:/dev/ttyUSB0:115200",
            "tcpout:127.0.0.1:5760",
            "tcpout:localhost:5760",
            "tcpin:0.0.0.0:5760",
            "udpin:0.0.0.0:14550",
            "udpin:[::1]:14550",
            "udpout:127.0.0.1:14551",
        ] {
            let a: Address = s.parse().unwrap();
            assert_eq!(a.to_string(), s);
        }
    }

    #[test]
    fn parts_are_read_right() {
        assert_eq!(
            "serial:/dev/pts/3:57600".parse::<Address>().unwrap(),
            Address::Serial {
                path: "/dev/pts/3".into(),
                baud: 57600
            }
        );
        assert_eq!(
            "tcpout:sitl.local:5762".parse::<Address>().unwrap(),
            Address::TcpOut(HostPort {
                host: "sitl.local".into(),
                port: 5762
            })
        );
    }

    #[test]
    fn bad_addresses_say_what_is_wrong() {
        for (s, why) in [
            ("", "missing scheme"),
            ("ttyUSB0", "missing scheme"),
            ("serial:/dev/ttyUSB0", "missing baud rate"),
            ("serial:/dev/ttyUSB0:fast", "not a whole number"),
            ("serial::115200", "empty device path"),
            ("serial:/dev/ttyUSB0:0", "above zero"),
            ("tcpout:127.0.0.1", "missing port"),
            ("tcpout::5760", "empty host"),
            ("tcpout:127.0.0.1:99999", "not a number"),
            ("udpin:localhost:14550", "not an IP address"),
            ("udp:127.0.0.1:14550", "unknown scheme"),
        ] {
            let e = s.parse::<Address>().unwrap_err();
            assert!(e.to_string().contains(why), "{s:?} gave {e}");
            assert!(e.to_string().contains("expected serial:PATH:BAUD"));
        }
    }
}
