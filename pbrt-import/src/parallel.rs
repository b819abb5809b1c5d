//! Parallel parsing of *state-neutral* included files ([`crate::ParseOptions::parallel_includes`]).
//!
//! A neutral file only places shapes and instances under the graphics state current at
//! its `Include`/`Import` and leaves that state exactly as it found it. Such a file can be
//! parsed on a worker thread against a [`Snapshot`] of the state into a [`Parsed`] buffer;
//! the main thread replays the buffer in document order, so sinks see the same events in
//! the same order as a sequential parse. Everything order-dependent (shape `seq`, object
//! name resolution, statistics, file ids) is done at replay time.
//!
//! The worker is deliberately narrow and is the authority on neutrality: any directive,
//! construct or error outside the supported subset makes it give up ([`Outcome::Fallback`])
//! and the main thread parses the file sequentially, so errors keep their exact positions
//! and messages. There is no byte-level prefilter in front of it: such a pass read every
//! piece twice (4% of island 0.005's import, session 49) to spare a worker the part of a
//! non-neutral piece before its first disqualifying directive, which the worker stops at.

use std::sync::Arc;

use crate::events::{AreaLight, Geometry, Material, ShapeEvent};
use crate::lexer::{Lexer, Loc, TokenKind};
use crate::math::{self, M64};
use crate::params::ParamList;
use crate::shapes;
use crate::{FileId, PbrtVersion};

/// The graphics state a neutral file is parsed against.
#[derive(Clone)]
pub(crate) struct Snapshot {
    pub version: PbrtVersion,
    pub ctm: M64,
    pub material: Arc<Material>,
    pub reverse_orientation: bool,
    pub area_light: Option<Arc<AreaLight>>,
    pub tessellation_segments: u32,
}

impl Snapshot {
    /// Whether a buffer parsed against `self` is valid under `other` (the state at replay).
    pub fn same_as(&self, other: &Snapshot) -> bool {
        self.version == other.version
            && self.ctm == other.ctm
            && Arc::ptr_eq(&self.material, &other.material)
            && self.reverse_orientation == other.reverse_orientation
            && match (&self.area_light, &other.area_light) {
                (None, None) => true,
                (Some(a), Some(b)) => Arc::ptr_eq(a, b),
                _ => false,
            }
            && self.tessellation_segments == other.tessellation_segments
    }
}

/// One buffered event. Locations carry a placeholder file id, patched at replay.
pub(crate) enum Buffered {
    /// `ObjectInstance`: index into [`Parsed::names`], CTM, directive and name locations.
    Instance {
        name: u32,
        parent_from_instance: crate::Mat4,
        loc: Loc,
        name_loc: Loc,
    },
    /// A shape (`seq`, `element` and the file id are set at replay).
    Shape(Box<ShapeEvent>),
    /// A warning about a shape (`notes` from the shape builders).
    Warn { loc: Loc, message: String },
    /// A shape skipped for invalid data, with its warning.
    Skipped { loc: Loc, message: String },
}

/// A neutral file, parsed.
#[derive(Default)]
pub(crate) struct Parsed {
    /// Object names referenced, each once.
    pub names: Vec<String>,
    pub events: Vec<Buffered>,
    /// Newlines in the piece parsed (locations are relative to its first line).
    pub lines: u32,
}

/// What a worker made of a file.
pub(crate) enum Outcome {
    /// Neutral and parsed.
    Parsed(Parsed),
    /// Not neutral, or not in the supported subset, or malformed: parse it sequentially.
    Fallback,
}

/// Placeholder file id for buffered locations.
const PLACEHOLDER: FileId = FileId(u32::MAX);

