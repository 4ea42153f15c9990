//! RGB-D camera frames and the camera frame stream: how a drone's camera reaches the station
//! when it is not in the same process (specified in `link/CAMERA.md`).
//!
//! Each message is a fixed 44-byte header followed by the colour image as JPEG and the depth image
//! as a 16-bit greyscale PNG in millimetres (lossless; 0 = no reading).

use std::io::{self, Read, Write};
use std::time::Duration;

use image::codecs::jpeg::JpegEncoder;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageBuffer, ImageEncoder, ImageFormat, Luma};

/// Pinhole camera intrinsics, pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Focal length along x.
    pub fx: f32,
    /// Focal length along y.
    pub fy: f32,
    /// Principal point x.
    pub cx: f32,
    /// Principal point y.
    pub cy: f32,
}

impl Intrinsics {
    /// A Kinect-like camera (fx = fy = 525 at 640×480) scaled to `width × height`.
    pub fn kinect(width: u32, height: u32) -> Self {
        let s = width as f32 / 640.0;
        Self {
            fx: 525.0 * s,
            fy: 525.0 * s,
            cx: (width as f32 - 1.0) / 2.0,
            cy: (height as f32 - 1.0) / 2.0,
        }
    }

    /// The angle from the optical axis to the nearer of the image's left and right edges, for
    /// an image `width` pixels wide, radians: half the horizontal field of view that is seen on
    /// both sides (0.55 for a Kinect). Negative when the principal point lies outside the image.
    pub fn half_fov_x(&self, width: u32) -> f64 {
        let (fx, cx) = (f64::from(self.fx), f64::from(self.cx));
        // Pixel centres are at whole numbers: the image spans −0.5 … width − 0.5.
        let left = (cx + 0.5) / fx;
        let right = (f64::from(width) - 0.5 - cx) / fx;
        left.min(right).atan()
    }
}

/// One RGB-D frame: colour and registered depth of the same size.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbdFrame {
    /// The camera's vehicle (index in the fleet).
    pub vehicle: u8,
    /// Capture time since the start of the run (simulated time in SITL).
    pub stamp: Duration,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// The camera's intrinsics.
    pub intrinsics: Intrinsics,
    /// Colour, RGB8, row-major from the top-left, `width × height × 3` bytes.
    pub rgb: Vec<u8>,
    /// Depth along the optical axis in millimetres, row-major, 0 = no reading.
    pub depth_mm: Vec<u16>,
}

/// Magic bytes that start every frame message.
pub const MAGIC: [u8; 4] = *b"RGBD";
/// The stream's version.
pub const VERSION: u8 = 1;
/// Header length, bytes.
pub const HEADER_LEN: usize = 44;
/// Largest accepted image side, pixels.
pub const MAX_SIDE: u32 = 4096;
/// Largest accepted compressed image, bytes.
pub const MAX_IMAGE_BYTES: u32 = 32 << 20;

/// A frame message that could not be encoded, read or decoded.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// The stream failed or ended.
    #[error("camera stream: {0}")]
    Io(#[from] io::Error),
    /// The bytes are not a frame message of this version.
    #[error("camera stream: not a frame message: {0}")]
    Format(String),
    /// An image inside the message could not be decoded or encoded.
    #[error("camera stream: {0}")]
    Image(String),
}

impl RgbdFrame {
    /// Checks that the images match the stated size.
    pub fn validate(&self) -> Result<(), CameraError> {
        let n = self.width as usize * self.height as usize;
        if self.width == 0 || self.height == 0 || self.width > MAX_SIDE || self.height > MAX_SIDE {
            return Err(CameraError::Format(format!(
                "image size {}×{} is outside 1..={MAX_SIDE}",
                self.width, self.height
            )));
        }
        if self.rgb.len() != n * 3 || self.depth_mm.len() != n {
            return Err(CameraError::Format(format!(
                "{}×{} frame has {} colour bytes and {} depth pixels",
                self.width,
                self.height,
                self.rgb.len(),
                self.depth_mm.len()
            )));
        }
        Ok(())
    }

