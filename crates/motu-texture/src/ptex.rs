//! Ptex files (`.ptx`): a reader of the documented format's level-0 face data, and a writer
//! tests use to make their own files.
//!
//! Why a reader of our own rather than libptex through FFI: the import needs only the header,
//! the face table and each face's finest level (about 300 lines with `flate2`), while FFI
//! would bring `unsafe` outside `motu-vk`, a C++ build dependency on every CI machine and a
//! writer we could not use without it. The layout (Ptex's `PtexIO.h`): a 64-byte header,
//! an extended header, the zlib-compressed face infos (20 bytes each: `ulog2 vlog2` as `i8`,
//! adjacent edges, flags, four adjacent faces), the compressed constant data, one 16-byte
//! level info per level, then each level: its compressed face-data headers (a `u32` per face:
//! block size in the low 30 bits, encoding in the top 2) followed by the faces' blocks.
//! Encodings: constant (one pixel), zipped (the face's channel planes one after another,
//! zlib), diff-zipped (the same with 8/16-bit values stored as differences of the previous
//! one), tiled (tile resolution, the compressed size of the tile headers, the tile headers and
//! the tiles, each a block of its own). Edits (rare, appended by old tools) are not applied.
//!
//! Colour: 8-bit data is taken as sRGB-encoded (pbrt-v4's default for 8-bit Ptex), 16-bit,
//! half and float data as linear. One channel is grey; with an alpha channel (the header's
//! `alphachan`), its value is kept as coverage.

use std::io::{Read, Write};
use std::path::Path;

use motu_abi::ptex::PtexFace;

use crate::{half, io_err, pack, LinearImage, TextureError};

const MAGIC: &[u8; 4] = b"Ptex";
const HEADER_BYTES: usize = 64;
const FACE_INFO_BYTES: usize = 20;
const LEVEL_INFO_BYTES: usize = 16;
const ENC_CONSTANT: u32 = 0;
const ENC_ZIPPED: u32 = 1;
const ENC_DIFFZIPPED: u32 = 2;
const ENC_TILED: u32 = 3;
/// Largest face edge a file may declare (2^15 texels; real files stay far below), and the
/// largest face (2^24 texels): a corrupt header cannot ask for more memory than that.
const MAX_LOG2: u8 = 15;
const MAX_LOG2_AREA: i8 = 24;
/// Most channels a file may declare.
const MAX_CHANNELS: usize = 64;

/// Ptex data types (`Ptex::DataType`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataType {
    U8,
    U16,
    Half,
    F32,
}

impl DataType {
    fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::U8,
            1 => Self::U16,
            2 => Self::Half,
            3 => Self::F32,
            _ => return None,
        })
    }

    fn code(self) -> u32 {
        match self {
            Self::U8 => 0,
            Self::U16 => 1,
            Self::Half => 2,
            Self::F32 => 3,
        }
    }

    pub fn size(self) -> usize {
        match self {
            Self::U8 => 1,
            Self::U16 | Self::Half => 2,
            Self::F32 => 4,
        }
    }
}

/// A file's level 0: per face its resolution and pixels, each channel as a float in the data
/// type's own scale (8/16-bit: 0–1; half and float: as stored).
#[derive(Clone, Debug, PartialEq)]
pub struct PtexImage {
    pub data_type: DataType,
    pub channels: usize,
    /// The alpha channel's index, if any.
    pub alpha: Option<usize>,
    /// Per face: `(ulog2, vlog2, pixels)`, `channels` floats a pixel, row-major from v = 0.
    pub faces: Vec<(u8, u8, Vec<f32>)>,
}

struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| {
            format!(
                "truncated: {n} bytes wanted at byte {}, the file has {}",
                self.at,
                self.bytes.len()
            )
        })?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn unzip(data: &[u8], want: usize, what: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(want.min(data.len().saturating_mul(1032)));
    flate2::read::ZlibDecoder::new(data)
        .take(want as u64 + 1)
        .read_to_end(&mut out)
        .map_err(|e| format!("{what}: {e}"))?;
    if out.len() != want {
        return Err(format!(
            "{what}: inflates to {} bytes, {want} expected",
            out.len()
        ));
    }
    Ok(out)
}

fn half_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = i32::from((h >> 10) & 0x1f);
    let frac = f32::from(h & 0x3ff);
    match exp {
        0 => sign * frac * 2f32.powi(-24),
        31 if frac == 0.0 => sign * f32::INFINITY,
        31 => f32::NAN,
        _ => sign * (1.0 + frac / 1024.0) * 2f32.powi(exp - 15),
    }
}

struct Layout {
    data_type: DataType,
    channels: usize,
}

