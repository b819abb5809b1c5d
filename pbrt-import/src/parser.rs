//! The directive interpreter: the parser's state, the entry point and the directive dispatch.
//! Each directive's work lives in a file named after its job: `args` (reading arguments,
//! errors at file:line:column), `graphics` (transforms, blocks, cameras), `materials` (lights,
//! materials, textures: each version's parameter semantics), `shape` (shapes, PLY batches),
//! `objects` (object definitions and instances), `includes` (`Include`/`Import`, shared and
//! parallel includes). They are one `impl Parser` split by job, children of this module.

use std::borrow::Cow;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;

use crate::color;
use crate::error::{Error, Location, MissingFile, ParseError, ParseErrorKind};
use crate::events::*;
use crate::lexer::{LexError, LexErrorKind, Lexer, Loc, Token, TokenKind};
use crate::math::{self, M64};
use crate::parallel::{self, Buffered, Outcome, Parsed, Snapshot};
use crate::params::{Param, ParamError, ParamList, ParamType, Values};
use crate::prescan::{prescan_is_v4, V4_NAMES};
use crate::shapes;
use crate::source::SourceBytes;
use crate::{
    ElementId, FileId, MaterialId, ObjectId, ParseOptions, ParseStats, PbrtVersion, PlyLoading,
    VersionOption,
};

mod args;
mod graphics;
mod includes;
mod materials;
mod objects;
mod shape;

use includes::{count_includes, SharedInclude};

#[derive(Clone, Copy)]
pub(crate) enum Entry<'a> {
    Path(&'a Path),
    Text { text: &'a [u8], base_dir: &'a Path },
}

type Result<T> = std::result::Result<T, Error>;

#[derive(Clone)]
struct GState {
    reverse_orientation: bool,
    material: Arc<Material>,
    area_light: Option<Arc<AreaLight>>,
}

#[derive(Clone, Copy)]
struct XState {
    ctm: [M64; 2],
    /// Bit 0: start transform active, bit 1: end transform active.
    active: u8,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum BlockKind {
    Attribute,
    Transform,
    Object,
}

impl BlockKind {
    fn begin(self) -> &'static str {
        match self {
            BlockKind::Attribute => "AttributeBegin",
            BlockKind::Transform => "TransformBegin",
            BlockKind::Object => "ObjectBegin",
        }
    }
}

struct PendingCamera {
    kind: String,
    camera_from_world: M64,
    fov_deg: Option<f32>,
    screen_window: Option<[f32; 4]>,
    lens_radius: f32,
    focal_distance: Option<f32>,
    loc: Loc,
}

struct PendingPly {
    path: PathBuf,
    event: ShapeEvent,
}

pub(crate) fn parse_entry(
    entry: Entry<'_>,
    opts: &ParseOptions,
    sink: &mut dyn SceneSink,
) -> Result<ParseStats> {
    let span = tracing::info_span!("pbrt_parse");
    let _guard = span.enter();
    let (path, base_dir, owned_src);
    let mut source = None;
    let bytes: &[u8] = match entry {
        Entry::Path(p) => {
            owned_src = SourceBytes::open(p).map_err(|source| Error::Io {
                path: p.to_path_buf(),
                source,
            })?;
            path = p.to_path_buf();
            base_dir = p.parent().map(Path::to_path_buf).unwrap_or_default();
            source = Some(&owned_src);
            owned_src.bytes()
        }
        Entry::Text {
            text,
            base_dir: dir,
        } => {
            path = dir.join("<input>");
            base_dir = dir.to_path_buf();
            text
        }
    };
    let version = match opts.version {
        VersionOption::V3 => PbrtVersion::V3,
        VersionOption::V4 => PbrtVersion::V4,
        VersionOption::Auto if prescan_is_v4(bytes) => PbrtVersion::V4,
        VersionOption::Auto => PbrtVersion::V3,
    };
    let mut p = Parser::new(opts, sink, base_dir, version);
    if let Entry::Path(entry) = entry {
        // The entry file is open too: an include of it is a cycle at its first repeat.
        p.open_files
            .push(entry.canonicalize().unwrap_or_else(|_| entry.to_path_buf()));
    }
    p.sink.material(&p.gs.material)?;
    p.run_file(path, bytes, source, Via::Entry, None, None)?;
    p.finish()
}

