//! Reading a directive's arguments (strings, numbers, parameter lists) and reporting errors
//! and warnings at their file:line:column.

use super::*;

impl<'s> Parser<'s> {
    pub(super) fn location(&self, loc: Loc) -> Location {
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

    pub(super) fn err(&self, tok: &Token<'_>, kind: ParseErrorKind) -> Error {
        Error::Parse(Box::new(ParseError {
            loc: self.location(tok.loc),
            token: tok.display(),
            kind,
        }))
    }

    pub(super) fn err_at(&self, loc: Loc, token: &str, kind: ParseErrorKind) -> Error {
        Error::Parse(Box::new(ParseError {
            loc: self.location(loc),
            token: token.to_owned(),
            kind,
        }))
    }

    pub(super) fn lex_err(&self, e: LexError) -> Error {
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

    pub(super) fn warn(&mut self, loc: Option<Loc>, message: String) {
        self.stats.warnings += 1;
        match loc {
            Some(l) => tracing::warn!("{}: {message}", self.location(l)),
            None => tracing::warn!("{message}"),
        }
        self.sink.warning(&Warning { loc, message });
    }

    /// Warn once per `key` (repeated constructs in huge scenes).
    pub(super) fn warn_once(&mut self, key: &str, loc: Option<Loc>, message: String) {
        if self.warned.insert(key.to_owned()) {
            self.warn(loc, message);
        }
    }

    pub(super) fn missing_file(&mut self, path: PathBuf, loc: Loc) {
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

    pub(super) fn next<'b>(
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

    pub(super) fn string<'b>(
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
    pub(super) fn numbers<'b, const N: usize>(
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
    pub(super) fn require_finite(&self, directive: &str, p: &ParamList<'_>) -> Result<()> {
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

    pub(super) fn params<'b>(&mut self, lx: &mut Lexer<'b>) -> Result<ParamList<'b>> {
        let p = ParamList::parse(lx).map_err(|e| self.param_err(e))?;
        if p.v4_spelling {
            self.hint_v4("v4 parameter type");
        }
        Ok(p)
    }

    // ---- files ------------------------------------------------------------------------

    pub(super) fn resolve(&self, name: &str) -> PathBuf {
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
}
