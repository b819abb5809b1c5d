//! `motu gen`: its arguments (the scene kind and its size knobs).

use clap::{Args, ValueEnum};
use std::path::PathBuf;

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum GenKindArg {
    Forest,
    Sphereflake,
    LodGrid,
    Island,
    /// A lighting test: a courtyard lit by a sky map and a sun through a roof opening.
    Courtyard,
}

#[derive(Args, Debug)]
pub struct GenArgs {
    pub kind: GenKindArg,
    /// Output directory: written into a temp directory beside it and renamed into place when
    /// complete. An existing non-empty directory is refused unless --force.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Replace an existing non-empty output directory (as a whole, once the new scene is
    /// complete).
    #[arg(long)]
    pub force: bool,
    /// forest: grid levels above the tree; trees = (W·H)^N (the thesis layout is 3).
    #[arg(long)]
    pub levels: Option<u32>,
    /// forest: copies per level as a WxH grid (the thesis layout is 4x3); lod-grid: W across,
    /// H rows going away from the camera.
    #[arg(long)]
    pub grid: Option<String>,
    /// forest: leaf instances per tree.
    #[arg(long)]
    pub leaves: Option<u32>,
    /// forest: trunk detail (3..=512).
    #[arg(long)]
    pub trunk_segments: Option<u32>,
    /// sphereflake: recursion depth (spheres = 1 + 9 + … + 9^N).
    #[arg(long)]
    pub depth: Option<u32>,
    /// sphereflake: sphere tessellation.
    #[arg(long)]
    pub sphere_segments: Option<u32>,
    /// island: 1 approximates Moana's counts (~28M instances, ~36 GB of pbrt).
    #[arg(long)]
    pub scale: Option<f64>,
    /// island: number of elements (1–20, Moana's names).
    #[arg(long)]
    pub elements: Option<u32>,
    /// lod-grid: target triangles of the dense mesh.
    #[arg(long)]
    pub triangles: Option<u32>,
    /// lod-grid: distance between copies.
    #[arg(long)]
    pub spacing: Option<f64>,
    /// forest, sphereflake: write standard single-level pbrt (no nested ObjectInstance).
    #[arg(long)]
    pub flat: bool,
    /// Random seed (generation is deterministic for a seed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Image width written to the Film.
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height written to the Film.
    #[arg(long)]
    pub height: Option<u32>,
    /// island: writer threads.
    #[arg(long)]
    pub threads: Option<usize>,
    /// island: triangles per terrain patch / trunk section before it is split (64..=2^30;
    /// default 1000000).
    #[arg(long)]
    pub max_mesh_triangles: Option<u32>,
    /// island: wrap each terrain geometry file in its own object instanced once, so every
    /// patch gets its own BLAS (the unit `--stream` builds and evicts).
    #[arg(long)]
    pub terrain_objects: bool,
    /// island: the file layout: `pbrt` (Moana's pbrt-v3 release) or `json` (Moana's JSON+OBJ
    /// base package: `DIR/json/island.json`, element JSON, OBJ).
    #[arg(long, value_enum, default_value = "pbrt")]
    pub format: GenFormatArg,
    /// One JSON object on stdout describing what was written.
    #[arg(long)]
    pub json: bool,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum GenFormatArg {
    Pbrt,
    Json,
}
