//! Moana's JSON+OBJ base package (Disney's original release, `island/json/…` and
//! `island/obj/…`), read into the same [`SceneSink`] events the pbrt parser produces.
//!
//! Layout (paths inside the files are relative to the island root, the folder holding `json/`):
//!
//! ```text
//! json/<el>/<el>.json            element: name, matFile, geomObjFile, transformMatrix,
//!                                instancedCopies, instancedPrimitiveJsonFiles
//! json/<el>/materials.json       material name → baseColor, roughness, metallic, colorMap
//!                                (the Ptex folder), assignment (curve primitives it colours)
//! json/<el>/<el>_<prim>.json     type `archive`: OBJ path → instance name → 16 numbers;
//!                                type `curve`: a list of curves, each a list of [x, y, z]
//! json/cameras/<cam>.json        eye, look, up, fov (horizontal, degrees), ratio (width/height)
//! json/lights/<any>.json         light name → type `quad` | `dome` (| motu's `distant`)
//! obj/<el>/…                     OBJ geometry, one `g` group per mesh
//! ```
//!
//! Mapping (mis2rib, Disney's reference converter, is the model):
//! - An element is an [`crate::ElementId`] named by its `name` (else its file stem).
//! - `transformMatrix` and every instance matrix are 16 numbers in pbrt's `Transform` order
//!   (column-major, translation in 12–14); `null` is the identity (the release has some).
//! - An element with `instancedCopies` that have no geometry of their own is one object
//!   instanced at its `transformMatrix` and at each copy's; otherwise its geometry and
//!   primitives are placed directly under its transform (a single placement needs no object,
//!   which is what the pbrt release does too). A copy with its own `geomObjFile` is placed the
//!   same way with its own `instancedPrimitiveJsonFiles`.
//! - Each OBJ named by an `archive` primitive is one object, defined once per file; its
//!   instances come from streaming the archive JSON (constant memory whatever its size).
//! - Events come in pbrt's document order for the equivalent file: archive objects first, then
//!   the element's own geometry, then the placements and curves.
//! - `curve` primitives: each point list is a cubic B-spline whose end points are repeated so
//!   the curve reaches them (as mis2rib does); width from `widthRoot` to `widthTip`.
//! - Cameras: `LookAt(eye, look, up)` mirrored in x (the release's cameras are right-handed,
//!   pbrt's left-handed; `"handedness": "left"` turns that off), `fov` converted to the shorter
//!   image axis as pbrt's is; an optional `resolution` [w, h] (motu's extension) sets the image.

mod camera;
mod element;
mod geometry;
mod json;
mod lights;
mod obj;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use json::{JsonError, Node, Reader, Value};
use obj::ObjError;

use crate::events::{FileEvent, Material, SceneSink, Via, Warning};
use crate::math::{self, M64};
use crate::source::{classify, FileKind, SourceBytes};
use crate::{
    ElementId, Error, FileId, Loc, Location, MaterialId, MissingFile, ObjectId, ParseOptions,
    ParseStats,
};

/// Whether `path` looks like the base package: a `.json` file, or a folder holding element JSON
/// files (`json/`, the island root above it, or one element's folder).
pub fn is_moana_json(path: &Path) -> bool {
    if path.is_dir() {
        return plan_dir(path).is_ok_and(|p| !p.elements.is_empty());
    }
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
}

/// Reads the base package at `path` (an element JSON, a scene list `{"elements": [...],
/// "cameras": [...], "lights": [...]}`, or a folder) into `sink`.
pub fn parse_moana_json(
    path: &Path,
    options: &ParseOptions,
    sink: &mut dyn SceneSink,
) -> Result<ParseStats, Error> {
    let _span = tracing::info_span!("parse_moana_json", path = %path.display()).entered();
    let mut imp = Importer {
        opts: options,
        sink,
        stats: ParseStats::default(),
        root: PathBuf::new(),
        next_object: 0,
        next_material: 1,
        archives: HashMap::new(),
        default_material: Arc::new(Material {
            id: MaterialId(0),
            name: None,
            kind: "diffuse".into(),
            base_color: Some([0.5; 3]),
            base_color_texture: None,
            opacity: None,
            base_color_image: None,
            ptex: None,
            roughness: Some(1.0),
            metallic: Some(0.0),
            loc: Loc::default(),
        }),
        seq: 0,
        entry_taken: false,
        per_group: HashMap::new(),
    };
    let plan = if path.is_dir() {
        plan_dir(path)?
    } else {
        imp.plan_file(path)?
    };
    if plan.elements.is_empty() {
        return Err(Error::Json {
            path: path.to_path_buf(),
            offset: 0,
            message: "no element JSON files found (expected json/<element>/<element>.json)".into(),
        });
    }
    imp.root = plan.root.clone();
    for (i, (el, referenced_at)) in plan.elements.iter().enumerate() {
        imp.element(el, ElementId(i as u32), referenced_at.as_ref())?;
    }
    for (cam, referenced_at) in &plan.cameras {
        imp.camera(cam, referenced_at.as_ref())?;
    }
    for (lights, referenced_at) in &plan.lights {
        imp.lights(lights, referenced_at.as_ref())?;
    }
    imp.stats.version = None;
    Ok(imp.stats)
}

