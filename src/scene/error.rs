use crate::limits;
use std::fmt;

/// A scene that cannot be rendered, with where the problem is.
/// Lines and columns count from 1; columns count characters. Both are 0
/// when no line is at fault: a required directive that never appears
/// ([`SceneError::is_located`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SceneError {
    pub line: usize,
    pub column: usize,
    pub kind: SceneErrorKind,
}

#[derive(Clone, Debug, PartialEq)]
pub enum SceneErrorKind {
    /// A token that is not a number where a number belongs.
    ExpectedNumber {
        field: &'static str,
        found: String,
    },
    /// NaN, an infinity, or a literal too large for a double (`1e999`).
    NotFinite {
        field: &'static str,
        found: String,
    },
    /// The line ended before this field.
    MissingField {
        field: &'static str,
    },
    /// More tokens than the directive takes.
    ExtraToken {
        found: String,
    },
    UnknownKeyword {
        found: String,
        /// The keyword `found` is a likely misspelling of.
        suggestion: Option<&'static str>,
    },
    /// A number outside the values the field allows; `rule` says which ones.
    OutOfRange {
        field: &'static str,
        value: f64,
        rule: &'static str,
    },
    /// RES needs whole numbers.
    NotWhole {
        field: &'static str,
        found: String,
    },
    /// NEAR, LEFT, … given twice.
    Duplicate {
        keyword: &'static str,
        first_line: usize,
    },
    /// No directive at all: the text is empty, or blank lines and comments.
    Empty,
    /// A required directive never appeared; `example` is such a line.
    MissingDirective {
        keyword: &'static str,
        example: &'static str,
    },
    /// LEFT ≥ RIGHT or BOTTOM ≥ TOP.
    EmptyExtent {
        low: &'static str,
        high: &'static str,
        low_value: f64,
        high_value: f64,
    },
    /// A SPHERE/LIGHT line in the other dialect than the file's earlier ones.
    MixedDialects {
        first_line: usize,
    },
    /// The OUTPUT name is missing or not UTF-8.
    BadOutputName,
    TooMany {
        what: &'static str,
        limit: usize,
    },
    /// A length (coordinate, scale or camera value) beyond
    /// [`limits::MAX_LENGTH`] in magnitude: see `scene::bounds`.
    TooLong {
        field: &'static str,
        value: f64,
    },
    /// A scale below [`limits::MIN_SCALE`] in magnitude.
    TooThin {
        field: &'static str,
        value: f64,
    },
    /// An ellipsoid whose axes differ by more than [`limits::MAX_AXIS_RATIO`].
    AxisRatio {
        thin_field: &'static str,
        thin: f64,
        wide_field: &'static str,
        wide: f64,
    },
    /// Two lengths of the scene more than [`limits::MAX_LENGTH_RATIO`] apart.
    LengthRatio {
        small: Length,
        large: Length,
    },
    /// A line longer than [`limits::MAX_LINE_BYTES`].
    LineTooLong,
    /// A control byte near the start of the text: not a scene but binary
    /// data, of a known kind when its first bytes are that kind's signature.
    Binary {
        byte: u8,
        format: Option<&'static str>,
    },
}

/// A length of the scene and where it was given, for [`SceneErrorKind::LengthRatio`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Length {
    pub field: &'static str,
    pub value: f64,
    pub line: usize,
}

/// Plain decimals where they are short, scientific notation where they are
/// not (`1e39` rather than forty digits).
fn number(value: f64) -> String {
    let magnitude = value.abs();
    if magnitude == 0.0 || (1e-4..1e16).contains(&magnitude) {
        format!("{value}")
    } else {
        format!("{value:e}")
    }
}

impl SceneError {
    /// An error that belongs to no line of the text.
    pub fn of_whole_scene(kind: SceneErrorKind) -> Self {
        SceneError {
            line: 0,
            column: 0,
            kind,
        }
    }

    /// Whether a line and column are at fault (all but an empty scene and a
    /// missing directive).
    pub fn is_located(&self) -> bool {
        self.line > 0
    }
}

