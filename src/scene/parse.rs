//! The scene text parser: one pure function per line (`parse_line`), folded
//! into a [`Scene`] by [`SceneBuilder`], which checks what spans lines
//! (duplicates, required directives, extents, dialect consistency).

use super::{Camera, Dialect, Light, Material, Scene, SceneError, SceneErrorKind, Sphere};
use crate::limits;
use glam::DVec3;

/// Parses a scene in either dialect. Never panics, whatever the bytes.
pub fn parse(text: impl AsRef<[u8]>) -> Result<Scene, SceneError> {
    let mut builder = SceneBuilder::default();
    let mut line_count = 0;
    for (i, line) in split_lines(text.as_ref()).enumerate() {
        line_count = i + 1;
        let directive = parse_line(i + 1, line).map_err(|e| builder.explain(i + 1, line, e))?;
        builder.apply(i + 1, directive)?;
    }
    builder.finish(line_count.max(1))
}

/// The lines of `text`, without their LF or CRLF endings.
fn split_lines(text: &[u8]) -> impl Iterator<Item = &[u8]> {
    let text = text.strip_suffix(b"\n").unwrap_or(text);
    let mut lines = text.split(|&b| b == b'\n');
    // An empty input has no lines at all rather than one empty line.
    let mut first = !text.is_empty();
    std::iter::from_fn(move || {
        if !first {
            return None;
        }
        match lines.next() {
            Some(l) => Some(l.strip_suffix(b"\r").unwrap_or(l)),
            None => {
                first = false;
                None
            }
        }
    })
}

/// What one line says.
#[derive(Debug)]
enum Directive {
    Blank,
    /// NEAR, LEFT, RIGHT, BOTTOM, TOP: a keyword and its value, with the value's column.
    Extent(Keyword, f64, usize),
    Resolution(u32, u32),
    Background(DVec3),
    Ambient(DVec3),
    Output(String),
    Sphere(Sphere, Dialect),
    Light(Light, Dialect),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Keyword {
    Near,
    Left,
    Right,
    Bottom,
    Top,
    Res,
    Sphere,
    Light,
    Back,
    Ambient,
    Output,
}

impl Keyword {
    const ALL: [Keyword; 11] = [
        Keyword::Near,
        Keyword::Left,
        Keyword::Right,
        Keyword::Bottom,
        Keyword::Top,
        Keyword::Res,
        Keyword::Sphere,
        Keyword::Light,
        Keyword::Back,
        Keyword::Ambient,
        Keyword::Output,
    ];

    fn name(self) -> &'static str {
        match self {
            Keyword::Near => "NEAR",
            Keyword::Left => "LEFT",
            Keyword::Right => "RIGHT",
            Keyword::Bottom => "BOTTOM",
            Keyword::Top => "TOP",
            Keyword::Res => "RES",
            Keyword::Sphere => "SPHERE",
            Keyword::Light => "LIGHT",
            Keyword::Back => "BACK",
            Keyword::Ambient => "AMBIENT",
            Keyword::Output => "OUTPUT",
        }
    }

    fn from_token(token: &[u8]) -> Option<Keyword> {
        Keyword::ALL
            .into_iter()
            .find(|k| k.name().as_bytes().eq_ignore_ascii_case(token))
    }
}

const CLASSIC_SPHERE_FIELDS: [&str; 16] = [
    "<pos x>",
    "<pos y>",
    "<pos z>",
    "<scl x>",
    "<scl y>",
    "<scl z>",
    "<r>",
    "<g>",
    "<b>",
    "<Ka>",
    "<Kd>",
    "<Ks>",
    "<Kr>",
    "<n>",
    "<Krefract>",
    "<ior>",
];
const BROWSER_SPHERE_FIELDS: [&str; 16] = [
    "<x>",
    "<y>",
    "<z>",
    "<sx>",
    "<sy>",
    "<sz>",
    "<r>",
    "<g>",
    "<b>",
    "<k_a>",
    "<k_d>",
    "<k_s>",
    "<n>",
    "<k_r>",
    "<k_refract>",
    "<refract_index>",
];
const LIGHT_FIELDS: [&str; 6] = ["<pos x>", "<pos y>", "<pos z>", "<Ir>", "<Ig>", "<Ib>"];