/// Parse `bytes` as a neutral file against `snap`.
pub(crate) fn parse_neutral(bytes: &[u8], snap: &Snapshot) -> Outcome {
    match Worker::new(snap).run(bytes) {
        Some(p) => Outcome::Parsed(p),
        None => Outcome::Fallback,
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Block {
    Attribute,
    Transform,
}

struct Worker<'s> {
    snap: &'s Snapshot,
    ctm: M64,
    reverse_orientation: bool,
    /// Per open block: its kind and the state it restores.
    stack: Vec<(Block, M64, bool)>,
    names: std::collections::HashMap<String, u32>,
    out: Parsed,
}

impl<'s> Worker<'s> {
    fn new(snap: &'s Snapshot) -> Self {
        Worker {
            snap,
            ctm: snap.ctm,
            reverse_orientation: snap.reverse_orientation,
            stack: Vec::new(),
            names: std::collections::HashMap::new(),
            out: Parsed::default(),
        }
    }

    fn v4(&self) -> bool {
        self.snap.version == PbrtVersion::V4
    }

    /// `None`: fall back to the sequential parser. A piece without any shape or instance
    /// falls back too (comments only, empty blocks, an empty file): that is the rule the
    /// old byte prescan applied, kept so the same files take the same path.
    fn run(mut self, bytes: &[u8]) -> Option<Parsed> {
        let mut lx = Lexer::new(bytes, PLACEHOLDER);
        let mut any = false;
        while let Some(tok) = lx.next_token().ok()? {
            if tok.kind != TokenKind::Word {
                return None;
            }
            match tok.bytes {
                b"AttributeBegin" => {
                    self.stack
                        .push((Block::Attribute, self.ctm, self.reverse_orientation));
                }
                b"TransformBegin" => {
                    self.stack
                        .push((Block::Transform, self.ctm, self.reverse_orientation));
                }
                b"AttributeEnd" | b"TransformEnd" => {
                    let want = if tok.bytes == b"AttributeEnd" {
                        Block::Attribute
                    } else {
                        Block::Transform
                    };
                    let (kind, ctm, rev) = self.stack.pop()?;
                    if kind != want {
                        return None;
                    }
                    self.ctm = ctm;
                    if kind == Block::Attribute {
                        self.reverse_orientation = rev;
                    }
                }
                b"Translate" => {
                    let v = numbers::<3>(&mut lx)?;
                    self.apply(math::translate([v[0], v[1], v[2]]))?;
                }
                b"Scale" => {
                    let v = numbers::<3>(&mut lx)?;
                    self.apply(math::scale([v[0], v[1], v[2]]))?;
                }
                b"Rotate" => {
                    let v = numbers::<4>(&mut lx)?;
                    self.apply(math::rotate(v[0], [v[1], v[2], v[3]]))?;
                }
                b"Transform" | b"ConcatTransform" => {
                    let v = numbers::<16>(&mut lx)?;
                    let m = math::from_pbrt(&v);
                    if tok.bytes == b"Transform" {
                        self.in_block()?;
                        self.ctm = m;
                    } else {
                        self.apply(m)?;
                    }
                }
                b"Identity" => {
                    self.in_block()?;
                    self.ctm = math::IDENTITY;
                }
                b"ReverseOrientation" => {
                    // Only an attribute block restores the orientation.
                    if !self.stack.iter().any(|b| b.0 == Block::Attribute) {
                        return None;
                    }
                    self.reverse_orientation = !self.reverse_orientation;
                }
                b"ObjectInstance" => {
                    any = true;
                    self.instance(&mut lx, tok.loc)?;
                }
                b"Shape" => {
                    any = true;
                    self.shape(&mut lx, tok.loc)?;
                }
                _ => return None,
            }
        }
        if !any || !self.stack.is_empty() {
            return None;
        }
        // All whitespace is consumed at the end: the line count is the newline count.
        self.out.lines = lx.loc().line.saturating_sub(1);
        Some(self.out)
    }

    /// Transforms must not leak: only inside blocks.
    fn in_block(&self) -> Option<()> {
        (!self.stack.is_empty()).then_some(())
    }

    fn apply(&mut self, m: M64) -> Option<()> {
        self.in_block()?;
        self.ctm = math::mul(&self.ctm, &m);
        Some(())
    }

    fn instance(&mut self, lx: &mut Lexer<'_>, loc: Loc) -> Option<()> {
        let t = lx.next_token().ok()??;
        if t.kind != TokenKind::String {
            return None;
        }
        let name = t.unescaped()?;
        let idx = match self.names.get(name.as_ref()) {
            Some(&i) => i,
            None => {
                let i = self.out.names.len() as u32;
                self.names.insert(name.to_string(), i);
                self.out.names.push(name.into_owned());
                i
            }
        };
        self.out.events.push(Buffered::Instance {
            name: idx,
            parent_from_instance: math::to_f32(&self.ctm),
            loc,
            name_loc: t.loc,
        });
        Some(())
    }

    /// Mirrors `Parser::shape` for the cases that need no shared state.
    fn shape(&mut self, lx: &mut Lexer<'_>, loc: Loc) -> Option<()> {
        let ktok = lx.next_token().ok()??;
        if ktok.kind != TokenKind::String {
            return None;
        }
        let kind = ktok.unescaped()?;
        let mut p = ParamList::parse(lx).ok()?;
        if p.v4_spelling && !self.v4() {
            return None; // a version switch: let the main parser see it
        }
        if !self.v4()
            && ["Kd", "reflectance", "color", "Kr", "opacity", "roughness"]
                .iter()
                .any(|k| p.get(k).is_some())
        {
            return None; // v3 shape-level material override: needs material ids
        }
        if p.texture("alpha").is_some() {
            return None; // alpha textures resolve through the named-texture tables
        }
        let mut event = ShapeEvent {
            seq: 0,
            kind: String::new(),
            parent_from_shape: math::to_f32(&self.ctm),
            reverse_orientation: self.reverse_orientation,
            material: self.snap.material.clone(),
            alpha_texture: p.texture("alpha").map(str::to_owned),
            alpha: p.float("alpha"),
            alpha_image: None,
            area_light: self.snap.area_light.clone(),
            object: None,
            element: None,
            source_path: None,
            loc,
            geometry: Geometry::Unsupported,
        };
        let segs = self.snap.tessellation_segments.max(3);
        let mut notes = Vec::new();
        let built: Result<Geometry, String> = match kind.as_ref() {
            "trianglemesh" | "loopsubdiv" => {
                shapes::triangle_mesh(&mut p, &mut notes).map(Geometry::Mesh)
            }
            "bilinearmesh" if self.v4() => {
                shapes::bilinear_mesh(&mut p, &mut notes).map(Geometry::Mesh)
            }
            "sphere" => shapes::sphere(&p, segs).map(Geometry::Mesh),
            "disk" => shapes::disk(&p, segs).map(Geometry::Mesh),
            "cylinder" => shapes::cylinder(&p, segs).map(Geometry::Mesh),
            "curve" => shapes::curve(&mut p).map(Geometry::Curve),
            // plymesh (file access, PLY queue), unsupported kinds (warn once) and
            // v3 bilinearmesh (version switch) stay on the main thread.
            _ => return None,
        };
        for n in notes {
            self.out.events.push(Buffered::Warn {
                loc: ktok.loc,
                message: format!("{kind}: {n}"),
            });
        }
        match built {
            Ok(g) => {
                event.kind = kind.into_owned();
                event.geometry = g;
                self.out.events.push(Buffered::Shape(Box::new(event)));
            }
            Err(m) => self.out.events.push(Buffered::Skipped {
                loc: ktok.loc,
                message: format!("{kind}: {m}; shape skipped"),
            }),
        }
        Some(())
    }
}

/// `N` numbers, optionally inside `[ ]`, as `Parser::numbers` reads them.
fn numbers<const N: usize>(lx: &mut Lexer<'_>) -> Option<[f64; N]> {
    let bracketed = lx.peek_byte() == Some(b'[');
    if bracketed {
        lx.next_token().ok()?;
    }
    let mut out = [0.0; N];
    for slot in &mut out {
        *slot = lx.read_f64()?;
    }
    if bracketed {
        let t = lx.next_token().ok()??;
        if t.kind != TokenKind::Close {
            return None;
        }
    }
    Some(out)
}

/// Where to cut a file into pieces of about `target` bytes for separate workers: offsets
/// (the first is 0) of lines that start with a directive that can begin a top-level
/// statement of a neutral file (`AttributeBegin`, `TransformBegin`, `Shape`,
/// `ObjectInstance`) at column 1. A cut inside a token or block cannot go unnoticed: the piece before it
/// then ends in an unterminated string or array, an argument-less directive or an open
/// block, and its worker gives up, so the whole file is parsed sequentially. Pieces of a
/// neutral file each start at block depth 0, where the state is the include's.
///
/// Finding a cut can read far past `target` (a file of a few huge `Shape`s is scanned line by
/// line to the next one): `release` is called on the ranges read, every
/// [`SCAN_RELEASE_BYTES`], so a file waiting in the window for its workers is not resident whole
/// (issue 48 item 1: island 0.1's parse held ~180 MiB of such text).
pub(crate) fn split_points(
    bytes: &[u8],
    target: usize,
    mut release: impl FnMut(usize, usize),
) -> Vec<usize> {
    let mut starts = vec![0];
    let mut pos = target;
    // Start of the bytes read and not yet released.
    let mut read_from = pos;
    while pos < bytes.len() {
        if pos >= read_from + SCAN_RELEASE_BYTES {
            release(read_from, pos);
            read_from = pos;
        }
        // `memchr`: vectorised, where a byte loop here was 2.5% of island 0.0127's import.
        let Some(nl) = memchr::memchr(b'\n', &bytes[pos..]) else {
            pos = bytes.len();
            break;
        };
        let next = pos + nl + 1;
        let rest = bytes.get(next..).unwrap_or_default();
        if [
            &b"AttributeBegin"[..],
            b"TransformBegin",
            b"Shape",
            b"ObjectInstance",
        ]
        .iter()
        .any(|w| rest.starts_with(w))
        {
            starts.push(next);
            release(read_from, (next + WORD_BYTES).min(bytes.len()));
            pos = next + target;
            read_from = pos;
        } else {
            pos = next;
        }
    }
    if read_from < pos.min(bytes.len()) {
        release(read_from, pos.min(bytes.len()));
    }
    starts
}

/// How much text [`split_points`] reads between releases.
const SCAN_RELEASE_BYTES: usize = 4 << 20;

/// The longest directive word [`split_points`] looks at after a newline.
const WORD_BYTES: usize = "AttributeBegin".len();

#[cfg(test)]
mod tests;
