//! The directive interpreter: graphics state, version semantics, includes, events.

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
use crate::shapes;
use crate::source::SourceBytes;
use crate::{
    ElementId, FileId, MaterialId, ObjectId, ParseOptions, ParseStats, PbrtVersion, PlyLoading,
    VersionOption,
};

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

/// v4-only material and film names; seeing one switches `Auto` to v4.
const V4_NAMES: &[&[u8]] = &[
    b"coateddiffuse",
    b"coatedconductor",
    b"conductor",
    b"dielectric",
    b"thindielectric",
    b"diffusetransmission",
    b"gbuffer",
    b"spectral",
    b"bilinearmesh",
];

const V4_DIRECTIVES: &[&[u8]] = &[b"Import", b"ColorSpace", b"Option", b"Attribute"];

/// Find pbrt-v4-only constructs in (the start of) a file.
///
/// A byte scanner rather than the lexer: it only looks at words that start with an
/// upper-case letter (directives) and at quoted strings, and skips numbers without
/// building tokens, so it costs a fraction of a parse even on instance-heavy files.
fn prescan_is_v4(bytes: &[u8]) -> bool {
    let bytes = &bytes[..bytes.len().min(16 << 20)];
    let mut pos = 0;
    while pos < bytes.len() {
        let b = bytes[pos];
        match b {
            b'#' => {
                pos += bytes[pos..]
                    .iter()
                    .position(|&c| c == b'\n')
                    .unwrap_or(bytes.len() - pos);
            }
            b'"' => {
                let start = pos + 1;
                let mut p = start;
                while p < bytes.len() && !matches!(bytes[p], b'"' | b'\n') {
                    p += if bytes[p] == b'\\' { 2 } else { 1 };
                }
                if p >= bytes.len() || bytes[p] == b'\n' {
                    return false; // unterminated string: the lexer stops here too
                }
                let text = &bytes[start..p];
                if V4_NAMES.contains(&text) || V4_TYPE_PREFIXES.iter().any(|t| text.starts_with(t))
                {
                    return true;
                }
                pos = p + 1;
            }
            b'A'..=b'Z' => {
                let start = pos;
                while pos < bytes.len() && !crate::lexer::is_word_end_byte(bytes[pos]) {
                    pos += 1;
                }
                if V4_DIRECTIVES.contains(&&bytes[start..pos]) {
                    return true;
                }
            }
            _ if crate::lexer::is_word_end_byte(b) => pos += 1,
            _ => {
                // Numbers and lower-case words: skip the whole word, then every 8-byte run
                // without a quote, `#` or upper-case letter (pure numbers and whitespace).
                while pos < bytes.len() && !crate::lexer::is_word_end_byte(bytes[pos]) {
                    pos += 1;
                }
                while let Some(chunk) = bytes.get(pos..pos + 8) {
                    let x = u64::from_le_bytes(chunk.try_into().unwrap_or([b'"'; 8]));
                    if swar_interesting(x) {
                        break;
                    }
                    pos += 8;
                }
                // A skip may stop inside a word (`abcdefghXyz`): finish that word, so an
                // upper-case letter is only taken for a directive at a word start.
                while pos > 0
                    && pos < bytes.len()
                    && !crate::lexer::is_word_end_byte(bytes[pos - 1])
                    && !crate::lexer::is_word_end_byte(bytes[pos])
                {
                    pos += 1;
                }
            }
        }
    }
    false
}

/// Whether any byte of `x` is `"`, `#` or `A`..=`Z` (exact: no false positives or negatives
/// for "any"; bytes >= 0x80 never match). Word boundaries are rechecked byte by byte.
#[inline]
pub(crate) fn swar_interesting(x: u64) -> bool {
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    let has_zero = |v: u64| v.wrapping_sub(LO) & !v & HI != 0;
    let quote = has_zero(x ^ (LO * u64::from(b'"')));
    let hash = has_zero(x ^ (LO * u64::from(b'#')));
    // Bytes c with 'A' <= c <= 'Z': (c & 0x7f) + (0x7f - 'Z') has bit 7 clear and
    // (c & 0x7f) + (0x80 - 'A') has bit 7 set, and c itself has bit 7 clear.
    let low7 = x & (LO * 0x7f);
    let above_z = low7 + LO * u64::from(0x7f - b'Z');
    let from_a = low7 + LO * u64::from(0x80 - b'A');
    let upper = !above_z & from_a & !x & HI != 0;
    quote || hash || upper
}

/// How often each raw `Include`/`Import` file name occurs in `bytes`. A heuristic that
/// only decides whether sharing is attempted (a wrong count costs a prototype or a copy,
/// never correctness); files without either word are not tokenized.
fn count_includes(bytes: &[u8]) -> HashMap<Vec<u8>, u32> {
    let mut counts = HashMap::new();
    if !mentions_include(bytes) {
        return counts;
    }
    let mut lx = Lexer::new(bytes, FileId(0));
    let mut after_include = false;
    while let Ok(Some(t)) = lx.next_token() {
        if after_include && t.kind == TokenKind::String {
            *counts.entry(t.bytes.to_vec()).or_insert(0) += 1;
        }
        after_include = t.kind == TokenKind::Word && matches!(t.bytes, b"Include" | b"Import");
    }
    counts
}

/// Whether `bytes` contain `Import` or `Include` anywhere: a SWAR scan for `I`, 8 bytes a
/// step, so the huge number-only files Moana is made of cost next to nothing.
fn mentions_include(bytes: &[u8]) -> bool {
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    let mut pos = 0;
    while pos < bytes.len() {
        if let Some(chunk) = bytes.get(pos..pos + 8) {
            let x =
                u64::from_le_bytes(chunk.try_into().unwrap_or([b'I'; 8])) ^ (LO * u64::from(b'I'));
            if x.wrapping_sub(LO) & !x & HI == 0 {
                pos += 8;
                continue;
            }
        }
        let end = (pos + 8).min(bytes.len());
        for i in pos..end {
            let rest = &bytes[i..];
            if rest.starts_with(b"Import") || rest.starts_with(b"Include") {
                return true;
            }
        }
        pos = end;
    }
    false
}

/// Whether a file's meaning depends only on the CTM and graphics state at its inclusion and
/// it changes nothing visible after it, so that one parse in its own frame can stand for
/// every inclusion. Deliberately narrow: shapes and instances, inside balanced blocks
/// any relative transforms, and material changes only inside `AttributeBegin` blocks.
/// Absolute transforms (`Transform`, `Identity`, `CoordSysTransform`), definitions
/// (objects, named materials, textures, media, coordinate systems), lights, nested
/// includes and anything else disqualify the file.
fn shareable(bytes: &[u8]) -> bool {
    let mut lx = Lexer::new(bytes, FileId(0));
    let mut blocks: Vec<BlockKind> = Vec::new();
    let mut any = false;
    loop {
        let t = match lx.next_token() {
            Ok(Some(t)) => t,
            Ok(None) => break,
            Err(_) => return false,
        };
        if t.kind != TokenKind::Word || !t.bytes.first().is_some_and(u8::is_ascii_uppercase) {
            continue; // parameters and values
        }
        let in_attribute = blocks.contains(&BlockKind::Attribute);
        match t.bytes {
            b"AttributeBegin" => blocks.push(BlockKind::Attribute),
            b"TransformBegin" => blocks.push(BlockKind::Transform),
            b"AttributeEnd" if blocks.pop() == Some(BlockKind::Attribute) => {}
            b"TransformEnd" if blocks.pop() == Some(BlockKind::Transform) => {}
            b"Shape" | b"ObjectInstance" => any = true,
            b"Translate" | b"Scale" | b"Rotate" | b"ConcatTransform" | b"LookAt"
                if !blocks.is_empty() => {}
            b"Material" | b"NamedMaterial" | b"ReverseOrientation" if in_attribute => {}
            _ => return false,
        }
    }
    any && blocks.is_empty()
}

