//! Image textures for motu packages: a file (PNG, TGA, JPEG, OpenEXR through the `image`
//! crate; PFM read here, `image` has no PFM decoder) becomes a mip chain of RGBA8 texels whose
//! largest side is at most a cap, ready for the package's texel section (FORMAT.md,
//! "Textures"). Colour channels are stored sRGB-encoded (8 bits keep dark tones), alpha as is;
//! levels are box-filtered in linear space. HDR images (EXR, PFM) are clipped to [0, 1].
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! Image textures at import: PNG, TGA, JPEG, EXR (the `image` crate) and PFM read into capped mip
//! chains (`--texture-max`), the texels the package's `textures`/`texels` sections hold; the GPU
//! and the CPU oracle sample them identically (`shaders/texture.glsl`, `motu-trace` `shade.rs`).
//! `ptex.rs`: a reader of Ptex files' level 0 (constant, zipped, diff-zipped and tiled faces;
//! `flate2`), each face resampled to at most `--ptex-max` texels an edge, and a writer for tests.
//!
//! Key types: `load`, `read_linear`, `mip_chain`, `MipChain`, `ptex::load`, `ptex::write`.

use std::path::{Path, PathBuf};

pub mod ptex;

/// Why a texture could not be read.
#[derive(Debug, thiserror::Error)]
pub enum TextureError {
    /// The file's contents are not a texture this reader takes (the reason says why).
    #[error("{path}: {reason}")]
    Read { path: PathBuf, reason: String },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file is not a Ptex file this reader takes (the reader says why).
    #[error("{path}: corrupt Ptex file: {source}")]
    Ptex {
        path: PathBuf,
        #[source]
        source: ptex::PtexFormatError,
    },
    /// The `image` crate could not decode the file.
    #[error("{path}: {source}")]
    Image {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
}

/// A decoded image in linear RGBA (`f32`), row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<[f32; 4]>,
}

/// A capped mip chain: level 0 first, each `max(1, size >> level)`; texels packed RGBA8
/// (R in the low byte), colour sRGB-encoded.
#[derive(Clone, Debug, PartialEq)]
pub struct MipChain {
    pub width: u32,
    pub height: u32,
    pub levels: Vec<Vec<u32>>,
}

impl MipChain {
    /// Texels of all levels.
    pub fn texel_count(&self) -> usize {
        self.levels.iter().map(Vec::len).sum()
    }
}

fn err(path: &Path, reason: String) -> TextureError {
    TextureError::Read {
        path: path.to_path_buf(),
        reason,
    }
}

fn io_err(path: &Path, source: std::io::Error) -> TextureError {
    TextureError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_to_srgb8(v: f32) -> u32 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u32
}

/// Reads `path` into linear RGBA. 8- and 16-bit images are taken as sRGB-encoded (pbrt's rule
/// for 8-bit files), float images (EXR, PFM) as linear. Greyscale fills R, G and B.
pub fn read_linear(path: &Path) -> Result<LinearImage, TextureError> {
    let is_pfm = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("pfm"));
    if is_pfm {
        let bytes = std::fs::read(path).map_err(|e| io_err(path, e))?;
        return read_pfm(&bytes).map_err(|r| err(path, r));
    }
    let img = image::ImageReader::open(path)
        .map_err(|e| io_err(path, e))?
        .with_guessed_format()
        .map_err(|e| io_err(path, e))?
        .decode()
        .map_err(|source| TextureError::Image {
            path: path.to_path_buf(),
            source,
        })?;
    let (width, height) = (img.width(), img.height());
    let is_float = matches!(
        img.color(),
        image::ColorType::Rgb32F | image::ColorType::Rgba32F
    );
    let texels = if is_float {
        img.into_rgba32f()
            .pixels()
            .map(|p| p.0)
            .collect::<Vec<[f32; 4]>>()
    } else {
        img.into_rgba32f()
            .pixels()
            .map(|p| {
                let [r, g, b, a] = p.0;
                [srgb_to_linear(r), srgb_to_linear(g), srgb_to_linear(b), a]
            })
            .collect()
    };
    Ok(LinearImage {
        width,
        height,
        texels,
    })
}

