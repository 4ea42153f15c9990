//! MAVLink 1 and 2 frames found in a byte stream: CRC-checked, with everything that is not a
//! frame (boot text, line noise, cut-off frames) skipped and counted.

use ::mavlink::dialects::ardupilotmega::MavMessage;
use ::mavlink::error::ParserError;
use ::mavlink::{
    MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, Message, SigningData, calculate_crc,
};

const STX_V1: u8 = 0xFE;
const STX_V2: u8 = 0xFD;
const V1_HEADER: usize = 6;
const V2_HEADER: usize = 10;
const SIGNATURE: usize = 13;
const IFLAG_SIGNED: u8 = 0x01;
/// The longest frame: a signed MAVLink 2 frame with a 255-byte payload.
pub const MAX_FRAME: usize = V2_HEADER + 255 + 2 + SIGNATURE;

/// What the bytes at the start of a buffer are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Check {
    /// A whole frame with a valid checksum, this many bytes long.
    Valid(usize),
    /// The start of what may be a frame; more bytes are needed.
    Incomplete,
    /// Not a frame (no start byte, unknown flags, or a bad checksum).
    Invalid,
}

/// Checks whether `bytes` starts with a valid MAVLink frame of the ardupilotmega dialect.
pub fn check(bytes: &[u8]) -> Check {
    let Some(&stx) = bytes.first() else {
        return Check::Incomplete;
    };
    let (header, msgid, extra) = match stx {
        STX_V1 => {
            if bytes.len() < V1_HEADER {
                return Check::Incomplete;
            }
            (V1_HEADER, u32::from(bytes[5]), 0)
        }
        STX_V2 => {
            if bytes.len() < V2_HEADER {
                return Check::Incomplete;
            }
            if bytes[2] & !IFLAG_SIGNED != 0 {
                return Check::Invalid; // flags we do not understand: the spec says drop it
            }
            let id = u32::from_le_bytes([bytes[7], bytes[8], bytes[9], 0]);
            let sig = if bytes[2] & IFLAG_SIGNED != 0 {
                SIGNATURE
            } else {
                0
            };
            (V2_HEADER, id, sig)
        }
        _ => return Check::Invalid,
    };
    let len = usize::from(bytes[1]);
    let total = header + len + 2 + extra;
    if bytes.len() < total {
        return Check::Incomplete;
    }
    let crc = u16::from_le_bytes([bytes[header + len], bytes[header + len + 1]]);
    if crc == calculate_crc(&bytes[1..header + len], MavMessage::extra_crc(msgid)) {
        Check::Valid(total)
    } else {
        Check::Invalid
    }
}

/// One CRC-valid frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawFrame {
    bytes: Vec<u8>,
}

impl RawFrame {
    /// The frame's bytes, start byte to checksum (and signature).
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// MAVLink 1 or 2.
    pub fn version(&self) -> MavlinkVersion {
        if self.bytes[0] == STX_V1 {
            MavlinkVersion::V1
        } else {
            MavlinkVersion::V2
        }
    }

    fn header_len(&self) -> usize {
        if self.bytes[0] == STX_V1 {
            V1_HEADER
        } else {
            V2_HEADER
        }
    }

    /// Sender header: system, component, sequence.
    pub fn header(&self) -> MavHeader {
        let b = &self.bytes;
        let (seq, sys, comp) = if b[0] == STX_V1 {
            (b[2], b[3], b[4])
        } else {
            (b[4], b[5], b[6])
        };
        MavHeader {
            system_id: u32::from(sys),
            component_id: comp,
            sequence: seq,
        }
    }

    /// Message id.
    pub fn message_id(&self) -> u32 {
        let b = &self.bytes;
        if b[0] == STX_V1 {
            u32::from(b[5])
        } else {
            u32::from_le_bytes([b[7], b[8], b[9], 0])
        }
    }

    /// Whether the frame carries a MAVLink 2 signature.
    pub fn is_signed(&self) -> bool {
        self.bytes[0] == STX_V2 && self.bytes[2] & IFLAG_SIGNED != 0
    }

    /// The payload as sent (MAVLink 2 trims trailing zeros).
    pub fn payload(&self) -> &[u8] {
        let h = self.header_len();
        &self.bytes[h..h + usize::from(self.bytes[1])]
    }

    /// Decodes the message.
    pub fn decode(&self) -> Result<MavMessage, ParserError> {
        MavMessage::parse(self.version(), self.message_id(), self.payload())
    }

    /// Checks the signature with `signing` (and its replay protection). Unsigned frames pass only
    /// when the configuration allows unsigned input.
    pub fn verify(&self, signing: &SigningData) -> bool {
        if self.bytes[0] != STX_V2 {
            return allows_unsigned(signing);
        }
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.as_mut_slice()[..self.bytes.len()].copy_from_slice(&self.bytes);
        signing.verify_signature(&raw)
    }
}

