//! The shield protocol on the wire (see `link/PROTOCOL.md`): zero-copy views over bytes
//! ([`Command`], [`Frame`]), validated representations with `parse`/`emit` ([`CommandRepr`],
//! [`RpytRepr`], [`UpRepr`]), and byte-at-a-time decoders that resynchronise after corruption.

use crate::rc::{Axis, Pulses};

/// Lowest pulse the shield outputs, µs.
pub const PULSE_MIN_US: u16 = 1000;
/// Highest pulse the shield outputs, µs.
pub const PULSE_MAX_US: u16 = 2000;
/// Start byte of every upstream frame.
pub const UP_SYNC: u8 = 0xA5;
/// Longest upstream payload.
pub const UP_MAX_PAYLOAD: usize = 64;
/// Upstream frame overhead: sync, type, len, two checksum bytes.
pub const UP_OVERHEAD: usize = 5;

/// Something on the wire that is not a valid command or frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// Fewer bytes than the structure needs.
    #[error("truncated: need {need} bytes, have {have}")]
    Truncated {
        /// Bytes needed.
        need: usize,
        /// Bytes present.
        have: usize,
    },
    /// The first byte of a command does not have its top bit set.
    #[error("byte {0:#04x} is not a command header")]
    NotAHeader(u8),
    /// The second byte of a command has its top bit set.
    #[error("byte {0:#04x} is not a command value")]
    NotAValue(u8),
    /// The parity bit does not match.
    #[error("parity error in command {0:#04x} {1:#04x}")]
    Parity(u8, u8),
    /// A channel value that is not a 1000–2000 µs pulse.
    #[error("{axis:?} pulse {pulse_us} µs is outside 1000–2000 µs")]
    PulseOutOfRange {
        /// The channel.
        axis: Axis,
        /// The pulse it would have been.
        pulse_us: u16,
    },
    /// An RPYT packet whose commands are not roll, pitch, yaw, throttle in that order.
    #[error("RPYT packet has command {found} at position {position}")]
    OutOfOrder {
        /// Index 0–3 in the packet.
        position: usize,
        /// Command id found there.
        found: u8,
    },
    /// An upstream frame that does not start with the sync byte.
    #[error("frame starts with {0:#04x}, not the sync byte 0xa5")]
    NoSync(u8),
    /// An upstream frame whose declared length is over the limit.
    #[error("frame length {0} is over the limit of 64")]
    TooLong(u8),
    /// An upstream frame whose checksum does not match.
    #[error("frame checksum {found:#06x} does not match {computed:#06x}")]
    Checksum {
        /// In the frame.
        found: u16,
        /// Over the bytes.
        computed: u16,
    },
    /// An upstream frame of a type this side does not know.
    #[error("unknown frame type {0:#04x}")]
    UnknownType(u8),
    /// A known frame type with the wrong payload length.
    #[error("frame type {kind:#04x} has length {len}, expected {expected}")]
    BadLength {
        /// Frame type.
        kind: u8,
        /// Length found.
        len: usize,
        /// Length expected.
        expected: usize,
    },
    /// A field value that is not allowed.
    #[error("bad field {0}")]
    BadField(&'static str),
}

/// CRC-16/MCRF4XX (MAVLink's X.25 checksum).
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        let mut t = b ^ (crc as u8);
        t ^= t << 4;
        crc = (crc >> 8) ^ (u16::from(t) << 8) ^ (u16::from(t) << 3) ^ (u16::from(t) >> 4);
    }
    crc
}

// ---------------------------------------------------------------------------------------------
// Downstream commands
// ---------------------------------------------------------------------------------------------

/// A special (non-channel) command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Special {
    /// Start the motors (the Naza stick combination, done by the shield).
    Start,
    /// Arm the outputs.
    Arm,
    /// Disarm.
    Disarm,
    /// Land where it is, then disarm.
    Land,
}

impl Special {
    /// Command id on the wire (4–7).
    pub fn id(self) -> u8 {
        match self {
            Special::Start => 4,
            Special::Arm => 5,
            Special::Disarm => 6,
            Special::Land => 7,
        }
    }

    /// The special command with this id.
    pub fn from_id(id: u8) -> Option<Self> {
        match id {
            4 => Some(Special::Start),
            5 => Some(Special::Arm),
            6 => Some(Special::Disarm),
            7 => Some(Special::Land),
            _ => None,
        }
    }
}

fn axis_id(axis: Axis) -> u8 {
    match axis {
        Axis::Roll => 0,
        Axis::Pitch => 1,
        Axis::Yaw => 2,
        Axis::Throttle => 3,
    }
}