/// What to read: files with the place that named them (none when found by listing a folder).
struct Plan {
    root: PathBuf,
    elements: Vec<(PathBuf, Option<Location>)>,
    cameras: Vec<(PathBuf, Option<Location>)>,
    lights: Vec<(PathBuf, Option<Location>)>,
}

/// The island root for a path inside `json/`: the folder above the nearest `json` ancestor.
fn island_root(path: &Path) -> PathBuf {
    for a in path.ancestors() {
        if a.file_name().is_some_and(|n| n == "json") {
            return a.parent().unwrap_or(Path::new(".")).to_path_buf();
        }
    }
    if path.is_dir() {
        path.to_path_buf()
    } else {
        path.parent().unwrap_or(Path::new(".")).to_path_buf()
    }
}

fn sorted_json_files(dir: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && p.extension().is_some_and(|e| e == "json"))
                .collect()
        })
        .unwrap_or_default();
    out.sort();
    out
}

fn plan_dir(path: &Path) -> Result<Plan, Error> {
    let json_dir = if path.join("json").is_dir() {
        path.join("json")
    } else {
        path.to_path_buf()
    };
    let name = json_dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let own = json_dir.join(format!("{name}.json"));
    let root = island_root(&json_dir);
    if own.is_file() {
        // One element's folder.
        return Ok(Plan {
            root,
            elements: vec![(own, None)],
            cameras: Vec::new(),
            lights: Vec::new(),
        });
    }
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(&json_dir)
        .map_err(|source| Error::Io {
            path: json_dir.clone(),
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    let elements = dirs
        .iter()
        .filter_map(|d| {
            let n = d.file_name()?.to_string_lossy().into_owned();
            let f = d.join(format!("{n}.json"));
            (n != "cameras" && n != "lights" && f.is_file()).then_some((f, None))
        })
        .collect();
    let mut cameras = sorted_json_files(&json_dir.join("cameras"));
    // The release's main camera renders by default (the active camera is the last, as in pbrt).
    if let Some(i) = cameras
        .iter()
        .position(|c| c.file_stem().is_some_and(|s| s == "shotCam"))
    {
        let shot = cameras.remove(i);
        cameras.push(shot);
    }
    Ok(Plan {
        root,
        elements,
        cameras: cameras.into_iter().map(|c| (c, None)).collect(),
        lights: sorted_json_files(&json_dir.join("lights"))
            .into_iter()
            .map(|l| (l, None))
            .collect(),
    })
}

/// Stops a streamed file: its own syntax, an OBJ's, or an error already located elsewhere.
enum Stop {
    Json(JsonError),
    Obj(ObjError),
    Done(Error),
}

impl From<JsonError> for Stop {
    fn from(e: JsonError) -> Self {
        Stop::Json(e)
    }
}
impl From<ObjError> for Stop {
    fn from(e: ObjError) -> Self {
        Stop::Obj(e)
    }
}
impl From<Error> for Stop {
    fn from(e: Error) -> Self {
        Stop::Done(e)
    }
}

/// One open input file.
struct Input {
    path: PathBuf,
    file: FileId,
    bytes: SourceBytes,
    /// The last offset turned into a line and column, its line and its line's start: offsets
    /// asked in increasing order (curves, placements) cost only the bytes between them.
    cursor: std::cell::Cell<(usize, u32, usize)>,
}

impl Input {
    fn json_error(&self, e: JsonError) -> Error {
        let (line, column) = self.line_column(e.offset);
        Error::Json {
            path: self.path.clone(),
            offset: e.offset as u64,
            message: format!("(line {line}, column {column}) {}", e.message),
        }
    }

    fn stop(&self, s: Stop) -> Error {
        match s {
            Stop::Json(e) => self.json_error(e),
            Stop::Obj(e) => Error::Obj {
                path: self.path.clone(),
                line: e.line,
                message: e.message,
            },
            Stop::Done(e) => e,
        }
    }

    fn line_column(&self, offset: usize) -> (u32, u32) {
        let bytes = self.bytes.bytes();
        let offset = offset.min(bytes.len());
        let (mut at, mut line, mut start) = self.cursor.get();
        if offset < at {
            (at, line, start) = (0, 1, 0);
        }
        for (i, &b) in bytes[at..offset].iter().enumerate() {
            if b == b'\n' {
                line += 1;
                start = at + i + 1;
            }
        }
        self.cursor.set((offset, line, start));
        (line, (offset - start + 1) as u32)
    }

    fn loc(&self, offset: usize) -> Loc {
        let (line, column) = self.line_column(offset);
        Loc {
            file: self.file,
            line,
            column,
        }
    }

    fn location(&self, offset: usize) -> Location {
        let (line, column) = self.line_column(offset);
        Location {
            path: self.path.clone(),
            line,
            column,
        }
    }

    /// The whole file as a tree (small files: elements, materials, cameras, lights).
    fn tree(&self) -> Result<Node, Error> {
        let mut r = Reader::new(self.bytes.bytes());
        let n = r.node().map_err(|e| self.json_error(e))?;
        r.finish().map_err(|e| self.json_error(e))?;
        Ok(n)
    }

    fn invalid(&self, at: usize, message: impl Into<String>) -> Error {
        self.json_error(JsonError {
            offset: at,
            message: message.into(),
        })
    }
}

/// The materials of one element: by name, and curve primitive → material (`assignment`).
#[derive(Default)]
struct Materials {
    by_name: HashMap<String, Arc<Material>>,
    by_primitive: HashMap<String, Arc<Material>>,
    /// Materials with a `colorMap`: the folder of their meshes' `<group>.ptx` files.
    ptex_dirs: HashMap<MaterialId, PathBuf>,
}

struct Importer<'s> {
    opts: &'s ParseOptions,
    sink: &'s mut dyn SceneSink,
    stats: ParseStats,
    root: PathBuf,
    next_object: u32,
    next_material: u32,
    /// Archive OBJ files defined as objects (`None`: missing, skipped with `allow_missing`).
    archives: HashMap<PathBuf, Option<ObjectId>>,
    default_material: Arc<Material>,
    seq: u64,
    entry_taken: bool,
    /// A textured material per OBJ group (its own Ptex file), as Moana's pbrt release has.
    per_group: HashMap<(MaterialId, String), Arc<Material>>,
}

impl Importer<'_> {
    fn warn(&mut self, loc: Option<Loc>, message: String) {
        tracing::warn!("{message}");
        self.stats.warnings += 1;
        self.sink.warning(&Warning { loc, message });
    }

    /// A path from a file: against the island root, else against the naming file's folder.
    fn resolve(&self, rel: &str, from: &Path) -> PathBuf {
        let p = Path::new(rel);
        if p.is_absolute() {
            return p.to_path_buf();
        }
        let at_root = self.root.join(p);
        if at_root.exists() {
            return at_root;
        }
        let beside = from.parent().unwrap_or(Path::new(".")).join(p);
        if beside.exists() {
            beside
        } else {
            at_root
        }
    }

    /// Opens a referenced file. `Ok(None)`: missing and skipped (`allow_missing`).
    fn open(
        &mut self,
        path: &Path,
        referenced_at: Option<&Location>,
        element: Option<(ElementId, &str)>,
    ) -> Result<Option<Input>, Error> {
        match classify(path) {
            FileKind::Regular => {}
            FileKind::Missing => {
                let m = MissingFile {
                    path: path.to_path_buf(),
                    referenced_at: referenced_at.cloned().unwrap_or(Location {
                        path: path.to_path_buf(),
                        line: 0,
                        column: 0,
                    }),
                };
                if self.opts.allow_missing {
                    self.warn(
                        None,
                        format!(
                            "{}: missing file skipped: {}",
                            m.referenced_at,
                            path.display()
                        ),
                    );
                    self.stats.missing.push(m);
                    return Ok(None);
                }
                return Err(Error::MissingFiles { files: vec![m] });
            }
            FileKind::Other(what) => {
                return Err(Error::Io {
                    path: path.to_path_buf(),
                    source: std::io::Error::new(
                        std::io::ErrorKind::InvalidInput,
                        format!("{what}, not a regular file"),
                    ),
                })
            }
        }
        let bytes = SourceBytes::open(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let file = FileId(self.stats.files.len() as u32);
        self.stats.files.push(path.to_path_buf());
        self.stats.text_bytes += bytes.bytes().len() as u64;
        let via = if self.entry_taken {
            Via::Include
        } else {
            Via::Entry
        };
        self.entry_taken = true;
        let event = FileEvent {
            file,
            path,
            depth: u32::from(via != Via::Entry),
            via,
            from_entry_world: element.is_some(),
            element: element.map(|e| e.0),
            element_name: element.map(|e| e.1),
            size_bytes: bytes.bytes().len() as u64,
        };
        self.sink.file_enter(&event)?;
        Ok(Some(Input {
            path: path.to_path_buf(),
            file,
            bytes,
            cursor: std::cell::Cell::new((0, 1, 0)),
        }))
    }

    fn plan_file(&mut self, path: &Path) -> Result<Plan, Error> {
        let root = island_root(path);
        let bytes = SourceBytes::open(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let input = Input {
            path: path.to_path_buf(),
            file: FileId(0),
            bytes,
            cursor: std::cell::Cell::new((0, 1, 0)),
        };
        let doc = input.tree()?;
        let Some(list) = doc.get("elements") else {
            return Ok(Plan {
                root,
                elements: vec![(path.to_path_buf(), None)],
                cameras: Vec::new(),
                lights: Vec::new(),
            });
        };
        // A scene list: its own file is read (an input) but belongs to no element.
        self.root = root.clone();
        let listed = |key: &str,
                      node: Option<&Node>|
         -> Result<Vec<(PathBuf, Option<Location>)>, Error> {
            let Some(node) = node else {
                return Ok(Vec::new());
            };
            if !matches!(node.value, Value::Arr(_)) {
                return Err(input.invalid(node.at, format!("`{key}` must be a list of paths")));
            }
            node.items()
                .iter()
                .map(|n| match n.as_str() {
                    Some(s) => Ok((self.resolve(s, path), Some(input.location(n.at)))),
                    None => Err(input.invalid(n.at, format!("`{key}` items must be path strings"))),
                })
                .collect()
        };
        let plan = Plan {
            root: root.clone(),
            elements: listed("elements", Some(list))?,
            cameras: listed("cameras", doc.get("cameras"))?,
            lights: listed("lights", doc.get("lights"))?,
        };
        // Register the list as the entry file.
        drop(input);
        self.open(path, None, None)?;
        Ok(plan)
    }

    fn matrix(input: &Input, node: Option<&Node>, what: &str) -> Result<M64, Error> {
        let Some(node) = node else {
            return Ok(math::IDENTITY);
        };
        if matches!(node.value, Value::Null) {
            return Ok(math::IDENTITY);
        }
        let items = node.items();
        if items.len() != 16 || !matches!(node.value, Value::Arr(_)) {
            return Err(input.invalid(node.at, format!("{what} must be a list of 16 numbers")));
        }
        let mut v = [0.0f64; 16];
        for (i, n) in items.iter().enumerate() {
            v[i] = n.as_f64().ok_or_else(|| {
                input.invalid(n.at, format!("{what} must be a list of 16 numbers"))
            })?;
        }
        if let Some(i) = non_finite_position(&v) {
            return Err(input.invalid(
                node.at,
                format!("{what} holds a non-finite value (NaN or infinity) at position {i}"),
            ));
        }
        Ok(math::from_pbrt(&v))
    }
}

struct Ctx<'a> {
    element: ElementId,
    name: &'a str,
    mats: &'a Materials,
}

struct CurveSpec {
    width_root: f32,
    width_tip: f32,
    material: Arc<Material>,
}

/// Where 16 numbers (pbrt's `Transform` order) hold a non-finite value (NaN or infinity), if
/// anywhere.
fn non_finite_position(v: &[f64; 16]) -> Option<usize> {
    v.iter().position(|x| !x.is_finite())
}

#[cfg(test)]
mod tests;
