//! The scene text parser: one pure function per line (`parse_line`), folded
//! into a [`Scene`] by [`SceneBuilder`], which checks what spans lines
//! (duplicates, required directives, extents, dialect consistency, and the
//! scene-wide bounds of `scene::bounds`).

use super::bounds::{self, Extremes, Located};
use super::decimal::{fast_decimal, scan_decimal};
use super::error::Length;
use super::lines::{check_line, column_of, split_chunks, split_lines};
use super::{Camera, Dialect, Light, Material, Scene, SceneError, SceneErrorKind, Sphere};
use crate::limits;
use glam::DVec3;
use rayon::prelude::*;

/// Parses a scene in either dialect. Never panics, whatever the bytes.
pub fn parse(text: impl AsRef<[u8]>) -> Result<Scene, SceneError> {
    let mut parser = Parser::new();
    parser.feed(text.as_ref())?;
    parser.finish()
}

/// A scene parsed piece by piece as its text arrives (see `scene::read`),
/// with the same result as [`parse`] on the whole text.
///
/// Each piece is cut at line ends into chunks whose lines are parsed in
/// parallel (each line on its own, by [`parse_line`]); the directives are then
/// folded in file order by one [`SceneBuilder`], so the first error in the
/// file is the one reported, with its exact line and column, as if parsed
/// line by line.
pub(super) struct Parser {
    builder: SceneBuilder,
    /// The number of the next line, and how far into the text it starts.
    next_line: usize,
    offset: usize,
}

impl Parser {
    pub fn new() -> Self {
        Parser {
            builder: SceneBuilder::default(),
            next_line: 1,
            offset: 0,
        }
    }

    /// Parses `text`, the text that follows what was fed before. Every piece
    /// but the last must end with a newline.
    pub fn feed(&mut self, text: &[u8]) -> Result<(), SceneError> {
        let chunks = split_chunks(text);
        // Lines before each chunk, so every chunk knows its first line's number.
        let line_counts: Vec<usize> = chunks
            .par_iter()
            .map(|chunk| memchr::memchr_iter(b'\n', chunk).count())
            .collect();
        let starts: Vec<(usize, usize)> = chunks
            .iter()
            .zip(&line_counts)
            .scan((self.next_line, self.offset), |next, (chunk, &count)| {
                let first = *next;
                *next = (next.0 + count, next.1 + chunk.len());
                Some(first)
            })
            .collect();
        let mut parsed: Vec<ParsedChunk> = chunks
            .par_iter()
            .zip(starts.par_iter().zip(&line_counts))
            .map(|(chunk, (&(first, offset), &lines))| parse_chunk(chunk, first, offset, lines))
            .collect();
        for ((chunk, text), (&(first, _), &newlines)) in parsed
            .iter_mut()
            .zip(&chunks)
            .zip(starts.iter().zip(&line_counts))
        {
            let mut lines = chunk.sphere_lines.as_slice();
            for (line, folded) in chunk.directives.drain(..) {
                match folded {
                    Folded::One(directive) => self.builder.apply(line, directive)?,
                    Folded::Spheres(dialect, count) => {
                        let (run, rest) = lines.split_at(count);
                        self.builder.count_spheres(run, dialect)?;
                        lines = rest;
                    }
                }
            }
            if let Some(error) = chunk.error.take() {
                let line = split_lines(text)
                    .nth(error.line - first)
                    .unwrap_or_default();
                return Err(self.builder.explain(error.line, line, error));
            }
            self.builder.extremes.merge(&chunk.extremes);
            self.next_line = first + newlines;
        }
        self.builder.append_spheres(&parsed);
        self.offset += text.len();
        Ok(())
    }

    /// The number of the line the next text fed starts with.
    pub fn next_line(&self) -> usize {
        self.next_line
    }

    /// Checks the start of the next line, whose end has not come yet (see
    /// [`check_line`]): a text that never ends its line fails here.
    pub fn check_unfinished(&self, start: &[u8]) -> Result<(), SceneError> {
        check_line(self.next_line, self.offset, start)
    }

    pub fn finish(self) -> Result<Scene, SceneError> {
        self.builder.finish()
    }
}