/// Text parsed between releases of a mapped file's pages already read (`parse_tokens`).
const RELEASE_TEXT_BYTES: usize = 4 << 20;

struct Parser<'s> {
    opts: &'s ParseOptions,
    sink: &'s mut dyn SceneSink,
    version: PbrtVersion,
    stats: ParseStats,
    entry_dir: PathBuf,
    dirs: Vec<PathBuf>,
    depth: u32,
    open_files: Vec<PathBuf>,
    in_world: bool,
    gs: GState,
    xs: XState,
    attr_stack: Vec<GState>,
    xform_stack: Vec<XState>,
    blocks: Vec<(BlockKind, Loc)>,
    named_coords: HashMap<String, [M64; 2]>,
    named_materials: HashMap<String, Arc<Material>>,
    next_material: u32,
    float_textures: HashMap<String, [f32; 3]>,
    color_textures: HashMap<String, [f32; 3]>,
    /// Textures whose value is an image file times a constant, by (is float, name). Their
    /// entry in `float_textures`/`color_textures` is the constant colour used without it.
    image_textures: HashMap<(bool, String), (PathBuf, [f32; 3])>,
    /// `ptex` colour textures: name → file, resolved.
    ptex_textures: HashMap<String, PathBuf>,
    objects: HashMap<String, ObjectId>,
    object_names: Vec<String>,
    object_defined: Vec<bool>,
    forward_refs: Vec<(ObjectId, Loc, String)>,
    /// (object, object it instances) → the first such `ObjectInstance`: an instancing cycle is
    /// reported at the instance that closes it (pbrt-v4 forward references make them possible).
    instance_edges: std::collections::BTreeMap<(u32, u32), Loc>,
    current_object: Option<ObjectId>,
    cameras: Vec<PendingCamera>,
    film_resolution: [u32; 2],
    element: Option<ElementId>,
    element_names: Vec<String>,
    missing: Vec<MissingFile>,
    ply_queue: Vec<PendingPly>,
    ply_queue_bytes: u64,
    next_seq: u64,
    warned: HashSet<String>,
    spectrum_cache: HashMap<PathBuf, Option<[f32; 3]>>,
    /// Raw name token and id of the last resolved `ObjectInstance` (see `object_instance`).
    last_instance: Option<(Vec<u8>, ObjectId)>,
    /// Per open file (with `share_repeated_includes`): how often each raw `Include`/`Import`
    /// name occurs in it.
    include_counts: Vec<HashMap<Vec<u8>, u32>>,
    /// Files whose content became a shared object, by canonical path.
    shared: HashMap<PathBuf, SharedInclude>,
}

fn default_material(version: PbrtVersion) -> Material {
    let kind = if version == PbrtVersion::V4 {
        "diffuse"
    } else {
        "matte"
    };
    Material {
        id: MaterialId(0),
        name: None,
        kind: kind.into(),
        base_color: Some([0.5; 3]),
        base_color_texture: None,
        opacity: None,
        base_color_image: None,
        ptex: None,
        roughness: Some(1.0),
        metallic: Some(0.0),
        loc: Loc::default(),
    }
}

