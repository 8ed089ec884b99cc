//! HiPNUC's serial protocol (HI226, HI229, CH100, CH110 and kin): frames `5A A5 LEN(u16 LE)
//! CRC(u16 LE) PAYLOAD`, the CRC-16/XMODEM of the first four bytes and the payload. The
//! payload is a sequence of tagged items: the 0x91 packet (76 bytes: acceleration in g,
//! rate in °/s, quaternion w x y z, as f32) or the older items 0xA0/0xA1 acceleration
//! (i16, mg), 0xB0/0xB1 rate (i16, 0.1 °/s), 0xD1 quaternion (4 f32), 0x90 id, 0xC0 magnetic,
//! 0xD0 Euler angles, 0xF0 pressure.

use crc::{CRC_16_XMODEM, Crc};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::{G, ImuSample, ImuStats};
use crate::time::Timestamp;

const CRC16: Crc<u16> = Crc::<u16>::new(&CRC_16_XMODEM);
/// Header length: sync, length, CRC.
pub const HEADER_LEN: usize = 6;
/// Longest payload accepted (a frame holds one 0x91 packet, or legacy items).
pub const MAX_PAYLOAD: usize = 256;
/// Size of the 0x91 packet, tag included.
pub const PACKET_91_LEN: usize = 76;

/// A frame around `payload` (for simulators and tests).
pub fn frame(payload: &[u8]) -> Vec<u8> {
    let len = payload.len() as u16;
    let mut f = vec![0x5A, 0xA5];
    f.extend_from_slice(&len.to_le_bytes());
    let mut digest = CRC16.digest();
    digest.update(&f);
    digest.update(payload);
    f.extend_from_slice(&digest.finalize().to_le_bytes());
    f.extend_from_slice(payload);
    f
}

/// A 0x91 packet with acceleration (g), rate (°/s) and quaternion (w, x, y, z).
pub fn packet_91(timestamp_ms: u32, acc_g: [f32; 3], gyr_dps: [f32; 3], quat: [f32; 4]) -> Vec<u8> {
    let mut p = vec![0u8; PACKET_91_LEN];
    p[0] = 0x91;
    p[8..12].copy_from_slice(&timestamp_ms.to_le_bytes());
    let mut put = |at: usize, values: &[f32]| {
        for (i, v) in values.iter().enumerate() {
            p[at + 4 * i..at + 4 * i + 4].copy_from_slice(&v.to_le_bytes());
        }
    };
    put(12, &acc_g);
    put(24, &gyr_dps);
    put(60, &quat);
    p
}

/// Incremental decoder.
#[derive(Debug, Clone, Default)]
pub struct HiPnuc {
    buf: Vec<u8>,
    stats: ImuStats,
}

impl HiPnuc {
    /// A decoder with nothing received.
    pub fn new() -> Self {
        Self::default()
    }

    /// Counters so far.
    pub fn stats(&self) -> ImuStats {
        self.stats
    }

    /// Feeds a chunk read at `rx`.
    pub fn push(&mut self, rx: Timestamp, bytes: &[u8], mut on_sample: impl FnMut(ImuSample)) {
        self.stats.bytes_in += bytes.len() as u64;
        self.buf.extend_from_slice(bytes);
        let mut at = 0;
        loop {
            let rest = &self.buf[at..];
            if rest.len() < HEADER_LEN {
                break;
            }
            if rest[0] != 0x5A || rest[1] != 0xA5 {
                at += 1;
                self.stats.bytes_skipped += 1;
                continue;
            }
            let len = usize::from(u16::from_le_bytes([rest[2], rest[3]]));
            if len > MAX_PAYLOAD {
                at += 1;
                self.stats.bytes_skipped += 1;
                continue;
            }
            if rest.len() < HEADER_LEN + len {
                break;
            }
            let crc = u16::from_le_bytes([rest[4], rest[5]]);
            let mut digest = CRC16.digest();
            digest.update(&rest[..4]);
            digest.update(&rest[HEADER_LEN..HEADER_LEN + len]);
            if digest.finalize() != crc {
                self.stats.checksum_errors += 1;
                self.stats.bytes_skipped += 1;
                at += 1;
                continue;
            }
            self.stats.frames += 1;
            let payload = rest[HEADER_LEN..HEADER_LEN + len].to_vec();
            at += HEADER_LEN + len;
            if let Some(sample) = parse_payload(rx, &payload) {
                self.stats.samples += 1;
                on_sample(sample);
            }
        }
        self.buf.drain(..at);
    }
}

fn f32_at(p: &[u8], at: usize) -> Option<f64> {
    let b: [u8; 4] = p.get(at..at + 4)?.try_into().ok()?;
    Some(f64::from(f32::from_le_bytes(b)))
}

fn i16_at(p: &[u8], at: usize) -> Option<f64> {
    let b: [u8; 2] = p.get(at..at + 2)?.try_into().ok()?;
    Some(f64::from(i16::from_le_bytes(b)))
}

fn vec3(
    p: &[u8],
    at: usize,
    read: fn(&[u8], usize) -> Option<f64>,
    width: usize,
) -> Option<Vector3<f64>> {
    Some(Vector3::new(
        read(p, at)?,
        read(p, at + width)?,
        read(p, at + 2 * width)?,
    ))
}

fn quaternion(p: &[u8], at: usize) -> Option<UnitQuaternion<f64>> {
    let q = Quaternion::new(
        f32_at(p, at)?,
        f32_at(p, at + 4)?,
        f32_at(p, at + 8)?,
        f32_at(p, at + 12)?,
    );
    (q.norm() > 0.5).then(|| UnitQuaternion::from_quaternion(q))
}

/// A sample from a frame's payload, when it holds acceleration and rate.
fn parse_payload(rx: Timestamp, p: &[u8]) -> Option<ImuSample> {
    let mut accel = None;
    let mut gyro = None;
    let mut orientation = None;
    let mut at = 0;
    while at < p.len() {
        let step = match p[at] {
            0x91 => {
                let packet = p.get(at..at + PACKET_91_LEN)?;
                accel = vec3(packet, 12, f32_at, 4).map(|a| a * G);
                gyro = vec3(packet, 24, f32_at, 4).map(|g| g * 1f64.to_radians());
                orientation = quaternion(packet, 60);
                PACKET_91_LEN
            }
            0xA0 | 0xA1 => {
                accel = vec3(p, at + 1, i16_at, 2).map(|a| a / 1000.0 * G);
                7
            }
            0xB0 | 0xB1 => {
                gyro = vec3(p, at + 1, i16_at, 2).map(|g| g / 10.0 * 1f64.to_radians());
                7
            }
            0xD1 => {
                orientation = quaternion(p, at + 1);
                17
            }
            0x90 => 2,
            0xC0 | 0xD0 => 7,
            0xF0 => 5,
            // An unknown item: its length is unknown, so the rest cannot be read.
            _ => break,
        };
        at += step;
    }
    Some(ImuSample {
        rx,
        accel: accel?,
        gyro: gyro?,
        orientation,
    })
}