/// A zero-copy view of one two-byte command.
#[derive(Debug, Clone, Copy)]
pub struct Command<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Command<T> {
    /// Wraps bytes without checking them.
    pub const fn new_unchecked(buffer: T) -> Self {
        Self { buffer }
    }

    /// Wraps bytes, checking there are two and that they are a header and a value.
    pub fn new_checked(buffer: T) -> Result<Self, WireError> {
        let c = Self::new_unchecked(buffer);
        c.check_framing()?;
        Ok(c)
    }

    /// Checks length and the header/value top bits.
    pub fn check_framing(&self) -> Result<(), WireError> {
        let b = self.buffer.as_ref();
        if b.len() < 2 {
            return Err(WireError::Truncated {
                need: 2,
                have: b.len(),
            });
        }
        if b[0] & 0x80 == 0 {
            return Err(WireError::NotAHeader(b[0]));
        }
        if b[1] & 0x80 != 0 {
            return Err(WireError::NotAValue(b[1]));
        }
        Ok(())
    }

    /// Command id, 0–7.
    pub fn command_id(&self) -> u8 {
        (self.buffer.as_ref()[0] >> 4) & 0x07
    }

    /// The 10-bit value.
    pub fn value(&self) -> u16 {
        let b = self.buffer.as_ref();
        (u16::from(b[0] & 0x07) << 7) | u16::from(b[1] & 0x7F)
    }

    /// Whether the parity bit makes the count of ones even.
    pub fn parity_ok(&self) -> bool {
        let b = self.buffer.as_ref();
        ((b[0] & 0x7F).count_ones() + (b[1] & 0x7F).count_ones()) % 2 == 0
    }

    /// The underlying bytes.
    pub fn into_inner(self) -> T {
        self.buffer
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Command<T> {
    /// Writes id and value with the parity bit. `value` is masked to 10 bits.
    pub fn set(&mut self, id: u8, value: u16) {
        let b = self.buffer.as_mut();
        let hi = ((value >> 7) & 0x07) as u8;
        let lo = (value & 0x7F) as u8;
        let h = 0x80 | ((id & 0x07) << 4) | hi;
        let p = ((h & 0x7F).count_ones() + lo.count_ones()) % 2;
        b[0] = h | ((p as u8) << 3);
        b[1] = lo;
    }
}

/// A validated command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CommandRepr {
    /// Output this pulse on a channel.
    Channel {
        /// Which output.
        axis: Axis,
        /// Pulse width, 1000–2000 µs.
        pulse_us: u16,
    },
    /// Perform a special action.
    Special {
        /// Which action.
        action: Special,
        /// Sequence number (0–1023) echoed in the acknowledgement.
        seq: u16,
    },
}

impl CommandRepr {
    /// Encoded length in bytes.
    pub const LEN: usize = 2;

    /// Validates a command: framing, parity, and for channels the 1000–2000 µs range.
    pub fn parse<T: AsRef<[u8]>>(c: &Command<T>) -> Result<Self, WireError> {
        c.check_framing()?;
        if !c.parity_ok() {
            let b = c.buffer.as_ref();
            return Err(WireError::Parity(b[0], b[1]));
        }
        let id = c.command_id();
        let v = c.value();
        match Special::from_id(id) {
            Some(action) => Ok(CommandRepr::Special { action, seq: v }),
            None => {
                let axis = Axis::ALL[usize::from(id)];
                let pulse_us = PULSE_MIN_US + v;
                if pulse_us > PULSE_MAX_US {
                    return Err(WireError::PulseOutOfRange { axis, pulse_us });
                }
                Ok(CommandRepr::Channel { axis, pulse_us })
            }
        }
    }

    /// Writes this command. Panics never; an out-of-range pulse or sequence is rejected.
    pub fn emit<T: AsRef<[u8]> + AsMut<[u8]>>(&self, c: &mut Command<T>) -> Result<(), WireError> {
        match *self {
            CommandRepr::Channel { axis, pulse_us } => {
                if !(PULSE_MIN_US..=PULSE_MAX_US).contains(&pulse_us) {
                    return Err(WireError::PulseOutOfRange { axis, pulse_us });
                }
                c.set(axis_id(axis), pulse_us - PULSE_MIN_US);
            }
            CommandRepr::Special { action, seq } => {
                if seq > 1023 {
                    return Err(WireError::BadField("sequence above 1023"));
                }
                c.set(action.id(), seq);
            }
        }
        Ok(())
    }