impl<'s> Parser<'s> {
    fn new(
        opts: &'s ParseOptions,
        sink: &'s mut dyn SceneSink,
        entry_dir: PathBuf,
        version: PbrtVersion,
    ) -> Self {
        let mut named_coords = HashMap::new();
        named_coords.insert("world".to_owned(), [math::IDENTITY; 2]);
        Parser {
            opts,
            sink,
            version,
            stats: ParseStats::default(),
            entry_dir,
            dirs: Vec::new(),
            depth: 0,
            open_files: Vec::new(),
            in_world: false,
            gs: GState {
                reverse_orientation: false,
                material: Arc::new(default_material(version)),
                area_light: None,
            },
            xs: XState {
                ctm: [math::IDENTITY; 2],
                active: 3,
            },
            attr_stack: Vec::new(),
            xform_stack: Vec::new(),
            blocks: Vec::new(),
            named_coords,
            named_materials: HashMap::new(),
            next_material: 1,
            float_textures: HashMap::new(),
            color_textures: HashMap::new(),
            image_textures: HashMap::new(),
            ptex_textures: HashMap::new(),
            objects: HashMap::new(),
            object_names: Vec::new(),
            object_defined: Vec::new(),
            forward_refs: Vec::new(),
            instance_edges: std::collections::BTreeMap::new(),
            current_object: None,
            cameras: Vec::new(),
            film_resolution: [1280, 720],
            element: None,
            element_names: Vec::new(),
            missing: Vec::new(),
            ply_queue: Vec::new(),
            ply_queue_bytes: 0,
            next_seq: 0,
            warned: HashSet::new(),
            spectrum_cache: HashMap::new(),
            last_instance: None,
            include_counts: Vec::new(),
            shared: HashMap::new(),
        }
    }

    fn v4(&self) -> bool {
        self.version == PbrtVersion::V4
    }

    fn hint_v4(&mut self, why: &str) {
        if self.opts.version == VersionOption::Auto && self.version == PbrtVersion::V3 {
            tracing::info!(reason = why, "switching to pbrt-v4 semantics");
            self.version = PbrtVersion::V4;
        }
    }

    // ---- errors and warnings -------------------------------------------------------

    fn run_file(
        &mut self,
        path: PathBuf,
        bytes: &[u8],
        source: Option<&SourceBytes>,
        via: Via,
        element: Option<ElementId>,
        replay: Option<Vec<Parsed>>,
    ) -> Result<()> {
        let file = FileId(self.stats.files.len() as u32);
        self.stats.files.push(path.clone());
        self.stats.text_bytes += bytes.len() as u64;
        let saved_element = self.element;
        if element.is_some() {
            self.element = element;
        }
        self.dirs
            .push(path.parent().map(Path::to_path_buf).unwrap_or_default());
        let from_entry_world = element.is_some();
        let event = FileEvent {
            file,
            path: &path,
            depth: self.depth,
            via,
            from_entry_world,
            element: self.element,
            element_name: self
                .element
                .and_then(|e| self.element_names.get(e.0 as usize))
                .map(String::as_str),
            size_bytes: bytes.len() as u64,
        };
        self.sink.file_enter(&event)?;
        if self.opts.share_repeated_includes {
            // The count reads the whole file: its pages leave the resident set as it goes.
            self.include_counts
                .push(count_includes(bytes, |start, end| {
                    if let Some(s) = source {
                        s.release(start, end);
                    }
                }));
        }
        let _span =
            tracing::debug_span!("pbrt_file", path = %path.display(), size_bytes = bytes.len())
                .entered();
        let parsed = match replay {
            Some(pieces) => self.replay(pieces, file),
            None => self.parse_tokens(bytes, source, file),
        };
        if self.opts.share_repeated_includes {
            self.include_counts.pop();
        }
        parsed?;
        let event = FileEvent {
            file,
            path: &path,
            depth: self.depth,
            via,
            from_entry_world,
            element: self.element,
            element_name: self
                .element
                .and_then(|e| self.element_names.get(e.0 as usize))
                .map(String::as_str),
            size_bytes: bytes.len() as u64,
        };
        self.sink.file_exit(&event)?;
        self.dirs.pop();
        self.element = saved_element;
        Ok(())
    }