fn allows_unsigned(signing: &SigningData) -> bool {
    // An all-zero raw message is unsigned: verify_signature answers with allow_unsigned.
    signing.verify_signature(&MAVLinkV2MessageRaw::new())
}

/// Finds frames in a byte stream fed in pieces. Memory stays bounded: at most one frame is kept
/// between calls.
#[derive(Debug, Default)]
pub struct FrameScanner {
    buf: Vec<u8>,
    start: usize,
    /// Bytes skipped because no frame started there.
    pub skipped_bytes: u64,
    /// Candidate frames dropped for a bad checksum or unknown flags.
    pub bad_frames: u64,
    /// Runs of skipped bytes (each run of noise or text counts once).
    pub garbage_runs: u64,
}

impl FrameScanner {
    /// An empty scanner.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.start > 0 {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// The next valid frame in what has been pushed, or `None` until more bytes arrive.
    pub fn next_frame(&mut self) -> Option<RawFrame> {
        loop {
            let rest = &self.buf[self.start..];
            let Some(at) = rest.iter().position(|&b| b == STX_V1 || b == STX_V2) else {
                self.skipped_bytes += rest.len() as u64;
                self.garbage_runs += u64::from(!rest.is_empty());
                self.start = self.buf.len();
                return None;
            };
            self.skipped_bytes += at as u64;
            self.garbage_runs += u64::from(at > 0);
            self.start += at;
            match check(&self.buf[self.start..]) {
                Check::Incomplete => return None,
                Check::Invalid => {
                    self.bad_frames += 1;
                    self.start += 1;
                }
                Check::Valid(n) => {
                    let bytes = self.buf[self.start..self.start + n].to_vec();
                    self.start += n;
                    return Some(RawFrame { bytes });
                }
            }
        }
    }
}

impl FrameScanner {
    /// The frame in `bytes` if they are exactly one valid frame.
    pub fn single(bytes: &[u8]) -> Option<RawFrame> {
        (check(bytes) == Check::Valid(bytes.len())).then(|| RawFrame {
            bytes: bytes.to_vec(),
        })
    }
}

/// Encodes a message into one frame's bytes (signed when `signing` says so).
pub fn encode(
    version: MavlinkVersion,
    header: MavHeader,
    msg: &MavMessage,
    signing: Option<&SigningData>,
) -> Vec<u8> {
    let mut out = Vec::with_capacity(64);
    // Writing into a Vec cannot fail.
    let _ = ::mavlink::write_versioned_msg_signed(&mut out, version, header, msg, signing);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ::mavlink::dialects::ardupilotmega::{
        HEARTBEAT_DATA, MavAutopilot, MavModeFlag, MavState, MavType,
    };
    use proptest::prelude::*;

    fn heartbeat(version: MavlinkVersion) -> Vec<u8> {
        let msg = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 5,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        });
        encode(
            version,
            MavHeader {
                system_id: 7,
                component_id: 1,
                sequence: 42,
            },
            &msg,
            None,
        )
    }

    #[test]
    fn finds_frames_among_boot_text_and_noise() {
        let mut bytes = b"Init ArduCopter V4.6\r\n\xFE\x09garbage".to_vec();
        bytes.extend(heartbeat(MavlinkVersion::V2));
        bytes.extend([0xFD, 0x01, 0x00]);
        bytes.extend(heartbeat(MavlinkVersion::V1));
        let mut s = FrameScanner::new();
        let mut frames = vec![];
        for chunk in bytes.chunks(5) {
            s.push(chunk);
            while let Some(f) = s.next_frame() {
                frames.push(f);
            }
        }
        assert_eq!(frames.len(), 2);
        assert_eq!(frames[0].version(), MavlinkVersion::V2);
        assert_eq!(frames[1].version(), MavlinkVersion::V1);
        for f in &frames {
            assert_eq!(
                f.header(),
                MavHeader {
                    system_id: 7,
                    component_id: 1,
                    sequence: 42
                }
            );
            match f.decode().unwrap() {
                MavMessage::HEARTBEAT(h) => assert_eq!(h.custom_mode, 5),
                m => panic!("{m:?}"),
            }
        }
        assert!(s.bad_frames >= 2);
        assert!(s.skipped_bytes > 20);
    }

    #[test]
    fn a_flipped_bit_is_a_bad_frame() {
        let mut b = heartbeat(MavlinkVersion::V2);
        b[12] ^= 0x10;
        assert_eq!(check(&b), Check::Invalid);
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_never_panic_and_memory_stays_bounded(chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..300), 0..20)) {
            let mut s = FrameScanner::new();
            for c in &chunks {
                s.push(c);
                while let Some(f) = s.next_frame() {
                    let _ = f.decode();
                }
                prop_assert!(s.buf.len() - s.start < MAX_FRAME);
            }
        }
    }
}
