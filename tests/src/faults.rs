//! A fault-injecting proxy for TCP, UDP and pseudo-terminals: it sits between a station and a
//! vehicle and drops, delays, reorders, duplicates or corrupts what passes, stalls the line or
//! cuts the connection, on command, so integration tests can show what the links do about it.
//!
//! Faults apply to *chunks*: one datagram on UDP, one read's worth of bytes on TCP and on a
//! pseudo-terminal (which is how a radio modem or a noisy serial line loses data too: in bursts
//! that ignore framing). Randomness comes from a seed, so a failing run can be repeated.

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How often a pump wakes up to deliver delayed chunks when nothing arrives.
const POLL: Duration = Duration::from_millis(2);

/// What happens to the chunks going one way. Probabilities are per chunk, in `0..=1`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Faults {
    /// The chunk is lost.
    pub drop: f64,
    /// The chunk arrives twice.
    pub duplicate: f64,
    /// One bit of the chunk is flipped.
    pub corrupt: f64,
    /// The chunk is held back and delivered after the next one.
    pub reorder: f64,
    /// Added to every chunk's delivery.
    pub delay: Duration,
    /// Up to this much more delay, drawn per chunk (order is kept: a chunk never overtakes the
    /// one before it through jitter alone).
    pub jitter: Duration,
}

impl Faults {
    /// Every fault at once, at probability `p` for each, with `delay` ± `delay` of jitter.
    pub fn all(p: f64, delay: Duration) -> Self {
        Self {
            drop: p,
            duplicate: p,
            corrupt: p,
            reorder: p,
            delay,
            jitter: delay,
        }
    }
}

/// Which way chunks travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// From the station to the vehicle.
    Up,
    /// From the vehicle to the station.
    Down,
}

/// What the proxy did, one way.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Chunks received.
    pub chunks: u64,
    /// Chunks delivered (duplicates included).
    pub delivered: u64,
    /// Chunks lost on purpose.
    pub dropped: u64,
    /// Chunks sent twice.
    pub duplicated: u64,
    /// Chunks with a flipped bit.
    pub corrupted: u64,
    /// Chunks held back behind the next one.
    pub reordered: u64,
    /// Chunks lost because the line was stalled.
    pub stalled: u64,
}

/// The proxy's settings and counters, shared by its threads.
struct Control {
    faults: Mutex<[Faults; 2]>,
    counts: Mutex<[Counts; 2]>,
    stalled: AtomicBool,
    stop: AtomicBool,
    /// Open TCP streams, shut down by [`FaultProxy::disconnect`].
    streams: Mutex<Vec<TcpStream>>,
    seed: u64,
}

impl Control {
    fn new(seed: u64) -> Arc<Self> {
        Arc::new(Self {
            faults: Mutex::new([Faults::default(); 2]),
            counts: Mutex::new([Counts::default(); 2]),
            stalled: AtomicBool::new(false),
            stop: AtomicBool::new(false),
            streams: Mutex::new(vec![]),
            seed,
        })
    }

    fn faults(&self, dir: Direction) -> Faults {
        self.faults.lock().unwrap_or_else(PoisonError::into_inner)[dir as usize]
    }

    fn count(&self, dir: Direction, f: impl FnOnce(&mut Counts)) {
        f(&mut self.counts.lock().unwrap_or_else(PoisonError::into_inner)[dir as usize]);
    }
}

/// Where the station reaches the proxy.
enum StationEnd {
    Tcp(SocketAddr),
    Udp(SocketAddr),
    /// The pseudo-terminals' device paths.
    Pty {
        station: String,
        vehicle: String,
    },
}

/// A running proxy. Dropping it stops it and closes every connection it holds.
pub struct FaultProxy {
    control: Arc<Control>,
    threads: Vec<JoinHandle<()>>,
    end: StationEnd,
    /// Keeps the pseudo-terminals' slave ends open while the proxy lives.
    _ptys: Vec<serialport::TTYPort>,
}