/// One line, for logs and JSON fields: `line L, column C: what`, or only
/// `what` when no line is at fault. `scene::Diagnostic` adds the source line.
impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if !self.is_located() {
            return write!(f, "{}", self.kind);
        }
        write!(
            f,
            "line {}, column {}: {}",
            self.line, self.column, self.kind
        )
    }
}

impl fmt::Display for SceneErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use SceneErrorKind::*;
        match self {
            ExpectedNumber { field, found } => write!(f, "expected a number for {field}, found {found:?}"),
            NotFinite { field, found } => write!(f, "expected a finite number for {field}, found {found:?}"),
            MissingField { field } => write!(f, "expected {field}, found the end of the line"),
            ExtraToken { found } => write!(f, "unexpected {found:?} after the last field"),
            UnknownKeyword { found, suggestion: Some(keyword) } => {
                write!(f, "unknown directive {found:?}: did you mean {keyword}?")
            }
            UnknownKeyword { found, suggestion: None } => write!(
                f,
                "unknown directive {found:?} (expected NEAR, LEFT, RIGHT, BOTTOM, TOP, RES, SPHERE, LIGHT, BACK, AMBIENT or OUTPUT)"
            ),
            OutOfRange { field, value, rule } => write!(f, "{field} must be {rule}, found {value}"),
            NotWhole { field, found } => write!(f, "{field} must be a whole number, found {found:?}"),
            Duplicate { keyword, first_line } => {
                write!(f, "{keyword} is given again (first on line {first_line})")
            }
            Empty => write!(
                f,
                "the scene is empty: it needs at least NEAR, LEFT, RIGHT, BOTTOM, TOP and RES lines, such as `NEAR 1`"
            ),
            MissingDirective { keyword, example } => {
                write!(f, "the scene has no {keyword} line: add one, such as `{example}`")
            }
            EmptyExtent { low, high, low_value, high_value } => {
                write!(f, "{low} ({low_value}) must be less than {high} ({high_value})")
            }
            MixedDialects { first_line } => write!(
                f,
                "this line is in the other dialect than line {first_line} (named and unnamed SPHERE/LIGHT lines cannot be mixed)"
            ),
            BadOutputName => write!(f, "OUTPUT needs a file name in UTF-8"),
            TooMany { what, limit } => write!(f, "more than {limit} {what}"),
            TooLong { field, value } => write!(
                f,
                "{field} is {}, beyond ±{:e}: the renderer computes in f32, where squared distances that long overflow",
                number(*value),
                limits::MAX_LENGTH
            ),
            TooThin { field, value } => write!(
                f,
                "{field} is {}, below {:e} in magnitude: the renderer computes in f32, where the inverse of so thin a scale, squared, overflows",
                number(*value),
                limits::MIN_SCALE
            ),
            AxisRatio { thin_field, thin, wide_field, wide } => write!(
                f,
                "{thin_field} ({}) is more than {:e} times smaller than {wide_field} ({}): the renderer's f32 hit test keeps no precision across so flat an ellipsoid",
                number(*thin),
                limits::MAX_AXIS_RATIO,
                number(*wide)
            ),
            LengthRatio { small, large } => write!(
                f,
                "{} {} (line {}) and {} {} (line {}) are more than a factor {:e} apart: the renderer's f32 hit test squares their ratio, which leaves f32's range there",
                small.field,
                number(small.value),
                small.line,
                large.field,
                number(large.value),
                large.line,
                limits::MAX_LENGTH_RATIO
            ),
            LineTooLong => write!(f, "the line is longer than {} bytes", limits::MAX_LINE_BYTES),
            Binary { format: Some(format), .. } => {
                write!(f, "this looks like a binary file ({format}), not a scene")
            }
            Binary { byte, format: None } => write!(
                f,
                "byte 0x{byte:02x} is a control character: this looks like a binary file, not a scene"
            ),
        }
    }
}

impl std::error::Error for SceneError {}