    /// The two bytes of this command.
    pub fn to_bytes(&self) -> Result<[u8; 2], WireError> {
        let mut b = [0u8; 2];
        self.emit(&mut Command::new_unchecked(&mut b[..]))?;
        Ok(b)
    }
}

/// A validated RPYT packet: the four channel pulses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RpytRepr(pub Pulses);

impl RpytRepr {
    /// Encoded length in bytes.
    pub const LEN: usize = 8;

    /// Parses an 8-byte packet: four valid channel commands in R, P, Y, T order.
    pub fn parse(bytes: &[u8]) -> Result<Self, WireError> {
        if bytes.len() < Self::LEN {
            return Err(WireError::Truncated {
                need: Self::LEN,
                have: bytes.len(),
            });
        }
        let mut pulses = Pulses {
            roll: 0,
            pitch: 0,
            yaw: 0,
            throttle: 0,
        };
        for (i, axis) in Axis::ALL.into_iter().enumerate() {
            let c = Command::new_checked(&bytes[2 * i..2 * i + 2])?;
            match CommandRepr::parse(&c)? {
                CommandRepr::Channel { axis: a, pulse_us } if a == axis => {
                    pulses.set(axis, pulse_us)
                }
                _ => {
                    return Err(WireError::OutOfOrder {
                        position: i,
                        found: c.command_id(),
                    });
                }
            }
        }
        Ok(Self(pulses))
    }

    /// Writes the packet; fails if a pulse is outside 1000–2000 µs.
    pub fn emit(&self, out: &mut [u8; 8]) -> Result<(), WireError> {
        for (i, axis) in Axis::ALL.into_iter().enumerate() {
            CommandRepr::Channel {
                axis,
                pulse_us: self.0.get(axis),
            }
            .emit(&mut Command::new_unchecked(&mut out[2 * i..2 * i + 2]))?;
        }
        Ok(())
    }
}

/// Downstream receiver: feed bytes one at a time; yields each command or the error that made it
/// drop bytes. It never yields a pulse outside 1000–2000 µs.
#[derive(Debug, Default, Clone)]
pub struct CommandDecoder {
    header: Option<u8>,
}

impl CommandDecoder {
    /// A decoder waiting for a header.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds one byte.
    pub fn push(&mut self, byte: u8) -> Option<Result<CommandRepr, WireError>> {
        match self.header.take() {
            None if byte & 0x80 == 0 => Some(Err(WireError::NotAHeader(byte))),
            None => {
                self.header = Some(byte);
                None
            }
            Some(h) if byte & 0x80 != 0 => {
                // The old header lost its value; this byte starts a new command.
                self.header = Some(byte);
                Some(Err(WireError::NotAValue(h)))
            }
            Some(h) => Some(CommandRepr::parse(&Command::new_unchecked([h, byte]))),
        }
    }
}

/// What the shield's receiver does with the bytes it gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// A complete RPYT packet: output these pulses.
    Pulses(Pulses),
    /// A whole special packet (see [`special_bytes`]).
    Special {
        /// The action.
        action: Special,
        /// Its sequence number.
        seq: u16,
    },
    /// Bytes or commands were dropped.
    Dropped(WireError),
}

/// The shield's receive logic on top of [`CommandDecoder`]: pulses apply only from a whole RPYT
/// packet (four valid channel commands in order, nothing in between), and a special command only
/// from a whole special packet (four commands of that id carrying seq, 1023−seq, seq, 1023−seq).
/// Random noise forms an RPYT packet with probability about 6·10⁻⁸ per byte offset (and its
/// pulses last one packet period), a special packet about 2⁻⁵², and never a pulse outside
/// 1000–2000 µs.
#[derive(Debug, Default, Clone)]
pub struct Receiver {
    decoder: CommandDecoder,
    packet: Pulses4,
    special: Option<(Special, u16, usize)>,
}

#[derive(Debug, Default, Clone, Copy)]
struct Pulses4 {
    got: usize,
    us: [u16; 4],
}

impl Receiver {
    /// A receiver waiting for the start of a command.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds one byte.
    pub fn push(&mut self, byte: u8) -> Option<Event> {
        match self.decoder.push(byte)? {
            Err(e) => {
                self.packet.got = 0;
                self.special = None;
                Some(Event::Dropped(e))
            }
            Ok(CommandRepr::Channel { axis, pulse_us }) => {
                self.special = None;
                let index = usize::from(axis_id(axis));
                if index != self.packet.got {
                    let found = axis_id(axis);
                    let position = self.packet.got;
                    self.packet.got = 0;
                    if index != 0 {
                        return Some(Event::Dropped(WireError::OutOfOrder { position, found }));
                    }
                }
                self.packet.us[index] = pulse_us;
                self.packet.got = index + 1;
                if self.packet.got < 4 {
                    return None;
                }
                self.packet.got = 0;
                let [roll, pitch, yaw, throttle] = self.packet.us;
                Some(Event::Pulses(Pulses {
                    roll,
                    pitch,
                    yaw,
                    throttle,
                }))
            }
            Ok(CommandRepr::Special { action, seq: value }) => {
                self.packet.got = 0;
                match self.special {
                    Some((a, seq, got)) if a == action && value == special_value(seq, got) => {
                        if got == 3 {
                            self.special = None;
                            return Some(Event::Special { action, seq });
                        }
                        self.special = Some((a, seq, got + 1));
                    }
                    _ => self.special = Some((action, value, 1)),
                }
                None
            }
        }
    }
}