/// The directives of one chunk up to its first error. Its sphere lines are
/// [`Folded::Spheres`] runs there, their spheres kept apart, so that
/// the fold, which runs on one thread, counts them a run at a time and the
/// scene takes them all at once, in parallel.
struct ParsedChunk {
    directives: Vec<(usize, Folded)>,
    /// The spheres of the chunk's runs, in line order, and their lines.
    spheres: Vec<Sphere>,
    sphere_lines: Vec<usize>,
    extremes: Extremes,
    error: Option<SceneError>,
}

impl ParsedChunk {
    /// Adds the sphere of line `number` to the chunk's last run, or starts
    /// a run if the directive before it was not a sphere of its dialect.
    fn add_sphere(&mut self, number: usize, sphere: Sphere, dialect: Dialect) {
        match self.directives.last_mut() {
            Some((_, Folded::Spheres(last, count))) if *last == dialect => *count += 1,
            _ => self.directives.push((number, Folded::Spheres(dialect, 1))),
        }
        self.spheres.push(sphere);
        self.sphere_lines.push(number);
    }
}

/// Parses the lines of a chunk whose first line is number `first` and
/// starts `offset` bytes into the text, and which ends `newlines` lines,
/// stopping at the first error.
fn parse_chunk(chunk: &[u8], first: usize, offset: usize, newlines: usize) -> ParsedChunk {
    // Nearly every line of a large scene is a sphere's.
    let mut parsed = ParsedChunk {
        directives: Vec::new(),
        spheres: Vec::with_capacity(newlines + 1),
        sphere_lines: Vec::with_capacity(newlines + 1),
        extremes: Extremes::default(),
        error: None,
    };
    for (i, line) in split_lines(chunk).enumerate() {
        let number = first + i;
        // Every line is a slice of the chunk.
        let start = offset + (line.as_ptr() as usize - chunk.as_ptr() as usize);
        let result = check_line(number, start, line)
            .and_then(|()| parse_line(number, line, &mut parsed.extremes));
        match result {
            Ok(Directive::Blank) => {}
            Ok(Directive::Sphere(sphere, dialect)) => parsed.add_sphere(number, sphere, dialect),
            Ok(directive) => parsed.directives.push((number, Folded::One(directive))),
            Err(error) => {
                parsed.error = Some(error);
                break;
            }
        }
    }
    parsed
}

/// Spheres one task of [`SceneBuilder::append_spheres`] copies at least.
const APPENDED_PER_TASK: usize = 1 << 12;

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

/// What a chunk hands the fold, line by line.
#[derive(Debug)]
enum Folded {
    /// A line's directive, other than a sphere.
    One(Directive),
    /// A run of this many sphere lines in a row (blank lines aside), all
    /// of one dialect, from this line on (see [`ParsedChunk`]).
    Spheres(Dialect, usize),
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

    /// The keyword `token` is most likely a misspelling of: the nearest by
    /// edit distance (a swap of two neighbours counts one, as in `BAKC`),
    /// if at most a third of its letters (and at least one) are off.
    fn nearest(token: &str) -> Option<Keyword> {
        let token = token.to_ascii_uppercase();
        let allowed = (token.chars().count() / 3).max(1);
        Keyword::ALL
            .into_iter()
            .map(|k| (strsim::osa_distance(&token, k.name()), k))
            .filter(|&(distance, _)| distance <= allowed)
            .min_by_key(|&(distance, _)| distance)
            .map(|(_, k)| k)
    }

    /// A line that gives this directive, for the message when it is missing.
    fn example(self) -> &'static str {
        match self {
            Keyword::Near => "NEAR 1",
            Keyword::Left => "LEFT -1",
            Keyword::Right => "RIGHT 1",
            Keyword::Bottom => "BOTTOM -1",
            Keyword::Top => "TOP 1",
            Keyword::Res => "RES 512 512",
            Keyword::Sphere => "SPHERE ball 0 0 -10 1 1 1 1 0 0 0.2 0.8 0.5 0 50",
            Keyword::Light => "LIGHT sun 0 10 0 1 1 1",
            Keyword::Back => "BACK 0 0 0",
            Keyword::Ambient => "AMBIENT 0.2 0.2 0.2",
            Keyword::Output => "OUTPUT image.png",
        }
    }
}