/// Reads the tokens of one line, remembering where each starts.
struct Tokens<'a> {
    line: &'a [u8],
    number: usize,
    pos: usize,
}

impl<'a> Tokens<'a> {
    fn new(number: usize, line: &'a [u8]) -> Self {
        // `#` comments run to the end of the line.
        let line = match line.iter().position(|&b| b == b'#') {
            Some(hash) => &line[..hash],
            None => line,
        };
        Tokens {
            line,
            number,
            pos: 0,
        }
    }

    fn skip_blanks(&mut self) {
        while self.pos < self.line.len() && matches!(self.line[self.pos], b' ' | b'\t') {
            self.pos += 1;
        }
    }

    /// The next token and its byte offset.
    fn next(&mut self) -> Option<(usize, &'a [u8])> {
        self.skip_blanks();
        let start = self.pos;
        while self.pos < self.line.len() && !matches!(self.line[self.pos], b' ' | b'\t') {
            self.pos += 1;
        }
        (self.pos > start).then(|| (start, &self.line[start..self.pos]))
    }

    fn peek(&mut self) -> Option<&'a [u8]> {
        let saved = self.pos;
        let token = self.next().map(|(_, t)| t);
        self.pos = saved;
        token
    }

    /// The rest of the line after the blanks that follow the keyword, trimmed.
    fn rest(&mut self) -> (usize, &'a [u8]) {
        self.skip_blanks();
        let start = self.pos;
        let mut rest = &self.line[start..];
        while let [head @ .., b' ' | b'\t'] = rest {
            rest = head;
        }
        self.pos = self.line.len();
        (start, rest)
    }

    /// The 1-based character column of byte offset `offset`.
    fn column(&self, offset: usize) -> usize {
        String::from_utf8_lossy(&self.line[..offset.min(self.line.len())])
            .chars()
            .count()
            + 1
    }

    /// An error located at byte offset `offset` of this line.
    fn error_at(&self, offset: usize, kind: SceneErrorKind) -> SceneError {
        SceneError {
            line: self.number,
            column: self.column(offset),
            kind,
        }
    }

    fn number(&mut self, field: &'static str) -> Result<(f64, usize), SceneError> {
        let Some((offset, token)) = self.next() else {
            let end = self.line.len();
            return Err(self.error_at(end, SceneErrorKind::MissingField { field }));
        };
        let found = || {
            String::from_utf8_lossy(token)
                .chars()
                .take(40)
                .collect::<String>()
        };
        let value: f64 = std::str::from_utf8(token)
            .ok()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| {
                self.error_at(
                    offset,
                    SceneErrorKind::ExpectedNumber {
                        field,
                        found: found(),
                    },
                )
            })?;
        if !value.is_finite() {
            return Err(self.error_at(
                offset,
                SceneErrorKind::NotFinite {
                    field,
                    found: found(),
                },
            ));
        }
        Ok((value, offset))
    }

    /// A number that must satisfy `ok`, which `rule` describes.
    fn checked(
        &mut self,
        field: &'static str,
        ok: fn(f64) -> bool,
        rule: &'static str,
    ) -> Result<f64, SceneError> {
        let (value, offset) = self.number(field)?;
        if ok(value) {
            Ok(value)
        } else {
            Err(self.error_at(offset, SceneErrorKind::OutOfRange { field, value, rule }))
        }
    }

    fn any(&mut self, field: &'static str) -> Result<f64, SceneError> {
        self.number(field).map(|(v, _)| v)
    }

    fn non_negative(&mut self, field: &'static str) -> Result<f64, SceneError> {
        self.checked(field, |v| v >= 0.0, "≥ 0")
    }

    fn vector(
        &mut self,
        fields: &[&'static str],
        check: fn(&mut Self, &'static str) -> Result<f64, SceneError>,
    ) -> Result<DVec3, SceneError> {
        Ok(DVec3::new(
            check(self, fields[0])?,
            check(self, fields[1])?,
            check(self, fields[2])?,
        ))
    }

    fn end(&mut self) -> Result<(), SceneError> {
        match self.next() {
            None => Ok(()),
            Some((offset, token)) => {
                let found = String::from_utf8_lossy(token).chars().take(40).collect();
                Err(self.error_at(offset, SceneErrorKind::ExtraToken { found }))
            }
        }
    }
}

/// A token names a sphere or light unless it reads as a number (or starts like one).
fn looks_numeric(token: &[u8]) -> bool {
    matches!(token.first(), Some(b'0'..=b'9' | b'+' | b'-' | b'.'))
        || std::str::from_utf8(token).is_ok_and(|s| s.parse::<f64>().is_ok())
}

fn parse_line(number: usize, line: &[u8]) -> Result<Directive, SceneError> {
    let mut tokens = Tokens::new(number, line);
    let Some((offset, word)) = tokens.next() else {
        return Ok(Directive::Blank);
    };
    let Some(keyword) = Keyword::from_token(word) else {
        let found = String::from_utf8_lossy(word).chars().take(40).collect();
        return Err(tokens.error_at(offset, SceneErrorKind::UnknownKeyword { found }));
    };
    let directive = match keyword {
        Keyword::Near => {
            let (value, offset) = tokens.number("<n>")?;
            if value <= 0.0 {
                let kind = SceneErrorKind::OutOfRange {
                    field: "NEAR",
                    value,
                    rule: "> 0",
                };
                return Err(tokens.error_at(offset, kind));
            }
            Directive::Extent(keyword, value, tokens.column(offset))
        }
        Keyword::Left | Keyword::Right | Keyword::Bottom | Keyword::Top => {
            let (value, offset) = tokens.number(extent_field(keyword))?;
            Directive::Extent(keyword, value, tokens.column(offset))
        }
        Keyword::Res => Directive::Resolution(
            resolution(&mut tokens, "<x>")?,
            resolution(&mut tokens, "<y>")?,
        ),
        Keyword::Back => {
            Directive::Background(tokens.vector(&["<r>", "<g>", "<b>"], Tokens::non_negative)?)
        }
        Keyword::Ambient => {
            Directive::Ambient(tokens.vector(&["<Ir>", "<Ig>", "<Ib>"], Tokens::non_negative)?)
        }
        Keyword::Output => {
            let (offset, name) = tokens.rest();
            match std::str::from_utf8(name) {
                Ok(name) if !name.is_empty() => Directive::Output(name.to_owned()),
                _ => return Err(tokens.error_at(offset, SceneErrorKind::BadOutputName)),
            }
        }
        Keyword::Sphere => {
            let (sphere, dialect) = sphere(&mut tokens)?;
            Directive::Sphere(sphere, dialect)
        }
        Keyword::Light => {
            let dialect = named_dialect(&mut tokens);
            let position = tokens.vector(&LIGHT_FIELDS[..3], Tokens::any)?;
            let intensity = tokens.vector(&LIGHT_FIELDS[3..], Tokens::non_negative)?;
            Directive::Light(
                Light {
                    position,
                    intensity,
                },
                dialect,
            )
        }
    };
    tokens.end()?;
    Ok(directive)
}

fn extent_field(keyword: Keyword) -> &'static str {
    match keyword {
        Keyword::Left => "<l>",
        Keyword::Right => "<r>",
        Keyword::Bottom => "<b>",
        _ => "<t>",
    }
}