/// The value of command `i` (0–3) of a special packet: seq, 1023−seq, seq, 1023−seq.
fn special_value(seq: u16, i: usize) -> u16 {
    if i.is_multiple_of(2) { seq } else { 1023 - seq }
}

/// The 8-byte special packet a station sends for a special command.
pub fn special_bytes(action: Special, seq: u16) -> Result<[u8; 8], WireError> {
    if seq > 1023 {
        return Err(WireError::BadField("sequence above 1023"));
    }
    let mut out = [0u8; 8];
    for i in 0..4 {
        let value = special_value(seq, i);
        let b = CommandRepr::Special { action, seq: value }.to_bytes()?;
        out[2 * i..2 * i + 2].copy_from_slice(&b);
    }
    Ok(out)
}

// ---------------------------------------------------------------------------------------------
// Upstream frames
// ---------------------------------------------------------------------------------------------

/// Upstream frame types.
pub mod kind {
    /// Sensor readings.
    pub const TELEMETRY: u8 = 0x01;
    /// Acknowledgement of a special command.
    pub const ACK: u8 = 0x02;
    /// A text message.
    pub const TEXT: u8 = 0x03;
}

/// A zero-copy view of one upstream frame.
#[derive(Debug, Clone, Copy)]
pub struct Frame<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Frame<T> {
    /// Wraps bytes without checking them.
    pub const fn new_unchecked(buffer: T) -> Self {
        Self { buffer }
    }

    /// Wraps bytes, checking sync, length and checksum.
    pub fn new_checked(buffer: T) -> Result<Self, WireError> {
        let f = Self::new_unchecked(buffer);
        f.check()?;
        Ok(f)
    }

    /// Checks sync byte, length limit, completeness and checksum.
    pub fn check(&self) -> Result<(), WireError> {
        let b = self.buffer.as_ref();
        if b.len() < 3 {
            return Err(WireError::Truncated {
                need: UP_OVERHEAD,
                have: b.len(),
            });
        }
        if b[0] != UP_SYNC {
            return Err(WireError::NoSync(b[0]));
        }
        if usize::from(b[2]) > UP_MAX_PAYLOAD {
            return Err(WireError::TooLong(b[2]));
        }
        let total = self.total_len();
        if b.len() < total {
            return Err(WireError::Truncated {
                need: total,
                have: b.len(),
            });
        }
        let found = u16::from_le_bytes([b[total - 2], b[total - 1]]);
        let computed = crc16(&b[1..total - 2]);
        if found != computed {
            return Err(WireError::Checksum { found, computed });
        }
        Ok(())
    }

    /// Frame type.
    pub fn kind(&self) -> u8 {
        self.buffer.as_ref()[1]
    }

    /// Whole frame length including sync and checksum.
    pub fn total_len(&self) -> usize {
        usize::from(self.buffer.as_ref()[2]) + UP_OVERHEAD
    }

    /// The payload.
    pub fn payload(&self) -> &[u8] {
        let b = self.buffer.as_ref();
        &b[3..3 + usize::from(b[2])]
    }
}

/// Shield status flags in a telemetry frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ShieldFlags {
    /// Outputs armed.
    pub armed: bool,
    /// Motors started.
    pub motors_running: bool,
    /// Link-loss failsafe active.
    pub failsafe: bool,
    /// Landing (commanded or failsafe).
    pub landing: bool,
}

impl ShieldFlags {
    fn to_byte(self) -> u8 {
        u8::from(self.armed)
            | u8::from(self.motors_running) << 1
            | u8::from(self.failsafe) << 2
            | u8::from(self.landing) << 3
    }

    fn from_byte(b: u8) -> Self {
        Self {
            armed: b & 1 != 0,
            motors_running: b & 2 != 0,
            failsafe: b & 4 != 0,
            landing: b & 8 != 0,
        }
    }
}

