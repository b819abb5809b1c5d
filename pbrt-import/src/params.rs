//! Parameter lists: `"type name" value` / `"type name" [ values ]`.

use std::borrow::Cow;

use crate::lexer::{LexError, Lexer, Loc, Token, TokenKind};

/// Every parameter type of pbrt-v3 and pbrt-v4.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamType {
    /// `integer`
    Integer,
    /// `float`
    Float,
    /// `bool`
    Bool,
    /// `string`
    String,
    /// `texture` (a named texture reference)
    Texture,
    /// `point2`
    Point2,
    /// `point3`, or v3 `point`
    Point3,
    /// `vector2`
    Vector2,
    /// `vector3`, or v3 `vector`
    Vector3,
    /// `normal3`, or `normal`
    Normal3,
    /// `rgb`, or v3 `color`
    Rgb,
    /// `xyz`
    Xyz,
    /// `blackbody` (v3: temperature/scale pairs; v4: one temperature)
    Blackbody,
    /// `spectrum` (wavelength/value pairs, a file name or a named spectrum)
    Spectrum,
}

impl ParamType {
    /// Parse a type name; also reports whether the spelling is pbrt-v4 only.
    pub fn from_name(s: &str) -> Option<(ParamType, bool)> {
        Some(match s {
            "integer" => (ParamType::Integer, false),
            "float" => (ParamType::Float, false),
            "bool" => (ParamType::Bool, false),
            "string" => (ParamType::String, false),
            "texture" => (ParamType::Texture, false),
            "point2" => (ParamType::Point2, true),
            "point3" => (ParamType::Point3, true),
            "point" => (ParamType::Point3, false),
            "vector2" => (ParamType::Vector2, true),
            "vector3" => (ParamType::Vector3, true),
            "vector" => (ParamType::Vector3, false),
            "normal3" => (ParamType::Normal3, true),
            "normal" => (ParamType::Normal3, false),
            "rgb" => (ParamType::Rgb, false),
            "color" => (ParamType::Rgb, false),
            "xyz" => (ParamType::Xyz, false),
            "blackbody" => (ParamType::Blackbody, false),
            "spectrum" => (ParamType::Spectrum, false),
            _ => return None,
        })
    }

    /// Canonical (pbrt-v4) spelling.
    pub fn name(self) -> &'static str {
        match self {
            ParamType::Integer => "integer",
            ParamType::Float => "float",
            ParamType::Bool => "bool",
            ParamType::String => "string",
            ParamType::Texture => "texture",
            ParamType::Point2 => "point2",
            ParamType::Point3 => "point3",
            ParamType::Vector2 => "vector2",
            ParamType::Vector3 => "vector3",
            ParamType::Normal3 => "normal3",
            ParamType::Rgb => "rgb",
            ParamType::Xyz => "xyz",
            ParamType::Blackbody => "blackbody",
            ParamType::Spectrum => "spectrum",
        }
    }

    /// Numbers per element (values count must be a multiple).
    fn arity(self) -> usize {
        match self {
            ParamType::Point2 | ParamType::Vector2 => 2,
            ParamType::Point3
            | ParamType::Vector3
            | ParamType::Normal3
            | ParamType::Rgb
            | ParamType::Xyz => 3,
            _ => 1,
        }
    }
}

/// Parsed values of one parameter.
#[derive(Clone, Debug, PartialEq)]
pub enum Values<'a> {
    /// Floating-point values (all numeric types except `integer`).
    Nums(Vec<f32>),
    /// `integer` values.
    Ints(Vec<i32>),
    /// `bool` values.
    Bools(Vec<bool>),
    /// `string`, `texture` and string-valued `spectrum` values.
    Strs(Vec<Cow<'a, str>>),
}

/// One parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct Param<'a> {
    /// Declared type.
    pub ty: ParamType,
    /// Parameter name.
    pub name: &'a str,
    /// Values.
    pub values: Values<'a>,
    /// Position of the `"type name"` string.
    pub loc: Loc,
}