    /// Encodes the frame as one message (JPEG colour at `quality`, PNG depth).
    pub fn encode(&self, quality: u8) -> Result<Vec<u8>, CameraError> {
        self.validate()?;
        let mut colour = vec![];
        JpegEncoder::new_with_quality(&mut colour, quality.clamp(1, 100))
            .encode(&self.rgb, self.width, self.height, ExtendedColorType::Rgb8)
            .map_err(|e| CameraError::Image(format!("JPEG encoding failed: {e}")))?;
        let depth: ImageBuffer<Luma<u16>, &[u16]> =
            ImageBuffer::from_raw(self.width, self.height, &self.depth_mm[..])
                .ok_or_else(|| CameraError::Format("depth size".into()))?;
        let mut depth_png = vec![];
        let bytes: Vec<u8> = depth
            .as_raw()
            .iter()
            .flat_map(|d| d.to_ne_bytes())
            .collect();
        PngEncoder::new_with_quality(&mut depth_png, CompressionType::Fast, FilterType::Sub)
            .write_image(&bytes, self.width, self.height, ExtendedColorType::L16)
            .map_err(|e| CameraError::Image(format!("PNG encoding failed: {e}")))?;
        let mut out = Vec::with_capacity(HEADER_LEN + colour.len() + depth_png.len());
        out.extend_from_slice(&MAGIC);
        out.push(VERSION);
        out.push(self.vehicle);
        out.extend_from_slice(&[0, 0]);
        out.extend_from_slice(&(self.stamp.as_micros() as u64).to_le_bytes());
        out.extend_from_slice(&(self.width as u16).to_le_bytes());
        out.extend_from_slice(&(self.height as u16).to_le_bytes());
        let k = self.intrinsics;
        for v in [k.fx, k.fy, k.cx, k.cy] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&(colour.len() as u32).to_le_bytes());
        out.extend_from_slice(&(depth_png.len() as u32).to_le_bytes());
        out.extend_from_slice(&colour);
        out.extend_from_slice(&depth_png);
        Ok(out)
    }

    /// Writes the frame as one message.
    pub fn write_to(&self, w: &mut impl Write, quality: u8) -> Result<(), CameraError> {
        w.write_all(&self.encode(quality)?)?;
        Ok(())
    }

    /// Reads one message from a stream. A message that is malformed leaves the stream at an
    /// unknown position: close it.
    pub fn read_from(r: &mut impl Read) -> Result<Self, CameraError> {
        let mut head = [0u8; HEADER_LEN];
        r.read_exact(&mut head)?;
        let header = Header::parse(&head)?;
        let mut body = vec![0u8; header.colour_len as usize + header.depth_len as usize];
        r.read_exact(&mut body)?;
        header.decode(&body)
    }

    /// Decodes one whole message.
    pub fn decode(bytes: &[u8]) -> Result<Self, CameraError> {
        let head = bytes.get(..HEADER_LEN).ok_or_else(|| {
            CameraError::Format(format!("{} bytes is shorter than a header", bytes.len()))
        })?;
        let header = Header::parse(head)?;
        let body = &bytes[HEADER_LEN..];
        let want = header.colour_len as usize + header.depth_len as usize;
        if body.len() != want {
            return Err(CameraError::Format(format!(
                "header announces {want} image bytes, message has {}",
                body.len()
            )));
        }
        header.decode(body)
    }
}

struct Header {
    vehicle: u8,
    stamp: Duration,
    width: u32,
    height: u32,
    intrinsics: Intrinsics,
    colour_len: u32,
    depth_len: u32,
}

impl Header {
    fn parse(h: &[u8]) -> Result<Self, CameraError> {
        let u16_at = |i: usize| u16::from_le_bytes([h[i], h[i + 1]]);
        let u32_at = |i: usize| u32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
        let f32_at = |i: usize| f32::from_bits(u32_at(i));
        if h[..4] != MAGIC {
            return Err(CameraError::Format(format!(
                "bad magic {:02x?} (expected \"RGBD\")",
                &h[..4]
            )));
        }
        if h[4] != VERSION {
            return Err(CameraError::Format(format!(
                "version {} (this station reads version {VERSION})",
                h[4]
            )));
        }
        let mut stamp_bytes = [0u8; 8];
        stamp_bytes.copy_from_slice(&h[8..16]);
        let header = Self {
            vehicle: h[5],
            stamp: Duration::from_micros(u64::from_le_bytes(stamp_bytes)),
            width: u32::from(u16_at(16)),
            height: u32::from(u16_at(18)),
            intrinsics: Intrinsics {
                fx: f32_at(20),
                fy: f32_at(24),
                cx: f32_at(28),
                cy: f32_at(32),
            },
            colour_len: u32_at(36),
            depth_len: u32_at(40),
        };
        let k = header.intrinsics;
        if ![k.fx, k.fy, k.cx, k.cy].iter().all(|v| v.is_finite()) || k.fx <= 0.0 || k.fy <= 0.0 {
            return Err(CameraError::Format(format!("bad intrinsics {k:?}")));
        }
        if header.width == 0
            || header.height == 0
            || header.width > MAX_SIDE
            || header.height > MAX_SIDE
        {
            return Err(CameraError::Format(format!(
                "image size {}×{} is outside 1..={MAX_SIDE}",
                header.width, header.height
            )));
        }
        if header.colour_len > MAX_IMAGE_BYTES || header.depth_len > MAX_IMAGE_BYTES {
            return Err(CameraError::Format(format!(
                "image lengths {} and {} exceed {MAX_IMAGE_BYTES} bytes",
                header.colour_len, header.depth_len
            )));
        }
        Ok(header)
    }