/// Sensor readings from the shield.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TelemetryRepr {
    /// Sonar height in mm, `None` when there is no echo.
    pub sonar_mm: Option<u16>,
    /// IMU yaw in centi-degrees, −18000…18000, + = counter-clockwise.
    pub yaw_cdeg: i16,
    /// Battery voltage, mV.
    pub battery_mv: u16,
    /// Status flags.
    pub flags: ShieldFlags,
    /// Bad downstream commands since the previous telemetry frame (saturating).
    pub rx_errors: u8,
}

/// Acknowledgement of a special command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AckRepr {
    /// Which command.
    pub action: Special,
    /// Its sequence number.
    pub seq: u16,
    /// Whether it was done.
    pub accepted: bool,
}

/// A validated upstream frame.
#[derive(Debug, Clone, PartialEq)]
pub enum UpRepr {
    /// Sensor readings.
    Telemetry(TelemetryRepr),
    /// Acknowledgement.
    Ack(AckRepr),
    /// Text message.
    Text(String),
}

impl UpRepr {
    /// Parses a checked frame into its representation.
    pub fn parse<T: AsRef<[u8]>>(f: &Frame<T>) -> Result<Self, WireError> {
        f.check()?;
        let p = f.payload();
        let need = |expected: usize| {
            if p.len() == expected {
                Ok(())
            } else {
                Err(WireError::BadLength {
                    kind: f.kind(),
                    len: p.len(),
                    expected,
                })
            }
        };
        match f.kind() {
            kind::TELEMETRY => {
                need(8)?;
                let sonar = u16::from_le_bytes([p[0], p[1]]);
                let yaw = i16::from_le_bytes([p[2], p[3]]);
                if !(-18000..=18000).contains(&yaw) {
                    return Err(WireError::BadField("yaw outside ±18000 centi-degrees"));
                }
                Ok(UpRepr::Telemetry(TelemetryRepr {
                    sonar_mm: (sonar != u16::MAX).then_some(sonar),
                    yaw_cdeg: yaw,
                    battery_mv: u16::from_le_bytes([p[4], p[5]]),
                    flags: ShieldFlags::from_byte(p[6]),
                    rx_errors: p[7],
                }))
            }
            kind::ACK => {
                need(4)?;
                let action = Special::from_id(p[0]).ok_or(WireError::BadField("ack command id"))?;
                let seq = u16::from_le_bytes([p[1], p[2]]);
                if seq > 1023 || p[3] > 1 {
                    return Err(WireError::BadField("ack sequence or result"));
                }
                Ok(UpRepr::Ack(AckRepr {
                    action,
                    seq,
                    accepted: p[3] == 0,
                }))
            }
            kind::TEXT => {
                if p.is_empty() {
                    return Err(WireError::BadLength {
                        kind: kind::TEXT,
                        len: 0,
                        expected: 1,
                    });
                }
                let s =
                    std::str::from_utf8(p).map_err(|_| WireError::BadField("text is not UTF-8"))?;
                Ok(UpRepr::Text(s.to_owned()))
            }
            k => Err(WireError::UnknownType(k)),
        }
    }

    /// Appends the encoded frame to `out`. Text longer than 64 bytes is cut at a character
    /// boundary.
    pub fn emit(&self, out: &mut Vec<u8>) {
        let mut payload = [0u8; UP_MAX_PAYLOAD];
        let (k, n) = match self {
            UpRepr::Telemetry(t) => {
                payload[0..2].copy_from_slice(&t.sonar_mm.unwrap_or(u16::MAX).to_le_bytes());
                payload[2..4].copy_from_slice(&t.yaw_cdeg.clamp(-18000, 18000).to_le_bytes());
                payload[4..6].copy_from_slice(&t.battery_mv.to_le_bytes());
                payload[6] = t.flags.to_byte();
                payload[7] = t.rx_errors;
                (kind::TELEMETRY, 8)
            }
            UpRepr::Ack(a) => {
                payload[0] = a.action.id();
                payload[1..3].copy_from_slice(&a.seq.min(1023).to_le_bytes());
                payload[3] = u8::from(!a.accepted);
                (kind::ACK, 4)
            }
            UpRepr::Text(s) => {
                let mut end = s.len().min(UP_MAX_PAYLOAD);
                while !s.is_char_boundary(end) {
                    end -= 1;
                }
                let end = end.max(1).min(s.len());
                let bytes = if s.is_empty() {
                    b" "
                } else {
                    &s.as_bytes()[..end]
                };
                payload[..bytes.len()].copy_from_slice(bytes);
                (kind::TEXT, bytes.len())
            }
        };
        let start = out.len();
        out.extend_from_slice(&[UP_SYNC, k, n as u8]);
        out.extend_from_slice(&payload[..n]);
        let crc = crc16(&out[start + 1..]);
        out.extend_from_slice(&crc.to_le_bytes());
    }
}

