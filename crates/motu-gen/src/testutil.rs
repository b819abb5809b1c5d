//! Test helpers: an independent reader for the generated files that checks
//! syntax (balanced blocks, resolvable files, valid PLY headers) and recounts
//! everything the summary claims.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

#[derive(Debug, Default)]
pub(crate) struct Parsed {
    pub(crate) files: u64,
    pub(crate) bytes: u64,
    pub(crate) object_instances: u64,
    pub(crate) flattened_instances: u64,
    pub(crate) unique_triangles: u64,
    pub(crate) instanced_triangles: u64,
    pub(crate) nested: bool,
    pub(crate) cameras: u64,
    pub(crate) elements: Vec<String>,
    pub(crate) v3_only_syntax: bool,
    pub(crate) v4_only_syntax: bool,
    pub(crate) world_end: bool,
}

#[derive(Debug, Default)]
struct Object {
    direct_triangles: u64,
    has_shapes: bool,
    children: Vec<String>,
}

#[derive(Debug, PartialEq)]
enum Tok {
    Word(String),
    Str(String),
    Open,
    Close,
}

fn tokenize(text: &str) -> Vec<Tok> {
    let mut toks = Vec::new();
    let bytes = text.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        let c = bytes[i];
        if c.is_ascii_whitespace() {
            i += 1;
        } else if c == b'#' {
            while i < bytes.len() && bytes[i] != b'\n' {
                i += 1;
            }
        } else if c == b'[' {
            toks.push(Tok::Open);
            i += 1;
        } else if c == b']' {
            toks.push(Tok::Close);
            i += 1;
        } else if c == b'"' {
            let start = i + 1;
            i = start;
            while i < bytes.len() && bytes[i] != b'"' {
                assert_ne!(bytes[i], b'\n', "unterminated string");
                i += 1;
            }
            assert!(i < bytes.len(), "unterminated string");
            toks.push(Tok::Str(text[start..i].to_string()));
            i += 1;
        } else {
            let start = i;
            while i < bytes.len()
                && !bytes[i].is_ascii_whitespace()
                && !b"[]\"#".contains(&bytes[i])
            {
                i += 1;
            }
            toks.push(Tok::Word(text[start..i].to_string()));
        }
    }
    toks
}

/// Checks a PLY header against the file size; returns (vertices, faces).
pub(crate) fn check_ply(path: &Path) -> (u64, u64) {
    let data = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let end = b"end_header\n";
    let header_len = data
        .windows(end.len())
        .position(|w| w == end)
        .map(|p| p + end.len())
        .unwrap_or_else(|| panic!("{}: no end_header", path.display()));
    let header = std::str::from_utf8(&data[..header_len]).expect("ascii header");
    let lines: Vec<&str> = header.lines().collect();
    assert_eq!(lines[0], "ply");
    assert_eq!(lines[1], "format binary_little_endian 1.0");
    let count = |prefix: &str| -> u64 {
        lines
            .iter()
            .find_map(|l| l.strip_prefix(prefix))
            .and_then(|n| n.trim().parse().ok())
            .unwrap_or_else(|| panic!("{}: missing {prefix}", path.display()))
    };
    let vertices = count("element vertex ");
    let faces = count("element face ");
    for p in [
        "property float x",
        "property float y",
        "property float z",
        "property list uchar int vertex_indices",
    ] {
        assert!(lines.contains(&p), "{}: missing {p}", path.display());
    }
    assert_eq!(
        data.len() as u64,
        header_len as u64 + 12 * vertices + 13 * faces,
        "{}",
        path.display()
    );
    let faces_at = header_len + 12 * vertices as usize;
    for f in 0..faces as usize {
        let rec = &data[faces_at + 13 * f..faces_at + 13 * (f + 1)];
        assert_eq!(rec[0], 3);
        for k in 0..3 {
            let i = i32::from_le_bytes([
                rec[1 + 4 * k],
                rec[2 + 4 * k],
                rec[3 + 4 * k],
                rec[4 + 4 * k],
            ]);
            assert!(
                i >= 0 && (i as u64) < vertices,
                "{}: index {i} out of range",
                path.display()
            );
        }
    }
    (vertices, faces)
}

struct Reader {
    root: PathBuf,
    parsed: Parsed,
    objects: HashMap<String, Object>,
    current_object: Option<String>,
    world_triangles: u64,
    world_instances: Vec<String>,
    in_world: bool,
    seen_files: std::collections::BTreeSet<PathBuf>,
}