impl FaultProxy {
    /// A TCP proxy listening on a free loopback port; each station connection gets its own
    /// connection to `vehicle`.
    pub fn tcp(vehicle: SocketAddr, seed: u64) -> io::Result<Self> {
        let listener = TcpListener::bind("127.0.0.1:0")?;
        listener.set_nonblocking(true)?;
        let local = listener.local_addr()?;
        let control = Control::new(seed);
        let c = control.clone();
        let accept = std::thread::Builder::new()
            .name("faults-tcp".into())
            .spawn(move || accept_tcp(&listener, vehicle, &c))?;
        Ok(Self {
            control,
            threads: vec![accept],
            end: StationEnd::Tcp(local),
            _ptys: vec![],
        })
    }

    /// A UDP proxy on a free loopback port: datagrams from the station go to `vehicle`, and the
    /// vehicle's answers go back to whoever sent last.
    pub fn udp(vehicle: SocketAddr, seed: u64) -> io::Result<Self> {
        let station_side = UdpSocket::bind("127.0.0.1:0")?;
        let vehicle_side = UdpSocket::bind("127.0.0.1:0")?;
        vehicle_side.connect(vehicle)?;
        for s in [&station_side, &vehicle_side] {
            s.set_read_timeout(Some(POLL))?;
        }
        let local = station_side.local_addr()?;
        let station: Arc<Mutex<Option<SocketAddr>>> = Arc::default();
        let control = Control::new(seed);
        let (up_in, up_out) = (station_side.try_clone()?, vehicle_side.try_clone()?);
        let st = station.clone();
        let up = spawn_pump(
            "faults-udp-up",
            &control,
            Direction::Up,
            move |buf| {
                let (n, from) = up_in.recv_from(buf)?;
                *st.lock().unwrap_or_else(PoisonError::into_inner) = Some(from);
                Ok(n)
            },
            move |bytes| datagram_sent(up_out.send(bytes)),
        )?;
        let down = spawn_pump(
            "faults-udp-down",
            &control,
            Direction::Down,
            move |buf| match vehicle_side.recv(buf) {
                // Nobody listens at the vehicle's port (yet): nothing came.
                Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => {
                    Err(io::ErrorKind::WouldBlock.into())
                }
                r => r,
            },
            move |bytes| match *station.lock().unwrap_or_else(PoisonError::into_inner) {
                Some(to) => datagram_sent(station_side.send_to(bytes, to)),
                None => Ok(()), // nobody to answer yet: lost, as on a real network
            },
        )?;
        Ok(Self {
            control,
            threads: vec![up, down],
            end: StationEnd::Udp(local),
            _ptys: vec![],
        })
    }

    /// A proxy between two pseudo-terminals: the station opens [`Self::station_path`], the vehicle
    /// (or its emulator) [`Self::vehicle_path`], both as serial devices.
    pub fn pty(seed: u64) -> io::Result<Self> {
        let pair = || serialport::TTYPort::pair().map_err(io::Error::other);
        let (mut station_master, station_slave) = pair()?;
        let (mut vehicle_master, vehicle_slave) = pair()?;
        let mut paths = vec![];
        for (master, slave) in [
            (&mut station_master, &station_slave),
            (&mut vehicle_master, &vehicle_slave),
        ] {
            serialport::SerialPort::set_timeout(master, POLL).map_err(io::Error::other)?;
            paths.push(
                serialport::SerialPort::name(slave)
                    .ok_or_else(|| io::Error::other("a pseudo-terminal without a name"))?,
            );
        }
        let mut station_in = station_master
            .try_clone_native()
            .map_err(io::Error::other)?;
        let mut vehicle_in = vehicle_master
            .try_clone_native()
            .map_err(io::Error::other)?;
        let control = Control::new(seed);
        let up = spawn_pump(
            "faults-pty-up",
            &control,
            Direction::Up,
            move |buf| station_in.read(buf),
            move |bytes| vehicle_master.write_all(bytes),
        )?;
        let down = spawn_pump(
            "faults-pty-down",
            &control,
            Direction::Down,
            move |buf| vehicle_in.read(buf),
            move |bytes| station_master.write_all(bytes),
        )?;
        let vehicle_path = paths.pop().unwrap_or_default();
        let station_path = paths.pop().unwrap_or_default();
        Ok(Self {
            control,
            threads: vec![up, down],
            end: StationEnd::Pty {
                station: station_path,
                vehicle: vehicle_path,
            },
            _ptys: vec![station_slave, vehicle_slave],
        })
    }