    fn decode(self, body: &[u8]) -> Result<RgbdFrame, CameraError> {
        let (colour, depth) = body.split_at(self.colour_len as usize);
        let rgb = bounded_reader(colour, ImageFormat::Jpeg)
            .decode()
            .map_err(|e| CameraError::Image(format!("colour image: {e}")))?
            .into_rgb8();
        let depth = bounded_reader(depth, ImageFormat::Png)
            .decode()
            .map_err(|e| CameraError::Image(format!("depth image: {e}")))?;
        if !matches!(depth.color(), image::ColorType::L16) {
            return Err(CameraError::Image(format!(
                "depth image is {:?}, expected 16-bit greyscale",
                depth.color()
            )));
        }
        let depth = depth.into_luma16();
        for (what, (w, h)) in [("colour", rgb.dimensions()), ("depth", depth.dimensions())] {
            if (w, h) != (self.width, self.height) {
                return Err(CameraError::Format(format!(
                    "{what} image is {w}×{h}, header says {}×{}",
                    self.width, self.height
                )));
            }
        }
        Ok(RgbdFrame {
            vehicle: self.vehicle,
            stamp: self.stamp,
            width: self.width,
            height: self.height,
            intrinsics: self.intrinsics,
            rgb: rgb.into_raw(),
            depth_mm: depth.into_raw(),
        })
    }
}