impl Layout {
    fn pixel_bytes(&self) -> usize {
        self.data_type.size() * self.channels
    }

    fn value(&self, b: &[u8]) -> f32 {
        match self.data_type {
            DataType::U8 => f32::from(b[0]) / 255.0,
            DataType::U16 => f32::from(u16::from_le_bytes([b[0], b[1]])) / 65535.0,
            DataType::Half => half_to_f32(u16::from_le_bytes([b[0], b[1]])),
            DataType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        }
    }

    /// One face block at `at` (`ulog2 × vlog2` pixels) into interleaved floats.
    fn block(
        &self,
        bytes: &[u8],
        at: usize,
        header: u32,
        res: (u8, u8),
    ) -> Result<Vec<f32>, String> {
        let size = (header & 0x3fff_ffff) as usize;
        let enc = header >> 30;
        let (w, h) = (1usize << res.0, 1usize << res.1);
        let ps = self.pixel_bytes();
        let block = bytes
            .get(at..at.saturating_add(size))
            .ok_or_else(|| format!("face block of {size} bytes at byte {at} is past the end"))?;
        match enc {
            ENC_CONSTANT => {
                let px = block
                    .get(..ps)
                    .ok_or("constant face block shorter than a pixel")?;
                let one: Vec<f32> = px
                    .chunks(self.data_type.size())
                    .map(|c| self.value(c))
                    .collect();
                Ok(one.repeat(w * h))
            }
            ENC_ZIPPED | ENC_DIFFZIPPED => {
                let mut planar = unzip(block, w * h * ps, "face data")?;
                if enc == ENC_DIFFZIPPED {
                    match self.data_type {
                        DataType::U8 => {
                            let mut prev = 0u8;
                            for v in &mut planar {
                                prev = prev.wrapping_add(*v);
                                *v = prev;
                            }
                        }
                        DataType::U16 => {
                            let mut prev = 0u16;
                            for c in planar.chunks_mut(2) {
                                prev = prev.wrapping_add(u16::from_le_bytes([c[0], c[1]]));
                                c.copy_from_slice(&prev.to_le_bytes());
                            }
                        }
                        _ => {}
                    }
                }
                let ds = self.data_type.size();
                let mut out = vec![0f32; w * h * self.channels];
                for c in 0..self.channels {
                    for p in 0..w * h {
                        let at = (c * w * h + p) * ds;
                        out[p * self.channels + c] = self.value(&planar[at..at + ds]);
                    }
                }
                Ok(out)
            }
            _ => {
                // Tiled: tile resolution, the tile headers' compressed size, the headers, the
                // tiles one after another.
                let tres = block.get(..6).ok_or("tiled face block too short")?;
                let (tu, tv) = (tres[0] as i8, tres[1] as i8);
                if tu < 0 || tv < 0 || tu as u8 > res.0 || tv as u8 > res.1 {
                    return Err(format!(
                        "tile resolution {tu}×{tv} (log2) does not fit the face"
                    ));
                }
                let (tu, tv) = (tu as u8, tv as u8);
                let zipped = u32_at(tres, 2) as usize;
                let (nu, nv) = (1usize << (res.0 - tu), 1usize << (res.1 - tv));
                let hz = block
                    .get(6..6usize.saturating_add(zipped))
                    .ok_or("tile headers past the face block")?;
                let headers = unzip(hz, 4 * nu * nv, "tile headers")?;
                let mut pos = at + 6 + zipped;
                let (tw, th) = (1usize << tu, 1usize << tv);
                let mut out = vec![0f32; w * h * self.channels];
                for t in 0..nu * nv {
                    let th_word = u32_at(&headers, 4 * t);
                    if th_word >> 30 == ENC_TILED {
                        return Err("a tile is itself tiled".into());
                    }
                    let tile = self.block(bytes, pos, th_word, (tu, tv))?;
                    pos += (th_word & 0x3fff_ffff) as usize;
                    let (ox, oy) = ((t % nu) * tw, (t / nu) * th);
                    for y in 0..th {
                        let src = &tile[y * tw * self.channels..(y + 1) * tw * self.channels];
                        let d = ((oy + y) * w + ox) * self.channels;
                        out[d..d + tw * self.channels].copy_from_slice(src);
                    }
                }
                Ok(out)
            }
        }
    }
}

/// Why bytes are not a Ptex file this reader takes (the reason in words): the cause of
/// [`TextureError::Ptex`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct PtexFormatError(pub String);

impl From<String> for PtexFormatError {
    fn from(reason: String) -> PtexFormatError {
        PtexFormatError(reason)
    }
}

