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
/// `lod` value of a streaming fallback pixel (`--stream-fallback coarse`): the bounds of a
/// structure not resident yet, not an exact hit (`mesh` names the structure's first source
/// mesh, `primitive` is `u32::MAX`, `t` the box's entry distance).
pub const LOD_FALLBACK: u8 = 254;

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
        let (width, height) = Self::parse_header(&h)?;
        let n = (width as u64) * (height as u64);
        // Read what is there before trusting the header's size: a short stream fails before
        // anything near the claimed size is allocated.
        let want = n * std::mem::size_of::<AovRecord>() as u64;
        let mut bytes = Vec::new();
        r.take(want).read_to_end(&mut bytes)?;
        if bytes.len() as u64 != want {
            return Err(AovError::Header(format!(
                "{width}×{height} needs {want} bytes of records, the file has {}",
                bytes.len()
            )));
        }
        let mut records = vec![AovRecord::default(); n as usize];
        bytemuck::cast_slice_mut(&mut records).copy_from_slice(&bytes);
        Ok(Self {
            width,
            height,
            records,
        })
    }

    /// Checks magic, version, record size and dimensions; returns (width, height).
    fn parse_header(h: &[u8; AOV_HEADER_BYTES]) -> Result<(u32, u32), AovError> {
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
        if width == 0 || height == 0 {
            return Err(AovError::Header(format!("{width}×{height} has no pixels")));
        }
        let n = (width as u64) * (height as u64);
        if n > (1 << 28) {
            return Err(AovError::Header(format!("{width}×{height} is too large")));
        }
        Ok((width, height))
    }

    /// The whole file as bytes (header and records).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(AOV_HEADER_BYTES + self.records.len() * 16);
        self.write_to(&mut out)
            .expect("writing to a Vec cannot fail");
        out
    }

    pub fn save(&self, path: &std::path::Path) -> Result<(), AovError> {
        let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
        self.write_to(&mut f)?;
        f.flush()?;
        Ok(())
    }

    /// Reads an AOV file, checking the header's size against the file's length before
    /// allocating anything for the records.
    pub fn load(path: &std::path::Path) -> Result<Self, AovError> {
        let f = std::fs::File::open(path)?;
        let len = f.metadata()?.len();
        let mut r = std::io::BufReader::new(f);
        let mut h = [0u8; AOV_HEADER_BYTES];
        r.read_exact(&mut h).map_err(|_| {
            AovError::Header(format!(
                "the file has {len} bytes, less than the {AOV_HEADER_BYTES}-byte header"
            ))
        })?;
        let (width, height) = Self::parse_header(&h)?;
        let want = AOV_HEADER_BYTES as u64
            + (width as u64) * (height as u64) * std::mem::size_of::<AovRecord>() as u64;
        if len != want {
            return Err(AovError::Header(format!(
                "the header says {width}×{height} ({want} bytes with the header) but the file has {len} bytes"
            )));
        }
        let mut all = h.to_vec();
        all.reserve_exact((want - AOV_HEADER_BYTES as u64) as usize);
        r.read_to_end(&mut all)?;
        Self::read_from(&all[..])
    }
}

#[cfg(test)]
mod tests;