/// Parameter type spellings only pbrt-v4 uses (a parameter declaration starts with one).
const V4_TYPE_PREFIXES: &[&[u8]] = &[
    b"point3 ",
    b"point2 ",
    b"normal3 ",
    b"vector3 ",
    b"vector2 ",
];

pub(crate) fn parse_entry(
    entry: Entry<'_>,
    opts: &ParseOptions,
    sink: &mut dyn SceneSink,
) -> Result<ParseStats> {
    let span = tracing::info_span!("pbrt_parse");
    let _guard = span.enter();
    let (path, base_dir, owned_src);
    let bytes: &[u8] = match entry {
        Entry::Path(p) => {
            owned_src = SourceBytes::open(p).map_err(|source| Error::Io {
                path: p.to_path_buf(),
                source,
            })?;
            path = p.to_path_buf();
            base_dir = p.parent().map(Path::to_path_buf).unwrap_or_default();
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
    p.run_file(path, bytes, Via::Entry, None, None)?;
    p.finish()
}

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
    objects: HashMap<String, ObjectId>,
    object_names: Vec<String>,
    object_defined: Vec<bool>,
    forward_refs: Vec<(ObjectId, Loc, String)>,
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

/// Input bytes of the files in flight in a parallel include run (buffered events take
/// less than their text); files over half of it are parsed sequentially (streaming).
const PARALLEL_WINDOW_BYTES: u64 = 256 << 20;

/// An `Include`/`Import` directive found while looking ahead in a parallel run.
struct RunItem<'b> {
    via: Via,
    /// An `Import` after the first item: switch `Auto` to pbrt-v4 when it is reached.
    hint_v4: bool,
    name: Cow<'b, str>,
    stok: Token<'b>,
    /// The lexer just after the directive.
    after: Lexer<'b>,
    /// Resolved path and contents, when the file exists and fits the window.
    src: Option<(PathBuf, Arc<SourceBytes>)>,
}

/// A file of a parallel run: the worker's snapshot and result slot, if one was started.
struct InFlight<'b> {
    item: RunItem<'b>,
    /// One slot per piece of the file.
    job: Option<(Snapshot, Vec<Arc<Slot>>)>,
}

/// Where a worker leaves its outcome for the main thread.
#[derive(Default)]
struct Slot {
    outcome: std::sync::Mutex<Option<Outcome>>,
    ready: std::sync::Condvar,
}

impl Slot {
    fn put(&self, outcome: Outcome) {
        let mut guard = self
            .outcome
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        *guard = Some(outcome);
        self.ready.notify_all();
    }

    /// Wait for the outcome. On a pool thread, run other pool work meanwhile (the job may
    /// sit in this thread's own queue); elsewhere, sleep on the condition variable.
    fn take(&self) -> Outcome {
        let mut guard = self
            .outcome
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        loop {
            if let Some(outcome) = guard.take() {
                return outcome;
            }
            if rayon::current_thread_index().is_some() {
                drop(guard);
                if rayon::yield_now() != Some(rayon::Yield::Executed) {
                    std::thread::yield_now();
                }
                guard = self
                    .outcome
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
            } else {
                guard = self
                    .ready
                    .wait(guard)
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
            }
        }
    }
}

/// What a parallel run prepared for one include.
struct Prepared {
    path: PathBuf,
    src: Arc<SourceBytes>,
    /// The workers' buffers (one per piece) and the state they assumed; `None` when a
    /// worker gave up.
    parsed: Option<(Snapshot, Option<Vec<Parsed>>)>,
}

/// Graphics state that a shared include's shapes inherit; a repeat under a different
/// state is parsed again (a copy) rather than instanced.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct ShareKey {
    material: MaterialId,
    reverse_orientation: bool,
}

struct SharedInclude {
    object: ObjectId,
    key: ShareKey,
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
            objects: HashMap::new(),
            object_names: Vec::new(),
            object_defined: Vec::new(),
            forward_refs: Vec::new(),
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

    fn location(&self, loc: Loc) -> Location {
        Location {
            path: self
                .stats
                .files
                .get(loc.file.0 as usize)
                .cloned()
                .unwrap_or_default(),
            line: loc.line,
            column: loc.column,
        }
    }

    fn err(&self, tok: &Token<'_>, kind: ParseErrorKind) -> Error {
        Error::Parse(Box::new(ParseError {
            loc: self.location(tok.loc),
            token: tok.display(),
            kind,
        }))
    }

    fn err_at(&self, loc: Loc, token: &str, kind: ParseErrorKind) -> Error {
        Error::Parse(Box::new(ParseError {
            loc: self.location(loc),
            token: token.to_owned(),
            kind,
        }))
    }

    fn lex_err(&self, e: LexError) -> Error {
        let kind = match e.kind {
            LexErrorKind::UnterminatedString => ParseErrorKind::BadString,
            LexErrorKind::ExpectedNumber => {
                ParseErrorKind::BadParameter("expected a number".into())
            }
            LexErrorKind::UnterminatedArray => ParseErrorKind::Unexpected { expected: "`]`" },
            LexErrorKind::BadInteger => {
                ParseErrorKind::BadParameter("expected an integer in range".into())
            }
        };
        Error::Parse(Box::new(ParseError {
            loc: self.location(e.loc),
            token: e.token,
            kind,
        }))
    }

    fn param_err(&self, e: ParamError<'_>) -> Error {
        match e {
            ParamError::Lex(e) => self.lex_err(e),
            ParamError::Bad(t, m) => self.err(&t, ParseErrorKind::BadParameter(m)),
        }
    }

    fn warn(&mut self, loc: Option<Loc>, message: String) {
        self.stats.warnings += 1;
        match loc {
            Some(l) => tracing::warn!("{}: {message}", self.location(l)),
            None => tracing::warn!("{message}"),
        }
        self.sink.warning(&Warning { loc, message });
    }

    /// Warn once per `key` (repeated constructs in huge scenes).
    fn warn_once(&mut self, key: &str, loc: Option<Loc>, message: String) {
        if self.warned.insert(key.to_owned()) {
            self.warn(loc, message);
        }
    }

    fn missing_file(&mut self, path: PathBuf, loc: Loc) {
        if self.opts.allow_missing {
            self.warn(
                Some(loc),
                format!("missing file {} (skipped)", path.display()),
            );
        }
        let referenced_at = self.location(loc);
        self.missing.push(MissingFile {
            path,
            referenced_at,
        });
    }

    // ---- token helpers ----------------------------------------------------------------