    /// The address a station's link opens to reach the vehicle through the proxy:
    /// `tcpout:…`, `udpout:…` or `serial:PATH:115200`.
    pub fn station_address(&self) -> String {
        match &self.end {
            StationEnd::Tcp(local) => format!("tcpout:{local}"),
            StationEnd::Udp(local) => format!("udpout:{local}"),
            StationEnd::Pty { station, .. } => format!("serial:{station}:115200"),
        }
    }

    /// The vehicle's pseudo-terminal (for a `pty` proxy).
    pub fn vehicle_path(&self) -> Option<&str> {
        match &self.end {
            StationEnd::Pty { vehicle, .. } => Some(vehicle),
            _ => None,
        }
    }

    /// Sets the faults one way.
    pub fn set(&self, dir: Direction, faults: Faults) {
        self.control
            .faults
            .lock()
            .unwrap_or_else(PoisonError::into_inner)[dir as usize] = faults;
    }

    /// Sets the same faults both ways.
    pub fn set_both(&self, faults: Faults) {
        self.set(Direction::Up, faults);
        self.set(Direction::Down, faults);
    }

    /// Stalls the line (everything sent meanwhile is lost, as out of radio range) or ends the
    /// stall.
    pub fn stall(&self, stalled: bool) {
        self.control.stalled.store(stalled, Ordering::Relaxed);
    }

    /// Cuts every open TCP connection (both peers see it closed); new ones are accepted.
    pub fn disconnect(&self) {
        for s in self
            .control
            .streams
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .drain(..)
        {
            let _ = s.shutdown(Shutdown::Both);
        }
    }

    /// What the proxy did one way so far.
    pub fn counts(&self, dir: Direction) -> Counts {
        self.control
            .counts
            .lock()
            .unwrap_or_else(PoisonError::into_inner)[dir as usize]
    }
}

impl Drop for FaultProxy {
    fn drop(&mut self) {
        self.control.stop.store(true, Ordering::Relaxed);
        self.disconnect();
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// A datagram nobody received is lost, not a reason to stop.
fn datagram_sent(sent: io::Result<usize>) -> io::Result<()> {
    match sent {
        Err(e) if e.kind() != io::ErrorKind::ConnectionRefused => Err(e),
        _ => Ok(()),
    }
}

/// Accepts station connections and pairs each with a new connection to the vehicle.
fn accept_tcp(listener: &TcpListener, vehicle: SocketAddr, control: &Arc<Control>) {
    while !control.stop.load(Ordering::Relaxed) {
        let station = match listener.accept() {
            Ok((s, _)) => s,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(5));
                continue;
            }
            Err(_) => return,
        };
        let Ok(vehicle) = TcpStream::connect_timeout(&vehicle, Duration::from_secs(1)) else {
            continue; // the station sees its connection closed, as if the vehicle were down
        };
        if let Err(e) = splice(station, vehicle, control) {
            eprintln!("fault proxy: could not relay a connection: {e}");
        }
    }
}

/// Runs both directions of one TCP connection pair.
fn splice(station: TcpStream, vehicle: TcpStream, control: &Arc<Control>) -> io::Result<()> {
    station.set_nonblocking(false)?;
    for s in [&station, &vehicle] {
        s.set_read_timeout(Some(POLL))?;
        s.set_nodelay(true)?;
    }
    control
        .streams
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .extend([station.try_clone()?, vehicle.try_clone()?]);
    for (name, dir, from, to) in [
        ("faults-tcp-up", Direction::Up, &station, &vehicle),
        ("faults-tcp-down", Direction::Down, &vehicle, &station),
    ] {
        let (mut from, mut to) = (from.try_clone()?, to.try_clone()?);
        let (a, b) = (from.try_clone()?, to.try_clone()?);
        let c = control.clone();
        std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                pump(
                    &c,
                    dir,
                    |buf| match from.read(buf) {
                        Ok(0) => Err(io::ErrorKind::UnexpectedEof.into()),
                        r => r,
                    },
                    |bytes| to.write_all(bytes),
                );
                // One side closed: close the other, as a TCP relay does.
                let _ = a.shutdown(Shutdown::Both);
                let _ = b.shutdown(Shutdown::Both);
            })?;
    }
    Ok(())
}

