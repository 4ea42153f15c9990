//! Byte transports behind an [`Address`]: serial, TCP client/server and UDP, each split into a
//! reader and a writer half so a link can read and write from two threads.
//!
//! A [`Transport`] owns what outlives one connection (a bound listener or UDP socket, the peers
//! heard on it); [`Transport::connect`] makes one [`Connection`], and the link calls it again when
//! that connection breaks.

use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream, ToSocketAddrs, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use crate::address::{Address, HostPort};

/// How long a blocking read waits before it returns `TimedOut`, so reader threads can notice a
/// stop request.
pub const READ_POLL: Duration = Duration::from_millis(100);
const CONNECT_TIMEOUT: Duration = Duration::from_secs(2);
const WRITE_TIMEOUT: Duration = Duration::from_secs(1);
/// The UDP peers heard on a `udpin` socket, with when each was last heard.
type Peers = Arc<Mutex<Vec<(SocketAddr, Instant)>>>;

/// UDP peers not heard from for this long are no longer sent to.
const UDP_PEER_TTL: Duration = Duration::from_secs(10);
const MAX_UDP_PEERS: usize = 16;

/// A transport could not be opened or connected.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// Binding a listening address failed (in use, not a local address, no permission).
    #[error("cannot listen on {address}: {source}")]
    Bind {
        /// The address as given.
        address: String,
        /// The operating system's reason.
        source: io::Error,
    },
    /// Connecting or opening the device failed; the link retries.
    #[error("cannot connect to {address}: {reason}")]
    Connect {
        /// The address as given.
        address: String,
        /// The reason.
        reason: String,
    },
    /// The caller asked to stop while waiting for a connection.
    #[error("stopped")]
    Stopped,
}

/// The reading half of a connection; reads return `TimedOut`/`WouldBlock` every [`READ_POLL`].
pub type Reader = Box<dyn Read + Send>;
/// The writing half of a connection. Each `write` call on a UDP transport is one datagram, so
/// callers write whole frames at once.
pub type Writer = Box<dyn Write + Send>;

/// One live connection to a vehicle.
pub struct Connection {
    /// Bytes from the vehicle.
    pub reader: Reader,
    /// Bytes to the vehicle.
    pub writer: Writer,
    /// Who is on the other side, for logs.
    pub peer: String,
    closer: Option<TcpStream>,
}

impl Connection {
    /// Builds a connection from any reader and writer (in-process pipes, tests, simulators).
    pub fn from_parts(reader: Reader, writer: Writer, peer: impl Into<String>) -> Self {
        Self {
            reader,
            writer,
            peer: peer.into(),
            closer: None,
        }
    }

    /// Returns a handle that unblocks and ends this connection from another thread.
    pub fn closer(&self) -> Closer {
        Closer(self.closer.as_ref().and_then(|s| s.try_clone().ok()))
    }
}

/// Ends a connection from another thread (shuts a TCP socket down; other kinds end when their
/// reader sees the stop flag).
pub struct Closer(Option<TcpStream>);

impl Closer {
    /// Shuts the connection down; errors are ignored because the socket may already be gone.
    pub fn close(&self) {
        if let Some(s) = &self.0 {
            let _ = s.shutdown(Shutdown::Both);
        }
    }
}

/// A vehicle transport that can be (re)connected.
pub struct Transport {
    address: Address,
    state: State,
}

enum State {
    Outgoing,
    TcpListener(TcpListener),
    Udp(UdpSocket, Peers),
}

impl Transport {
    /// Opens a transport: server addresses are bound now, so a taken port is reported at once.
    pub fn open(address: &Address) -> Result<Self, TransportError> {
        let bind_err = |source| TransportError::Bind {
            address: address.to_string(),
            source,
        };
        let state = match address {
            Address::TcpIn(a) => {
                let l = TcpListener::bind(a).map_err(bind_err)?;
                l.set_nonblocking(true).map_err(bind_err)?;
                State::TcpListener(l)
            }
            Address::UdpIn(a) => {
                let s = UdpSocket::bind(a).map_err(bind_err)?;
                s.set_read_timeout(Some(READ_POLL)).map_err(bind_err)?;
                State::Udp(s, Arc::default())
            }
            _ => State::Outgoing,
        };
        Ok(Self {
            address: address.clone(),
            state,
        })
    }