    fn finish(mut self) -> Result<ParseStats> {
        self.flush_plys()?;
        self.emit_cameras()?;
        if let Some(&(kind, loc)) = self.blocks.last() {
            return Err(self.err_at(
                loc,
                kind.begin(),
                ParseErrorKind::Unbalanced(format!("{} never closed", kind.begin())),
            ));
        }
        for (id, loc, name) in std::mem::take(&mut self.forward_refs) {
            if !self
                .object_defined
                .get(id.0 as usize)
                .copied()
                .unwrap_or(false)
            {
                return Err(self.err_at(
                    loc,
                    &format!("\"{name}\""),
                    ParseErrorKind::UnknownObject,
                ));
            }
        }
        if let Some((loc, cycle)) = self.instance_cycle() {
            let shown = format!("\"{}\"", cycle[cycle.len() - 1]);
            let path = cycle
                .iter()
                .map(|n| format!("\"{n}\""))
                .collect::<Vec<_>>()
                .join(" → ");
            return Err(self.err_at(
                loc,
                &shown,
                ParseErrorKind::Invalid(format!("instancing cycle: {path}")),
            ));
        }
        if !self.missing.is_empty() && !self.opts.allow_missing {
            return Err(Error::MissingFiles {
                files: std::mem::take(&mut self.missing),
            });
        }
        self.stats.missing = std::mem::take(&mut self.missing);
        self.stats.version = Some(self.version);
        tracing::info!(
            files = self.stats.files.len(),
            text_bytes = self.stats.text_bytes,
            shapes = self.stats.shapes,
            triangles = self.stats.triangles,
            instances = self.stats.instances,
            "pbrt parse done"
        );
        Ok(self.stats)
    }

    // ---- main loop ----------------------------------------------------------------------

    /// Parses `bytes` directive by directive. A mapped file's text already read leaves the
    /// resident set every [`RELEASE_TEXT_BYTES`] (a multi-gigabyte instance file would
    /// otherwise stay resident whole until it is closed).
    fn parse_tokens(
        &mut self,
        bytes: &[u8],
        source: Option<&SourceBytes>,
        file: FileId,
    ) -> Result<()> {
        let mut lx = Lexer::new(bytes, file);
        let mut released = 0usize;
        while let Some(tok) = lx.next_token().map_err(|e| self.lex_err(e))? {
            if let Some(s) = source.filter(|_| lx.offset() >= released + RELEASE_TEXT_BYTES) {
                s.release(released, lx.offset());
                released = lx.offset();
            }
            if tok.kind != TokenKind::Word {
                return Err(self.err(
                    &tok,
                    ParseErrorKind::Unexpected {
                        expected: "a directive",
                    },
                ));
            }
            self.directive(&mut lx, &tok)?;
        }
        Ok(())
    }

