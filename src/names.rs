//! The names users choose by: the index, the specular model, the rule set, the scene
//! distribution of `voxtrace gen`, the report's scene families. Each value
//! is parsed from and shown as one lower-case name wherever a user meets it
//! (flags, reports, error messages), and every such name is written once,
//! in the tables at the end of this file, so that a front end (the CLI's
//! flag parser, a test) reads them from here rather than keeping its own.

use crate::render::{IndexKind, Rules, SpecularModel};
use crate::tools::gen::Distribution;
use crate::tools::report::Family;
use std::fmt;

/// A type whose values each have one name.
///
/// ```
/// use voxtrace::names::Named;
/// use voxtrace::render::IndexKind;
/// assert_eq!(IndexKind::NAMES, ["grid", "walk", "brute"]);
/// assert_eq!("brute".parse::<IndexKind>(), Ok(IndexKind::Brute));
/// assert_eq!(IndexKind::Grid.to_string(), "grid");
/// assert!("octree".parse::<IndexKind>().is_err());
/// ```
pub trait Named: Copy + PartialEq + Sized + 'static {
    /// What the choice is, for messages: "index", "specular model".
    const WHAT: &'static str;
    /// Every value, in the order they are listed to users.
    const ALL: &'static [Self];
    /// Their names, in the same order.
    const NAMES: &'static [&'static str];

    fn name(self) -> &'static str;

    /// The value called `name` (exactly: names are lower case).
    fn from_name(name: &str) -> Result<Self, UnknownName> {
        Self::NAMES
            .iter()
            .position(|&n| n == name)
            .map(|at| Self::ALL[at])
            .ok_or_else(|| UnknownName {
                what: Self::WHAT,
                found: name.to_owned(),
                expected: Self::NAMES,
            })
    }
}

/// A name that is none of a choice's.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnknownName {
    pub what: &'static str,
    pub found: String,
    pub expected: &'static [&'static str],
}

impl fmt::Display for UnknownName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "unknown {} {:?}: expected one of {}",
            self.what,
            self.found,
            self.expected.join(", ")
        )
    }
}

impl std::error::Error for UnknownName {}

/// `Named`, `Display` and `FromStr` for a field-less enum, from its table
/// of names.
macro_rules! named {
    ($ty:ident, $what:literal, { $($value:ident => $name:literal),+ $(,)? }) => {
        impl Named for $ty {
            const WHAT: &'static str = $what;
            const ALL: &'static [Self] = &[$($ty::$value),+];
            const NAMES: &'static [&'static str] = &[$($name),+];

            fn name(self) -> &'static str {
                match self {
                    $($ty::$value => $name),+
                }
            }
        }

        impl fmt::Display for $ty {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.name())
            }
        }

        impl std::str::FromStr for $ty {
            type Err = UnknownName;

            fn from_str(s: &str) -> Result<Self, Self::Err> {
                Self::from_name(s)
            }
        }
    };
}

named!(IndexKind, "index", { Grid => "grid", Walk => "walk", Brute => "brute" });
named!(SpecularModel, "specular model", { Phong => "phong", Blinn => "blinn" });
named!(Rules, "rule set", { Default => "default", Ucla => "ucla" });
named!(Distribution, "distribution", {
    Uniform => "uniform",
    Mixed => "mixed",
    Clustered => "clustered",
    Clumps => "clumps",
    Straddle => "straddle",
});
named!(Family, "scene family", {
    Reference => "reference",
    Hard => "hard",
    Generated => "generated",
});

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trips<T: Named + fmt::Display + std::str::FromStr<Err = UnknownName> + fmt::Debug>() {
        assert_eq!(T::ALL.len(), T::NAMES.len());
        for &value in T::ALL {
            assert_eq!(value.to_string().parse::<T>(), Ok(value));
        }
        let unknown = "nothing".parse::<T>().unwrap_err();
        assert_eq!(unknown.expected, T::NAMES);
    }

    #[test]
    fn every_name_parses_back_to_its_value() {
        round_trips::<IndexKind>();
        round_trips::<SpecularModel>();
        round_trips::<Rules>();
        round_trips::<Distribution>();
        round_trips::<Family>();
    }

    #[test]
    fn an_unknown_name_says_what_was_expected() {
        let e = "fast".parse::<IndexKind>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "unknown index \"fast\": expected one of grid, walk, brute"
        );
    }
}
