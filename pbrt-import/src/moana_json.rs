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

mod json;
mod obj;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use json::{JsonError, Node, Reader, Value};
use obj::{ObjError, ObjMesh};

use crate::events::{
    CameraEvent, Curve, FileEvent, Geometry, InstanceEvent, LightEvent, Material, ObjectEvent,
    SceneSink, ShapeEvent, Via, Warning,
};
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
        checked_matrix(&v).map_err(|m| input.invalid(node.at, format!("{what} {m}")))
    }

    fn materials(
        &mut self,
        el: &Input,
        doc: &Node,
        element: (ElementId, &str),
    ) -> Result<Materials, Error> {
        let mut out = Materials::default();
        let Some(node) = doc.get("matFile") else {
            return Ok(out);
        };
        let Some(rel) = node.as_str() else {
            return Err(el.invalid(node.at, "matFile must be a path string"));
        };
        let path = self.resolve(rel, &el.path);
        let Some(input) = self.open(&path, Some(&el.location(node.at)), Some(element))? else {
            return Ok(out);
        };
        let tree = input.tree()?;
        if !tree.is_obj() {
            return Err(input.invalid(
                tree.at,
                "a materials file must be an object (name → material)",
            ));
        }
        for (name, m) in tree.members() {
            let color = |key: &str| -> Result<Option<[f32; 3]>, Error> {
                let Some(c) = m.get(key) else { return Ok(None) };
                let v: Vec<f64> = c.items().iter().filter_map(Node::as_f64).collect();
                if v.len() < 3 || v[..3].iter().any(|x| !x.is_finite()) {
                    return Err(input.invalid(c.at, format!("{key} must be 3 finite numbers")));
                }
                Ok(Some([v[0] as f32, v[1] as f32, v[2] as f32]))
            };
            let scalar = |key: &str| m.get(key).and_then(Node::as_f64).filter(|x| x.is_finite());
            let material = Arc::new(Material {
                id: MaterialId(self.next_material),
                name: Some(format!("{}/{name}", element.1)),
                kind: m
                    .get("type")
                    .and_then(Node::as_str)
                    .unwrap_or("disney")
                    .to_string(),
                base_color: color("baseColor")?,
                base_color_texture: None,
                opacity: None,
                base_color_image: None,
                ptex: None,
                roughness: scalar("roughness").map(|r| r.clamp(0.0, 1.0) as f32),
                metallic: scalar("metallic").map(|r| r.clamp(0.0, 1.0) as f32),
                loc: input.loc(m.at),
            });
            self.next_material += 1;
            self.sink.material(&material)?;
            if let Some(dir) = m
                .get("colorMap")
                .and_then(Node::as_str)
                .filter(|s| !s.is_empty())
            {
                out.ptex_dirs
                    .insert(material.id, self.resolve(dir, &input.path));
            }
            for a in m.get("assignment").map(Node::items).unwrap_or_default() {
                if let Some(p) = a.as_str() {
                    out.by_primitive.insert(p.to_string(), material.clone());
                }
            }
            out.by_name.insert(name.clone(), material);
        }
        Ok(out)
    }

    fn element(
        &mut self,
        path: &Path,
        id: ElementId,
        referenced_at: Option<&Location>,
    ) -> Result<(), Error> {
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "element".into());
        // The element's name is known only once the file is read; the stem names it (Moana's
        // files are `<name>/<name>.json`).
        let Some(input) = self.open(path, referenced_at, Some((id, &stem)))? else {
            return Ok(());
        };
        let doc = input.tree()?;
        let keys = [
            "geomObjFile",
            "instancedPrimitiveJsonFiles",
            "instancedCopies",
        ];
        if !doc.is_obj() || keys.iter().all(|k| doc.get(k).is_none()) {
            return Err(input.invalid(
                doc.at,
                "not a Moana element file (an object with geomObjFile, instancedPrimitiveJsonFiles or instancedCopies) nor a scene list (an object with elements)",
            ));
        }
        let name = stem.as_str();
        let mats = self.materials(&input, &doc, (id, name))?;
        let world_from_element =
            Self::matrix(&input, doc.get("transformMatrix"), "transformMatrix")?;
        let copies: &[(String, Node)] = doc
            .get("instancedCopies")
            .map(Node::members)
            .unwrap_or_default();
        let instanced = copies.iter().any(|(_, c)| c.get("geomObjFile").is_none());
        let ctx = Ctx {
            element: id,
            name,
            mats: &mats,
        };
        if instanced {
            let object = self.new_object();
            self.sink.object_begin(&ObjectEvent {
                object,
                name,
                element: Some(id),
                loc: input.loc(doc.at),
            })?;
            self.body(&input, &doc, &math::IDENTITY, Some(object), &ctx)?;
            self.sink.object_end(&ObjectEvent {
                object,
                name,
                element: Some(id),
                loc: input.loc(doc.at),
            })?;
            self.instance(
                object,
                name,
                &world_from_element,
                None,
                id,
                input.loc(doc.at),
            )?;
            for (copy, c) in copies {
                if c.get("geomObjFile").is_none() {
                    let m = Self::matrix(
                        &input,
                        c.get("transformMatrix"),
                        &format!("instancedCopies.{copy}.transformMatrix"),
                    )?;
                    self.instance(object, name, &m, None, id, input.loc(c.at))?;
                }
            }
        } else {
            self.body(&input, &doc, &world_from_element, None, &ctx)?;
        }
        // Copies with geometry of their own (the release's coral).
        for (copy, c) in copies {
            if c.get("geomObjFile").is_some() {
                let m = Self::matrix(
                    &input,
                    c.get("transformMatrix"),
                    &format!("instancedCopies.{copy}.transformMatrix"),
                )?;
                self.body(&input, c, &m, None, &ctx)?;
            }
        }
        self.sink.file_exit(&FileEvent {
            file: input.file,
            path: &input.path,
            depth: 1,
            via: Via::Include,
            from_entry_world: true,
            element: Some(id),
            element_name: Some(name),
            size_bytes: input.bytes.bytes().len() as u64,
        })?;
        Ok(())
    }

    fn new_object(&mut self) -> ObjectId {
        let o = ObjectId(self.next_object);
        self.next_object += 1;
        self.stats.objects += 1;
        o
    }

    fn instance(
        &mut self,
        object: ObjectId,
        name: &str,
        parent_from_instance: &M64,
        inside: Option<ObjectId>,
        element: ElementId,
        loc: Loc,
    ) -> Result<(), Error> {
        self.stats.instances += 1;
        self.sink.object_instance(&InstanceEvent {
            object,
            name,
            parent_from_instance: math::to_f32(parent_from_instance),
            inside,
            element: Some(element),
            loc,
        })?;
        Ok(())
    }

    /// An element's (or a copy's) geometry and primitives under `base`.
    fn body(
        &mut self,
        input: &Input,
        node: &Node,
        base: &M64,
        inside: Option<ObjectId>,
        ctx: &Ctx<'_>,
    ) -> Result<(), Error> {
        let prims: &[(String, Node)] = node
            .get("instancedPrimitiveJsonFiles")
            .map(Node::members)
            .unwrap_or_default();
        // 1. The archives as objects.
        for (_, p) in prims {
            if p.get("type").and_then(Node::as_str) != Some("archive") {
                continue;
            }
            for a in p.get("archives").map(Node::items).unwrap_or_default() {
                let Some(rel) = a.as_str() else {
                    return Err(input.invalid(a.at, "archives must be a list of OBJ paths"));
                };
                let path = self.resolve(rel, &input.path);
                self.archive_object(&path, Some(&input.location(a.at)), ctx)?;
            }
        }
        // 2. The element's own geometry.
        if let Some(g) = node.get("geomObjFile") {
            let Some(rel) = g.as_str() else {
                return Err(input.invalid(g.at, "geomObjFile must be a path string"));
            };
            let path = self.resolve(rel, &input.path);
            self.obj_shapes(&path, Some(&input.location(g.at)), inside, base, ctx)?;
        }
        // 3. Placements and curves, in the file's order.
        for (prim, p) in prims {
            let kind = p.get("type").and_then(Node::as_str).unwrap_or("");
            let Some(file) = p.get("jsonFile") else {
                self.warn(
                    Some(input.loc(p.at)),
                    format!("primitive `{prim}` names no jsonFile; skipped"),
                );
                continue;
            };
            let Some(rel) = file.as_str() else {
                return Err(input.invalid(file.at, "jsonFile must be a path string"));
            };
            let path = self.resolve(rel, &input.path);
            let at = input.location(file.at);
            match kind {
                "archive" => self.archive_placements(&path, &at, base, inside, ctx)?,
                "curve" => {
                    let width = |k: &str| p.get(k).and_then(Node::as_f64).unwrap_or(0.01) as f32;
                    let material = ctx
                        .mats
                        .by_primitive
                        .get(prim)
                        .cloned()
                        .unwrap_or_else(|| self.default_material.clone());
                    let curve = CurveSpec {
                        width_root: width("widthRoot"),
                        width_tip: width("widthTip"),
                        material,
                    };
                    self.curves(&path, &at, base, inside, ctx, &curve)?;
                }
                other => self.warn(
                    Some(input.loc(p.at)),
                    format!("primitive `{prim}` has type `{other}` (archive and curve are read); skipped"),
                ),
            }
        }
        Ok(())
    }

    fn archive_object(
        &mut self,
        path: &Path,
        referenced_at: Option<&Location>,
        ctx: &Ctx<'_>,
    ) -> Result<Option<ObjectId>, Error> {
        if let Some(&o) = self.archives.get(path) {
            return Ok(o);
        }
        if classify(path) == FileKind::Missing && self.opts.allow_missing {
            self.open(path, referenced_at, Some((ctx.element, ctx.name)))?;
            self.archives.insert(path.to_path_buf(), None);
            return Ok(None);
        }
        let object = self.new_object();
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let loc = Loc::default();
        self.sink.object_begin(&ObjectEvent {
            object,
            name: &name,
            element: Some(ctx.element),
            loc,
        })?;
        self.obj_shapes(path, referenced_at, Some(object), &math::IDENTITY, ctx)?;
        self.sink.object_end(&ObjectEvent {
            object,
            name: &name,
            element: Some(ctx.element),
            loc,
        })?;
        self.archives.insert(path.to_path_buf(), Some(object));
        Ok(Some(object))
    }

    fn obj_shapes(
        &mut self,
        path: &Path,
        referenced_at: Option<&Location>,
        object: Option<ObjectId>,
        parent_from_shape: &M64,
        ctx: &Ctx<'_>,
    ) -> Result<(), Error> {
        let Some(input) = self.open(path, referenced_at, Some((ctx.element, ctx.name)))? else {
            return Ok(());
        };
        let m = math::to_f32(parent_from_shape);
        let result = obj::read::<Stop>(input.bytes.bytes(), |om: ObjMesh| {
            let mut material = ctx
                .mats
                .by_name
                .get(&om.material)
                .cloned()
                .unwrap_or_else(|| self.default_material.clone());
            let dir = ctx.mats.ptex_dirs.get(&material.id);
            if let (Some(dir), false) = (dir, om.group.is_empty()) {
                let key = (material.id, om.group.clone());
                material = match self.per_group.get(&key) {
                    Some(m) => m.clone(),
                    None => {
                        let m = Arc::new(Material {
                            id: MaterialId(self.next_material),
                            ptex: Some(dir.join(format!("{}.ptx", om.group))),
                            ..(*material).clone()
                        });
                        self.next_material += 1;
                        self.sink.material(&m).map_err(|e| Stop::Done(e.into()))?;
                        self.per_group.insert(key, m.clone());
                        m
                    }
                };
            }
            self.stats.shapes += 1;
            self.stats.triangles += om.mesh.triangle_count() as u64;
            let seq = self.seq;
            self.seq += 1;
            self.sink
                .shape(ShapeEvent {
                    seq,
                    kind: "objmesh".into(),
                    parent_from_shape: m,
                    reverse_orientation: false,
                    material,
                    alpha_texture: None,
                    alpha: None,
                    alpha_image: None,
                    area_light: None,
                    object,
                    element: Some(ctx.element),
                    source_path: Some(input.path.clone()),
                    loc: Loc {
                        file: input.file,
                        line: om.line,
                        column: 1,
                    },
                    geometry: Geometry::Mesh(om.mesh),
                })
                .map_err(|e| Stop::Done(e.into()))
        });
        result.map_err(|s| input.stop(s))
    }

    fn archive_placements(
        &mut self,
        path: &Path,
        referenced_at: &Location,
        base: &M64,
        inside: Option<ObjectId>,
        ctx: &Ctx<'_>,
    ) -> Result<(), Error> {
        let Some(input) = self.open(path, Some(referenced_at), Some((ctx.element, ctx.name)))?
        else {
            return Ok(());
        };
        let mut r = Reader::new(input.bytes.bytes());
        let result = r.object::<Stop>(
            "an archive file (OBJ path → instances)",
            |r, obj_path, key_at| {
                let obj_path = self.resolve(&obj_path, &input.path);
                let object = self.archive_object(&obj_path, Some(&input.location(key_at)), ctx)?;
                let name = obj_path
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default();
                r.object::<Stop>(
                    "an archive's instance map (name → matrix)",
                    |r, _instance, _| {
                        let at = r.offset();
                        let v = r.numbers::<16>("an instance matrix")?;
                        let m = checked_matrix(&v)
                            .map_err(|m| r.error(at, format!("instance matrix {m}")))?;
                        if let Some(object) = object {
                            let parent_from_instance = math::mul(base, &m);
                            self.instance(
                                object,
                                &name,
                                &parent_from_instance,
                                inside,
                                ctx.element,
                                input.loc(at),
                            )?;
                        }
                        Ok(())
                    },
                )
            },
        );
        result
            .and_then(|()| r.finish().map_err(Stop::Json))
            .map_err(|s| input.stop(s))
    }

    fn curves(
        &mut self,
        path: &Path,
        referenced_at: &Location,
        base: &M64,
        inside: Option<ObjectId>,
        ctx: &Ctx<'_>,
        spec: &CurveSpec,
    ) -> Result<(), Error> {
        let Some(input) = self.open(path, Some(referenced_at), Some((ctx.element, ctx.name)))?
        else {
            return Ok(());
        };
        let m = math::to_f32(base);
        let mut r = Reader::new(input.bytes.bytes());
        let mut points: Vec<[f32; 3]> = Vec::new();
        let result = r.array::<Stop>("a curve file (a list of curves)", |r, _| {
            let at = r.offset();
            points.clear();
            r.array::<Stop>("a curve (a list of points)", |r, _| {
                let p_at = r.offset();
                let p = r.numbers::<3>("a curve point")?;
                if p.iter().any(|x| !x.is_finite()) {
                    return Err(r
                        .error(p_at, "curve point is not finite (NaN or infinity)")
                        .into());
                }
                points.push(p.map(|x| x as f32));
                Ok(())
            })?;
            if points.len() < 2 {
                return Err(r
                    .error(
                        at,
                        format!(
                            "a curve needs at least 2 points, this one has {}",
                            points.len()
                        ),
                    )
                    .into());
            }
            // Cubic B-spline through its end points: each end repeated twice more.
            let (first, last) = (points[0], points[points.len() - 1]);
            let mut cp = Vec::with_capacity(points.len() + 4);
            cp.extend_from_slice(&[first, first]);
            cp.extend_from_slice(&points);
            cp.extend_from_slice(&[last, last]);
            self.stats.shapes += 1;
            self.stats.curves += 1;
            let seq = self.seq;
            self.seq += 1;
            self.sink
                .shape(ShapeEvent {
                    seq,
                    kind: "curve".into(),
                    parent_from_shape: m,
                    reverse_orientation: false,
                    material: spec.material.clone(),
                    alpha_texture: None,
                    alpha: None,
                    alpha_image: None,
                    area_light: None,
                    object: inside,
                    element: Some(ctx.element),
                    source_path: None,
                    loc: input.loc(at),
                    geometry: Geometry::Curve(Curve {
                        basis: "bspline".into(),
                        curve_type: "flat".into(),
                        degree: 3,
                        control_points: cp,
                        width0: spec.width_root,
                        width1: spec.width_tip,
                        normals: None,
                    }),
                })
                .map_err(|e| Stop::Done(e.into()))
        });
        result
            .and_then(|()| r.finish().map_err(Stop::Json))
            .map_err(|s| input.stop(s))
    }

    fn camera(&mut self, path: &Path, referenced_at: Option<&Location>) -> Result<(), Error> {
        let Some(input) = self.open(path, referenced_at, None)? else {
            return Ok(());
        };
        let doc = input.tree()?;
        let vec3 = |key: &str| -> Result<[f64; 3], Error> {
            let n = doc
                .get(key)
                .ok_or_else(|| input.invalid(doc.at, format!("a camera needs `{key}`")))?;
            let v: Vec<f64> = n.items().iter().filter_map(Node::as_f64).collect();
            if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
                return Err(input.invalid(n.at, format!("`{key}` must be 3 finite numbers")));
            }
            Ok([v[0], v[1], v[2]])
        };
        let (eye, look, up) = (vec3("eye")?, vec3("look")?, vec3("up")?);
        let fov = doc.get("fov").and_then(Node::as_f64).unwrap_or(90.0);
        let ratio = doc.get("ratio").and_then(Node::as_f64).unwrap_or(1.0);
        if !(fov.is_finite() && fov > 0.0 && fov < 180.0 && ratio.is_finite() && ratio > 0.0) {
            return Err(input.invalid(
                doc.at,
                format!("camera fov {fov} or ratio {ratio} is out of range"),
            ));
        }
        let Some(look_at) = math::look_at(eye, look, up) else {
            return Err(input.invalid(doc.at, "camera eye, look and up are degenerate"));
        };
        let right_handed = doc.get("handedness").and_then(Node::as_str) != Some("left");
        let camera_from_world = if right_handed {
            math::mul(&math::scale([-1.0, 1.0, 1.0]), &look_at)
        } else {
            look_at
        };
        let Some(world_from_camera) = math::inverse(&camera_from_world) else {
            return Err(input.invalid(doc.at, "camera transform is not invertible"));
        };
        // `fov` spans the image's width; pbrt's spans the shorter side.
        let fov_short = if ratio > 1.0 {
            2.0 * ((fov.to_radians() * 0.5).tan() / ratio).atan().to_degrees()
        } else {
            fov
        };
        let resolution = match doc.get("resolution").map(Node::items) {
            Some([w, h]) => {
                let (w, h) = (w.as_f64().unwrap_or(0.0), h.as_f64().unwrap_or(0.0));
                if !(w >= 1.0 && h >= 1.0 && w <= 65536.0 && h <= 65536.0) {
                    return Err(input.invalid(doc.at, "resolution must be two sizes in 1..=65536"));
                }
                [w as u32, h as u32]
            }
            _ => [1024, ((1024.0 / ratio).round() as u32).clamp(1, 65536)],
        };
        self.stats.cameras += 1;
        self.sink.camera(&CameraEvent {
            kind: "perspective".into(),
            camera_from_world: math::to_f32(&camera_from_world),
            world_from_camera: math::to_f32(&world_from_camera),
            fov_deg: Some(fov_short as f32),
            screen_window: None,
            lens_radius: doc
                .get("lensRadius")
                .and_then(Node::as_f64)
                .filter(|x| x.is_finite())
                .unwrap_or(0.0) as f32,
            focal_distance: doc
                .get("centerOfInterest")
                .and_then(Node::as_f64)
                .filter(|x| x.is_finite())
                .map(|x| x as f32),
            resolution,
            path,
            loc: input.loc(doc.at),
        })?;
        Ok(())
    }

    fn lights(&mut self, path: &Path, referenced_at: Option<&Location>) -> Result<(), Error> {
        let Some(input) = self.open(path, referenced_at, None)? else {
            return Ok(());
        };
        let doc = input.tree()?;
        for (name, l) in doc.members() {
            let vec3 = |key: &str| -> Result<Option<[f64; 3]>, Error> {
                let Some(n) = l.get(key) else { return Ok(None) };
                let v: Vec<f64> = n.items().iter().filter_map(Node::as_f64).collect();
                if v.len() < 3 || v[..3].iter().any(|x| !x.is_finite()) {
                    return Err(input.invalid(
                        n.at,
                        format!("light `{name}`: `{key}` must be 3 finite numbers"),
                    ));
                }
                Ok(Some([v[0], v[1], v[2]]))
            };
            let exposure = l.get("exposure").and_then(Node::as_f64).unwrap_or(0.0);
            let gain = 2f64.powf(exposure);
            let color = vec3("color")?.unwrap_or([1.0; 3]);
            let world_from_light = Self::matrix(
                &input,
                l.get("translationMatrix"),
                &format!("light `{name}` translationMatrix"),
            )?;
            let kind = l.get("type").and_then(Node::as_str).unwrap_or("");
            let f = |v: [f64; 3]| v.map(|x| x as f32);
            let event = match kind {
                "distant" => LightEvent {
                    kind: "distant".into(),
                    world_from_light: math::to_f32(&world_from_light),
                    color: Some(f(color.map(|c| c * gain))),
                    from: vec3("from")?.map(f),
                    to: vec3("to")?.map(f),
                    map: None,
                    map_path: None,
                    cone_deg: None,
                    object: None,
                    element: None,
                    loc: input.loc(l.at),
                },
                "quad" => {
                    // An area light as a point light of its power at its centre.
                    let w = l.get("width").and_then(Node::as_f64).unwrap_or(1.0);
                    let h = l.get("height").and_then(Node::as_f64).unwrap_or(1.0);
                    let area = (w * h).abs();
                    LightEvent {
                        kind: "point".into(),
                        world_from_light: math::to_f32(&world_from_light),
                        color: Some(f(color.map(|c| c.powf(2.2) * gain * area))),
                        from: Some([0.0; 3]),
                        to: None,
                        map: None,
                        map_path: None,
                        cone_deg: None,
                        object: None,
                        element: None,
                        loc: input.loc(l.at),
                    }
                }
                "dome" => {
                    let map = l.get("map").and_then(Node::as_str).map(str::to_string);
                    let map_path = map.as_ref().map(|m| self.resolve(m, &input.path));
                    LightEvent {
                        kind: "infinite".into(),
                        world_from_light: math::to_f32(&world_from_light),
                        color: Some(f([gain; 3])),
                        from: None,
                        to: None,
                        map,
                        map_path,
                        cone_deg: None,
                        object: None,
                        element: None,
                        loc: input.loc(l.at),
                    }
                }
                other => {
                    self.warn(
                        Some(input.loc(l.at)),
                        format!("light `{name}` has type `{other}` (quad, dome and distant are read); skipped"),
                    );
                    continue;
                }
            };
            self.stats.lights += 1;
            self.sink.light(&event)?;
        }
        Ok(())
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

/// 16 numbers (pbrt's `Transform` order) → a finite matrix, or why not.
fn checked_matrix(v: &[f64; 16]) -> Result<M64, String> {
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(format!(
            "holds a non-finite value (NaN or infinity) at position {i}"
        ));
    }
    Ok(math::from_pbrt(v))
}

#[cfg(test)]
mod tests;