/// Problems while reading a parameter list.
#[derive(Debug)]
pub(crate) enum ParamError<'a> {
    Lex(LexError),
    /// Bad declaration or values at `token`.
    Bad(Token<'a>, String),
}

impl From<LexError> for ParamError<'_> {
    fn from(e: LexError) -> Self {
        ParamError::Lex(e)
    }
}

/// A directive's parameters, in file order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParamList<'a> {
    /// Parameters in the order written.
    pub params: Vec<Param<'a>>,
    /// Some type was spelled the pbrt-v4 way (`point3`, `normal3`, ...): a version hint.
    pub v4_spelling: bool,
}

impl<'a> ParamList<'a> {
    /// Read parameters until the next token is not a string (usually the next directive).
    pub(crate) fn parse(lx: &mut Lexer<'a>) -> Result<ParamList<'a>, ParamError<'a>> {
        let mut params = Vec::new();
        let mut v4_spelling = false;
        while lx.peek_byte() == Some(b'"') {
            let Some(decl) = lx.next_token()? else { break };
            let text = std::str::from_utf8(decl.bytes)
                .map_err(|_| ParamError::Bad(decl, "not UTF-8".into()))?;
            let mut words = text.split_ascii_whitespace();
            let (Some(ty_name), Some(name), None) = (words.next(), words.next(), words.next())
            else {
                return Err(ParamError::Bad(decl, "expected \"type name\"".into()));
            };
            let Some((ty, v4)) = ParamType::from_name(ty_name) else {
                return Err(ParamError::Bad(
                    decl,
                    format!("unknown parameter type `{ty_name}`"),
                ));
            };
            v4_spelling |= v4;
            let values = parse_values(lx, ty, decl)?;
            params.push(Param {
                ty,
                name,
                values,
                loc: decl.loc,
            });
        }
        Ok(ParamList {
            params,
            v4_spelling,
        })
    }

    /// Find a parameter by name.
    pub fn get(&self, name: &str) -> Option<&Param<'a>> {
        self.params.iter().find(|p| p.name == name)
    }

    /// Remove and return a parameter (used to move large arrays out without copying).
    pub fn take(&mut self, name: &str) -> Option<Param<'a>> {
        let i = self.params.iter().position(|p| p.name == name)?;
        Some(self.params.swap_remove(i))
    }

    /// Numbers of a float-like parameter.
    pub fn nums(&self, name: &str) -> Option<&[f32]> {
        match &self.get(name)?.values {
            Values::Nums(v) => Some(v),
            _ => None,
        }
    }

    /// First value of a `float` parameter.
    pub fn float(&self, name: &str) -> Option<f32> {
        let p = self.get(name)?;
        match (&p.values, p.ty) {
            (Values::Nums(v), ParamType::Float) => v.first().copied(),
            (Values::Ints(v), _) => v.first().map(|&i| i as f32),
            _ => None,
        }
    }

    /// First value of an `integer` parameter.
    pub fn int(&self, name: &str) -> Option<i32> {
        match &self.get(name)?.values {
            Values::Ints(v) => v.first().copied(),
            _ => None,
        }
    }

    /// First value of a `bool` parameter.
    pub fn bool(&self, name: &str) -> Option<bool> {
        match &self.get(name)?.values {
            Values::Bools(v) => v.first().copied(),
            _ => None,
        }
    }

    /// First value of a `string` parameter.
    pub fn string(&self, name: &str) -> Option<&str> {
        let p = self.get(name)?;
        match (&p.values, p.ty) {
            (Values::Strs(v), ParamType::String) => v.first().map(|s| s.as_ref()),
            _ => None,
        }
    }

    /// First value of a `texture` parameter.
    pub fn texture(&self, name: &str) -> Option<&str> {
        let p = self.get(name)?;
        match (&p.values, p.ty) {
            (Values::Strs(v), ParamType::Texture) => v.first().map(|s| s.as_ref()),
            _ => None,
        }
    }
}