    fn next<'b>(
        &self,
        lx: &mut Lexer<'b>,
        what: &'static str,
        after: &Token<'b>,
    ) -> Result<Token<'b>> {
        match lx.next_token().map_err(|e| self.lex_err(e))? {
            Some(t) => Ok(t),
            None => Err(self.err(after, ParseErrorKind::Unexpected { expected: what })),
        }
    }

    fn string<'b>(
        &self,
        lx: &mut Lexer<'b>,
        after: &Token<'b>,
    ) -> Result<(Cow<'b, str>, Token<'b>)> {
        let t = self.next(lx, "a quoted string", after)?;
        if t.kind != TokenKind::String {
            return Err(self.err(
                &t,
                ParseErrorKind::Unexpected {
                    expected: "a quoted string",
                },
            ));
        }
        match t.unescaped() {
            Some(s) => Ok((s, t)),
            None => Err(self.err(&t, ParseErrorKind::BadString)),
        }
    }

    /// `N` numbers, optionally inside `[ ]` (no allocation: this is the per-directive path).
    fn numbers<'b, const N: usize>(
        &self,
        lx: &mut Lexer<'b>,
        after: &Token<'b>,
    ) -> Result<[f64; N]> {
        let bracketed = lx.peek_byte() == Some(b'[');
        if bracketed {
            lx.next_token().map_err(|e| self.lex_err(e))?;
        }
        let mut out = [0.0; N];
        for slot in &mut out {
            // Fast path straight from the bytes; build a token only to report an error.
            match lx.read_f64() {
                Some(v) => *slot = v,
                None => {
                    let t = self.next(lx, "a number", after)?;
                    return Err(self.err(
                        &t,
                        ParseErrorKind::Unexpected {
                            expected: "a number",
                        },
                    ));
                }
            }
        }
        if bracketed {
            let t = self.next(lx, "`]`", after)?;
            if t.kind != TokenKind::Close {
                return Err(self.err(&t, ParseErrorKind::Unexpected { expected: "`]`" }));
            }
        }
        // A NaN or infinity in a transform poisons every matrix below it.
        if let Some(i) = out.iter().position(|v| !v.is_finite()) {
            return Err(self.err(
                after,
                ParseErrorKind::Invalid(format!(
                    "value {} of {} is {}, not a finite number",
                    i + 1,
                    after.display(),
                    out[i]
                )),
            ));
        }
        Ok(out)
    }

    /// Refuses non-finite numeric parameters of `directive` (camera and light values end up
    /// in the package's JSON, which has no NaN or infinity).
    fn require_finite(&self, directive: &str, p: &ParamList<'_>) -> Result<()> {
        for param in &p.params {
            if let crate::params::Values::Nums(v) = &param.values {
                if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
                    return Err(self.err_at(
                        param.loc,
                        param.name,
                        ParseErrorKind::BadParameter(format!(
                            "{directive} parameter \"{} {}\" has the value {bad}: it must be a finite number",
                            param.ty.name(),
                            param.name
                        )),
                    ));
                }
            }
        }
        Ok(())
    }

    fn params<'b>(&mut self, lx: &mut Lexer<'b>) -> Result<ParamList<'b>> {
        let p = ParamList::parse(lx).map_err(|e| self.param_err(e))?;
        if p.v4_spelling {
            self.hint_v4("v4 parameter type");
        }
        Ok(p)
    }

    // ---- files ------------------------------------------------------------------------

    fn resolve(&self, name: &str) -> PathBuf {
        let p = Path::new(name);
        if p.is_absolute() {
            return p.to_path_buf();
        }
        let here = self.dirs.last().unwrap_or(&self.entry_dir).join(p);
        if here.exists() {
            return here;
        }
        let entry = self.entry_dir.join(p);
        if entry.exists() {
            return entry;
        }
        here
    }

    fn run_file(
        &mut self,
        path: PathBuf,
        bytes: &[u8],
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
            self.include_counts.push(count_includes(bytes));
        }
        let _span =
            tracing::debug_span!("pbrt_file", path = %path.display(), size_bytes = bytes.len())
                .entered();
        let parsed = match replay {
            Some(pieces) => self.replay(pieces, file),
            None => self.parse_tokens(bytes, file),
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

    fn include<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>, via: Via) -> Result<()> {
        let (name, stok) = self.string(lx, tok)?;
        if self.opts.parallel_includes
            && rayon::current_num_threads() > 1
            && self.snapshot().is_some()
        {
            return self.include_run(lx, via, name, stok);
        }
        self.include_one(&name, &stok, via, None)
    }

    /// One `Include`/`Import` whose name has been read; `pre` is what a parallel run
    /// prepared for it (opened file, worker result).
    fn include_one(
        &mut self,
        name: &str,
        stok: &Token<'_>,
        via: Via,
        pre: Option<Prepared>,
    ) -> Result<()> {
        let (path, pre_src, pre_parsed) = match pre {
            Some(p) => (p.path, Some(p.src), p.parsed),
            None => (self.resolve(name), None, None),
        };
        match crate::source::classify(&path) {
            crate::source::FileKind::Regular => {}
            crate::source::FileKind::Missing => {
                self.missing_file(path, stok.loc);
                return Ok(());
            }
            crate::source::FileKind::Other(what) => {
                return Err(self.err(
                    stok,
                    ParseErrorKind::Invalid(format!(
                        "{}: {} is {what}, not a scene file",
                        if via == Via::Import {
                            "Import"
                        } else {
                            "Include"
                        },
                        path.display()
                    )),
                ))
            }
        }
        if self.depth + 1 > self.opts.max_include_depth {
            return Err(self.err(
                stok,
                ParseErrorKind::Misplaced(format!(
                    "include depth over {}",
                    self.opts.max_include_depth
                )),
            ));
        }
        let canonical = path.canonicalize().unwrap_or_else(|_| path.clone());
        if self.open_files.contains(&canonical) {
            return Err(self.err(
                stok,
                ParseErrorKind::Invalid("recursive Include/Import".into()),
            ));
        }
        let share_key = self.share_key();
        if let (Some(key), Some(shared)) = (share_key, self.shared.get(&canonical)) {
            if shared.key == key {
                // A repeat of a shared file: one more instance edge, no re-parse.
                let object = shared.object;
                let element = self.element_for(&path);
                return self.emit_include_instance(object, element, stok.loc);
            }
        }
        let src = match pre_src {
            Some(src) => src,
            None => Arc::new(SourceBytes::open(&path).map_err(|source| Error::Io {
                path: path.clone(),
                source,
            })?),
        };
        let repeated = self
            .include_counts
            .last()
            .and_then(|counts| counts.get(stok.bytes))
            .is_some_and(|&n| n >= 2);
        let share = share_key.filter(|_| {
            repeated && !self.shared.contains_key(&canonical) && shareable(src.bytes())
        });
        let element = self.element_for(&path);
        let Some(key) = share else {
            // A worker's buffer stands for the file only under the state it was parsed in.
            let replay = match (pre_parsed, self.snapshot()) {
                (Some((snap, Some(pieces))), Some(now)) if snap.same_as(&now) => Some(pieces),
                _ => None,
            };
            return self.run_include(path, canonical, src.bytes(), via, element, replay);
        };
        // First inclusion of a shared file: its content becomes an object defined in the
        // include's frame, placed by an instance; later inclusions add instances only.
        let object = ObjectId(self.object_names.len() as u32);
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        self.object_names.push(stem);
        self.object_defined.push(true);
        self.sink.object_begin(&ObjectEvent {
            object,
            name: &self.object_names[object.0 as usize],
            element: element.or(self.element),
            loc: stok.loc,
        })?;
        let (saved_gs, saved_xs) = (self.gs.clone(), self.xs);
        self.xs.ctm = [math::IDENTITY; 2];
        self.current_object = Some(object);
        let r = self.run_include(path, canonical.clone(), src.bytes(), via, element, None);
        self.current_object = None;
        self.gs = saved_gs;
        self.xs = saved_xs;
        r?;
        self.sink.object_end(&ObjectEvent {
            object,
            name: &self.object_names[object.0 as usize],
            element: element.or(self.element),
            loc: stok.loc,
        })?;
        self.shared.insert(canonical, SharedInclude { object, key });
        self.stats.shared_includes += 1;
        self.emit_include_instance(object, element, stok.loc)
    }

    /// The graphics state a shared include's content depends on, or `None` where sharing
    /// is off or the state could not be shared: outside the world block, inside an object
    /// definition, under motion (`ActiveTransform`), or with an area light (emitters
    /// cannot be instanced).
    fn share_key(&self) -> Option<ShareKey> {
        let ok = self.opts.share_repeated_includes
            && self.in_world
            && self.current_object.is_none()
            && self.xs.active == 3
            && self.xs.ctm[0] == self.xs.ctm[1]
            && self.gs.area_light.is_none();
        ok.then_some(ShareKey {
            material: self.gs.material.id,
            reverse_orientation: self.gs.reverse_orientation,
        })
    }

    fn emit_include_instance(
        &mut self,
        object: ObjectId,
        element: Option<ElementId>,
        loc: Loc,
    ) -> Result<()> {
        self.stats.include_instances += 1;
        let ev = InstanceEvent {
            object,
            name: self
                .object_names
                .get(object.0 as usize)
                .map_or("", String::as_str),
            parent_from_instance: math::to_f32(&self.xs.ctm[0]),
            inside: None,
            element: element.or(self.element),
            loc,
        };
        self.sink.object_instance(&ev)?;
        Ok(())
    }

    /// The element of a file included from the entry file's world block (named by its stem).
    fn element_for(&mut self, path: &Path) -> Option<ElementId> {
        if self.depth != 0 || !self.in_world {
            return None;
        }
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let stem = stem
            .strip_suffix(".pbrt")
            .map(str::to_owned)
            .unwrap_or(stem);
        let id = match self.element_names.iter().position(|n| *n == stem) {
            Some(i) => ElementId(i as u32),
            None => {
                self.element_names.push(stem);
                ElementId(self.element_names.len() as u32 - 1)
            }
        };
        Some(id)
    }

    fn run_include(
        &mut self,
        path: PathBuf,
        canonical: PathBuf,
        bytes: &[u8],
        via: Via,
        element: Option<ElementId>,
        replay: Option<Vec<Parsed>>,
    ) -> Result<()> {
        if via == Via::Import {
            self.attr_stack.push(self.gs.clone());
            self.push_xform();
        }
        self.open_files.push(canonical);
        self.depth += 1;
        let r = self.run_file(path, bytes, via, element, replay);
        self.depth -= 1;
        self.open_files.pop();
        if via == Via::Import {
            if let (Some(g), Some(x)) = (self.attr_stack.pop(), self.xform_stack.pop()) {
                self.gs = g;
                self.xs = x;
            }
        }
        r
    }

    // ---- parallel includes ------------------------------------------------------------

    /// The state a neutral include is parsed against, or `None` where includes here must
    /// be parsed sequentially: outside the world block, inside an object definition, or
    /// under `ActiveTransform` (the workers track one transform).
    fn snapshot(&self) -> Option<Snapshot> {
        let ok = self.in_world && self.current_object.is_none() && self.xs.active == 3;
        ok.then(|| Snapshot {
            version: self.version,
            ctm: self.xs.ctm[0],
            material: self.gs.material.clone(),
            reverse_orientation: self.gs.reverse_orientation,
            area_light: self.gs.area_light.clone(),
            tessellation_segments: self.opts.tessellation_segments,
        })
    }

    /// A run of consecutive `Include`/`Import` directives starting with the one just read.
    /// A sliding window of the following files is parsed on the rayon pool while the main
    /// thread replays finished ones in document order (see [`crate::parallel`]). The window
    /// holds at most [`PARALLEL_WINDOW_BYTES`] of input and a few files per thread.
    fn include_run<'b>(
        &mut self,
        lx: &mut Lexer<'b>,
        via: Via,
        name: Cow<'b, str>,
        stok: Token<'b>,
    ) -> Result<()> {
        let max_files = rayon::current_num_threads().saturating_mul(4).max(4);
        let chunk_bytes = self.opts.parallel_chunk_bytes.max(1);
        let mut cursor = lx.clone();
        let mut first = Some(RunItem {
            via,
            hint_v4: false,
            name,
            stok,
            after: lx.clone(),
            src: None,
        });
        rayon::in_place_scope(|scope| {
            let mut window: std::collections::VecDeque<InFlight<'b>> = Default::default();
            let mut window_bytes = 0u64;
            let mut exhausted = false;
            loop {
                // Refill: state can only change at a sequential fallback, which `same_as`
                // detects at replay, so the current state is the guess for every file.
                while !exhausted && window.len() < max_files && window_bytes < PARALLEL_WINDOW_BYTES
                {
                    let next = first.take().or_else(|| self.next_item(&mut cursor));
                    let Some(item) = next.map(|item| self.open_item(item)) else {
                        exhausted = true;
                        break;
                    };
                    let mut job = None;
                    if let (Some((_, src)), Some(snap)) = (&item.src, self.snapshot()) {
                        window_bytes += src.bytes().len() as u64;
                        let starts = parallel::split_points(src.bytes(), chunk_bytes);
                        let mut slots = Vec::with_capacity(starts.len());
                        for (i, &start) in starts.iter().enumerate() {
                            let end = starts.get(i + 1).copied().unwrap_or(src.bytes().len());
                            let slot = Arc::new(Slot::default());
                            let (src, worker_slot) = (src.clone(), slot.clone());
                            let worker_snap = snap.clone();
                            scope.spawn(move |_| {
                                let piece = src.bytes().get(start..end).unwrap_or_default();
                                worker_slot.put(parallel::parse_neutral(piece, &worker_snap));
                            });
                            slots.push(slot);
                        }
                        job = Some((snap, slots));
                    }
                    window.push_back(InFlight { item, job });
                }
                let Some(InFlight { item, job }) = window.pop_front() else {
                    return Ok(());
                };
                let parsed = job.map(|(snap, slots)| {
                    // Every slot is waited for, so no worker outlives its file's replay.
                    let outcomes: Vec<Outcome> = slots.iter().map(|slot| slot.take()).collect();
                    let pieces = outcomes
                        .into_iter()
                        .map(|o| match o {
                            Outcome::Parsed(p) => Some(p),
                            Outcome::Fallback => None,
                        })
                        .collect::<Option<Vec<_>>>();
                    (snap, pieces)
                });
                if let Some((_, src)) = &item.src {
                    if parsed.is_some() {
                        window_bytes -= src.bytes().len() as u64;
                    }
                }
                if item.hint_v4 {
                    self.hint_v4("Import");
                }
                let pre = item.src.map(|(path, src)| Prepared { path, src, parsed });
                self.include_one(&item.name, &item.stok, item.via, pre)?;
                *lx = item.after;
            }
        })
    }

    /// The next `Include`/`Import` directive right at `cursor`.
    fn next_item<'b>(&self, cursor: &mut Lexer<'b>) -> Option<RunItem<'b>> {
        let mut c = cursor.clone();
        let word = c.next_token().ok()??;
        let via = match (word.kind, word.bytes) {
            (TokenKind::Word, b"Include") => Via::Include,
            (TokenKind::Word, b"Import") => Via::Import,
            _ => return None,
        };
        let stok = c.next_token().ok()??;
        if stok.kind != TokenKind::String {
            return None;
        }
        let name = stok.unescaped()?;
        *cursor = c.clone();
        Some(RunItem {
            via,
            hint_v4: via == Via::Import,
            name,
            stok,
            after: c,
            src: None,
        })
    }

    /// Open an item's file when it exists and is small enough to buffer.
    fn open_item<'b>(&self, mut item: RunItem<'b>) -> RunItem<'b> {
        let path = self.resolve(&item.name);
        // Files over the window (and `.gz`, whose size is unknown) stream sequentially.
        let gz = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
        let fits = std::fs::metadata(&path)
            .is_ok_and(|m| m.is_file() && m.len() <= PARALLEL_WINDOW_BYTES / 2);
        if fits && !gz {
            item.src = SourceBytes::open(&path)
                .ok()
                .map(|src| (path, Arc::new(src)));
        }
        item
    }

    /// Deliver a worker's buffer for file `file` (the body of `run_file`).
    fn replay(&mut self, pieces: Vec<Parsed>, file: FileId) -> Result<()> {
        self.stats.parallel_files += 1;
        let mut line_offset = 0u32;
        for piece in pieces {
            let lines = piece.lines;
            self.replay_piece(piece, file, line_offset)?;
            line_offset = line_offset.saturating_add(lines);
        }
        Ok(())
    }

    /// One piece of a file; its locations count lines from the piece's start.
    fn replay_piece(&mut self, buffer: Parsed, file: FileId, line_offset: u32) -> Result<()> {
        let fix = |mut loc: Loc| {
            loc.file = file;
            loc.line += line_offset;
            loc
        };
        let Parsed { names, events, .. } = buffer;
        let mut ids: Vec<Option<ObjectId>> = vec![None; names.len()];
        for ev in events {
            match ev {
                Buffered::Instance {
                    name,
                    parent_from_instance,
                    loc,
                    name_loc,
                } => {
                    let (loc, name_loc) = (fix(loc), fix(name_loc));
                    let slot = name as usize;
                    let id = match ids.get(slot).copied().flatten() {
                        Some(id) => id,
                        None => {
                            let n = names.get(slot).map_or("", String::as_str);
                            let id = match self.objects.get(n).copied() {
                                Some(id) => id,
                                None if self.v4() => {
                                    let id = self.new_object(n);
                                    self.forward_refs.push((id, name_loc, n.to_owned()));
                                    id
                                }
                                None => {
                                    // As `Token::display` shows the name token.
                                    let raw = &n.as_bytes()[..n.len().min(64)];
                                    let shown = format!("\"{}\"", String::from_utf8_lossy(raw));
                                    return Err(self.err_at(
                                        name_loc,
                                        &shown,
                                        ParseErrorKind::UnknownObject,
                                    ));
                                }
                            };
                            if let Some(s) = ids.get_mut(slot) {
                                *s = Some(id);
                            }
                            id
                        }
                    };
                    self.stats.instances += 1;
                    let ev = InstanceEvent {
                        object: id,
                        name: self
                            .object_names
                            .get(id.0 as usize)
                            .map_or("", String::as_str),
                        parent_from_instance,
                        inside: None,
                        element: self.element,
                        loc,
                    };
                    self.sink.object_instance(&ev)?;
                }
                Buffered::Shape(mut shape) => {
                    shape.seq = self.next_seq;
                    self.next_seq += 1;
                    shape.element = self.element;
                    shape.loc = fix(shape.loc);
                    self.emit_shape(*shape)?;
                }
                Buffered::Warn { loc, message } => {
                    let loc = fix(loc);
                    self.warn(Some(loc), message);
                }
                Buffered::Skipped { loc, message } => {
                    let loc = fix(loc);
                    self.next_seq += 1;
                    self.stats.skipped_shapes += 1;
                    self.warn(Some(loc), message);
                }
            }
        }
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

    fn parse_tokens(&mut self, bytes: &[u8], file: FileId) -> Result<()> {
        let mut lx = Lexer::new(bytes, file);
        while let Some(tok) = lx.next_token().map_err(|e| self.lex_err(e))? {
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

    fn apply(&mut self, m: M64) {
        for i in 0..2 {
            if self.xs.active & (1 << i) != 0 {
                self.xs.ctm[i] = math::mul(&self.xs.ctm[i], &m);
            }
        }
    }

    fn set(&mut self, m: M64) {
        for i in 0..2 {
            if self.xs.active & (1 << i) != 0 {
                self.xs.ctm[i] = m;
            }
        }
    }

    fn require_world(&mut self, tok: &Token<'_>) {
        if !self.in_world {
            let name = String::from_utf8_lossy(tok.bytes).into_owned();
            self.warn_once(
                &format!("world:{name}"),
                Some(tok.loc),
                format!("{name} before WorldBegin"),
            );
        }
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
            _ => return Err(self.err(tok, ParseErrorKind::UnknownDirective)),
        }
        Ok(())
    }

    fn pop_block(&mut self, tok: &Token<'_>, kind: BlockKind) -> Result<()> {
        let Some(&(top, _)) = self.blocks.last() else {
            let what = String::from_utf8_lossy(tok.bytes);
            return Err(self.err(
                tok,
                ParseErrorKind::Unbalanced(format!("{what} without a matching begin")),
            ));
        };
        // pbrt-v3 keeps separate attribute and transform stacks and lets ObjectBegin/End
        // interleave with AttributeBegin/End; pbrt-v4 requires proper nesting.
        if top != kind && (self.v4() || kind == BlockKind::Transform || top == BlockKind::Transform)
        {
            let what = String::from_utf8_lossy(tok.bytes);
            return Err(self.err(
                tok,
                ParseErrorKind::Unbalanced(format!("{what} closes {}", top.begin())),
            ));
        }
        self.blocks.pop();
        match kind {
            BlockKind::Transform => self.pop_xform(),
            BlockKind::Attribute | BlockKind::Object => {
                if let Some(g) = self.attr_stack.pop() {
                    self.gs = g;
                    self.pop_xform();
                }
            }
        }
        Ok(())
    }

    /// Save the transform state. `XState` is 264 bytes and this runs twice per
    /// `AttributeBegin`/`End` pair: copy it once, straight into the stack's slot.
    #[inline]
    fn push_xform(&mut self) {
        self.xform_stack
            .extend_from_slice(std::slice::from_ref(&self.xs));
    }

    /// Restore the saved transform state (one copy, from the stack's slot).
    #[inline]
    fn pop_xform(&mut self) {
        if let Some(x) = self.xform_stack.last() {
            self.xs = *x;
            self.xform_stack.truncate(self.xform_stack.len() - 1);
        }
    }

    // ---- cameras and lights -------------------------------------------------------------

    fn camera<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        let (kind, _) = self.string(lx, tok)?;
        let p = self.params(lx)?;
        self.require_finite("Camera", &p)?;
        if self.in_world {
            self.warn(Some(tok.loc), "Camera inside the world block".into());
        }
        let camera_from_world = self.xs.ctm[0];
        if let Some(inv) = math::inverse(&camera_from_world) {
            self.named_coords.insert("camera".into(), [inv; 2]);
        }
        let sw = p
            .nums("screenwindow")
            .filter(|v| v.len() == 4)
            .map(|v| [v[0], v[1], v[2], v[3]]);
        self.cameras.push(PendingCamera {
            fov_deg: (kind == "perspective").then(|| p.float("fov").unwrap_or(90.0)),
            kind: kind.into_owned(),
            camera_from_world,
            screen_window: sw,
            lens_radius: p.float("lensradius").unwrap_or(0.0),
            focal_distance: p.float("focaldistance"),
            loc: tok.loc,
        });
        Ok(())
    }

    fn emit_cameras(&mut self) -> Result<()> {
        for c in std::mem::take(&mut self.cameras) {
            let world_from_camera = match math::inverse(&c.camera_from_world) {
                Some(m) => m,
                None => {
                    self.warn(Some(c.loc), "singular camera transform".into());
                    math::IDENTITY
                }
            };
            self.stats.cameras += 1;
            let ev = CameraEvent {
                kind: c.kind,
                camera_from_world: math::to_f32(&c.camera_from_world),
                world_from_camera: math::to_f32(&world_from_camera),
                fov_deg: c.fov_deg,
                screen_window: c.screen_window,
                lens_radius: c.lens_radius,
                focal_distance: c.focal_distance,
                resolution: self.film_resolution,
                path: self
                    .stats
                    .files
                    .get(c.loc.file.0 as usize)
                    .map(PathBuf::as_path)
                    .unwrap_or(Path::new("")),
                loc: c.loc,
            };
            self.sink.camera(&ev)?;
        }
        Ok(())
    }

    /// `L`/`I` times `scale` (v3: spectrum scale; v4: float scale).
    fn emission(&mut self, p: &ParamList<'_>, name: &str) -> Option<[f32; 3]> {
        let base = match p.get(name) {
            Some(param) => self.color_of(param)?.0,
            None => [1.0; 3],
        };
        let scale = match p.get("scale") {
            Some(param) if param.ty == ParamType::Float => p.float("scale").map(|s| [s; 3]),
            Some(param) => self.color_of(param).map(|c| c.0),
            None => None,
        }
        .unwrap_or([1.0; 3]);
        Some([base[0] * scale[0], base[1] * scale[1], base[2] * scale[2]])
    }

    fn light<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        self.require_world(tok);
        let (kind, _) = self.string(lx, tok)?;
        let p = self.params(lx)?;
        self.require_finite("LightSource", &p)?;
        let which = if p.get("I").is_some() { "I" } else { "L" };
        let color = self.emission(&p, which);
        let pt = |n: &str| {
            p.nums(n)
                .filter(|v| v.len() == 3)
                .map(|v| [v[0], v[1], v[2]])
        };
        let ev = LightEvent {
            world_from_light: math::to_f32(&self.xs.ctm[0]),
            color,
            from: pt("from"),
            to: pt("to"),
            map: p
                .string("mapname")
                .or(p.string("filename"))
                .map(str::to_owned),
            object: self.current_object,
            element: self.element,
            loc: tok.loc,
            kind: kind.into_owned(),
        };
        self.stats.lights += 1;
        self.sink.light(&ev)?;
        Ok(())
    }

    // ---- colours, textures, materials ----------------------------------------------------

    /// A colour from a parameter; the second value names a texture it came from.
    fn color_of(&mut self, p: &Param<'_>) -> Option<([f32; 3], Option<String>)> {
        match (&p.values, p.ty) {
            (Values::Nums(v), ParamType::Rgb) if v.len() >= 3 => Some(([v[0], v[1], v[2]], None)),
            (Values::Nums(v), ParamType::Xyz) if v.len() >= 3 => {
                Some((color::xyz_to_rgb([v[0], v[1], v[2]]), None))
            }
            (Values::Nums(v), ParamType::Blackbody) if !v.is_empty() => {
                let scale = if v.len() >= 2 && !self.v4() {
                    v[1]
                } else {
                    1.0
                };
                if v.len() == 1 {
                    self.hint_v4("one-value blackbody");
                }
                Some((color::blackbody_rgb(v[0]).map(|c| c * scale), None))
            }
            (Values::Nums(v), ParamType::Spectrum) => {
                let pairs: Vec<(f32, f32)> = v.chunks_exact(2).map(|c| (c[0], c[1])).collect();
                color::spectrum_rgb(&pairs).map(|c| (c, None))
            }
            (Values::Nums(v), ParamType::Float) => v.first().map(|&f| ([f; 3], None)),
            (Values::Strs(s), ParamType::Spectrum) => {
                let name = s.first()?.to_string();
                let path = self.resolve(&name);
                if let Some(c) = self.spectrum_cache.get(&path) {
                    return c.map(|c| (c, None));
                }
                let rgb = match std::fs::read(&path) {
                    Ok(bytes) => {
                        color::parse_spd(&bytes).and_then(|pairs| color::spectrum_rgb(&pairs))
                    }
                    Err(_) => None,
                };
                if rgb.is_none() {
                    self.warn_once(
                        &format!("spd:{name}"),
                        Some(p.loc),
                        format!(
                            "spectrum \"{name}\" is not a readable spectrum file; colour unknown"
                        ),
                    );
                }
                self.spectrum_cache.insert(path, rgb);
                rgb.map(|c| (c, None))
            }
            (Values::Strs(s), ParamType::Texture) => {
                let name = s.first()?;
                let rgb = self
                    .color_textures
                    .get(name.as_ref())
                    .or_else(|| self.float_textures.get(name.as_ref()))
                    .copied();
                match rgb {
                    Some(c) => Some((c, Some(name.to_string()))),
                    None => {
                        let n = name.to_string();
                        self.warn_once(
                            &format!("tex:{n}"),
                            Some(p.loc),
                            format!("unknown texture \"{n}\"; grey"),
                        );
                        Some(([0.5; 3], Some(n)))
                    }
                }
            }
            _ => None,
        }
    }

    fn make_material(
        &mut self,
        name: Option<String>,
        kind: &str,
        p: &ParamList<'_>,
        loc: Loc,
    ) -> Arc<Material> {
        let id = MaterialId(self.next_material);
        self.next_material += 1;
        let mut base_color = None;
        let mut base_color_texture = None;
        for key in ["Kd", "reflectance", "color", "Kr"] {
            if let Some(param) = p.get(key) {
                if let Some((c, tex)) = self.color_of(param) {
                    base_color = Some(c);
                    base_color_texture = tex;
                    break;
                }
            }
        }
        if base_color.is_none() && kind == "mix" {
            // v3: namedmaterial1/2; v4: "string materials" [a b].
            let names: Vec<String> = match p.get("materials").map(|p| &p.values) {
                Some(Values::Strs(v)) => v.iter().map(|s| s.to_string()).collect(),
                _ => ["namedmaterial1", "namedmaterial2"]
                    .iter()
                    .filter_map(|k| p.string(k).map(str::to_owned))
                    .collect(),
            };
            let colors: Vec<[f32; 3]> = names
                .iter()
                .filter_map(|n| self.named_materials.get(n).and_then(|m| m.base_color))
                .collect();
            if colors.len() == 2 {
                let amount = p
                    .get("amount")
                    .and_then(|a| self.color_of(a))
                    .map(|c| c.0)
                    .unwrap_or([0.5; 3]);
                base_color = Some(std::array::from_fn(|i| {
                    colors[0][i] * (1.0 - amount[i]) + colors[1][i] * amount[i]
                }));
            }
        }
        if base_color.is_none() {
            base_color = match kind {
                "matte" | "diffuse" | "coateddiffuse" | "substrate" | "disney" | "translucent" => {
                    Some([0.5; 3])
                }
                "plastic" | "uber" => Some([0.25; 3]),
                "mirror" => Some([0.9; 3]),
                _ => None,
            };
        }
        let opacity = p.get("opacity").and_then(|o| self.color_of(o)).map(|c| c.0);
        Arc::new(Material {
            id,
            name,
            kind: kind.to_owned(),
            base_color,
            base_color_texture,
            opacity,
            loc,
        })
    }

    fn texture<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        let (name, ntok) = self.string(lx, tok)?;
        let (ty, ttok) = self.string(lx, tok)?;
        let (class, _) = self.string(lx, tok)?;
        let p = self.params(lx)?;
        let is_float = match ty.as_ref() {
            "float" => true,
            "color" | "spectrum" | "rgb" => false,
            _ => {
                return Err(self.err(
                    &ttok,
                    ParseErrorKind::Invalid("texture type must be float, color or spectrum".into()),
                ))
            }
        };
        let operand = |this: &mut Self, key: &str, default: f32| -> [f32; 3] {
            p.get(key)
                .and_then(|param| this.color_of(param))
                .map(|c| c.0)
                .unwrap_or([default; 3])
        };
        let avg =
            |a: [f32; 3], b: [f32; 3]| -> [f32; 3] { std::array::from_fn(|i| 0.5 * (a[i] + b[i])) };
        let value = match class.as_ref() {
            "constant" => operand(self, "value", 1.0),
            "imagemap" | "ptex" => {
                let file = p.string("filename").unwrap_or("").to_owned();
                let exists = !file.is_empty() && self.resolve(&file).is_file();
                let why = if exists {
                    "image textures are reduced to constant grey"
                } else {
                    "texture file missing; constant grey"
                };
                self.warn_once(
                    &format!("img:{file}"),
                    Some(tok.loc),
                    format!("texture \"{name}\" ({file}): {why}"),
                );
                [0.5; 3]
            }
            "scale" => {
                let (a, b) = if p.get("tex").is_some() || self.v4() {
                    (operand(self, "tex", 1.0), operand(self, "scale", 1.0))
                } else {
                    (operand(self, "tex1", 1.0), operand(self, "tex2", 1.0))
                };
                std::array::from_fn(|i| a[i] * b[i])
            }
            "mix" | "directionmix" => {
                let (a, b) = (operand(self, "tex1", 0.0), operand(self, "tex2", 1.0));
                match p.get("amount").and_then(|x| self.color_of(x)) {
                    Some((t, _)) => std::array::from_fn(|i| a[i] * (1.0 - t[i]) + b[i] * t[i]),
                    None => avg(a, b),
                }
            }
            "checkerboard" => avg(operand(self, "tex1", 1.0), operand(self, "tex2", 0.0)),
            "dots" => avg(operand(self, "inside", 1.0), operand(self, "outside", 0.0)),
            "bilerp" => {
                let (a, b) = (operand(self, "v00", 0.0), operand(self, "v01", 1.0));
                let (c, d) = (operand(self, "v10", 0.0), operand(self, "v11", 1.0));
                avg(avg(a, b), avg(c, d))
            }
            _ => [0.5; 3],
        };
        let table = if is_float {
            &mut self.float_textures
        } else {
            &mut self.color_textures
        };
        let redefined = table.insert(name.to_string(), value).is_some();
        if redefined {
            if self.v4() {
                return Err(self.err(
                    &ntok,
                    ParseErrorKind::Invalid("named texture redefined".into()),
                ));
            }
            // v3 scenes (Moana) redefine textures; the later definition wins.
            self.warn_once(
                &format!("texredef:{name}"),
                Some(ntok.loc),
                format!("texture \"{name}\" redefined"),
            );
        }
        Ok(())
    }

    // ---- shapes and objects ---------------------------------------------------------------

    fn shape<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        self.require_world(tok);
        let (kind, ktok) = self.string(lx, tok)?;
        let mut p = self.params(lx)?;
        let seq = self.next_seq;
        self.next_seq += 1;
        let mut material = self.gs.material.clone();
        if !self.v4()
            && ["Kd", "reflectance", "color", "Kr", "opacity"]
                .iter()
                .any(|k| p.get(k).is_some())
        {
            // pbrt-v3: material parameters on a Shape override the current material's.
            let merged = ParamList {
                params: p
                    .params
                    .iter()
                    .filter(|q| !matches!(q.values, Values::Nums(ref v) if v.len() > 64))
                    .cloned()
                    .collect(),
                v4_spelling: false,
            };
            let derived = self.make_material(
                material.name.clone(),
                &material.kind.clone(),
                &merged,
                ktok.loc,
            );
            let keep_base = derived.base_color.is_none()
                || !["Kd", "reflectance", "color", "Kr"]
                    .iter()
                    .any(|k| p.get(k).is_some());
            let m = Material {
                base_color: if keep_base {
                    material.base_color
                } else {
                    derived.base_color
                },
                base_color_texture: if keep_base {
                    material.base_color_texture.clone()
                } else {
                    derived.base_color_texture.clone()
                },
                opacity: derived.opacity.or(material.opacity),
                ..(*derived).clone()
            };
            material = Arc::new(m);
            self.sink.material(&material)?;
        }
        let mut event = ShapeEvent {
            seq,
            kind: String::new(),
            parent_from_shape: math::to_f32(&self.xs.ctm[0]),
            reverse_orientation: self.gs.reverse_orientation,
            material,
            alpha_texture: p.texture("alpha").map(str::to_owned),
            alpha: p.float("alpha"),
            area_light: self.gs.area_light.clone(),
            object: self.current_object,
            element: self.element,
            source_path: None,
            loc: tok.loc,
            geometry: Geometry::Unsupported,
        };
        let segs = self.opts.tessellation_segments.max(3);
        let mut notes = Vec::new();
        let built: std::result::Result<Geometry, String> = match kind.as_ref() {
            "trianglemesh" => shapes::triangle_mesh(&mut p, &mut notes).map(Geometry::Mesh),
            "loopsubdiv" => shapes::triangle_mesh(&mut p, &mut notes).map(Geometry::Mesh),
            "bilinearmesh" => {
                self.hint_v4("bilinearmesh");
                shapes::bilinear_mesh(&mut p, &mut notes).map(Geometry::Mesh)
            }
            "sphere" => shapes::sphere(&p, segs).map(Geometry::Mesh),
            "disk" => shapes::disk(&p, segs).map(Geometry::Mesh),
            "cylinder" => shapes::cylinder(&p, segs).map(Geometry::Mesh),
            "curve" => shapes::curve(&mut p).map(Geometry::Curve),
            "plymesh" => {
                event.kind = kind.into_owned();
                return self.plymesh(&p, &ktok, event);
            }
            other => {
                let known = matches!(
                    other,
                    "cone" | "paraboloid" | "hyperboloid" | "heightfield" | "nurbs"
                );
                let msg = if known {
                    "not converted"
                } else {
                    "unknown shape type"
                };
                self.warn_once(
                    &format!("shape:{other}"),
                    Some(ktok.loc),
                    format!("shape \"{other}\": {msg}; counted as unsupported"),
                );
                Ok(Geometry::Unsupported)
            }
        };
        for n in notes {
            self.warn(Some(ktok.loc), format!("{kind}: {n}"));
        }
        match built {
            Ok(g) => {
                event.kind = kind.into_owned();
                event.geometry = g;
                self.emit_shape(event)
            }
            Err(m) => {
                self.stats.skipped_shapes += 1;
                self.warn(Some(ktok.loc), format!("{kind}: {m}; shape skipped"));
                Ok(())
            }
        }
    }

    fn emit_shape(&mut self, event: ShapeEvent) -> Result<()> {
        self.stats.shapes += 1;
        match &event.geometry {
            Geometry::Mesh(m) => self.stats.triangles += m.triangle_count() as u64,
            Geometry::Curve(_) => self.stats.curves += 1,
            Geometry::Unsupported => self.stats.unsupported_shapes += 1,
        }
        self.sink.shape(event)?;
        Ok(())
    }

    fn plymesh(
        &mut self,
        p: &ParamList<'_>,
        ktok: &Token<'_>,
        mut event: ShapeEvent,
    ) -> Result<()> {
        let Some(name) = p.string("filename") else {
            return Err(self.err(
                ktok,
                ParseErrorKind::BadParameter("plymesh needs \"string filename\"".into()),
            ));
        };
        if p.get("displacement").is_some() {
            self.warn_once(
                "displacement",
                Some(ktok.loc),
                "plymesh displacement recorded but not applied".into(),
            );
        }
        let path = self.resolve(name);
        let size = match crate::source::classify(&path) {
            crate::source::FileKind::Regular => std::fs::metadata(&path).map_or(0, |m| m.len()),
            crate::source::FileKind::Missing => {
                self.missing_file(path, ktok.loc);
                self.stats.skipped_shapes += 1;
                return Ok(());
            }
            crate::source::FileKind::Other(what) => {
                return Err(self.err(
                    ktok,
                    ParseErrorKind::Invalid(format!(
                        "plymesh: {} is {what}, not a PLY file",
                        path.display()
                    )),
                ))
            }
        };
        event.source_path = Some(path.clone());
        match self.opts.ply_loading {
            PlyLoading::Sequential => {
                self.stats.ply_bytes += size;
                let (mesh, report) = match crate::ply::read_ply_report(&path) {
                    Ok(r) => r,
                    Err(source) => {
                        return Err(Error::Ply {
                            path,
                            referenced_at: Box::new(self.location(ktok.loc)),
                            source: Box::new(source),
                        })
                    }
                };
                if let Some(w) = report.warning() {
                    self.warn(Some(ktok.loc), format!("{}: {w}", path.display()));
                }
                event.geometry = Geometry::Mesh(mesh);
                self.emit_shape(event)
            }
            PlyLoading::Parallel { batch_bytes } => {
                self.ply_queue.push(PendingPly { path, event });
                self.ply_queue_bytes += size;
                if self.ply_queue_bytes >= batch_bytes {
                    self.flush_plys()?;
                }
                Ok(())
            }
        }
    }

    /// Load the queued PLY files in parallel, then emit their shapes in queue order.
    fn flush_plys(&mut self) -> Result<()> {
        if self.ply_queue.is_empty() {
            return Ok(());
        }
        let queue = std::mem::take(&mut self.ply_queue);
        self.stats.ply_bytes += self.ply_queue_bytes;
        self.ply_queue_bytes = 0;
        let _span = tracing::debug_span!("ply_batch", files = queue.len()).entered();
        let loaded: Vec<_> = queue
            .par_iter()
            .map(|job| crate::ply::read_ply_report(&job.path))
            .collect();
        for (job, mesh) in queue.into_iter().zip(loaded) {
            match mesh {
                Ok((m, report)) => {
                    if let Some(w) = report.warning() {
                        self.warn(Some(job.event.loc), format!("{}: {w}", job.path.display()));
                    }
                    let mut ev = job.event;
                    ev.geometry = Geometry::Mesh(m);
                    self.emit_shape(ev)?;
                }
                Err(source) => {
                    return Err(Error::Ply {
                        path: job.path,
                        referenced_at: Box::new(self.location(job.event.loc)),
                        source: Box::new(source),
                    });
                }
            }
        }
        Ok(())
    }

    fn object_begin<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        self.require_world(tok);
        let (name, ntok) = self.string(lx, tok)?;
        if self.current_object.is_some() {
            return Err(self.err(
                tok,
                ParseErrorKind::Misplaced("ObjectBegin inside an object definition".into()),
            ));
        }
        self.attr_stack.push(self.gs.clone());
        self.push_xform();
        self.blocks.push((BlockKind::Object, tok.loc));
        let id = match self.objects.get(name.as_ref()).copied() {
            Some(id) if self.object_defined[id.0 as usize] => {
                if self.v4() {
                    return Err(self.err(&ntok, ParseErrorKind::Invalid("object redefined".into())));
                }
                self.warn(
                    Some(ntok.loc),
                    format!("object \"{name}\" redefined; the later definition wins"),
                );
                self.new_object(&name)
            }
            Some(id) => id,
            None => self.new_object(&name),
        };
        self.object_defined[id.0 as usize] = true;
        self.current_object = Some(id);
        self.stats.objects += 1;
        self.sink.object_begin(&ObjectEvent {
            object: id,
            name: &name,
            element: self.element,
            loc: tok.loc,
        })?;
        Ok(())
    }

    fn new_object(&mut self, name: &str) -> ObjectId {
        // A (v3) redefinition gives the name a new id.
        self.last_instance = None;
        let id = ObjectId(self.object_names.len() as u32);
        self.object_names.push(name.to_owned());
        self.object_defined.push(false);
        self.objects.insert(name.to_owned(), id);
        id
    }

    fn object_instance<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        self.require_world(tok);
        // Instance-heavy files name the same object over and over: compare the raw token
        // with the last one instead of unescaping, validating and hashing it again.
        let mut peek = lx.clone();
        if let (Ok(Some(t)), Some((raw, id))) = (peek.next_token(), &self.last_instance) {
            if t.kind == TokenKind::String
                && t.bytes == raw.as_slice()
                && self.current_object != Some(*id)
            {
                let id = *id;
                *lx = peek;
                return self.emit_instance(id, tok);
            }
        }
        let (name, ntok) = self.string(lx, tok)?;
        let id = match self.objects.get(name.as_ref()).copied() {
            Some(id) => {
                self.last_instance = Some((ntok.bytes.to_vec(), id));
                id
            }
            None if self.v4() => {
                // pbrt-v4 resolves instances after parsing: forward references are legal.
                let id = self.new_object(&name);
                self.forward_refs.push((id, ntok.loc, name.to_string()));
                id
            }
            None => return Err(self.err(&ntok, ParseErrorKind::UnknownObject)),
        };
        if Some(id) == self.current_object {
            return Err(self.err(
                &ntok,
                ParseErrorKind::Invalid("object instances itself".into()),
            ));
        }
        self.emit_instance(id, tok)
    }

    fn emit_instance(&mut self, id: ObjectId, tok: &Token<'_>) -> Result<()> {
        self.stats.instances += 1;
        let ev = InstanceEvent {
            object: id,
            name: self
                .object_names
                .get(id.0 as usize)
                .map_or("", String::as_str),
            parent_from_instance: math::to_f32(&self.xs.ctm[0]),
            inside: self.current_object,
            element: self.element,
            loc: tok.loc,
        };
        self.sink.object_instance(&ev)?;
        Ok(())
    }
}

