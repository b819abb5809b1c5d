//! `motu import`: its arguments (levels, curves, the package options).

use crate::size::parse_size;
use clap::{Args, ValueEnum};
use std::path::PathBuf;

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CurvesArg {
    Skip,
    Ribbons,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LevelsArg {
    Ml,
    Auto,
    Sl,
    N(u32),
}

fn parse_levels(s: &str) -> Result<LevelsArg, String> {
    match s {
        "ml" => Ok(LevelsArg::Ml),
        "auto" => Ok(LevelsArg::Auto),
        "sl" => Ok(LevelsArg::Sl),
        n => match n.parse::<u32>() {
            Ok(v) if v >= 1 => Ok(LevelsArg::N(v)),
            _ => Err(format!(
                "'{s}': expected ml, auto, sl or a number of levels ≥ 1"
            )),
        },
    }
}

#[derive(Args, Debug)]
pub struct ImportArgs {
    /// The entry .pbrt (or .pbrt.gz) file, an .obj file, or Moana's JSON+OBJ base package: its
    /// `json/` folder (or the island folder above it), one element's folder or JSON file, or a
    /// list `{"elements": [...], "cameras": [...], "lights": [...]}` (`motu gen island --format
    /// json` writes `json/island.json`).
    pub scene: PathBuf,
    /// Output package path.
    #[arg(short, long)]
    pub output: PathBuf,
    /// ml: keep the instancing graph; auto: ml with cheap grouping levels inlined, small
    /// instanced prototypes (at most 2^17 triangles with their copies) baked into triangle BLASes
    /// and levels whose inlining costs at most 2^16 instances inlined (fewer traces per ray, big
    /// geometry still shared); sl: flatten to one level; N: at most N levels.
    #[arg(long, default_value = "ml", value_parser = parse_levels)]
    pub levels: LevelsArg,
    /// Instances per TLAS before it is split (default: the spec's 2^24−1).
    #[arg(long, default_value_t = (1 << 24) - 1)]
    pub max_instances: u32,
    /// Also split a TLAS whose estimated build scratch would exceed this (128 B per instance).
    #[arg(long, value_parser = parse_size)]
    pub max_tlas_scratch: Option<u64>,
    /// Triangles per triangle BLAS (the partitioner's bound): a mesh over it is split into
    /// spatial clusters, small meshes are grouped by location under it. Default: chosen from
    /// the scene's size: 2^16 (every BLAS around 6.5 MiB, ≤ 12 MiB with build scratch and
    /// geometry), or about a 256th of the whole build on scenes under ~8.4M triangles (at
    /// least 4,096; heavily instanced meshes are not split), so a streaming budget far below
    /// the full build still holds the largest one and a frame's working set is not padded out
    /// by whole coarse units.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub max_blas_triangles: Option<u32>,
    /// Build N LOD levels for heavy meshes.
    #[arg(long)]
    pub lod: Option<u32>,
    /// With --lod: meshes with more triangles than this get a LOD chain.
    #[arg(long, default_value_t = 10_000)]
    pub lod_min_triangles: u32,
    /// Compress chunks with zstd at this level (1–22).
    #[arg(long)]
    pub zstd: Option<i32>,
    /// `curve` shapes: `ribbons` tessellates them into flat ribbons (motu traces triangles),
    /// `skip` counts and drops them.
    #[arg(long, value_enum, default_value = "ribbons")]
    pub curves: CurvesArg,
    /// Warn about missing referenced files and skip their shapes instead of failing.
    #[arg(long)]
    pub allow_missing: bool,
    /// Do not store the boxes inside triangle BLASes (the `proxy_boxes` section): a faster
    /// import whose streamed renders make them from every mesh at start instead.
    #[arg(long)]
    pub no_proxy_boxes: bool,
    /// Do not store the proxy clusters of the TLASes (the `proxy_clusters` section): a faster
    /// import whose streamed renders and `motu report` run the binned SAH over every instance
    /// instead.
    #[arg(long)]
    pub no_proxy_clusters: bool,
    /// The split `motu render --stream` makes of every TLAS over N instances (spatial pieces
    /// rebuilt one at a time) is made here and stored, with the proxy boxes and clusters of
    /// the hierarchy it gives; the package records N, and streamed renders split at it unless
    /// their own --stream-split-instances names another (then they make their own). 0: no
    /// split.
    #[arg(long, value_name = "N", default_value_t = motu_compile::STREAM_SPLIT_INSTANCES, value_parser = super::stream::parse_split_instances)]
    pub stream_split_instances: u32,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Keep only these elements (comma-separated names).
    #[arg(long, value_delimiter = ',')]
    pub subset: Vec<String>,
    /// Force the pbrt version instead of detecting it (3 or 4).
    #[arg(long, value_parser = clap::value_parser!(u32).range(3..=4))]
    pub pbrt_version: Option<u32>,
    /// Chunk target size.
    #[arg(long, value_parser = parse_size, default_value = "64MiB")]
    pub chunk_size: u64,
    /// Image textures are stored as mip chains whose finest level has at most this many
    /// texels per side (larger images are halved until they fit).
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(1..=16384))]
    pub texture_max: u32,
    /// Ptex faces keep at most this many texels per face edge (larger faces are halved with a
    /// box filter until they fit).
    #[arg(long, default_value_t = motu_import::DEFAULT_PTEX_MAX, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub ptex_max: u32,
    /// One JSON object on stdout describing the import.
    #[arg(long)]
    pub json: bool,
}