/// Portable float map: `PF` (RGB) or `Pf` (grey), width height, scale (negative: little
/// endian), then rows bottom to top.
fn read_pfm(bytes: &[u8]) -> Result<LinearImage, String> {
    let mut fields = Vec::new();
    let mut at = 0usize;
    while fields.len() < 4 {
        while at < bytes.len() && bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        let start = at;
        while at < bytes.len() && !bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        if start == at {
            return Err("truncated PFM header".into());
        }
        fields.push(String::from_utf8_lossy(&bytes[start..at]).into_owned());
    }
    at += 1; // the single whitespace byte before the data
    let channels = match fields[0].as_str() {
        "PF" => 3usize,
        "Pf" => 1,
        other => return Err(format!("not a PFM file (magic {other:?})")),
    };
    let parse = |s: &str| s.parse::<u32>().map_err(|_| format!("bad PFM size {s:?}"));
    let (width, height) = (parse(&fields[1])?, parse(&fields[2])?);
    let scale: f32 = fields[3]
        .parse()
        .map_err(|_| format!("bad PFM scale {:?}", fields[3]))?;
    let n = width as usize * height as usize;
    let need = n.checked_mul(channels * 4).ok_or("PFM size overflows")?;
    let data = bytes.get(at..at + need).ok_or_else(|| {
        format!(
            "PFM data is {} bytes, {width}×{height} needs {need}",
            bytes.len().saturating_sub(at)
        )
    })?;
    let value = |i: usize| {
        let b = [
            data[4 * i],
            data[4 * i + 1],
            data[4 * i + 2],
            data[4 * i + 3],
        ];
        if scale < 0.0 {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    let mut texels = vec![[0.0f32; 4]; n];
    for y in 0..height as usize {
        // PFM rows run bottom to top.
        let row = height as usize - 1 - y;
        for x in 0..width as usize {
            let src = (y * width as usize + x) * channels;
            let t = &mut texels[row * width as usize + x];
            for (c, v) in t.iter_mut().take(3).enumerate() {
                *v = value(src + if channels == 3 { c } else { 0 });
            }
            t[3] = 1.0;
        }
    }
    Ok(LinearImage {
        width,
        height,
        texels,
    })
}

/// Halves an image (2×2 box filter, odd edges clamped).
fn half(img: &LinearImage) -> LinearImage {
    let (w, h) = ((img.width / 2).max(1), (img.height / 2).max(1));
    let mut texels = Vec::with_capacity(w as usize * h as usize);
    for y in 0..h {
        for x in 0..w {
            let mut sum = [0.0f32; 4];
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let sx = (2 * x + dx).min(img.width - 1);
                let sy = (2 * y + dy).min(img.height - 1);
                let t = img.texels[(sy * img.width + sx) as usize];
                for (s, v) in sum.iter_mut().zip(t) {
                    *s += 0.25 * v;
                }
            }
            texels.push(sum);
        }
    }
    LinearImage {
        width: w,
        height: h,
        texels,
    }
}

fn pack(img: &LinearImage) -> Vec<u32> {
    img.texels
        .iter()
        .map(|t| {
            let a = (t[3].clamp(0.0, 1.0) * 255.0 + 0.5) as u32;
            linear_to_srgb8(t[0])
                | linear_to_srgb8(t[1]) << 8
                | linear_to_srgb8(t[2]) << 16
                | a << 24
        })
        .collect()
}

/// The mip chain of `img` with its largest side at most `max_size` (halved until it fits).
pub fn mip_chain(img: LinearImage, max_size: u32) -> MipChain {
    let mut img = img;
    let cap = max_size.max(1);
    while img.width.max(img.height) > cap {
        img = half(&img);
    }
    let (width, height) = (img.width, img.height);
    let mut levels = vec![pack(&img)];
    while img.width > 1 || img.height > 1 {
        img = half(&img);
        levels.push(pack(&img));
    }
    MipChain {
        width,
        height,
        levels,
    }
}

/// Reads `path` as a capped mip chain. A coverage (alpha) texture without an alpha channel
/// takes its coverage from the first channel (pbrt reads float image textures that way).
pub fn load(path: &Path, max_size: u32, as_coverage: bool) -> Result<MipChain, TextureError> {
    let mut img = read_linear(path)?;
    if as_coverage && img.texels.iter().all(|t| t[3] >= 1.0) {
        for t in &mut img.texels {
            // Coverage is a plain number: undo the sRGB decode applied to colour channels.
            t[3] = linear_to_srgb8(t[0]) as f32 / 255.0;
        }
    }
    Ok(mip_chain(img, max_size))
}

/// Widest environment map the package keeps (halved until it fits; the height follows): the
/// map and its sampling tables travel in the package's meta and with each GPU frame.
pub const ENVIRONMENT_MAX_WIDTH: u32 = 256;

/// Reads an environment map (an `infinite` light's image) as linear RGB, halved until it is at
/// most [`ENVIRONMENT_MAX_WIDTH`] wide: `(width, height, texels)`, row 0 at the top.
pub fn load_environment(path: &Path) -> Result<(u32, u32, Vec<[f32; 3]>), TextureError> {
    let img = read_linear(path)?;
    let texels = img.texels.iter().map(|t| [t[0], t[1], t[2]]).collect();
    Ok(cap_width(
        ENVIRONMENT_MAX_WIDTH,
        img.width,
        img.height,
        texels,
    ))
}

/// Halves a `width × height` map (2×2 box filter; an odd last column or row is dropped) until
/// its width is at most `max_width`.
fn cap_width(
    max_width: u32,
    mut width: u32,
    mut height: u32,
    mut texels: Vec<[f32; 3]>,
) -> (u32, u32, Vec<[f32; 3]>) {
    while width > max_width.max(1) && height > 1 {
        let (nw, nh) = (width / 2, height / 2);
        let mut out = vec![[0.0f32; 3]; nw as usize * nh as usize];
        for y in 0..nh as usize {
            for x in 0..nw as usize {
                let mut s = [0.0f32; 3];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let t = texels[(2 * y + dy) * width as usize + 2 * x + dx];
                    for i in 0..3 {
                        s[i] += if t[i].is_finite() { t[i] } else { 0.0 } / 4.0;
                    }
                }
                out[y * nw as usize + x] = s;
            }
        }
        (width, height, texels) = (nw, nh, out);
    }
    (width, height, texels)
}

/// Mean linear RGB of an image (an environment map's constant approximation).
pub fn average(path: &Path) -> Result<[f32; 3], TextureError> {
    let img = read_linear(path)?;
    let n = img.texels.len().max(1) as f64;
    let mut sum = [0.0f64; 3];
    for t in &img.texels {
        for (s, v) in sum.iter_mut().zip(t) {
            if v.is_finite() {
                *s += *v as f64;
            }
        }
    }
    Ok(sum.map(|s| (s / n) as f32))
}

#[cfg(test)]
mod tests;