fn parse_values<'a>(
    lx: &mut Lexer<'a>,
    ty: ParamType,
    decl: Token<'a>,
) -> Result<Values<'a>, ParamError<'a>> {
    let bracketed = lx.peek_byte() == Some(b'[');
    if bracketed {
        lx.next_token()?;
    }
    let values = match ty {
        ParamType::Integer => {
            let mut v = Vec::new();
            if bracketed {
                lx.read_i32_array(&mut v)?;
            } else {
                let t = single(lx, decl)?;
                v.push(int_of(&t)?);
            }
            Values::Ints(v)
        }
        ParamType::String | ParamType::Texture => Values::Strs(read_strings(lx, bracketed, decl)?),
        ParamType::Bool => {
            let mut out = Vec::new();
            loop {
                let t = if bracketed {
                    lx.next_token()?
                } else {
                    Some(single(lx, decl)?)
                };
                let Some(t) = t else {
                    return Err(ParamError::Bad(decl, "unterminated array".into()));
                };
                if t.kind == TokenKind::Close && bracketed {
                    break;
                }
                match (t.kind, t.bytes) {
                    (TokenKind::Word | TokenKind::String, b"true") => out.push(true),
                    (TokenKind::Word | TokenKind::String, b"false") => out.push(false),
                    _ => return Err(ParamError::Bad(t, "expected true or false".into())),
                }
                if !bracketed {
                    break;
                }
            }
            Values::Bools(out)
        }
        ParamType::Spectrum if lx.peek_byte() == Some(b'"') => {
            Values::Strs(read_strings(lx, bracketed, decl)?)
        }
        _ => {
            let mut v = Vec::new();
            if bracketed {
                lx.read_f32_array(&mut v)?;
            } else {
                let t = single(lx, decl)?;
                match t.as_f64() {
                    Some(f) => v.push(f as f32),
                    None => {
                        return Err(ParamError::Bad(
                            t,
                            format!("expected a number for `{}`", ty.name()),
                        ))
                    }
                }
            }
            if v.len() % ty.arity() != 0 {
                return Err(ParamError::Bad(
                    decl,
                    format!(
                        "{} values for `{}`, not a multiple of {}",
                        v.len(),
                        ty.name(),
                        ty.arity()
                    ),
                ));
            }
            Values::Nums(v)
        }
    };
    Ok(values)
}

fn single<'a>(lx: &mut Lexer<'a>, decl: Token<'a>) -> Result<Token<'a>, ParamError<'a>> {
    match lx.next_token()? {
        Some(t) if matches!(t.kind, TokenKind::Word | TokenKind::String) => Ok(t),
        Some(t) => Err(ParamError::Bad(t, "expected a value".into())),
        None => Err(ParamError::Bad(decl, "missing value".into())),
    }
}

fn int_of<'a>(t: &Token<'a>) -> Result<i32, ParamError<'a>> {
    match t.as_f64() {
        Some(f) if f.fract() == 0.0 && f >= f64::from(i32::MIN) && f <= f64::from(i32::MAX) => {
            Ok(f as i32)
        }
        _ => Err(ParamError::Bad(*t, "expected an integer".into())),
    }
}

fn read_strings<'a>(
    lx: &mut Lexer<'a>,
    bracketed: bool,
    decl: Token<'a>,
) -> Result<Vec<Cow<'a, str>>, ParamError<'a>> {
    let mut out = Vec::new();
    loop {
        let t = if bracketed {
            lx.next_token()?
        } else {
            Some(single(lx, decl)?)
        };
        let Some(t) = t else {
            return Err(ParamError::Bad(decl, "unterminated array".into()));
        };
        match t.kind {
            TokenKind::Close if bracketed => break,
            TokenKind::String => match t.unescaped() {
                Some(s) => out.push(s),
                None => return Err(ParamError::Bad(t, "string is not UTF-8".into())),
            },
            _ => return Err(ParamError::Bad(t, "expected a quoted string".into())),
        }
        if !bracketed {
            break;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