impl Reader {
    fn read_file(&mut self, relative: &str, depth: usize) {
        let path = self.root.join(relative);
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        self.note_file(&path);
        let toks = tokenize(&text);
        let mut attr_depth = 0i64;
        let mut i = 0;
        let word = |t: &Tok| match t {
            Tok::Word(w) => w.clone(),
            other => panic!("{relative}: expected a directive, got {other:?}"),
        };
        while i < toks.len() {
            let directive = word(&toks[i]);
            i += 1;
            // Gather parameters until the next directive.
            let start = i;
            while i < toks.len()
                && !matches!(&toks[i], Tok::Word(w) if w.starts_with(|c: char| c.is_ascii_uppercase()))
            {
                i += 1;
            }
            let args = &toks[start..i];
            let mut depth_brackets = 0i64;
            for a in args {
                match a {
                    Tok::Open => depth_brackets += 1,
                    Tok::Close => depth_brackets -= 1,
                    _ => {}
                }
                assert!(
                    (0..=1).contains(&depth_brackets),
                    "{relative}: bad brackets in {directive}"
                );
            }
            assert_eq!(
                depth_brackets, 0,
                "{relative}: unbalanced brackets in {directive}"
            );
            let strs: Vec<&str> = args
                .iter()
                .filter_map(|t| {
                    if let Tok::Str(s) = t {
                        Some(s.as_str())
                    } else {
                        None
                    }
                })
                .collect();
            match directive.as_str() {
                "AttributeBegin" => attr_depth += 1,
                "AttributeEnd" => {
                    attr_depth -= 1;
                    assert!(
                        attr_depth >= 0,
                        "{relative}: AttributeEnd without AttributeBegin"
                    );
                }
                "WorldBegin" => self.in_world = true,
                "WorldEnd" => self.parsed.world_end = true,
                "Camera" => self.parsed.cameras += 1,
                "ObjectBegin" => {
                    assert!(
                        self.current_object.is_none(),
                        "{relative}: ObjectBegin inside ObjectBegin"
                    );
                    let name = strs[0].to_string();
                    assert!(
                        !self.objects.contains_key(&name),
                        "{relative}: {name} defined twice"
                    );
                    self.objects.insert(name.clone(), Object::default());
                    self.current_object = Some(name);
                }
                "ObjectEnd" => {
                    assert!(
                        self.current_object.take().is_some(),
                        "{relative}: ObjectEnd without ObjectBegin"
                    );
                }
                "ObjectInstance" => {
                    let name = strs[0].to_string();
                    assert!(
                        self.objects.contains_key(&name),
                        "{relative}: {name} instanced before its definition"
                    );
                    self.parsed.object_instances += 1;
                    match &self.current_object {
                        Some(parent) => {
                            self.parsed.nested = true;
                            self.objects
                                .get_mut(parent)
                                .expect("open object")
                                .children
                                .push(name);
                        }
                        None => self.world_instances.push(name),
                    }
                }
                "Include" => {
                    if self.in_world && depth == 0 {
                        let stem = Path::new(strs[0])
                            .file_stem()
                            .and_then(|s| s.to_str())
                            .unwrap_or("")
                            .to_string();
                        self.parsed.elements.push(stem);
                    }
                    self.read_file(strs[0], depth + 1);
                }
                "Shape" => {
                    let triangles = self.shape_triangles(relative, strs[0], args);
                    self.parsed.unique_triangles += triangles;
                    match &self.current_object {
                        Some(name) => {
                            let o = self.objects.get_mut(name).expect("open object");
                            o.direct_triangles += triangles;
                            o.has_shapes = true;
                        }
                        None => self.world_triangles += triangles,
                    }
                }
                "MakeNamedMaterial" => {
                    if strs.contains(&"rgb Kd") {
                        self.parsed.v3_only_syntax = true;
                    }
                    if strs.contains(&"rgb reflectance") {
                        self.parsed.v4_only_syntax = true;
                    }
                }
                "LookAt" | "Film" | "Sampler" | "LightSource" | "NamedMaterial" | "Transform"
                | "Identity" => {}
                other => panic!("{relative}: unexpected directive {other}"),
            }
        }
        assert_eq!(
            attr_depth, 0,
            "{relative}: unbalanced AttributeBegin/AttributeEnd"
        );
        if depth > 0 {
            assert!(self.current_object.is_none() || depth > 0);
        }
    }

    fn note_file(&mut self, path: &Path) {
        if self.seen_files.insert(path.to_path_buf()) {
            self.parsed.files += 1;
            self.parsed.bytes += std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
        }
    }

