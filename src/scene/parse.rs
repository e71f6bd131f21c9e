//! The scene text parser: one pure function per line (`parse_line`, over
//! the line's [`Tokens`]), its directives folded into a [`Scene`] by a
//! [`SceneBuilder`] (`scene::builder`), which checks what spans lines.

use super::bounds::Extremes;
use super::builder::{Directive, SceneBuilder};
use super::keyword::{
    extent_field, Keyword, AMBIENT_FIELDS, BACK_FIELDS, COLUMNS_FIELD, LIGHT_FIELDS, NEAR_FIELD,
    ROWS_FIELD, SPHERE_FIELDS,
};
use super::lines::{check_line, split_chunks, split_lines};
use super::tokens::{named_dialect, Tokens};
use super::{Dialect, Light, Material, Scene, SceneError, SceneErrorKind, Sphere};
use crate::limits;
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
            self.builder.merge_extremes(&chunk.extremes);
            self.next_line = first + newlines;
        }
        let runs: Vec<&[Sphere]> = parsed
            .iter()
            .map(|chunk| chunk.spheres.as_slice())
            .collect();
        self.builder.append_spheres(&runs);
        self.offset += text.len();
        Ok(())
    }

    /// Gives the scene's spheres room for a whole text of `total` bytes, at
    /// the rate (spheres a byte) of the text fed so far, with a sixteenth
    /// more for lines a little shorter further on. Only a hint: the spheres
    /// still grow past it as they must.
    pub fn expect_bytes(&mut self, total: u64) {
        if self.offset == 0 {
            return;
        }
        let per_byte = self.builder.sphere_count() as f64 / self.offset as f64;
        let expected = per_byte * total as f64 * (1.0 + 1.0 / 16.0);
        // `as` saturates; the builder caps it at the spheres a scene may have.
        self.builder.reserve_spheres(expected as usize);
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

/// What a chunk hands the fold, line by line.
#[derive(Debug)]
enum Folded {
    /// A line's directive, other than a sphere.
    One(Directive),
    /// A run of this many sphere lines in a row (blank lines aside), all
    /// of one dialect, from this line on (see [`ParsedChunk`]).
    Spheres(Dialect, usize),
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

fn resolution(tokens: &mut Tokens, field: &'static str) -> Result<u32, SceneError> {
    let (value, offset) = tokens.number(field)?;
    image_side(field, value).map_err(|kind| tokens.error_at(offset, kind))
}

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

#[cfg(test)]
mod tests {
    use super::super::lines::CHUNK_BYTES;
    use super::*;

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