    /// The address this transport was opened with.
    pub fn address(&self) -> &Address {
        &self.address
    }

    /// The local address a server transport is bound to (useful with port 0).
    pub fn local_addr(&self) -> Option<SocketAddr> {
        match &self.state {
            State::TcpListener(l) => l.local_addr().ok(),
            State::Udp(s, _) => s.local_addr().ok(),
            State::Outgoing => None,
        }
    }

    /// Makes one connection. A `tcpin` transport waits for a client until `stop` is set.
    pub fn connect(&mut self, stop: &AtomicBool) -> Result<Connection, TransportError> {
        let address = self.address.to_string();
        let fail = |reason: String| TransportError::Connect {
            address: address.clone(),
            reason,
        };
        match (&self.address, &self.state) {
            (Address::Serial { path, baud }, _) => {
                let port = serialport::new(path, *baud)
                    .timeout(READ_POLL)
                    .open()
                    .map_err(|e| fail(e.to_string()))?;
                let writer = port.try_clone().map_err(|e| fail(e.to_string()))?;
                Ok(Connection::from_parts(
                    Box::new(port),
                    Box::new(writer),
                    path.clone(),
                ))
            }
            (Address::TcpOut(hp), _) => {
                let stream = connect_tcp(hp).map_err(|e| fail(e.to_string()))?;
                tcp_connection(stream).map_err(|e| fail(e.to_string()))
            }
            (_, State::TcpListener(listener)) => loop {
                if stop.load(Ordering::Relaxed) {
                    return Err(TransportError::Stopped);
                }
                match listener.accept() {
                    Ok((stream, _)) => {
                        stream
                            .set_nonblocking(false)
                            .map_err(|e| fail(e.to_string()))?;
                        return tcp_connection(stream).map_err(|e| fail(e.to_string()));
                    }
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                        std::thread::sleep(Duration::from_millis(20));
                    }
                    Err(e) => return Err(fail(e.to_string())),
                }
            },
            (_, State::Udp(socket, peers)) => {
                let r = socket.try_clone().map_err(|e| fail(e.to_string()))?;
                let w = socket.try_clone().map_err(|e| fail(e.to_string()))?;
                Ok(Connection::from_parts(
                    Box::new(UdpReader::new(r, Some(peers.clone()))),
                    Box::new(UdpInWriter {
                        socket: w,
                        peers: peers.clone(),
                    }),
                    "udp clients",
                ))
            }
            (Address::UdpOut(hp), _) => {
                let target = resolve(hp).map_err(|e| fail(e.to_string()))?;
                let local: SocketAddr = if target.is_ipv4() {
                    "0.0.0.0:0"
                } else {
                    "[::]:0"
                }
                .parse()
                .map_err(|_| fail("bad local address".into()))?;
                let socket = UdpSocket::bind(local).map_err(|e| fail(e.to_string()))?;
                socket.connect(target).map_err(|e| fail(e.to_string()))?;
                socket
                    .set_read_timeout(Some(READ_POLL))
                    .map_err(|e| fail(e.to_string()))?;
                let w = socket.try_clone().map_err(|e| fail(e.to_string()))?;
                Ok(Connection::from_parts(
                    Box::new(UdpReader::new(socket, None)),
                    Box::new(UdpOutWriter(w)),
                    target.to_string(),
                ))
            }
            (Address::TcpIn(_) | Address::UdpIn(_), State::Outgoing) => {
                Err(fail("server transport was not bound".into()))
            }
        }
    }
}

fn resolve(hp: &HostPort) -> io::Result<SocketAddr> {
    (hp.host.trim_matches(['[', ']']), hp.port)
        .to_socket_addrs()?
        .next()
        .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "host name has no address"))
}

fn connect_tcp(hp: &HostPort) -> io::Result<TcpStream> {
    let mut last = io::Error::new(io::ErrorKind::NotFound, "host name has no address");
    for addr in (hp.host.trim_matches(['[', ']']), hp.port).to_socket_addrs()? {
        match TcpStream::connect_timeout(&addr, CONNECT_TIMEOUT) {
            Ok(s) => return Ok(s),
            Err(e) => last = e,
        }
    }
    Err(last)
}

