//! Error types. Every scene error names file, line, column and the offending token.

use std::fmt;
use std::path::PathBuf;

/// A resolved source position (file path instead of [`crate::FileId`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    /// File path as opened.
    pub path: PathBuf,
    /// 1-based line.
    pub line: u32,
    /// 1-based byte column.
    pub column: u32,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.path.display(), self.line, self.column)
    }
}

/// What kind of syntax or semantic error a [`Error::Parse`] is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ParseErrorKind {
    /// A word where a directive was expected is not a pbrt directive.
    UnknownDirective,
    /// The token does not fit the grammar here.
    Unexpected {
        /// What the grammar wanted.
        expected: &'static str,
    },
    /// A string literal is unterminated or not UTF-8.
    BadString,
    /// A parameter's declared type is unknown, or its values do not match the type.
    BadParameter(String),
    /// A value has the wrong type for what the directive needs.
    WrongParameterType(String),
    /// `AttributeEnd`/`TransformEnd`/`ObjectEnd` without a matching begin, or a block left open.
    Unbalanced(String),
    /// `ObjectInstance` of an object never defined.
    UnknownObject,
    /// A directive used where the format forbids it (e.g. nested `ObjectBegin`).
    Misplaced(String),
    /// Any other invalid construct.
    Invalid(String),
}

impl fmt::Display for ParseErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParseErrorKind::UnknownDirective => write!(f, "unknown directive"),
            ParseErrorKind::Unexpected { expected } => write!(f, "expected {expected}"),
            ParseErrorKind::BadString => write!(f, "unterminated or non-UTF-8 string"),
            ParseErrorKind::BadParameter(m) => write!(f, "bad parameter: {m}"),
            ParseErrorKind::WrongParameterType(m) => write!(f, "wrong parameter type: {m}"),
            ParseErrorKind::Unbalanced(m) => write!(f, "unbalanced block: {m}"),
            ParseErrorKind::UnknownObject => write!(f, "unknown object name"),
            ParseErrorKind::Misplaced(m) => write!(f, "misplaced directive: {m}"),
            ParseErrorKind::Invalid(m) => write!(f, "{m}"),
        }
    }
}

/// A file that was referenced but could not be found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MissingFile {
    /// Resolved path that was tried.
    pub path: PathBuf,
    /// Where it was referenced.
    pub referenced_at: Location,
}

/// Errors from the PLY reader.
#[derive(Debug, thiserror::Error)]
pub enum PlyError {
    /// Bad header line.
    #[error("PLY header line {line}: {message}")]
    Header {
        /// 1-based header line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// Body data is truncated or malformed.
    #[error("PLY element `{element}` property `{property}` (item {index}): {message}")]
    Body {
        /// Element name (`vertex`, `face`, ...).
        element: String,
        /// Property name.
        property: String,
        /// Element index.
        index: usize,
        /// What is wrong.
        message: String,
    },
    /// Required data is absent or inconsistent.
    #[error("PLY: {0}")]
    Content(String),
    /// The file cannot be read.
    #[error("PLY: cannot read: {0}")]
    Read(#[source] std::io::Error),
}

/// Error returned by a [`crate::SceneSink`] to abort the parse.
#[derive(Debug, thiserror::Error)]
#[error("scene sink: {0}")]
pub struct SinkError(#[source] pub Box<dyn std::error::Error + Send + Sync>);

impl SinkError {
    /// Wrap any error.
    pub fn new(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> Self {
        SinkError(e.into())
    }
}

/// A syntax or semantic error: file, line, column, offending token, and what is wrong.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{loc}: {kind} (at `{token}`)")]
pub struct ParseError {
    /// Where.
    pub loc: Location,
    /// The offending token text.
    pub token: String,
    /// What.
    pub kind: ParseErrorKind,
}

/// Everything that can stop a parse.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Syntax or semantic error at a position.
    #[error(transparent)]
    Parse(Box<ParseError>),
    /// Referenced files (Include/Import/PLY) that do not exist; all of them are listed.
    #[error("{} missing file(s): {}", files.len(), list_missing(files))]
    MissingFiles {
        /// Every missing file with the place it was referenced.
        files: Vec<MissingFile>,
    },
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
    /// A PLY file is malformed.
    #[error("{path} (referenced at {referenced_at}): {source}")]
    Ply {
        /// The PLY file.
        path: PathBuf,
        /// The `Shape "plymesh"` that named it.
        referenced_at: Box<Location>,
        /// Cause.
        #[source]
        source: Box<PlyError>,
    },
    /// A JSON file of Moana's base package is malformed or holds a value it cannot.
    #[error("{}: byte {offset} {message}", path.display())]
    Json {
        /// The JSON file.
        path: PathBuf,
        /// Byte offset of the fault.
        offset: u64,
        /// Line and column, and what is wrong.
        message: String,
    },
    /// An OBJ file is malformed.
    #[error("{}:{line}: {message}", path.display())]
    Obj {
        /// The OBJ file.
        path: PathBuf,
        /// 1-based line.
        line: u32,
        /// What is wrong.
        message: String,
    },
    /// The sink asked to stop.
    #[error(transparent)]
    Sink(#[from] SinkError),
}

fn list_missing(files: &[MissingFile]) -> String {
    let mut s = String::new();
    for (i, m) in files.iter().enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        if i == 20 {
            s.push_str(&format!("... and {} more", files.len() - 20));
            break;
        }
        s.push_str(&format!("{} (from {})", m.path.display(), m.referenced_at));
    }
    s
}
