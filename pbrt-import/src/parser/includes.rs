//! `Include` and `Import`: resolving, cycles, sharing a repeated state-neutral include as one
//! object, and parallel runs of includes (workers parse ahead, the main thread replays their
//! buffered events in document order).

use super::*;
use crate::prescan::mentions_include;

/// How often each raw `Include`/`Import` file name occurs in `bytes`. A heuristic that
/// only decides whether sharing is attempted (a wrong count costs a prototype or a copy,
/// never correctness); files without either word are not tokenized.
pub(super) fn count_includes(
    bytes: &[u8],
    mut release: impl FnMut(usize, usize),
) -> HashMap<Vec<u8>, u32> {
    let mut counts = HashMap::new();
    // A window at a time, each window's pages released once scanned: a file of millions of
    // instances is never resident whole (issue 48 item 1). Windows overlap by a word's
    // length so a word across a boundary is found.
    const OVERLAP: usize = "Include".len() - 1;
    let mut at = 0;
    let mut mentioned = false;
    while at < bytes.len() {
        let end = (at + super::RELEASE_TEXT_BYTES).min(bytes.len());
        if mentions_include(&bytes[at..(end + OVERLAP).min(bytes.len())]) {
            mentioned = true;
            break;
        }
        release(at, end);
        at = end;
    }
    if !mentioned {
        return counts;
    }
    let mut lx = Lexer::new(bytes, FileId(0));
    let mut after_include = false;
    let mut released = 0;
    while let Ok(Some(t)) = lx.next_token() {
        if after_include && t.kind == TokenKind::String {
            *counts.entry(t.bytes.to_vec()).or_insert(0) += 1;
        }
        after_include = t.kind == TokenKind::Word && matches!(t.bytes, b"Include" | b"Import");
        if lx.offset() >= released + super::RELEASE_TEXT_BYTES {
            release(released, lx.offset());
            released = lx.offset();
        }
    }
    release(released, bytes.len());
    counts
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

/// Files over this are parsed sequentially (streaming), whatever the window: a worker's buffer
/// of a bigger file would outweigh the window itself.
const MAX_PARALLEL_FILE_BYTES: u64 = 128 << 20;

/// The window of a parallel include run, in pieces ([`crate::ParseOptions::parallel_chunk_bytes`],
/// 4 MiB by default): this many per pool thread, between [`MIN_WINDOW_PIECES`] and
/// [`MAX_WINDOW_PIECES`]. What a worker parsed waits in the window, as events and meshes, until
/// its file is replayed: on island 0.1 with 2 threads a 256 MiB window held ~80 MiB more of
/// them at the parse's peak than a 64 MiB one, which kept both workers busy as well (issue 48
/// item 1).
const WINDOW_PIECES_PER_THREAD: u64 = 4;

/// The smallest window (64 MiB at the default pieces): a few pieces per worker even for files
/// cut at huge shapes.
const MIN_WINDOW_PIECES: u64 = 16;

/// The largest window, whatever the thread count (128 MiB at the default pieces; it was
/// 256 MiB at 16 threads and more, session 49). Why this keeps a 16-thread parse fed: the
/// main thread replays in document order and is the slower side by far: a worker parses
/// placement text at ~0.8 GB/s (island 0.0127: `parse_neutral` ~20% of 2.4 s of CPU for
/// 382 MB) while the replay and the sink behind it take ~0.2 GB/s (island 0.05's parse phase,
/// 1.9 GB in ~9 s on 2 cores). The replay waits only when the file at the head is not parsed
/// yet; one worker alone parses ~4× faster than the replay consumes, so the head is ready as
/// long as the window holds the next file or two (island files are ≤ 75 MB), and 32 pieces are
/// still 2 per worker at 16 threads (one parsed, one queued). More pieces in flight would only
/// hold more parsed buffers (about half their text's bytes): at 16 threads the old 256 MiB
/// window plus the one file that crosses its line could hold ~330 MB of text at a time.
const MAX_WINDOW_PIECES: u64 = 32;

/// The window of a parallel include run, in bytes of input, on a pool of `threads` cutting
/// pieces of `piece_bytes`. The run admits files while it holds less than this, so at most
/// this plus one file (≤ [`MAX_PARALLEL_FILE_BYTES`]) is in flight.
fn window_bytes_for(threads: usize, piece_bytes: usize) -> u64 {
    (threads as u64)
        .saturating_mul(WINDOW_PIECES_PER_THREAD)
        .clamp(MIN_WINDOW_PIECES, MAX_WINDOW_PIECES)
        .saturating_mul(piece_bytes.max(1) as u64)
}

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

pub(super) struct SharedInclude {
    object: ObjectId,
    key: ShareKey,
}

impl<'s> Parser<'s> {
    pub(super) fn include<'b>(
        &mut self,
        lx: &mut Lexer<'b>,
        tok: &Token<'b>,
        via: Via,
    ) -> Result<()> {
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
            return self.run_include(path, canonical, &src, via, element, replay);
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
        let r = self.run_include(path, canonical.clone(), &src, via, element, None);
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
        src: &SourceBytes,
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
        let r = self.run_file(path, src.bytes(), Some(src), via, element, replay);
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
    /// holds at most [`window_bytes_for`] the pool's threads of input (and one more file) and
    /// a few files per thread; the most it held is counted in
    /// [`crate::ParseStats::parallel_window_peak_bytes`].
    fn include_run<'b>(
        &mut self,
        lx: &mut Lexer<'b>,
        via: Via,
        name: Cow<'b, str>,
        stok: Token<'b>,
    ) -> Result<()> {
        let max_files = rayon::current_num_threads().saturating_mul(4).max(4);
        let chunk_bytes = self.opts.parallel_chunk_bytes.max(1);
        let max_window_bytes = window_bytes_for(rayon::current_num_threads(), chunk_bytes);
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
                while !exhausted && window.len() < max_files && window_bytes < max_window_bytes {
                    let next = first.take().or_else(|| self.next_item(&mut cursor));
                    let Some(item) = next.map(|item| self.open_item(item)) else {
                        exhausted = true;
                        break;
                    };
                    let mut job = None;
                    if let (Some((_, src)), Some(snap)) = (&item.src, self.snapshot()) {
                        window_bytes += src.bytes().len() as u64;
                        // The scan's pages leave the resident set behind it; the workers
                        // fault their pieces back from the page cache.
                        let starts = parallel::split_points(src.bytes(), chunk_bytes, |a, b| {
                            src.release(a, b)
                        });
                        let mut slots = Vec::with_capacity(starts.len());
                        for (i, &start) in starts.iter().enumerate() {
                            let end = starts.get(i + 1).copied().unwrap_or(src.bytes().len());
                            let slot = Arc::new(Slot::default());
                            let (src, worker_slot) = (src.clone(), slot.clone());
                            let worker_snap = snap.clone();
                            scope.spawn(move |_| {
                                let piece = src.bytes().get(start..end).unwrap_or_default();
                                worker_slot.put(parallel::parse_neutral(piece, &worker_snap));
                                // Parsed: the piece's text leaves the resident set while the
                                // window waits for its replay (it faults back if read again).
                                src.release(start, end);
                            });
                            slots.push(slot);
                        }
                        job = Some((snap, slots));
                    }
                    window.push_back(InFlight { item, job });
                }
                let peak = &mut self.stats.parallel_window_peak_bytes;
                *peak = (*peak).max(window_bytes);
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
            .is_ok_and(|m| m.is_file() && m.len() <= MAX_PARALLEL_FILE_BYTES);
        if fits && !gz {
            item.src = SourceBytes::open(&path)
                .ok()
                .map(|src| (path, Arc::new(src)));
        }
        item
    }

    /// Deliver a worker's buffer for file `file` (the body of `run_file`).
    pub(super) fn replay(&mut self, pieces: Vec<Parsed>, file: FileId) -> Result<()> {
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
                    self.emit_instance_at(id, parent_from_instance, None, loc)?;
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
}

#[cfg(test)]
mod tests;