/// Upstream receiver: feed bytes; yields frames, and errors for what it dropped.
#[derive(Debug, Default, Clone)]
pub struct FrameDecoder {
    buf: Vec<u8>,
}

impl FrameDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds bytes; every complete frame or drop is appended to `out`.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Result<UpRepr, WireError>>) {
        self.buf.extend_from_slice(bytes);
        let mut start = 0;
        loop {
            let b = &self.buf[start..];
            let Some(sync) = b.iter().position(|&x| x == UP_SYNC) else {
                if !b.is_empty() {
                    out.push(Err(WireError::NoSync(b[0])));
                }
                start = self.buf.len();
                break;
            };
            if sync > 0 {
                out.push(Err(WireError::NoSync(b[0])));
                start += sync;
                continue;
            }
            let f = Frame::new_unchecked(b);
            match f.check() {
                Err(WireError::Truncated { .. }) => break,
                Err(e) => {
                    out.push(Err(e));
                    start += 1;
                }
                Ok(()) => {
                    out.push(UpRepr::parse(&f));
                    start += f.total_len();
                }
            }
        }
        self.buf.drain(..start);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const FIXTURE: [u8; 8] = [0x83, 0x74, 0x9B, 0x74, 0xAB, 0x74, 0xB0, 0x00];
    const FIXTURE_PULSES: Pulses = Pulses {
        roll: 1500,
        pitch: 1500,
        yaw: 1500,
        throttle: 1000,
    };

    fn decode_all(bytes: &[u8]) -> (Vec<CommandRepr>, usize) {
        let mut d = CommandDecoder::new();
        let mut ok = vec![];
        let mut errs = 0;
        for &b in bytes {
            match d.push(b) {
                Some(Ok(c)) => ok.push(c),
                Some(Err(_)) => errs += 1,
                None => {}
            }
        }
        (ok, errs)
    }

    #[test]
    fn protocol_md_example_bytes() {
        let mut out = [0u8; 8];
        RpytRepr(FIXTURE_PULSES).emit(&mut out).unwrap();
        assert_eq!(out, FIXTURE);
        assert_eq!(RpytRepr::parse(&FIXTURE).unwrap(), RpytRepr(FIXTURE_PULSES));
    }

    #[test]
    fn command_view_reads_fields() {
        let c = Command::new_checked(&FIXTURE[2..4]).unwrap();
        assert_eq!(c.command_id(), 1);
        assert_eq!(c.value(), 500);
        assert!(c.parity_ok());
    }

    #[test]
    fn special_commands_round_trip() {
        for action in [Special::Start, Special::Arm, Special::Disarm, Special::Land] {
            for seq in [0, 1, 511, 1023] {
                let r = CommandRepr::Special { action, seq };
                let b = r.to_bytes().unwrap();
                assert_eq!(
                    CommandRepr::parse(&Command::new_checked(b).unwrap()).unwrap(),
                    r
                );
            }
        }
        assert!(
            CommandRepr::Special {
                action: Special::Arm,
                seq: 1024
            }
            .to_bytes()
            .is_err()
        );
    }

    #[test]
    fn out_of_range_pulses_are_errors_both_ways() {
        assert!(matches!(
            CommandRepr::Channel {
                axis: Axis::Roll,
                pulse_us: 2001
            }
            .to_bytes(),
            Err(WireError::PulseOutOfRange { .. })
        ));
        assert!(
            CommandRepr::Channel {
                axis: Axis::Roll,
                pulse_us: 999
            }
            .to_bytes()
            .is_err()
        );
        // Value 1001 (pulse 2001) with correct parity on the wire.
        let mut b = [0u8; 2];
        Command::new_unchecked(&mut b[..]).set(0, 1001);
        assert_eq!(
            CommandRepr::parse(&Command::new_unchecked(b)),
            Err(WireError::PulseOutOfRange {
                axis: Axis::Roll,
                pulse_us: 2001
            })
        );
    }

    #[test]
    fn every_single_bit_flip_is_caught() {
        for pulse in [1000u16, 1234, 1500, 2000] {
            let good = CommandRepr::Channel {
                axis: Axis::Yaw,
                pulse_us: pulse,
            }
            .to_bytes()
            .unwrap();
            for bit in 0..16 {
                let mut b = good;
                b[bit / 8] ^= 1 << (bit % 8);
                let (ok, _) = decode_all(&b);
                assert!(
                    ok.is_empty(),
                    "flip of bit {bit} in {good:02x?} gave {ok:?}"
                );
            }
        }
    }