/// Starts a thread moving chunks one way until the proxy stops or a side fails.
fn spawn_pump(
    name: &str,
    control: &Arc<Control>,
    dir: Direction,
    mut recv: impl FnMut(&mut [u8]) -> io::Result<usize> + Send + 'static,
    mut send: impl FnMut(&[u8]) -> io::Result<()> + Send + 'static,
) -> io::Result<JoinHandle<()>> {
    let control = control.clone();
    std::thread::Builder::new()
        .name(name.into())
        .spawn(move || pump(&control, dir, &mut recv, &mut send))
}

/// Moves chunks one way. `recv` returns a timeout error when nothing came (then delayed chunks
/// are delivered) and any other error when its side is gone.
fn pump(
    control: &Control,
    dir: Direction,
    mut recv: impl FnMut(&mut [u8]) -> io::Result<usize>,
    mut send: impl FnMut(&[u8]) -> io::Result<()>,
) {
    let mut line = Line::new(control.seed.wrapping_add(dir as u64 + 1));
    let mut buf = vec![0u8; 64 * 1024];
    while !control.stop.load(Ordering::Relaxed) {
        match recv(&mut buf) {
            Ok(0) => {}
            Ok(n) => line.push(control, dir, &buf[..n]),
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) => {}
            Err(_) => return,
        }
        if line.deliver(control, dir, &mut send).is_err() {
            return;
        }
    }
}

/// One direction's chunks in flight.
struct Line {
    rng: u64,
    queue: VecDeque<(Instant, Vec<u8>)>,
    held: Option<(Instant, Vec<u8>)>,
    last_due: Instant,
}

/// A chunk held back for reordering is let go after this long if nothing follows it.
const HOLD_AT_MOST: Duration = Duration::from_millis(50);

impl Line {
    fn new(seed: u64) -> Self {
        Self {
            rng: seed,
            queue: VecDeque::new(),
            held: None,
            last_due: Instant::now(),
        }
    }