#[cfg(test)]
mod prescan_tests {
    use super::*;

    /// The token-based definition the byte scanner must agree with.
    fn reference(bytes: &[u8]) -> bool {
        let mut lx = Lexer::new(bytes, FileId(0));
        while let Ok(Some(t)) = lx.next_token() {
            match t.kind {
                TokenKind::Word if V4_DIRECTIVES.contains(&t.bytes) => return true,
                TokenKind::String
                    if V4_NAMES.contains(&t.bytes)
                        || V4_TYPE_PREFIXES.iter().any(|p| t.bytes.starts_with(p)) =>
                {
                    return true
                }
                _ => {}
            }
        }
        false
    }

    #[test]
    fn mentions_include_finds_the_word_at_any_offset() {
        for pad in 0..20 {
            for word in ["Include", "Import"] {
                let text = format!("{}{word} \"x\"", "1 ".repeat(pad));
                assert!(mentions_include(text.as_bytes()), "{text}");
                // Straddling the end of the buffer.
                assert!(mentions_include(&text.as_bytes()[..pad * 2 + word.len()]));
            }
            let text = format!("{}Incl Impor IInclud", "0 ".repeat(pad));
            assert!(!mentions_include(text.as_bytes()), "{text}");
        }
    }

    #[test]
    fn swar_interesting_is_exact_per_byte() {
        for b in 0..=255u8 {
            let want = b == b'"' || b == b'#' || b.is_ascii_uppercase();
            for lane in 0..8 {
                let mut chunk = [b'0'; 8];
                chunk[lane] = b;
                assert_eq!(
                    swar_interesting(u64::from_le_bytes(chunk)),
                    want,
                    "{b:#x} at {lane}"
                );
            }
        }
    }