    #[test]
    fn decoder_drops_non_headers_and_orphan_headers() {
        let mut bytes = vec![0x12, 0x00, 0x83]; // two value bytes, then a header with no value
        bytes.extend_from_slice(&FIXTURE);
        let (ok, errs) = decode_all(&bytes);
        assert_eq!(errs, 3);
        assert_eq!(ok.len(), 4);
        assert_eq!(
            ok[3],
            CommandRepr::Channel {
                axis: Axis::Throttle,
                pulse_us: 1000
            }
        );
    }

    #[test]
    fn rpyt_packet_must_be_in_order() {
        let mut b = FIXTURE;
        b.swap(0, 2);
        b.swap(1, 3);
        assert!(matches!(
            RpytRepr::parse(&b),
            Err(WireError::OutOfOrder {
                position: 0,
                found: 1
            })
        ));
        assert!(matches!(
            RpytRepr::parse(&b[..7]),
            Err(WireError::Truncated { .. })
        ));
    }

    #[test]
    fn upstream_frames_round_trip() {
        let frames = [
            UpRepr::Telemetry(TelemetryRepr {
                sonar_mm: Some(1234),
                yaw_cdeg: -9000,
                battery_mv: 11_100,
                flags: ShieldFlags {
                    armed: true,
                    motors_running: true,
                    failsafe: false,
                    landing: true,
                },
                rx_errors: 3,
            }),
            UpRepr::Telemetry(TelemetryRepr {
                sonar_mm: None,
                ..Default::default()
            }),
            UpRepr::Ack(AckRepr {
                action: Special::Land,
                seq: 77,
                accepted: false,
            }),
            UpRepr::Text("failsafe: landing".into()),
        ];
        let mut bytes = vec![];
        for f in &frames {
            f.emit(&mut bytes);
        }
        let mut d = FrameDecoder::new();
        let mut out = vec![];
        for chunk in bytes.chunks(3) {
            d.push(chunk, &mut out);
        }
        let got: Vec<UpRepr> = out.into_iter().map(|r| r.unwrap()).collect();
        assert_eq!(got, frames);
    }

    #[test]
    fn telemetry_fixture_bytes() {
        let mut b = vec![];
        UpRepr::Ack(AckRepr {
            action: Special::Arm,
            seq: 1,
            accepted: true,
        })
        .emit(&mut b);
        assert_eq!(&b[..7], &[0xA5, 0x02, 0x04, 0x05, 0x01, 0x00, 0x00]);
        assert_eq!(b.len(), 9);
        let crc = crc16(&b[1..7]);
        assert_eq!(&b[7..], &crc.to_le_bytes());
        // CRC-16/MCRF4XX check value.
        assert_eq!(crc16(b"123456789"), 0x6F91);
    }

    #[test]
    fn long_text_is_cut_at_a_char_boundary() {
        let s = "é".repeat(40); // 80 bytes
        let mut b = vec![];
        UpRepr::Text(s).emit(&mut b);
        let mut out = vec![];
        FrameDecoder::new().push(&b, &mut out);
        match &out[0] {
            Ok(UpRepr::Text(t)) => assert_eq!(t.len(), 64),
            other => panic!("{other:?}"),
        }
    }

    fn receive_all(bytes: &[u8]) -> Vec<Event> {
        let mut r = Receiver::new();
        bytes
            .iter()
            .filter_map(|&b| r.push(b))
            .filter(|e| !matches!(e, Event::Dropped(_)))
            .collect()
    }

    #[test]
    fn receiver_needs_whole_packets() {
        assert_eq!(receive_all(&FIXTURE), vec![Event::Pulses(FIXTURE_PULSES)]);
        assert!(receive_all(&FIXTURE[..6]).is_empty());
        // A packet broken by a lost byte is not applied; the next one is.
        let mut b = FIXTURE.to_vec();
        b.remove(3);
        b.extend_from_slice(&FIXTURE);
        assert_eq!(receive_all(&b), vec![Event::Pulses(FIXTURE_PULSES)]);
        assert_eq!(
            special_bytes(Special::Arm, 1).unwrap(),
            [0xD8, 0x01, 0xDF, 0x7E, 0xD8, 0x01, 0xDF, 0x7E] // PROTOCOL.md's example
        );
        let arm = special_bytes(Special::Arm, 9).unwrap();
        assert_eq!(
            receive_all(&arm),
            vec![Event::Special {
                action: Special::Arm,
                seq: 9
            }]
        );
        assert!(receive_all(&arm[..6]).is_empty());
        // A stuck line repeating one command never forms a special packet.
        let one = CommandRepr::Special {
            action: Special::Disarm,
            seq: 5,
        }
        .to_bytes()
        .unwrap();
        assert!(receive_all(&one.repeat(100)).is_empty());
        assert!(special_bytes(Special::Arm, 1024).is_err());
    }