/// The sphere's fields in words, in the classic dialect's order (the
/// browser dialect swaps the exponent and the reflectivity, see [`sphere`]).
const SPHERE_FIELDS: [&str; 16] = [
    "the sphere's x position",
    "the sphere's y position",
    "the sphere's z position",
    "the sphere's x scale",
    "the sphere's y scale",
    "the sphere's z scale",
    "the sphere's red component",
    "the sphere's green component",
    "the sphere's blue component",
    "the sphere's ambient coefficient",
    "the sphere's diffuse coefficient",
    "the sphere's specular coefficient",
    "the sphere's reflectivity",
    "the sphere's specular exponent",
    "the sphere's refractivity",
    "the sphere's index of refraction",
];
const LIGHT_FIELDS: [&str; 6] = [
    "the light's x position",
    "the light's y position",
    "the light's z position",
    "the light's red intensity",
    "the light's green intensity",
    "the light's blue intensity",
];
const BACK_FIELDS: [&str; 3] = [
    "the background's red component",
    "the background's green component",
    "the background's blue component",
];
const AMBIENT_FIELDS: [&str; 3] = [
    "the ambient light's red intensity",
    "the ambient light's green intensity",
    "the ambient light's blue intensity",
];
/// NEAR's value, in words.
pub(super) const NEAR_FIELD: &str = "the distance to the image plane (NEAR)";

/// Reads the tokens of one line, remembering where each starts.
struct Tokens<'a> {
    line: &'a [u8],
    number: usize,
    pos: usize,
    /// The lengths read so far, this line's and those before it in its
    /// chunk: a length that is no new extreme costs two comparisons.
    extremes: &'a mut Extremes,
}