impl From<&str> for PtexFormatError {
    fn from(reason: &str) -> PtexFormatError {
        PtexFormatError(reason.to_string())
    }
}

/// Parses a Ptex file's level 0 (every face in memory: tests and small files).
pub fn parse(bytes: &[u8]) -> Result<PtexImage, PtexFormatError> {
    let mut faces = Vec::new();
    let h = read_faces(bytes, |_, u, v, px| faces.push((u, v, px)))?;
    Ok(PtexImage {
        data_type: h.data_type,
        channels: h.channels,
        alpha: h.alpha,
        faces,
    })
}

/// What the header says about the pixels.
#[derive(Clone, Copy, Debug)]
pub struct PixelFormat {
    pub data_type: DataType,
    pub channels: usize,
    pub alpha: Option<usize>,
}

/// Reads level 0 face by face, handing each face's `(ulog2, vlog2, pixels)` to `each` (a
/// constant face as one pixel, 1×1), so a file is never held as floats whole.
pub fn read_faces(
    bytes: &[u8],
    each: impl FnMut(&PixelFormat, u8, u8, Vec<f32>),
) -> Result<PixelFormat, PtexFormatError> {
    read_level0(bytes, each).map_err(PtexFormatError)
}

/// [`read_faces`], its reason in words.
fn read_level0(
    bytes: &[u8],
    mut each: impl FnMut(&PixelFormat, u8, u8, Vec<f32>),
) -> Result<PixelFormat, String> {
    if bytes.len() < HEADER_BYTES || &bytes[..4] != MAGIC {
        return Err("not a Ptex file (no \"Ptex\" magic)".into());
    }
    let h = &bytes[..HEADER_BYTES];
    let version = u32_at(h, 4);
    if version != 1 {
        return Err(format!("Ptex version {version} (only 1 is read)"));
    }
    let data_type =
        DataType::from_u32(u32_at(h, 12)).ok_or_else(|| format!("data type {}", u32_at(h, 12)))?;
    let alphachan = u32_at(h, 16) as i32;
    let channels = usize::from(u16::from_le_bytes([h[20], h[21]]));
    let levels = usize::from(u16::from_le_bytes([h[22], h[23]]));
    let faces = u32_at(h, 24) as usize;
    let ext = u32_at(h, 28) as usize;
    let faceinfo_zip = u32_at(h, 32) as usize;
    let constdata_zip = u32_at(h, 36) as usize;
    let levelinfo = u32_at(h, 40) as usize;
    if !(1..=MAX_CHANNELS).contains(&channels) || levels == 0 {
        return Err(format!("{channels} channels, {levels} levels"));
    }
    if faces > bytes.len() {
        return Err(format!("{faces} faces in a file of {} bytes", bytes.len()));
    }
    let mut c = Cursor {
        bytes,
        at: HEADER_BYTES,
    };
    c.take(ext)?;
    let info = unzip(c.take(faceinfo_zip)?, faces * FACE_INFO_BYTES, "face infos")?;
    c.take(constdata_zip)?;
    let li = c.take(levelinfo)?;
    if li.len() < LEVEL_INFO_BYTES {
        return Err("no level info".into());
    }
    let (header_zip, level_faces) = (u32_at(li, 8) as usize, u32_at(li, 12) as usize);
    if level_faces != faces {
        return Err(format!("level 0 has {level_faces} faces, the file {faces}"));
    }
    let fdh = unzip(c.take(header_zip)?, 4 * faces, "face data headers")?;
    let layout = Layout {
        data_type,
        channels,
    };
    let format = PixelFormat {
        data_type,
        channels,
        alpha: usize::try_from(alphachan).ok().filter(|&a| a < channels),
    };
    let mut pos = c.at;
    for f in 0..faces {
        let (u, v) = (
            info[f * FACE_INFO_BYTES] as i8,
            info[f * FACE_INFO_BYTES + 1] as i8,
        );
        if u < 0 || v < 0 || u as u8 > MAX_LOG2 || v as u8 > MAX_LOG2 || u + v > MAX_LOG2_AREA {
            return Err(format!("face {f}: resolution 2^{u} × 2^{v}"));
        }
        let header = u32_at(&fdh, 4 * f);
        let res = if header >> 30 == ENC_CONSTANT {
            (0, 0)
        } else {
            (u as u8, v as u8)
        };
        let pixels = layout
            .block(bytes, pos, header, res)
            .map_err(|e| format!("face {f}: {e}"))?;
        pos += (header & 0x3fff_ffff) as usize;
        each(&format, res.0, res.1, pixels);
    }
    Ok(format)
}