    fn directive<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        match tok.bytes {
            b"AttributeBegin" => {
                self.attr_stack.push(self.gs.clone());
                self.push_xform();
                self.blocks.push((BlockKind::Attribute, tok.loc));
            }
            b"AttributeEnd" => self.pop_block(tok, BlockKind::Attribute)?,
            b"TransformBegin" => {
                self.push_xform();
                self.blocks.push((BlockKind::Transform, tok.loc));
            }
            b"TransformEnd" => self.pop_block(tok, BlockKind::Transform)?,
            b"Translate" => {
                let v = self.numbers::<3>(lx, tok)?;
                self.apply(math::translate([v[0], v[1], v[2]]));
            }
            b"Scale" => {
                let v = self.numbers::<3>(lx, tok)?;
                self.apply(math::scale([v[0], v[1], v[2]]));
            }
            b"Rotate" => {
                let v = self.numbers::<4>(lx, tok)?;
                if v[1] == 0.0 && v[2] == 0.0 && v[3] == 0.0 {
                    self.warn(
                        Some(tok.loc),
                        format!("Rotate {} about a zero axis; ignored", v[0]),
                    );
                } else {
                    self.apply(math::rotate(v[0], [v[1], v[2], v[3]]));
                }
            }
            b"LookAt" => {
                let v = self.numbers::<9>(lx, tok)?;
                match math::look_at([v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]) {
                    Some(m) => self.apply(m),
                    None => self.warn(
                        Some(tok.loc),
                        "LookAt: up vector parallel to view direction; ignored".into(),
                    ),
                }
            }
            b"Transform" | b"ConcatTransform" => {
                let v = self.numbers::<16>(lx, tok)?;
                let m = math::from_pbrt(&v);
                if tok.bytes == b"Transform" {
                    self.set(m);
                } else {
                    self.apply(m);
                }
            }
            b"Identity" => self.set(math::IDENTITY),
            b"CoordinateSystem" => {
                let (name, _) = self.string(lx, tok)?;
                self.named_coords.insert(name.into_owned(), self.xs.ctm);
            }
            b"CoordSysTransform" => {
                let (name, stok) = self.string(lx, tok)?;
                match self.named_coords.get(name.as_ref()) {
                    Some(m) => self.xs.ctm = *m,
                    None => self.warn(
                        Some(stok.loc),
                        format!("unknown coordinate system \"{name}\""),
                    ),
                }
            }
            b"ActiveTransform" => {
                let t = self.next(lx, "StartTime, EndTime or All", tok)?;
                self.xs.active = match t.bytes {
                    b"StartTime" => 1,
                    b"EndTime" => 2,
                    b"All" => 3,
                    _ => {
                        return Err(self.err(
                            &t,
                            ParseErrorKind::Unexpected {
                                expected: "StartTime, EndTime or All",
                            },
                        ))
                    }
                };
            }
            b"TransformTimes" => {
                self.numbers::<2>(lx, tok)?;
            }
            b"ReverseOrientation" => self.gs.reverse_orientation = !self.gs.reverse_orientation,
            b"WorldBegin" => {
                if self.in_world {
                    self.warn(Some(tok.loc), "second WorldBegin".into());
                }
                self.in_world = true;
                self.xs.ctm = [math::IDENTITY; 2];
                self.xs.active = 3;
                self.named_coords
                    .insert("world".into(), [math::IDENTITY; 2]);
                self.emit_cameras()?;
            }
            b"WorldEnd" => {
                if !self.v4() {
                    self.flush_plys()?;
                    while let Some((kind, _)) = self.blocks.last().copied() {
                        if kind == BlockKind::Object {
                            break;
                        }
                        self.warn(
                            Some(tok.loc),
                            format!("WorldEnd: missing end to {}", kind.begin()),
                        );
                        self.pop_block(tok, kind)?;
                    }
                }
            }
            b"Include" => self.include(lx, tok, Via::Include)?,
            b"Import" => {
                self.hint_v4("Import");
                self.include(lx, tok, Via::Import)?;
            }
            b"Camera" => self.camera(lx, tok)?,
            b"Film" => {
                let (kind, _) = self.string(lx, tok)?;
                if V4_NAMES.contains(&kind.as_bytes()) || kind == "rgb" {
                    self.hint_v4("v4 film");
                }
                let p = self.params(lx)?;
                let x = p.int("xresolution").unwrap_or(1280).max(1) as u32;
                let y = p.int("yresolution").unwrap_or(720).max(1) as u32;
                self.film_resolution = [x, y];
            }
            b"Sampler" | b"Accelerator" | b"Integrator" | b"PixelFilter" | b"SurfaceIntegrator"
            | b"VolumeIntegrator" | b"Renderer" => {
                // Rendering settings: validated, then ignored by design.
                self.string(lx, tok)?;
                self.params(lx)?;
            }
            b"ColorSpace" => {
                self.hint_v4("ColorSpace");
                self.string(lx, tok)?;
            }
            b"Option" => {
                self.hint_v4("Option");
                self.params(lx)?;
            }
            b"Attribute" => {
                self.hint_v4("Attribute");
                let (target, t) = self.string(lx, tok)?;
                if !matches!(
                    target.as_ref(),
                    "shape" | "light" | "material" | "medium" | "texture"
                ) {
                    return Err(self.err(
                        &t,
                        ParseErrorKind::Invalid("unknown Attribute target".into()),
                    ));
                }
                self.params(lx)?;
                self.warn_once(
                    "Attribute",
                    Some(tok.loc),
                    "Attribute defaults are not applied".into(),
                );
            }
            b"MakeNamedMedium" => {
                self.string(lx, tok)?;
                self.params(lx)?;
            }
            b"MediumInterface" => {
                self.string(lx, tok)?;
                if lx.peek_byte() == Some(b'"') {
                    self.string(lx, tok)?;
                }
            }
            b"Texture" => self.texture(lx, tok)?,
            b"Material" => {
                self.require_world(tok);
                let (kind, t) = self.string(lx, tok)?;
                if V4_NAMES.contains(&kind.as_bytes()) {
                    self.hint_v4("v4 material");
                }
                let p = self.params(lx)?;
                self.check_material("Material", &kind, &p, t.loc)?;
                let m = self.make_material(None, &kind, &p, t.loc);
                self.sink.material(&m)?;
                self.gs.material = m;
            }
            b"MakeNamedMaterial" => {
                let (name, t) = self.string(lx, tok)?;
                let p = self.params(lx)?;
                let Some(kind) = p.string("type").map(str::to_owned) else {
                    return Err(self.err(
                        &t,
                        ParseErrorKind::BadParameter(
                            "MakeNamedMaterial needs \"string type\"".into(),
                        ),
                    ));
                };
                if V4_NAMES.contains(&kind.as_bytes()) {
                    self.hint_v4("v4 material");
                }
                if self.named_materials.contains_key(name.as_ref()) {
                    if self.v4() {
                        return Err(self.err(
                            &t,
                            ParseErrorKind::Invalid("named material redefined".into()),
                        ));
                    }
                    self.warn(Some(t.loc), format!("named material \"{name}\" redefined"));
                }
                self.check_material("MakeNamedMaterial", &kind, &p, t.loc)?;
                let m = self.make_material(Some(name.to_string()), &kind, &p, t.loc);
                self.sink.material(&m)?;
                self.named_materials.insert(name.into_owned(), m);
            }
            b"NamedMaterial" => {
                let (name, t) = self.string(lx, tok)?;
                match self.named_materials.get(name.as_ref()) {
                    Some(m) => self.gs.material = m.clone(),
                    None => {
                        self.warn(
                            Some(t.loc),
                            format!("unknown named material \"{name}\"; using the default"),
                        );
                        self.gs.material = Arc::new(default_material(self.version));
                    }
                }
            }
            b"LightSource" => self.light(lx, tok)?,
            b"AreaLightSource" => {
                let (kind, _) = self.string(lx, tok)?;
                let p = self.params(lx)?;
                // Caught here with its location, not by the package's self-check.
                self.require_finite("AreaLightSource", &p)?;
                let radiance = self.emission(&p, "L");
                let two_sided = p.bool("twosided").unwrap_or(false);
                self.gs.area_light = Some(Arc::new(AreaLight {
                    kind: kind.into_owned(),
                    radiance,
                    two_sided,
                }));
            }
            b"Shape" => self.shape(lx, tok)?,
            b"ObjectBegin" => self.object_begin(lx, tok)?,
            b"ObjectEnd" => {
                let Some(id) = self.current_object else {
                    return Err(self.err(
                        tok,
                        ParseErrorKind::Unbalanced("ObjectEnd without ObjectBegin".into()),
                    ));
                };
                self.pop_block(tok, BlockKind::Object)?;
                self.current_object = None;
                let name = self.object_names[id.0 as usize].clone();
                self.sink.object_end(&ObjectEvent {
                    object: id,
                    name: &name,
                    element: self.element,
                    loc: tok.loc,
                })?;
            }
            b"ObjectInstance" => self.object_instance(lx, tok)?,
            _ => {
                // A scene in another encoding fails on its first token: name the encoding.
                let b = tok.bytes;
                let encoding = if b.starts_with(&[0xFF, 0xFE]) || b.starts_with(&[0xFE, 0xFF]) {
                    Some("UTF-16 text (it starts with a UTF-16 byte-order mark)")
                } else if b.contains(&0) {
                    Some("UTF-16 or binary data (the directive holds NUL bytes)")
                } else if b.starts_with(&[0xEF, 0xBB, 0xBF]) {
                    Some("UTF-8 with a byte-order mark")
                } else {
                    None
                };
                if let Some(what) = encoding {
                    return Err(self.err(
                        tok,
                        ParseErrorKind::Invalid(format!(
                            "the file is {what}; pbrt scenes are ASCII/UTF-8 text without a byte-order mark (convert it, e.g. `iconv -f UTF-16 -t UTF-8`)"
                        )),
                    ));
                }
                return Err(self.err(tok, ParseErrorKind::UnknownDirective));
            }
        }
        Ok(())
    }
}