/// Consumes the name of a classic SPHERE/LIGHT line, if there is one, and tells the dialect.
fn named_dialect(tokens: &mut Tokens) -> Dialect {
    match tokens.peek() {
        Some(token) if !looks_numeric(token) => {
            tokens.next();
            Dialect::Classic
        }
        _ => Dialect::Browser,
    }
}

fn resolution(tokens: &mut Tokens, field: &'static str) -> Result<u32, SceneError> {
    let (value, offset) = tokens.number(field)?;
    if value.fract() != 0.0 {
        let found = format!("{value}");
        return Err(tokens.error_at(offset, SceneErrorKind::NotWhole { field, found }));
    }
    if value < 1.0 || value > f64::from(limits::MAX_RESOLUTION) {
        let rule = "between 1 and 16384";
        return Err(tokens.error_at(offset, SceneErrorKind::OutOfRange { field, value, rule }));
    }
    Ok(value as u32)
}

fn sphere(tokens: &mut Tokens) -> Result<(Sphere, Dialect), SceneError> {
    let dialect = named_dialect(tokens);
    let fields = match dialect {
        Dialect::Classic => &CLASSIC_SPHERE_FIELDS,
        Dialect::Browser => &BROWSER_SPHERE_FIELDS,
    };
    let center = tokens.vector(&fields[0..3], Tokens::any)?;
    let scale = tokens.vector(&fields[3..6], |t, field| {
        t.checked(field, |v| v != 0.0, "non-zero")
    })?;
    let color = tokens.vector(&fields[6..9], Tokens::non_negative)?;
    let ambient = tokens.non_negative(fields[9])?;
    let diffuse = tokens.non_negative(fields[10])?;
    let specular = tokens.non_negative(fields[11])?;
    let (reflect, shininess) = match dialect {
        Dialect::Classic => (
            tokens.non_negative(fields[12])?,
            tokens.non_negative(fields[13])?,
        ),
        Dialect::Browser => {
            let shininess = tokens.non_negative(fields[12])?;
            (tokens.non_negative(fields[13])?, shininess)
        }
    };
    // The classic dialect's refraction pair is optional; the browser's is not.
    let (refract, ior) = if dialect == Dialect::Classic && tokens.peek().is_none() {
        (0.0, 1.0)
    } else {
        let refract = tokens.non_negative(fields[14])?;
        (refract, tokens.checked(fields[15], |v| v > 0.0, "> 0")?)
    };
    let material = Material {
        color,
        ambient,
        diffuse,
        specular,
        reflect,
        shininess,
        refract,
        ior,
    };
    Ok((
        Sphere {
            center,
            scale,
            material,
        },
        dialect,
    ))
}