/// Reads `path`'s level 0 and resamples every face to at most `max_edge` texels an edge
/// (2×2 box filter in linear light; an axis alone is halved while only it exceeds the cap):
/// RGBA8 texels for the package's texel store.
pub fn load(path: &Path, max_edge: u32) -> Result<Vec<PtexFace>, TextureError> {
    let bytes = std::fs::read(path).map_err(|e| io_err(path, e))?;
    let mut faces = Vec::new();
    read_faces(&bytes, |format, u, v, px| {
        faces.push(resample_face(format, u, v, &px, max_edge));
    })
    .map_err(|source| TextureError::Ptex {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(faces)
}

/// The faces of `img` as RGBA8 (colour sRGB-encoded), each edge at most `max_edge` texels.
pub fn resample(img: &PtexImage, max_edge: u32) -> Vec<PtexFace> {
    let format = PixelFormat {
        data_type: img.data_type,
        channels: img.channels,
        alpha: img.alpha,
    };
    img.faces
        .iter()
        .map(|(u, v, px)| resample_face(&format, *u, *v, px, max_edge))
        .collect()
}

/// One face (`channels` floats a pixel) as RGBA8, each edge at most `max_edge` texels.
pub fn resample_face(f: &PixelFormat, u: u8, v: u8, px: &[f32], max_edge: u32) -> PtexFace {
    let cap = max_edge.max(1);
    let srgb = f.data_type == DataType::U8;
    let n = f.channels;
    let texels = px
        .chunks(n)
        .map(|p| {
            let colour = |c: usize| {
                let x = p[c.min(n - 1)];
                if srgb {
                    crate::srgb_to_linear(x)
                } else {
                    x
                }
            };
            let rgb = if n >= 3 && f.alpha.is_none_or(|a| a >= 3) {
                [colour(0), colour(1), colour(2)]
            } else {
                [colour(0); 3]
            };
            let a = f.alpha.map_or(1.0, |a| p[a]);
            [rgb[0], rgb[1], rgb[2], a]
        })
        .collect();
    let mut face = LinearImage {
        width: 1 << u,
        height: 1 << v,
        texels,
    };
    while face.width > cap || face.height > cap {
        face = if face.width > cap && face.height > cap {
            half(&face)
        } else {
            half_axis(&face, face.width > cap)
        };
    }
    PtexFace {
        ulog2: face.width.trailing_zeros() as u8,
        vlog2: face.height.trailing_zeros() as u8,
        texels: pack(&face),
    }
}

/// Halves one axis (`x`: the width) with a 2-texel box.
fn half_axis(img: &LinearImage, x: bool) -> LinearImage {
    let (w, h) = if x {
        (img.width / 2, img.height)
    } else {
        (img.width, img.height / 2)
    };
    let mut texels = Vec::with_capacity((w * h) as usize);
    for j in 0..h {
        for i in 0..w {
            let (a, b) = if x {
                ((2 * i, j), (2 * i + 1, j))
            } else {
                ((i, 2 * j), (i, 2 * j + 1))
            };
            let ta = img.texels[(a.1 * img.width + a.0) as usize];
            let tb = img.texels[(b.1 * img.width + b.0) as usize];
            texels.push(std::array::from_fn(|k| 0.5 * (ta[k] + tb[k])));
        }
    }
    LinearImage {
        width: w,
        height: h,
        texels,
    }
}

/// How [`write`] stores a face.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// One pixel (the face's first).
    Constant,
    Zipped,
    /// Differences of 8/16-bit values, zipped.
    DiffZipped,
    /// Tiles of `2^a × 2^b` texels, each zipped.
    Tiled(u8, u8),
}

/// One face for [`write`]: resolution and interleaved little-endian pixels of the file's type.
#[derive(Clone, Debug)]
pub struct WriteFace {
    pub ulog2: u8,
    pub vlog2: u8,
    pub data: Vec<u8>,
    pub encoding: Encoding,
}

fn zip(data: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(data).expect("writing to a Vec");
    e.finish().expect("writing to a Vec")
}

fn planar(data: &[u8], ds: usize, channels: usize, diff: bool) -> Vec<u8> {
    let pixels = data.len() / (ds * channels);
    let mut out = Vec::with_capacity(data.len());
    for c in 0..channels {
        for p in 0..pixels {
            let at = (p * channels + c) * ds;
            out.extend_from_slice(&data[at..at + ds]);
        }
    }
    if diff && ds == 1 {
        let mut prev = 0u8;
        for v in &mut out {
            let cur = *v;
            *v = cur.wrapping_sub(prev);
            prev = cur;
        }
    } else if diff && ds == 2 {
        let mut prev = 0u16;
        for c in out.chunks_mut(2) {
            let cur = u16::from_le_bytes([c[0], c[1]]);
            c.copy_from_slice(&cur.wrapping_sub(prev).to_le_bytes());
            prev = cur;
        }
    }
    out
}

fn face_block(
    data: &[u8],
    res: (u8, u8),
    ds: usize,
    channels: usize,
    enc: Encoding,
) -> (u32, Vec<u8>) {
    let ps = ds * channels;
    match enc {
        Encoding::Constant => (ENC_CONSTANT, data[..ps].to_vec()),
        Encoding::Zipped => (ENC_ZIPPED, zip(&planar(data, ds, channels, false))),
        Encoding::DiffZipped => (ENC_DIFFZIPPED, zip(&planar(data, ds, channels, true))),
        Encoding::Tiled(tu, tv) => {
            let (w, tw, th) = (1usize << res.0, 1usize << tu, 1usize << tv);
            let (nu, nv) = (1usize << (res.0 - tu), 1usize << (res.1 - tv));
            let mut headers = Vec::new();
            let mut tiles = Vec::new();
            for t in 0..nu * nv {
                let (ox, oy) = ((t % nu) * tw, (t / nu) * th);
                let mut tile = Vec::with_capacity(tw * th * ps);
                for y in 0..th {
                    let at = ((oy + y) * w + ox) * ps;
                    tile.extend_from_slice(&data[at..at + tw * ps]);
                }
                let (e, b) = face_block(&tile, (tu, tv), ds, channels, Encoding::Zipped);
                headers.extend_from_slice(&(b.len() as u32 | e << 30).to_le_bytes());
                tiles.extend_from_slice(&b);
            }
            let hz = zip(&headers);
            let mut out = vec![tu, tv];
            out.extend_from_slice(&(hz.len() as u32).to_le_bytes());
            out.extend_from_slice(&hz);
            out.extend_from_slice(&tiles);
            (ENC_TILED, out)
        }
    }
}

/// Writes a one-level Ptex file (for tests): `mesh_type` 0 triangles, 1 quads; `alpha` the
/// alpha channel or none. Not atomic: test fixtures only.
pub fn write(
    path: &Path,
    data_type: DataType,
    channels: u16,
    alpha: Option<u16>,
    mesh_type: u32,
    faces: &[WriteFace],
) -> std::io::Result<()> {
    let ds = data_type.size();
    let ps = ds * usize::from(channels);
    let mut info = Vec::new();
    let mut constdata = Vec::new();
    let mut headers = Vec::new();
    let mut blocks = Vec::new();
    for f in faces {
        let constant = f.encoding == Encoding::Constant;
        info.extend_from_slice(&[f.ulog2, f.vlog2, 0, u8::from(constant)]);
        info.extend_from_slice(&[0xff; 16]); // no adjacent faces
        constdata.extend_from_slice(&f.data[..ps]);
        let (e, b) = face_block(
            &f.data,
            (f.ulog2, f.vlog2),
            ds,
            usize::from(channels),
            f.encoding,
        );
        headers.extend_from_slice(&(b.len() as u32 | e << 30).to_le_bytes());
        blocks.extend_from_slice(&b);
    }
    let (info_z, const_z, headers_z) = (zip(&info), zip(&constdata), zip(&headers));
    let level_bytes = (headers_z.len() + blocks.len()) as u64;
    let mut out = Vec::new();
    out.extend_from_slice(MAGIC);
    for v in [
        1,
        mesh_type,
        data_type.code(),
        alpha.map_or(u32::MAX, u32::from),
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&channels.to_le_bytes());
    out.extend_from_slice(&1u16.to_le_bytes());
    let ext = 40u32;
    for v in [
        faces.len() as u32,
        ext,
        info_z.len() as u32,
        const_z.len() as u32,
        LEVEL_INFO_BYTES as u32,
        0, // minor version
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&level_bytes.to_le_bytes());
    out.extend_from_slice(&[0u8; 8]); // no meta data
    out.extend_from_slice(&[0u8; 40]); // extended header: clamp borders, no large meta data
    out.extend_from_slice(&info_z);
    out.extend_from_slice(&const_z);
    out.extend_from_slice(&level_bytes.to_le_bytes());
    out.extend_from_slice(&(headers_z.len() as u32).to_le_bytes());
    out.extend_from_slice(&(faces.len() as u32).to_le_bytes());
    out.extend_from_slice(&headers_z);
    out.extend_from_slice(&blocks);
    out.extend_from_slice(&[0u8; 8]); // compatibility barrier after the (empty) meta data
    std::fs::write(path, out)
}

#[cfg(test)]
mod tests;