/// An image reader that refuses images larger than the stream allows, whatever they claim.
fn bounded_reader(bytes: &[u8], format: ImageFormat) -> image::ImageReader<io::Cursor<&[u8]>> {
    let mut reader = image::ImageReader::with_format(io::Cursor::new(bytes), format);
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_SIDE);
    limits.max_image_height = Some(MAX_SIDE);
    limits.max_alloc = Some(256 << 20);
    reader.limits(limits);
    reader
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> RgbdFrame {
        let (w, h) = (32u32, 24u32);
        RgbdFrame {
            vehicle: 3,
            stamp: Duration::from_micros(1_234_567),
            width: w,
            height: h,
            intrinsics: Intrinsics::kinect(w, h),
            rgb: (0..w * h * 3).map(|i| ((i / 3) % 7 * 30) as u8).collect(),
            depth_mm: (0..w * h)
                .map(|i| if i % 5 == 0 { 0 } else { 400 + i as u16 * 3 })
                .collect(),
        }
    }

    #[test]
    fn the_field_of_view_is_the_narrower_side_of_the_principal_point() {
        let kinect = Intrinsics::kinect(640, 480);
        assert!((kinect.half_fov_x(640) - (320.0f64 / 525.0).atan()).abs() < 1e-9);
        assert!((kinect.half_fov_x(640).to_degrees() - 31.4).abs() < 0.1);
        // The same lens at a quarter of the resolution sees the same angle.
        let small = Intrinsics::kinect(160, 120);
        assert!((small.half_fov_x(160) - kinect.half_fov_x(640)).abs() < 1e-6);
        // Off-centre to the right: the left side is the wider, the right one counts.
        let off = Intrinsics {
            cx: 419.5,
            ..kinect
        };
        assert!((off.half_fov_x(640) - (220.0f64 / 525.0).atan()).abs() < 1e-9);
        // A principal point beyond the image's edge sees nothing on that side.
        let outside = Intrinsics {
            cx: 700.0,
            ..kinect
        };
        assert!(outside.half_fov_x(640) < 0.0);
    }

    #[test]
    fn round_trip_keeps_depth_exactly_and_colour_closely() {
        let f = frame();
        let bytes = f.encode(95).unwrap();
        assert_eq!(&bytes[..4], b"RGBD");
        let g = RgbdFrame::decode(&bytes).unwrap();
        assert_eq!(g.depth_mm, f.depth_mm);
        assert_eq!(
            (g.vehicle, g.stamp, g.width, g.height),
            (3, f.stamp, 32, 24)
        );
        assert_eq!(g.intrinsics, f.intrinsics);
        let err: f64 = f
            .rgb
            .iter()
            .zip(&g.rgb)
            .map(|(a, b)| (f64::from(*a) - f64::from(*b)).abs())
            .sum::<f64>()
            / f.rgb.len() as f64;
        assert!(err < 6.0, "mean colour error {err}");
        // And through a stream, twice in a row.
        let mut stream = bytes.clone();
        stream.extend(&bytes);
        let mut r = io::Cursor::new(stream);
        for _ in 0..2 {
            assert_eq!(RgbdFrame::read_from(&mut r).unwrap().depth_mm, f.depth_mm);
        }
        assert!(matches!(
            RgbdFrame::read_from(&mut r),
            Err(CameraError::Io(_))
        ));
    }

    #[test]
    fn malformed_messages_are_errors_that_say_why() {
        let bytes = frame().encode(90).unwrap();
        let mut bad = bytes.clone();
        bad[0] = b'X';
        assert!(
            RgbdFrame::decode(&bad)
                .unwrap_err()
                .to_string()
                .contains("bad magic")
        );
        let mut bad = bytes.clone();
        bad[4] = 9;
        assert!(
            RgbdFrame::decode(&bad)
                .unwrap_err()
                .to_string()
                .contains("version 9")
        );
        let mut bad = bytes.clone();
        bad[16..18].copy_from_slice(&33u16.to_le_bytes());
        assert!(
            RgbdFrame::decode(&bad)
                .unwrap_err()
                .to_string()
                .contains("header says 33×24")
        );
        let mut bad = bytes.clone();
        bad[36..40].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(
            RgbdFrame::decode(&bad)
                .unwrap_err()
                .to_string()
                .contains("exceed")
        );
        assert!(RgbdFrame::decode(&bytes[..bytes.len() - 1]).is_err());
        assert!(
            RgbdFrame::decode(&bytes[..10])
                .unwrap_err()
                .to_string()
                .contains("shorter")
        );
        let mut bad = bytes;
        let n = bad.len();
        bad[n - 20] ^= 0xFF; // inside the depth PNG
        assert!(RgbdFrame::decode(&bad).is_err());
    }

    /// A message written by this version (fixture in `link/tests/fixtures`): the format must stay
    /// readable.
    #[test]
    fn the_fixture_message_decodes_to_its_known_content() {
        let bytes = include_bytes!("../tests/fixtures/rgbd-32x24.bin");
        assert_eq!(&bytes[..8], b"RGBD\x01\x01\x00\x00");
        let f = RgbdFrame::decode(bytes).unwrap();
        assert_eq!((f.vehicle, f.width, f.height), (1, 32, 24));
        assert_eq!(f.stamp, Duration::from_micros(2_500_000));
        assert_eq!(f.intrinsics, Intrinsics::kinect(32, 24));
        let want: Vec<u16> = (0..32 * 24)
            .map(|i: u32| {
                if i.is_multiple_of(7) {
                    0
                } else {
                    400 + (i as u16 * 5) % 3600
                }
            })
            .collect();
        assert_eq!(f.depth_mm, want);
    }

    #[test]
    fn inconsistent_frames_are_not_encoded() {
        let mut f = frame();
        f.depth_mm.pop();
        assert!(
            f.encode(90)
                .unwrap_err()
                .to_string()
                .contains("767 depth pixels")
        );
    }

    proptest::proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..200)) {
            let mut with_header = frame().encode(90).unwrap()[..HEADER_LEN].to_vec();
            with_header[36..44].copy_from_slice(&[100, 0, 0, 0, 100, 0, 0, 0]);
            with_header.extend(&bytes);
            let _ = RgbdFrame::decode(&with_header);
            let _ = RgbdFrame::decode(&bytes);
        }
    }
}