/// A singleton directive's value and the line that gave it.
type Given<T> = Option<(T, usize)>;

#[derive(Default)]
struct SceneBuilder {
    near: Given<f64>,
    left: Given<(f64, usize)>,
    right: Given<(f64, usize)>,
    bottom: Given<(f64, usize)>,
    top: Given<(f64, usize)>,
    resolution: Given<(u32, u32)>,
    background: Given<DVec3>,
    ambient: Given<DVec3>,
    output: Given<String>,
    dialect: Given<Dialect>,
    spheres: Vec<Sphere>,
    lights: Vec<Light>,
}

/// Stores a singleton's value, or reports the line that gave it first.
fn set_once<T>(
    slot: &mut Given<T>,
    value: T,
    line: usize,
    keyword: Keyword,
) -> Result<(), SceneError> {
    if let Some((_, first_line)) = slot {
        let kind = SceneErrorKind::Duplicate {
            keyword: keyword.name(),
            first_line: *first_line,
        };
        return Err(SceneError {
            line,
            column: 1,
            kind,
        });
    }
    *slot = Some((value, line));
    Ok(())
}

impl SceneBuilder {
    fn apply(&mut self, line: usize, directive: Directive) -> Result<(), SceneError> {
        match directive {
            Directive::Blank => Ok(()),
            Directive::Extent(keyword, value, column) => {
                let slot = match keyword {
                    Keyword::Near => return set_once(&mut self.near, value, line, keyword),
                    Keyword::Left => &mut self.left,
                    Keyword::Right => &mut self.right,
                    Keyword::Bottom => &mut self.bottom,
                    _ => &mut self.top,
                };
                set_once(slot, (value, column), line, keyword)
            }
            Directive::Resolution(w, h) => {
                set_once(&mut self.resolution, (w, h), line, Keyword::Res)
            }
            Directive::Background(c) => set_once(&mut self.background, c, line, Keyword::Back),
            Directive::Ambient(c) => set_once(&mut self.ambient, c, line, Keyword::Ambient),
            Directive::Output(name) => set_once(&mut self.output, name, line, Keyword::Output),
            Directive::Sphere(sphere, dialect) => {
                self.check_dialect(line, dialect)?;
                check_count(line, self.spheres.len(), limits::MAX_SPHERES, "spheres")?;
                self.spheres.push(sphere);
                Ok(())
            }
            Directive::Light(light, dialect) => {
                self.check_dialect(line, dialect)?;
                check_count(line, self.lights.len(), limits::MAX_LIGHTS, "lights")?;
                self.lights.push(light);
                Ok(())
            }
        }
    }