    fn shape_triangles(&mut self, relative: &str, kind: &str, args: &[Tok]) -> u64 {
        // Parameters: "type name" followed by a bracketed list.
        let mut params: BTreeMap<String, Vec<String>> = BTreeMap::new();
        let mut i = 1; // skip the shape kind string
        while i < args.len() {
            let Tok::Str(decl) = &args[i] else {
                panic!("{relative}: bad parameter {:?}", args[i])
            };
            assert_eq!(
                args.get(i + 1),
                Some(&Tok::Open),
                "{relative}: {decl} must be bracketed"
            );
            let mut values = Vec::new();
            i += 2;
            while args[i] != Tok::Close {
                match &args[i] {
                    Tok::Word(w) | Tok::Str(w) => values.push(w.clone()),
                    _ => unreachable!(),
                }
                i += 1;
            }
            i += 1;
            let decl_parts: Vec<&str> = decl.split_whitespace().collect();
            if decl_parts.first() == Some(&"point") {
                self.parsed.v3_only_syntax = true;
            }
            if decl_parts.first() == Some(&"point3") {
                self.parsed.v4_only_syntax = true;
            }
            params.insert(decl_parts.last().copied().unwrap_or("").to_string(), values);
        }
        match kind {
            "trianglemesh" => {
                let indices = &params["indices"];
                let p = &params["P"];
                assert_eq!(indices.len() % 3, 0);
                assert_eq!(p.len() % 3, 0);
                let vertices = (p.len() / 3) as u64;
                for v in p {
                    assert!(
                        v.parse::<f64>().map(f64::is_finite).unwrap_or(false),
                        "{relative}: bad float {v}"
                    );
                }
                for ix in indices {
                    let n: u64 = ix.parse().unwrap_or(u64::MAX);
                    assert!(n < vertices, "{relative}: index {ix} out of range");
                }
                (indices.len() / 3) as u64
            }
            "plymesh" => {
                let file = &params["filename"][0];
                let path = self.root.join(file);
                self.note_file(&path);
                check_ply(&path).1
            }
            other => panic!("{relative}: unexpected shape {other}"),
        }
    }

    fn flatten(&self, name: &str, memo: &mut HashMap<String, (u64, u64)>) -> (u64, u64) {
        if let Some(&v) = memo.get(name) {
            return v;
        }
        let o = &self.objects[name];
        let mut acc = (u64::from(o.has_shapes), o.direct_triangles);
        for child in &o.children {
            let (n, t) = self.flatten(child, memo);
            acc = (acc.0 + n, acc.1 + t);
        }
        memo.insert(name.to_string(), acc);
        acc
    }
}

/// Reads the scene at `scene` (and everything it references) and recounts.
pub(crate) fn check_scene(scene: &Path) -> Parsed {
    let root = scene.parent().expect("scene in a folder").to_path_buf();
    let mut r = Reader {
        root,
        parsed: Parsed::default(),
        objects: HashMap::new(),
        current_object: None,
        world_triangles: 0,
        world_instances: Vec::new(),
        in_world: false,
        seen_files: Default::default(),
    };
    let name = scene
        .file_name()
        .and_then(|n| n.to_str())
        .expect("file name")
        .to_string();
    r.read_file(&name, 0);
    assert!(r.current_object.is_none(), "ObjectBegin left open");
    let mut memo = HashMap::new();
    let mut flattened = 0;
    let mut instanced = r.world_triangles;
    for name in &r.world_instances {
        let (n, t) = r.flatten(name, &mut memo);
        flattened += n;
        instanced += t;
    }
    r.parsed.flattened_instances = flattened;
    r.parsed.instanced_triangles = instanced;
    // Every file under the root must be reachable from the scene.
    let mut on_disk = 0;
    let mut stack = vec![r.root.clone()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("read_dir").flatten() {
            let p = entry.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                on_disk += 1;
            }
        }
    }
    assert_eq!(on_disk, r.parsed.files, "files on disk vs referenced");
    r.parsed
}

/// xxh3 of every file's relative path and contents, in path order.
pub(crate) fn hash_dir(root: &Path) -> u64 {
    let mut files = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("read_dir").flatten() {
            let p = entry.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                files.push(p);
            }
        }
    }
    files.sort();
    let mut hasher = xxhash_rust::xxh3::Xxh3::new();
    for f in files {
        hasher.update(
            f.strip_prefix(root)
                .unwrap_or(&f)
                .to_string_lossy()
                .as_bytes(),
        );
        hasher.update(&std::fs::read(&f).expect("read"));
    }
    hasher.digest()
}
