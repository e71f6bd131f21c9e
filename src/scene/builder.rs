//! The fold: each line's directive, in file order, into a [`Scene`], with
//! the checks that span lines (duplicates, required directives, extents,
//! dialect consistency, counts, and the scene-wide bounds of
//! `scene::bounds`).

use super::bounds::{Extremes, Located};
use super::error::Length;
use super::keyword::{Keyword, NEAR_FIELD};
use super::tokens::{named_dialect, Tokens};
use super::{Camera, Dialect, Light, Scene, SceneError, SceneErrorKind, Sphere};
use crate::limits;
use glam::DVec3;
use rayon::prelude::*;

/// What one line says.
#[derive(Debug)]
pub(super) enum Directive {
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

/// Spheres one task of [`SceneBuilder::append_spheres`] copies at least.
const APPENDED_PER_TASK: usize = 1 << 12;

/// A singleton directive's value and the line that gave it.
type Given<T> = Option<(T, usize)>;

#[derive(Default)]
pub(super) struct SceneBuilder {
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
    pub(super) fn count_spheres(
        &mut self,
        lines: &[usize],
        dialect: Dialect,
    ) -> Result<(), SceneError> {
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

    /// Appends the spheres of `runs` (a piece's chunks' spheres, in file
    /// order), once they are all folded, in parallel: each thread copies its
    /// share straight into place.
    pub(super) fn append_spheres(&mut self, runs: &[&[Sphere]]) {
        let starts: Vec<usize> = runs
            .iter()
            .scan(0, |n, run| {
                let start = *n;
                *n += run.len();
                Some(start)
            })
            .collect();
        let total = runs.iter().map(|run| run.len()).sum();
        self.spheres.par_extend(
            (0..total)
                .into_par_iter()
                .with_min_len(APPENDED_PER_TASK)
                .map(|i| {
                    // The last run starting at or before i (an empty run
                    // starts where the next does).
                    let r = starts.partition_point(|&start| start <= i) - 1;
                    runs[r][i - starts[r]]
                }),
        );
    }

    /// Spheres folded so far, some of them perhaps not yet appended.
    pub(super) fn sphere_count(&self) -> usize {
        self.sphere_count
    }

    /// Room for `count` spheres in all, so that appending them up to there
    /// neither copies the spheres already in place nor faults in pages twice.
    pub(super) fn reserve_spheres(&mut self, count: usize) {
        let count = count.min(limits::MAX_SPHERES);
        self.spheres
            .reserve(count.saturating_sub(self.spheres.len()));
    }

    /// Counts the lengths of a piece's lines (`extremes`) into the scene's,
    /// for its scene-wide bounds.
    pub(super) fn merge_extremes(&mut self, extremes: &Extremes) {
        self.extremes.merge(extremes);
    }

    /// Folds line `line`'s directive. A chunk's spheres come by the run
    /// instead ([`Self::count_spheres`], then [`Self::append_spheres`] once
    /// their piece is folded); one given here joins the scene at once, so
    /// it must not come while a piece's runs wait to be appended.
    pub(super) fn apply(&mut self, line: usize, directive: Directive) -> Result<(), SceneError> {
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
    pub(super) fn explain(&self, line_number: usize, line: &[u8], error: SceneError) -> SceneError {
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

    pub(super) fn finish(self) -> Result<Scene, SceneError> {
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
    use super::*;

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
}