fn tcp_connection(stream: TcpStream) -> io::Result<Connection> {
    stream.set_nodelay(true)?;
    stream.set_read_timeout(Some(READ_POLL))?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    let peer = stream
        .peer_addr()
        .map(|a| a.to_string())
        .unwrap_or_else(|_| "tcp peer".into());
    let writer = stream.try_clone()?;
    let closer = stream.try_clone()?;
    Ok(Connection {
        reader: Box::new(TcpReader(stream)),
        writer: Box::new(writer),
        peer,
        closer: Some(closer),
    })
}

/// TCP reader that turns an orderly close (read of 0 bytes) into an error, so read loops end.
struct TcpReader(TcpStream);

impl Read for TcpReader {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match self.0.read(buf)? {
            0 if !buf.is_empty() => Err(io::Error::new(
                io::ErrorKind::ConnectionAborted,
                "peer closed the connection",
            )),
            n => Ok(n),
        }
    }
}

/// Presents datagrams as a byte stream; remembers who sent them on a `udpin` socket.
struct UdpReader {
    socket: UdpSocket,
    peers: Option<Peers>,
    buf: Vec<u8>,
    start: usize,
    end: usize,
}

impl UdpReader {
    fn new(socket: UdpSocket, peers: Option<Peers>) -> Self {
        Self {
            socket,
            peers,
            buf: vec![0; 65536],
            start: 0,
            end: 0,
        }
    }
}

impl Read for UdpReader {
    fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
        if self.start == self.end {
            let (n, from) = self.socket.recv_from(&mut self.buf)?;
            if let Some(peers) = &self.peers {
                let mut peers = peers.lock().unwrap_or_else(PoisonError::into_inner);
                let now = Instant::now();
                match peers.iter_mut().find(|(a, _)| *a == from) {
                    Some(p) => p.1 = now,
                    None => {
                        if peers.len() >= MAX_UDP_PEERS {
                            peers.sort_by_key(|p| std::cmp::Reverse(p.1));
                            peers.truncate(MAX_UDP_PEERS - 1);
                        }
                        peers.push((from, now));
                    }
                }
            }
            self.start = 0;
            self.end = n;
        }
        let n = out.len().min(self.end - self.start);
        out[..n].copy_from_slice(&self.buf[self.start..self.start + n]);
        self.start += n;
        Ok(n)
    }
}

/// Sends each write as one datagram to every peer heard recently (messages carry their target).
struct UdpInWriter {
    socket: UdpSocket,
    peers: Peers,
}

impl Write for UdpInWriter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let targets: Vec<SocketAddr> = {
            let peers = self.peers.lock().unwrap_or_else(PoisonError::into_inner);
            peers
                .iter()
                .filter(|(_, t)| t.elapsed() < UDP_PEER_TTL)
                .map(|(a, _)| *a)
                .collect()
        };
        for t in targets {
            // A peer that went away gives ICMP errors; it must not stop the others.
            let _ = self.socket.send_to(buf, t);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

struct UdpOutWriter(UdpSocket);

impl Write for UdpOutWriter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match self.0.send(buf) {
            // Nobody listening yet (ICMP port unreachable): the datagram is lost, as UDP is.
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => Ok(buf.len()),
            r => r,
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// Whether an I/O error from a reader only means "nothing arrived in time".
pub fn is_timeout(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    ) || (e.kind() == io::ErrorKind::ConnectionRefused) // udpout before the peer listens
}

/// Runs one connection in both directions: `read` on a new thread, `write` on this one. Each gets
/// the connection's `alive` flag; when either returns, or clears the flag, the other is ended too
/// (a TCP socket is shut down so a blocked read returns at once).
pub fn duplex(
    conn: Connection,
    name: &str,
    read: impl FnOnce(Reader, &AtomicBool) + Send + 'static,
    write: impl FnOnce(Writer, &AtomicBool),
) {
    let closer = conn.closer();
    let Connection { reader, writer, .. } = conn;
    let alive = Arc::new(AtomicBool::new(true));
    let reader_thread = {
        let alive = alive.clone();
        std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                read(reader, &alive);
                alive.store(false, Ordering::Relaxed);
            })
    };
    if reader_thread.is_ok() {
        write(writer, &alive);
    } else {
        tracing::error!("cannot start the {name} reader thread");
    }
    alive.store(false, Ordering::Relaxed);
    closer.close();
    if let Ok(t) = reader_thread {
        let _ = t.join();
    }
}

