//! What an import can fail with. Each variant reads as one clause of the CLI's error paragraph
//! (its cause, where there is one, follows it): the message names the file and what to do.

use motu_package::PackageError;
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    #[error("--subset needs element names, comma-separated (got an empty name): valid elements are {}", known.join(", "))]
    EmptySubsetName { known: Vec<String> },
    #[error("unknown element(s) {}: valid elements are {}", unknown.join(", "), known.join(", "))]
    UnknownElements {
        unknown: Vec<String>,
        known: Vec<String>,
    },
    #[error("{} is {kind}, not a scene file: give the entry .pbrt (or .obj) file", path.display())]
    NotASceneFile { path: PathBuf, kind: &'static str },
    #[error("{} does not exist: give the entry .pbrt (or .obj) file", path.display())]
    SceneMissing { path: PathBuf },
    #[error("{}: {error}", path.display())]
    SceneUnreadable {
        path: PathBuf,
        #[source]
        error: std::io::Error,
    },
    #[error("creating {}", path.display())]
    CreatePackage {
        path: PathBuf,
        #[source]
        source: PackageError,
    },
    #[error("creating a scratch file beside {}", path.display())]
    CreateScratch {
        path: PathBuf,
        #[source]
        source: PackageError,
    },
    #[error("moving the scene's instance edges to a scratch file in {} (the import keeps them out of memory; that directory must be writable, with room for 52 bytes an instance)", dir.display())]
    EdgeFile {
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("importing {}", path.display())]
    Ingest {
        path: PathBuf,
        #[source]
        source: motu_ingest::IngestError,
    },
    #[error("{option} {} is {}, a file the scene uses: an output never replaces an input (choose another path)", output.display(), input.display())]
    OutputIsInput {
        option: String,
        output: PathBuf,
        input: PathBuf,
    },
    #[error("compiling the instancing graph")]
    Compile(#[source] motu_compile::CompileError),
    #[error("finishing the scratch package")]
    FinishScratch(#[source] PackageError),
    #[error("writing the package")]
    FinishPackage(#[source] PackageError),
    #[error(transparent)]
    Package(#[from] PackageError),
    #[error(transparent)]
    Pack(#[from] motu_pack::PackError),
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    #[error("textures exceed 2^32 texels at {} (lower --texture-max)", path.display())]
    TooManyTexels { path: PathBuf },
    /// A broken promise between the compiler and the packer (a bug, not bad input).
    #[error("internal: {0}")]
    Internal(String),
    /// The meshes cut beside the parser could not all be stored (`precut.rs`).
    #[error("cutting meshes while parsing")]
    Cut {
        #[source]
        source: motu_scene::StoreError,
    },
    /// A source mesh the scene holds could not be read back (a bug, not bad input).
    #[error("internal: mesh {mesh}: {source}")]
    MeshData {
        mesh: u32,
        #[source]
        source: motu_scene::SceneError,
    },
}