    proptest::proptest! {
        #[test]
        fn prescan_agrees_with_the_lexer_on_token_soup(
            parts in proptest::collection::vec(
                proptest::prop_oneof![
                    proptest::strategy::Just("Import".to_owned()),
                    proptest::strategy::Just("Option".to_owned()),
                    proptest::strategy::Just("\"point3 P\"".to_owned()),
                    proptest::strategy::Just("\"conductor\"".to_owned()),
                    proptest::strategy::Just("# Import\n".to_owned()),
                    "[a-zA-Z0-9.\\-]{0,12}",
                    "[ \n\t\"\\[\\]#]{0,2}",
                ],
                0..24,
            )
        ) {
            let text = parts.concat();
            proptest::prop_assert_eq!(prescan_is_v4(text.as_bytes()), reference(text.as_bytes()), "{}", text);
        }
    }

    #[test]
    fn prescan_matches_the_token_definition() {
        let cases: &[&str] = &[
            "WorldBegin Shape \"sphere\"",
            "WorldBegin Import \"x.pbrt\"",
            "# Import \"x\"\nShape \"sphere\"",
            "Shape \"trianglemesh\" \"point3 P\" [0 0 0]",
            "Shape \"trianglemesh\" \"point P\" [0 0 0]",
            "Translate 1E5 2 3 Attribute \"shape\"",
            "Material \"coateddiffuse\"",
            "Texture \"a\" \"color\" \"imagemap\" \"string filename\" \"Import\"",
            "ColorSpaceX 1",
            "Transform [ 1 0 0 0 0 1 0 0 0 0 1 0 10.1657 2.08030009 28.5746002 1 ] Option 1",
            "1234567812345678Option",
            "x abcdefghImport 1",
            "1 abcdefgImport 1",
            "0.5 0.25 0.125 0.0625 abcdefghijklmnopOption Import",
            "\"unterminated\nOption",
        ];
        for case in cases {
            assert_eq!(
                prescan_is_v4(case.as_bytes()),
                reference(case.as_bytes()),
                "{case}"
            );
        }
    }
}