/// Keeps a transport connected until `stop`: runs `session` on every connection and reconnects
/// with a growing back-off (100 ms to 2 s) when it ends or fails.
pub fn run_sessions(
    transport: &mut Transport,
    stop: &AtomicBool,
    mut on_state: impl FnMut(bool),
    mut session: impl FnMut(Connection),
) {
    let mut backoff = Duration::from_millis(100);
    let mut failures = 0u32;
    while !stop.load(Ordering::Relaxed) {
        match transport.connect(stop) {
            Ok(conn) => {
                tracing::info!(address = %transport.address(), peer = %conn.peer, "link connected");
                failures = 0;
                backoff = Duration::from_millis(100);
                on_state(true);
                session(conn);
                on_state(false);
                if !stop.load(Ordering::Relaxed) {
                    tracing::warn!(address = %transport.address(), "link connection ended; reconnecting");
                }
            }
            Err(TransportError::Stopped) => break,
            Err(e) => {
                // Say it once, then again every 30 attempts, so a missing vehicle does not flood the log.
                if failures.is_multiple_of(30) {
                    tracing::warn!("{e}; retrying");
                }
                failures += 1;
            }
        }
        let until = Instant::now() + backoff;
        while Instant::now() < until && !stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(20));
        }
        backoff = (backoff * 2).min(Duration::from_secs(2));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn udp_pair_carries_datagrams_both_ways() {
        let mut server = Transport::open(&"udpin:127.0.0.1:0".parse().unwrap()).unwrap();
        let port = server.local_addr().unwrap().port();
        let stop = AtomicBool::new(false);
        let mut client = Transport::open(&format!("udpout:127.0.0.1:{port}").parse().unwrap())
            .unwrap()
            .connect(&stop)
            .unwrap();
        let mut srv = server.connect(&stop).unwrap();
        client.writer.write_all(b"hello").unwrap();
        let mut buf = [0u8; 3];
        srv.reader.read_exact(&mut buf).unwrap();
        assert_eq!(&buf, b"hel");
        srv.reader.read_exact(&mut buf[..2]).unwrap();
        assert_eq!(&buf[..2], b"lo");
        srv.writer.write_all(b"back").unwrap();
        let mut back = [0u8; 4];
        client.reader.read_exact(&mut back).unwrap();
        assert_eq!(&back, b"back");
    }

    #[test]
    fn tcp_close_is_an_error_not_an_endless_zero_read() {
        let mut server = Transport::open(&"tcpin:127.0.0.1:0".parse().unwrap()).unwrap();
        let port = server.local_addr().unwrap().port();
        let stop = AtomicBool::new(false);
        let t = std::thread::spawn(move || {
            let c = TcpStream::connect(("127.0.0.1", port)).unwrap();
            drop(c);
        });
        let mut conn = server.connect(&stop).unwrap();
        t.join().unwrap();
        let mut buf = [0u8; 8];
        let e = loop {
            match conn.reader.read(&mut buf) {
                Err(e) if is_timeout(&e) => continue,
                Err(e) => break e,
                Ok(n) => panic!("read {n} bytes from a closed socket"),
            }
        };
        assert_eq!(e.kind(), io::ErrorKind::ConnectionAborted);
    }

    #[test]
    fn taken_port_is_a_clear_bind_error() {
        let first = Transport::open(&"tcpin:127.0.0.1:0".parse().unwrap()).unwrap();
        let port = first.local_addr().unwrap().port();
        let err = Transport::open(&format!("tcpin:127.0.0.1:{port}").parse().unwrap())
            .err()
            .unwrap();
        assert!(
            err.to_string()
                .starts_with("cannot listen on tcpin:127.0.0.1:"),
            "{err}"
        );
    }

    #[test]
    fn tcpin_connect_returns_when_stopped() {
        let mut server = Transport::open(&"tcpin:127.0.0.1:0".parse().unwrap()).unwrap();
        let stop = AtomicBool::new(true);
        assert!(matches!(
            server.connect(&stop),
            Err(TransportError::Stopped)
        ));
    }
}