    /// A deterministic noise source (xorshift64*), so the noise test below cannot be flaky.
    fn noise(seed: u64, n: usize) -> Vec<u8> {
        let mut x = seed;
        (0..n)
            .map(|_| {
                x ^= x >> 12;
                x ^= x << 25;
                x ^= x >> 27;
                (x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 56) as u8
            })
            .collect()
    }

    #[test]
    fn a_megabyte_of_noise_between_packets() {
        let mut bytes = vec![];
        let mut real = 0;
        for chunk in noise(0x5eed, 1 << 20).chunks(97) {
            bytes.extend_from_slice(chunk);
            bytes.extend_from_slice(&FIXTURE);
            real += 1;
        }
        let got = receive_all(&bytes);
        assert!(
            got.iter().all(|e| matches!(e, Event::Pulses(_))),
            "noise formed a special command"
        );
        let wrong = got
            .iter()
            .filter(|e| **e != Event::Pulses(FIXTURE_PULSES))
            .count();
        // Expected ≈ 2^20 offsets × 6·10⁻⁸ ≈ 0.06 packets formed by noise.
        assert!(wrong <= 1, "{wrong} packets formed by noise");
        assert_eq!(got.len() - wrong, real, "every real packet is applied");
    }

    proptest! {
        #[test]
        fn every_packet_after_noise_is_applied(
            noise in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..40), 1..30),
        ) {
            let mut bytes = vec![];
            for n in &noise {
                bytes.extend_from_slice(n);
                bytes.extend_from_slice(&FIXTURE);
            }
            let got = receive_all(&bytes);
            let real = got.iter().filter(|e| **e == Event::Pulses(FIXTURE_PULSES)).count();
            // Recovery within one command: the packet right after any noise is applied.
            prop_assert!(real >= noise.len(), "{:?}", got);
            for e in got {
                if let Event::Pulses(p) = e {
                    for a in Axis::ALL {
                        prop_assert!((PULSE_MIN_US..=PULSE_MAX_US).contains(&p.get(a)));
                    }
                }
            }
        }

        #[test]
        fn arbitrary_bytes_never_yield_a_bad_pulse(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let (ok, _) = decode_all(&bytes);
            for c in ok {
                if let CommandRepr::Channel { pulse_us, .. } = c {
                    prop_assert!((PULSE_MIN_US..=PULSE_MAX_US).contains(&pulse_us));
                }
            }
            let mut out = vec![];
            FrameDecoder::new().push(&bytes, &mut out);
        }

        #[test]
        fn recovers_within_one_command_after_garbage(
            garbage in proptest::collection::vec(any::<u8>(), 0..64),
            r in 1000u16..=2000, p in 1000u16..=2000, y in 1000u16..=2000, t in 1000u16..=2000,
        ) {
            let pulses = Pulses { roll: r, pitch: p, yaw: y, throttle: t };
            let mut packet = [0u8; 8];
            RpytRepr(pulses).emit(&mut packet).unwrap();
            let mut d = CommandDecoder::new();
            for &b in &garbage { d.push(b); }
            // The very next command after garbage is decoded, whatever the garbage was.
            let got: Vec<_> = packet.iter().filter_map(|&b| d.push(b)).collect();
            let ok: Vec<_> = got.iter().filter_map(|r| r.as_ref().ok()).copied().collect();
            let expect: Vec<_> = Axis::ALL.iter().map(|&axis| CommandRepr::Channel { axis, pulse_us: pulses.get(axis) }).collect();
            prop_assert_eq!(ok, expect);
        }

        #[test]
        fn upstream_recovers_after_garbage(garbage in proptest::collection::vec(any::<u8>(), 0..200), mv in any::<u16>()) {
            let frame = UpRepr::Telemetry(TelemetryRepr { battery_mv: mv, ..Default::default() });
            let mut bytes = garbage.clone();
            // Two copies: garbage may swallow the first into a bogus long frame only if it
            // declares a length that reaches past it; the second is then always found.
            frame.emit(&mut bytes);
            for _ in 0..(UP_MAX_PAYLOAD / 13 + 1) { frame.emit(&mut bytes); }
            let mut out = vec![];
            FrameDecoder::new().push(&bytes, &mut out);
            prop_assert!(out.iter().any(|r| r.as_ref() == Ok(&frame)));
        }
    }
}