    /// A line in the other dialect fails on its field count; saying so is
    /// more useful than naming the missing field.
    fn explain(&self, line_number: usize, line: &[u8], error: SceneError) -> SceneError {
        let mut tokens = Tokens::new(line_number, line);
        let is_object = tokens
            .next()
            .and_then(|(_, word)| Keyword::from_token(word))
            .is_some_and(|k| matches!(k, Keyword::Sphere | Keyword::Light));
        match self.dialect {
            Some((first, first_line)) if is_object && named_dialect(&mut tokens) != first => {
                SceneError {
                    line: line_number,
                    column: 1,
                    kind: SceneErrorKind::MixedDialects { first_line },
                }
            }
            _ => error,
        }
    }

    fn check_dialect(&mut self, line: usize, dialect: Dialect) -> Result<(), SceneError> {
        match self.dialect {
            None => self.dialect = Some((dialect, line)),
            Some((first, first_line)) if first != dialect => {
                let kind = SceneErrorKind::MixedDialects { first_line };
                return Err(SceneError {
                    line,
                    column: 1,
                    kind,
                });
            }
            Some(_) => {}
        }
        Ok(())
    }

    fn finish(self, last_line: usize) -> Result<Scene, SceneError> {
        let missing = |keyword: Keyword| SceneError {
            line: last_line,
            column: 1,
            kind: SceneErrorKind::MissingDirective {
                keyword: keyword.name(),
            },
        };
        let (near, _) = self.near.ok_or_else(|| missing(Keyword::Near))?;
        let left = self.left.ok_or_else(|| missing(Keyword::Left))?;
        let right = self.right.ok_or_else(|| missing(Keyword::Right))?;
        let bottom = self.bottom.ok_or_else(|| missing(Keyword::Bottom))?;
        let top = self.top.ok_or_else(|| missing(Keyword::Top))?;
        let ((width, height), _) = self.resolution.ok_or_else(|| missing(Keyword::Res))?;
        check_extent((Keyword::Left, left), (Keyword::Right, right))?;
        check_extent((Keyword::Bottom, bottom), (Keyword::Top, top))?;
        // A file with an OUTPUT line is classic even if it has no SPHERE or LIGHT line.
        let dialect = self.dialect.map_or(Dialect::Classic, |(d, _)| d);
        Ok(Scene {
            dialect,
            camera: Camera {
                near,
                left: left.0 .0,
                right: right.0 .0,
                bottom: bottom.0 .0,
                top: top.0 .0,
                width,
                height,
            },
            spheres: self.spheres,
            lights: self.lights,
            background: self.background.map_or(DVec3::ZERO, |(c, _)| c),
            ambient: self.ambient.map_or(DVec3::ZERO, |(c, _)| c),
            output: self.output.map(|(name, _)| name),
        })
    }
}

fn check_count(
    line: usize,
    count: usize,
    limit: usize,
    what: &'static str,
) -> Result<(), SceneError> {
    if count >= limit {
        return Err(SceneError {
            line,
            column: 1,
            kind: SceneErrorKind::TooMany { what, limit },
        });
    }
    Ok(())
}

/// Checks low < high, blaming whichever of the two lines came later.
fn check_extent(
    (low_kw, ((low, low_col), low_line)): (Keyword, ((f64, usize), usize)),
    (high_kw, ((high, high_col), high_line)): (Keyword, ((f64, usize), usize)),
) -> Result<(), SceneError> {
    if low < high {
        return Ok(());
    }
    let (line, column) = if high_line >= low_line {
        (high_line, high_col)
    } else {
        (low_line, low_col)
    };
    let kind = SceneErrorKind::EmptyExtent {
        low: low_kw.name(),
        high: high_kw.name(),
        low_value: low,
        high_value: high,
    };
    Err(SceneError { line, column, kind })
}