    /// splitmix64: uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        self.rng = self.rng.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.rng;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && self.uniform() < p
    }

    fn below(&mut self, n: usize) -> usize {
        ((self.uniform() * n as f64) as usize).min(n.saturating_sub(1))
    }

    fn push(&mut self, control: &Control, dir: Direction, bytes: &[u8]) {
        let f = control.faults(dir);
        control.count(dir, |c| c.chunks += 1);
        if control.stalled.load(Ordering::Relaxed) {
            control.count(dir, |c| c.stalled += 1);
            return;
        }
        if self.chance(f.drop) {
            control.count(dir, |c| c.dropped += 1);
            return;
        }
        let mut bytes = bytes.to_vec();
        if self.chance(f.corrupt) {
            let i = self.below(bytes.len());
            bytes[i] ^= 1 << self.below(8);
            control.count(dir, |c| c.corrupted += 1);
        }
        let now = Instant::now();
        if self.held.is_none() && self.chance(f.reorder) {
            self.held = Some((now, bytes));
            control.count(dir, |c| c.reordered += 1);
            return;
        }
        let copies = if self.chance(f.duplicate) {
            control.count(dir, |c| c.duplicated += 1);
            2
        } else {
            1
        };
        let due = (now + f.delay + f.jitter.mul_f64(self.uniform())).max(self.last_due);
        self.last_due = due;
        for _ in 0..copies {
            self.queue.push_back((due, bytes.clone()));
        }
        if let Some((_, held)) = self.held.take() {
            self.queue.push_back((due, held));
        }
    }

    fn deliver(
        &mut self,
        control: &Control,
        dir: Direction,
        send: &mut impl FnMut(&[u8]) -> io::Result<()>,
    ) -> io::Result<()> {
        let now = Instant::now();
        if control.stalled.load(Ordering::Relaxed) {
            let lost = self.queue.len() + usize::from(self.held.is_some());
            self.queue.clear();
            self.held = None;
            control.count(dir, |c| c.stalled += lost as u64);
            return Ok(());
        }
        if let Some((since, _)) = &self.held
            && now.duration_since(*since) > HOLD_AT_MOST
            && let Some((_, held)) = self.held.take()
        {
            self.queue.push_back((now, held));
        }
        while let Some((due, _)) = self.queue.front() {
            if *due > now {
                break;
            }
            if let Some((_, bytes)) = self.queue.pop_front() {
                send(&bytes)?;
                control.count(dir, |c| c.delivered += 1);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A UDP peer that answers every datagram with the same bytes.
    fn echo() -> SocketAddr {
        let socket = UdpSocket::bind("127.0.0.1:0").expect("bind");
        let addr = socket.local_addr().expect("bound");
        std::thread::spawn(move || {
            let mut buf = [0u8; 2048];
            while let Ok((n, from)) = socket.recv_from(&mut buf) {
                let _ = socket.send_to(&buf[..n], from);
            }
        });
        addr
    }

    fn exchange(proxy: &FaultProxy, payloads: &[Vec<u8>]) -> Vec<Vec<u8>> {
        let station = UdpSocket::bind("127.0.0.1:0").expect("bind");
        station
            .set_read_timeout(Some(Duration::from_millis(300)))
            .expect("timeout");
        let to = proxy
            .station_address()
            .trim_start_matches("udpout:")
            .parse::<SocketAddr>()
            .expect("address");
        for p in payloads {
            station.send_to(p, to).expect("send");
            std::thread::sleep(Duration::from_millis(2));
        }
        let mut got = vec![];
        let mut buf = [0u8; 2048];
        while let Ok(n) = station.recv(&mut buf) {
            got.push(buf[..n].to_vec());
        }
        got
    }

    fn payloads() -> Vec<Vec<u8>> {
        (0..50u8).map(|i| vec![i; 8]).collect()
    }

    #[test]
    fn without_faults_everything_arrives_intact_and_in_order() {
        let proxy = FaultProxy::udp(echo(), 1).expect("proxy");
        assert_eq!(exchange(&proxy, &payloads()), payloads());
        assert_eq!(proxy.counts(Direction::Up).delivered, 50);
        assert_eq!(proxy.counts(Direction::Down).delivered, 50);
    }

    #[test]
    fn each_fault_does_what_it_says() {
        let proxy = FaultProxy::udp(echo(), 2).expect("proxy");
        let one = |f: Faults| {
            proxy.set(Direction::Up, f);
            exchange(&proxy, &payloads())
        };
        assert!(
            one(Faults {
                drop: 1.0,
                ..Faults::default()
            })
            .is_empty()
        );
        assert_eq!(
            one(Faults {
                duplicate: 1.0,
                ..Faults::default()
            })
            .len(),
            100
        );
        let corrupted = one(Faults {
            corrupt: 1.0,
            ..Faults::default()
        });
        assert_eq!(corrupted.len(), 50);
        for (got, sent) in corrupted.iter().zip(payloads()) {
            let flipped: u32 = got
                .iter()
                .zip(&sent)
                .map(|(a, b)| (a ^ b).count_ones())
                .sum();
            assert_eq!(flipped, 1, "{got:?} vs {sent:?}");
        }
        let reordered = one(Faults {
            reorder: 0.3,
            ..Faults::default()
        });
        let mut sorted = reordered.clone();
        sorted.sort();
        assert_eq!(sorted, payloads(), "reordering loses nothing");
        assert_ne!(reordered, payloads(), "but changes the order");
        let t0 = Instant::now();
        let delayed = one(Faults {
            delay: Duration::from_millis(100),
            ..Faults::default()
        });
        assert_eq!(delayed, payloads(), "delay keeps the order");
        assert!(t0.elapsed() >= Duration::from_millis(100));
        proxy.set(Direction::Up, Faults::default());
        proxy.stall(true);
        assert!(exchange(&proxy, &payloads()).is_empty());
        proxy.stall(false);
        assert_eq!(exchange(&proxy, &payloads()), payloads());
    }
}