impl<'a> Tokens<'a> {
    fn new(number: usize, line: &'a [u8], extremes: &'a mut Extremes) -> Self {
        // `#` comments run to the end of the line.
        let line = match memchr::memchr(b'#', line) {
            Some(hash) => &line[..hash],
            None => line,
        };
        Tokens {
            line,
            number,
            pos: 0,
            extremes,
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
        column_of(self.line, offset)
    }

    /// Counts a length for the scene-wide bounds. Where it was given is
    /// worked out only when it is a new extreme.
    fn count(&mut self, field: &'static str, value: f64, offset: usize, scale: bool) {
        let Tokens {
            line,
            number,
            extremes,
            ..
        } = self;
        let at = || Located {
            length: Length {
                field,
                value,
                line: *number,
            },
            column: column_of(line, offset),
        };
        if scale {
            extremes.scale(value, at);
        } else {
            extremes.length(value, at);
        }
    }

    /// An error located at byte offset `offset` of this line.
    fn error_at(&self, offset: usize, kind: SceneErrorKind) -> SceneError {
        SceneError {
            line: self.number,
            column: self.column(offset),
            kind,
        }
    }

    /// The next token as a number, and its byte offset. Inlined, like the
    /// field readers built on it, so that a plain decimal costs no call and
    /// no large `Result` to move; the rest is [`Tokens::unusual_number`].
    #[inline(always)]
    fn number(&mut self, field: &'static str) -> Result<(f64, usize), SceneError> {
        self.skip_blanks();
        let start = self.pos;
        match scan_decimal(self.line, start) {
            Some((value, end)) => {
                self.pos = end;
                Ok((value, start))
            }
            None => self.unusual_number(field),
        }
    }

    /// [`Tokens::number`] for a token that is no plain decimal: an exponent,
    /// many digits, or no number at all.
    #[cold]
    #[inline(never)]
    fn unusual_number(&mut self, field: &'static str) -> Result<(f64, usize), SceneError> {
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
        let value: f64 = fast_decimal(token)
            .or_else(|| std::str::from_utf8(token).ok()?.parse().ok())
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
    #[inline(always)]
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

    #[inline(always)]
    fn non_negative(&mut self, field: &'static str) -> Result<f64, SceneError> {
        self.checked(field, |v| v >= 0.0, "≥ 0")
    }

    /// A coordinate or camera value, within what the renderer can represent.
    #[inline(always)]
    fn length(&mut self, field: &'static str) -> Result<f64, SceneError> {
        let (value, offset) = self.number(field)?;
        self.length_at(field, value, offset)?;
        Ok(value)
    }

    /// Checks and counts a length already read.
    #[inline(always)]
    fn length_at(
        &mut self,
        field: &'static str,
        value: f64,
        offset: usize,
    ) -> Result<(), SceneError> {
        bounds::check_length(field, value).map_err(|kind| self.error_at(offset, kind))?;
        self.count(field, value, offset, false);
        Ok(())
    }

    /// An ellipsoid's scale vector: non-zero, within the bounds, its axes
    /// not too unequal.
    fn scales(&mut self, fields: &[&'static str]) -> Result<DVec3, SceneError> {
        let mut axes = [(0.0, "", 0); 3];
        for (axis, &field) in axes.iter_mut().zip(fields) {
            let (value, offset) = self.number(field)?;
            if value == 0.0 {
                let kind = SceneErrorKind::OutOfRange {
                    field,
                    value,
                    rule: "non-zero",
                };
                return Err(self.error_at(offset, kind));
            }
            bounds::check_scale(field, value).map_err(|kind| self.error_at(offset, kind))?;
            self.count(field, value, offset, true);
            *axis = (value, field, offset);
        }
        bounds::check_axes(axes).map_err(|(offset, kind)| self.error_at(offset, kind))?;
        Ok(DVec3::new(axes[0].0, axes[1].0, axes[2].0))
    }

    #[inline(always)]
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
    match token.first() {
        Some(b'0'..=b'9' | b'+' | b'-' | b'.') => true,
        // Past those, only `inf`, `infinity` and `nan` (in any case) are numbers.
        Some(b'i' | b'I' | b'n' | b'N') => {
            std::str::from_utf8(token).is_ok_and(|s| s.parse::<f64>().is_ok())
        }
        _ => false,
    }
}

/// Parses line number `number`, counting its lengths into `extremes`.
fn parse_line(
    number: usize,
    line: &[u8],
    extremes: &mut Extremes,
) -> Result<Directive, SceneError> {
    let mut tokens = Tokens::new(number, line, extremes);
    let Some((offset, word)) = tokens.next() else {
        return Ok(Directive::Blank);
    };
    let Some(keyword) = Keyword::from_token(word) else {
        let found: String = String::from_utf8_lossy(word).chars().take(40).collect();
        let suggestion = Keyword::nearest(&found).map(Keyword::name);
        let kind = SceneErrorKind::UnknownKeyword { found, suggestion };
        return Err(tokens.error_at(offset, kind));
    };
    let directive = match keyword {
        Keyword::Near => {
            let (value, offset) = tokens.number(NEAR_FIELD)?;
            if value <= 0.0 {
                let kind = SceneErrorKind::OutOfRange {
                    field: NEAR_FIELD,
                    value,
                    rule: "> 0",
                };
                return Err(tokens.error_at(offset, kind));
            }
            tokens.length_at(NEAR_FIELD, value, offset)?;
            Directive::Extent(keyword, value, tokens.column(offset))
        }
        Keyword::Left | Keyword::Right | Keyword::Bottom | Keyword::Top => {
            let field = extent_field(keyword);
            let (value, offset) = tokens.number(field)?;
            tokens.length_at(field, value, offset)?;
            Directive::Extent(keyword, value, tokens.column(offset))
        }
        Keyword::Res => Directive::Resolution(
            resolution(&mut tokens, COLUMNS_FIELD)?,
            resolution(&mut tokens, ROWS_FIELD)?,
        ),
        Keyword::Back => Directive::Background(tokens.vector(&BACK_FIELDS, Tokens::non_negative)?),
        Keyword::Ambient => {
            Directive::Ambient(tokens.vector(&AMBIENT_FIELDS, Tokens::non_negative)?)
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
            let position = tokens.vector(&LIGHT_FIELDS[..3], Tokens::length)?;
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
        Keyword::Left => "the left edge of the image plane",
        Keyword::Right => "the right edge of the image plane",
        Keyword::Bottom => "the bottom edge of the image plane",
        _ => "the top edge of the image plane",
    }
}

/// Consumes the name of a classic SPHERE/LIGHT line, if there is one, and tells the dialect.
fn named_dialect(tokens: &mut Tokens) -> Dialect {
    let before = tokens.pos;
    match tokens.next() {
        Some((_, token)) if !looks_numeric(token) => Dialect::Classic,
        _ => {
            tokens.pos = before;
            Dialect::Browser
        }
    }
}

fn resolution(tokens: &mut Tokens, field: &'static str) -> Result<u32, SceneError> {
    let (value, offset) = tokens.number(field)?;
    image_side(field, value).map_err(|kind| tokens.error_at(offset, kind))
}

/// RES's first number, in words.
pub const COLUMNS_FIELD: &str = "the number of columns";
/// RES's second number, in words.
pub const ROWS_FIELD: &str = "the number of rows";

/// A side of the image ([`COLUMNS_FIELD`] or [`ROWS_FIELD`]): a whole number
/// from 1 to [`limits::MAX_RESOLUTION`], given in RES or on the command line.
pub fn image_side(field: &'static str, value: f64) -> Result<u32, SceneErrorKind> {
    if value.fract() != 0.0 {
        let found = format!("{value}");
        return Err(SceneErrorKind::NotWhole { field, found });
    }
    if value < 1.0 || value > f64::from(limits::MAX_RESOLUTION) {
        let rule = "between 1 and 16384";
        return Err(SceneErrorKind::OutOfRange { field, value, rule });
    }
    Ok(value as u32)
}

fn sphere(tokens: &mut Tokens) -> Result<(Sphere, Dialect), SceneError> {
    let dialect = named_dialect(tokens);
    let fields = &SPHERE_FIELDS;
    let center = tokens.vector(&fields[0..3], Tokens::length)?;
    let scale = tokens.scales(&fields[3..6])?;
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
            let shininess = tokens.non_negative(fields[13])?;
            (tokens.non_negative(fields[12])?, shininess)
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
    /// NEAR's value and column, like the other extents'.
    near: Given<(f64, usize)>,
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
    /// Spheres folded so far, some of them not yet in `spheres`.
    sphere_count: usize,
    lights: Vec<Light>,
    /// The lengths of the lines folded so far, for the scene-wide bounds.
    extremes: Extremes,
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
    /// Folds a run of sphere lines `lines` of one dialect, as [`Self::apply`]
    /// would line by line: only the first can be of another dialect than
    /// the scene's, and the first past the limit is the one refused.
    fn count_spheres(&mut self, lines: &[usize], dialect: Dialect) -> Result<(), SceneError> {
        self.count_spheres_within(lines, dialect, limits::MAX_SPHERES)
    }

    /// [`Self::count_spheres`] under a limit of `limit` spheres.
    fn count_spheres_within(
        &mut self,
        lines: &[usize],
        dialect: Dialect,
        limit: usize,
    ) -> Result<(), SceneError> {
        let Some(&first) = lines.first() else {
            return Ok(());
        };
        self.check_dialect(first, dialect)?;
        let room = limit.saturating_sub(self.sphere_count);
        if let Some(&line) = lines.get(room) {
            check_count(line, limit, limit, "spheres")?;
        }
        self.sphere_count += lines.len();
        Ok(())
    }

    /// Appends the spheres of `chunks`, once they are all folded, in
    /// parallel: each thread copies its share straight into place.
    fn append_spheres(&mut self, chunks: &[ParsedChunk]) {
        let starts: Vec<usize> = chunks
            .iter()
            .scan(0, |n, chunk| {
                let start = *n;
                *n += chunk.spheres.len();
                Some(start)
            })
            .collect();
        let total = chunks.iter().map(|chunk| chunk.spheres.len()).sum();
        self.spheres.par_extend(
            (0..total)
                .into_par_iter()
                .with_min_len(APPENDED_PER_TASK)
                .map(|i| {
                    // The last chunk starting at or before i (an empty
                    // chunk starts where the next does).
                    let c = starts.partition_point(|&start| start <= i) - 1;
                    chunks[c].spheres[i - starts[c]]
                }),
        );
    }

    /// Folds line `line`'s directive. A chunk's spheres come by the run
    /// instead ([`Self::count_spheres`], then [`Self::append_spheres`] once
    /// their piece is folded); one given here joins the scene at once, so
    /// it must not come while a piece's runs wait to be appended.
    fn apply(&mut self, line: usize, directive: Directive) -> Result<(), SceneError> {
        match directive {
            Directive::Blank => Ok(()),
            Directive::Extent(keyword, value, column) => {
                let slot = match keyword {
                    Keyword::Near => &mut self.near,
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
                self.count_spheres(&[line], dialect)?;
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
        let mut unused = Extremes::default();
        let mut tokens = Tokens::new(line_number, line, &mut unused);
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

    fn finish(self) -> Result<Scene, SceneError> {
        if self.is_empty() {
            return Err(SceneError::of_whole_scene(SceneErrorKind::Empty));
        }
        let missing = |keyword: Keyword| {
            SceneError::of_whole_scene(SceneErrorKind::MissingDirective {
                keyword: keyword.name(),
                example: keyword.example(),
            })
        };
        let ((near, near_column), near_line) = self.near.ok_or_else(|| missing(Keyword::Near))?;
        let left = self.left.ok_or_else(|| missing(Keyword::Left))?;
        let right = self.right.ok_or_else(|| missing(Keyword::Right))?;
        let bottom = self.bottom.ok_or_else(|| missing(Keyword::Bottom))?;
        let top = self.top.ok_or_else(|| missing(Keyword::Top))?;
        let ((width, height), _) = self.resolution.ok_or_else(|| missing(Keyword::Res))?;
        check_extent((Keyword::Left, left), (Keyword::Right, right))?;
        check_extent((Keyword::Bottom, bottom), (Keyword::Top, top))?;
        self.extremes.check(Located {
            length: Length {
                field: NEAR_FIELD,
                value: near,
                line: near_line,
            },
            column: near_column,
        })?;
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

    /// Whether no line said anything.
    fn is_empty(&self) -> bool {
        let given = [
            self.near.is_some(),
            self.left.is_some(),
            self.right.is_some(),
            self.bottom.is_some(),
            self.top.is_some(),
            self.resolution.is_some(),
            self.background.is_some(),
            self.ambient.is_some(),
            self.output.is_some(),
        ];
        !given.contains(&true) && self.sphere_count == 0 && self.lights.is_empty()
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

#[cfg(test)]
mod tests {
    use super::super::lines::CHUNK_BYTES;
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn misspelt_keywords_get_the_nearest_one() {
        let nearest = |token| Keyword::nearest(token).map(Keyword::name);
        assert_eq!(nearest("BAKC"), Some("BACK"), "a swap counts one");
        assert_eq!(nearest("spheres"), Some("SPHERE"));
        assert_eq!(nearest("AMBIANT"), Some("AMBIENT"));
        assert_eq!(nearest("OUTPUTT"), Some("OUTPUT"));
        assert_eq!(nearest("RE"), Some("RES"));
        assert_eq!(nearest("CAMERA"), None);
        assert_eq!(nearest("X"), None);
        assert_eq!(nearest("--------------------------a6abca43715a41"), None);
    }

    proptest! {
        /// Only a token that starts like a number or like `inf`/`nan` is
        /// handed to `str::parse` to tell whether it is one.
        #[test]
        fn looks_numeric_is_what_str_parse_says(token in "[iInNfFaAtTyYsS0-9+.eE-]{0,9}|\\PC{0,4}") {
            let parses = token.parse::<f64>().is_ok();
            let starts_like_one = matches!(token.bytes().next(), Some(b'0'..=b'9' | b'+' | b'-' | b'.'));
            prop_assert_eq!(looks_numeric(token.as_bytes()), starts_like_one || parses, "{}", token);
        }
    }

    #[test]
    fn names_that_read_as_numbers_are_numbers() {
        for token in ["inf", "Infinity", "NaN", "nan", "iNf", "+inf", "-nan", "7"] {
            assert!(looks_numeric(token.as_bytes()), "{token}");
        }
        for token in ["in", "infinit", "nana", "s0", "ball", "N", "e5", "é"] {
            assert!(!looks_numeric(token.as_bytes()), "{token}");
        }
    }

    /// Sphere lines fold a run at a time, across chunks, blank lines and
    /// lights, into the scene's spheres in file order; a sphere of the
    /// other dialect, first of its run far into the file, is refused at its
    /// line, naming the scene's first object line.
    #[test]
    fn sphere_runs_fold_as_their_lines_do() {
        let mut text = String::from("NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 4 4\n");
        let mut line = 6;
        let mut spheres = 0;
        while text.len() < 3 * CHUNK_BYTES {
            text += &format!("SPHERE s {spheres} 0 -5 1 1 1 0.5 0.5 0.5 1 1 1 0 50\n");
            (line, spheres) = (line + 1, spheres + 1);
            if spheres % 997 == 0 {
                text += "\nLIGHT l 0 0 0 1 1 1\n";
                line += 2;
            }
        }
        let scene = parse(&text).unwrap();
        assert_eq!(scene.spheres.len(), spheres);
        assert!(scene
            .spheres
            .iter()
            .enumerate()
            .all(|(i, s)| s.center.x == i as f64));
        assert_eq!(scene.lights.len(), spheres / 997);
        // After a light, so first of its run, in the last chunk.
        let browser = "SPHERE 0 0 -5 1 1 1 0.5 0.5 0.5 1 1 1 50 0 0 1\n";
        let bad = format!("{text}LIGHT l 0 0 0 1 1 1\n\n{browser}{browser}");
        let error = parse(&bad).unwrap_err();
        assert_eq!((error.line, error.column), (line + 3, 1));
        assert_eq!(error.kind, SceneErrorKind::MixedDialects { first_line: 7 });
        // In the other dialect from the start, the same lines all parse.
        let scene = parse(format!(
            "{}{browser}{browser}",
            &text[..text.find("SPHERE").unwrap()]
        ))
        .unwrap();
        assert_eq!(scene.spheres.len(), 2);
    }

    /// The first sphere past the limit is refused at its own line, whether
    /// it starts its run or lies inside one.
    #[test]
    fn the_first_sphere_past_the_limit_is_the_one_refused() {
        let refused = |runs: &[&[usize]], limit| {
            let mut builder = SceneBuilder::default();
            runs.iter()
                .try_for_each(|run| builder.count_spheres_within(run, Dialect::Classic, limit))
                .map_err(|e| (e.line, e.kind))
        };
        let too_many = |line| {
            Err((
                line,
                SceneErrorKind::TooMany {
                    what: "spheres",
                    limit: 3,
                },
            ))
        };
        assert_eq!(refused(&[&[7, 8, 10]], 3), Ok(()));
        assert_eq!(refused(&[&[7, 8, 10, 11, 12]], 3), too_many(11));
        assert_eq!(refused(&[&[7, 8], &[10], &[12, 13]], 3), too_many(12));
        assert_eq!(refused(&[&[7, 8], &[10, 11]], 3), too_many(11));
    }

    /// Chunked parsing reports the first error of the file with its exact
    /// position, and counts lines across chunk boundaries exactly.
    #[test]
    fn chunked_parsing_keeps_line_numbers_and_the_first_error() {
        let mut text = String::from("NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 4 4\n");
        let sphere = "SPHERE s 0 0 -5 1 1 1 0.5 0.5 0.5 1 1 1 0 50\n";
        let lines_before = 6 + 3 * CHUNK_BYTES / sphere.len();
        for _ in 6..lines_before {
            text += sphere;
        }
        let scene = parse(&text).unwrap();
        assert_eq!(scene.spheres.len(), lines_before - 6);
        // Two errors, both far into the file: the first is reported.
        let bad = format!("{text}SPHERE s 0 0 -5 1 1 1 0.5 0.5 0.5 1 1 1 0 x\n{text}NEAR -1\n");
        let error = parse(&bad).unwrap_err();
        assert_eq!((error.line, error.column), (lines_before + 1, 43));
        // A missing directive is no line's fault, however long the text.
        let missing = format!("{}\n\n", &text["NEAR 1\n".len()..]);
        let error = parse(&missing).unwrap_err();
        assert_eq!((error.line, error.column), (0, 0));
        assert_eq!(
            error.kind,
            SceneErrorKind::MissingDirective {
                keyword: "NEAR",
                example: "NEAR 1"
            }
        );
    }
}
