//! The AOV file: the per-pixel hit record every backend writes and `motu compare` reads.
//!
//! Layout (little-endian): a 32-byte header — magic `b"MOTUAOV\0"`, `version: u32` (1),
//! `width: u32`, `height: u32`, `record_size: u32` (16), `reserved: u64` (0) — then
//! `width × height` [`AovRecord`]s in row-major order, row 0 at the top.

use bytemuck::{Pod, Zeroable};
use std::io::{Read, Write};

pub const AOV_MAGIC: [u8; 8] = *b"MOTUAOV\0";
pub const AOV_VERSION: u32 = 1;
pub const AOV_HEADER_BYTES: usize = 32;
/// `mesh` value of a miss.
pub const MISS: u32 = u32::MAX;

#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct AovRecord {
    /// Source mesh id, or [`MISS`].
    pub mesh: u32,
    /// Triangle index within the source mesh (of the LOD level's mesh when `lod > 0`).
    pub primitive: u32,
    /// World-space hit distance along the unit primary ray.
    pub t: f32,
    pub lod: u8,
    pub _pad: u8,
    /// Ray traces (`traceRayEXT` / ray queries / CPU TLAS walks) spent on this pixel.
    pub traces: u16,
}

impl AovRecord {
    pub const MISS: Self = Self {
        mesh: MISS,
        primitive: 0,
        t: 0.0,
        lod: 0,
        _pad: 0,
        traces: 0,
    };
}

#[derive(Debug, thiserror::Error)]
pub enum AovError {
    #[error("AOV I/O: {0}")]
    Io(#[from] std::io::Error),
    #[error("not an AOV file (bad magic)")]
    BadMagic,
    #[error("AOV version {found} is not supported (this build reads {AOV_VERSION})")]
    Version { found: u32 },
    #[error("AOV header: {0}")]
    Header(String),
}

#[derive(Clone, Debug, PartialEq)]
pub struct Aov {
    pub width: u32,
    pub height: u32,
    pub records: Vec<AovRecord>,
}

impl Aov {
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            records: vec![AovRecord::MISS; width as usize * height as usize],
        }
    }

    pub fn write_to(&self, mut w: impl Write) -> Result<(), AovError> {
        let mut h = [0u8; AOV_HEADER_BYTES];
        h[..8].copy_from_slice(&AOV_MAGIC);
        h[8..12].copy_from_slice(&AOV_VERSION.to_le_bytes());
        h[12..16].copy_from_slice(&self.width.to_le_bytes());
        h[16..20].copy_from_slice(&self.height.to_le_bytes());
        h[20..24].copy_from_slice(&(std::mem::size_of::<AovRecord>() as u32).to_le_bytes());
        w.write_all(&h)?;
        // Records are little-endian on every platform motu targets (x86-64, aarch64).
        w.write_all(bytemuck::cast_slice(&self.records))?;
        Ok(())
    }

    pub fn read_from(mut r: impl Read) -> Result<Self, AovError> {
        let mut h = [0u8; AOV_HEADER_BYTES];
        r.read_exact(&mut h)?;
        if h[..8] != AOV_MAGIC {
            return Err(AovError::BadMagic);
        }
        let u = |i: usize| u32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
        let (version, width, height, rs) = (u(8), u(12), u(16), u(20));
        if version != AOV_VERSION {
            return Err(AovError::Version { found: version });
        }
        if rs as usize != std::mem::size_of::<AovRecord>() {
            return Err(AovError::Header(format!("record size {rs}, expected 16")));
        }
        let n = (width as u64) * (height as u64);
        if n > (1 << 28) {
            return Err(AovError::Header(format!("{width}×{height} is too large")));
        }
        let mut records = vec![AovRecord::default(); n as usize];
        r.read_exact(bytemuck::cast_slice_mut(&mut records))?;
        Ok(Self {
            width,
            height,
            records,
        })
    }

    pub fn save(&self, path: &std::path::Path) -> Result<(), AovError> {
        let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
        self.write_to(&mut f)?;
        f.flush()?;
        Ok(())
    }

    pub fn load(path: &std::path::Path) -> Result<Self, AovError> {
        Self::read_from(std::io::BufReader::new(std::fs::File::open(path)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_rejects_garbage() {
        let mut a = Aov::new(3, 2);
        a.records[4] = AovRecord {
            mesh: 7,
            primitive: 9,
            t: 1.5,
            lod: 2,
            _pad: 0,
            traces: 3,
        };
        let mut bytes = Vec::new();
        a.write_to(&mut bytes).unwrap();
        assert_eq!(bytes.len(), 32 + 6 * 16);
        assert_eq!(Aov::read_from(&bytes[..]).unwrap(), a);
        assert!(matches!(
            Aov::read_from(&b"PNG....."[..]),
            Err(AovError::Io(_))
        ));
        let mut bad = bytes.clone();
        bad[0] = b'X';
        assert!(matches!(Aov::read_from(&bad[..]), Err(AovError::BadMagic)));
        assert!(Aov::read_from(&bytes[..40]).is_err());
    }
}
