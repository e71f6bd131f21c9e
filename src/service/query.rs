//! A query string as named parameters: decoded as a form encodes it
//! (`+` for a space, `%XX` for a byte), each name one the route reads and
//! given once. A typo is refused rather than passed over, and named.

use std::fmt;

/// Why a query string is refused before its values are looked at.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum QueryError {
    /// Names the route does not read, each with the known one it is
    /// closest to, if any is close.
    Unknown {
        names: Vec<(String, Option<&'static str>)>,
        known: Vec<&'static str>,
    },
    /// A name given more than once: which one counts would be a guess.
    Repeated { name: &'static str },
}

impl fmt::Display for QueryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            QueryError::Unknown { names, known } => {
                let plural = if names.len() == 1 { "" } else { "s" };
                write!(f, "unknown query parameter{plural} ")?;
                for (i, (name, suggestion)) in names.iter().enumerate() {
                    if i > 0 {
                        write!(f, ", ")?;
                    }
                    write!(f, "{name:?}")?;
                    if let Some(known) = suggestion {
                        write!(f, " (did you mean {known:?}?)")?;
                    }
                }
                write!(f, "; the parameters are {}", known.join(", "))
            }
            QueryError::Repeated { name } => {
                write!(f, "query parameter {name:?} is given more than once")
            }
        }
    }
}

/// The parameters of `query` in the order given, each as what `known`
/// pairs its name with.
pub fn parse<P: Copy + PartialEq>(
    query: &str,
    known: &[(&'static str, P)],
) -> Result<Vec<(P, String)>, QueryError> {
    let names: Vec<&'static str> = known.iter().map(|(name, _)| *name).collect();
    let mut params: Vec<(P, String)> = Vec::new();
    let mut unknown = Vec::new();
    for (name, value) in form_urlencoded::parse(query.as_bytes()) {
        match known.iter().find(|(k, _)| *k == name) {
            Some(&(k, param)) if params.iter().any(|(seen, _)| *seen == param) => {
                return Err(QueryError::Repeated { name: k })
            }
            Some(&(_, param)) => params.push((param, value.into_owned())),
            None => unknown.push((name.to_string(), closest(&name, &names))),
        }
    }
    if unknown.is_empty() {
        Ok(params)
    } else {
        Err(QueryError::Unknown {
            names: unknown,
            known: names,
        })
    }
}

/// Most edits (insertions, deletions, substitutions, swaps of neighbours)
/// that still make a name a likely typo of a known one.
const MAX_TYPO_EDITS: usize = 2;

/// The known name `name` is likely a typo of: the nearest within
/// [`MAX_TYPO_EDITS`] edits, and fewer edits than `name` has characters
/// (so that `x` is no typo of `spp`). Case is no edit.
fn closest(name: &str, known: &[&'static str]) -> Option<&'static str> {
    let lower = name.to_lowercase();
    known
        .iter()
        .map(|k| (strsim::osa_distance(&lower, k), *k))
        .filter(|&(edits, _)| edits <= MAX_TYPO_EDITS && edits < name.chars().count())
        .min_by_key(|&(edits, _)| edits)
        .map(|(_, k)| k)
}

#[cfg(test)]
mod tests {
    use super::*;

    const NAMES: &[&str] = &["format", "spp", "depth", "region", "rules"];
    /// Each name paired with itself.
    const KNOWN: &[(&str, &str)] = &[
        ("format", "format"),
        ("spp", "spp"),
        ("depth", "depth"),
        ("region", "region"),
        ("rules", "rules"),
    ];

    #[test]
    fn known_parameters_are_decoded_in_order() {
        assert_eq!(parse("", KNOWN), Ok(vec![]));
        assert_eq!(
            parse("spp=2&&region=1%2C2,3,4&rules=a+b", KNOWN),
            Ok(vec![
                ("spp", "2".to_owned()),
                ("region", "1,2,3,4".to_owned()),
                ("rules", "a b".to_owned())
            ])
        );
        assert_eq!(parse("depth", KNOWN), Ok(vec![("depth", String::new())]));
    }

    #[test]
    fn unknown_names_are_all_named_with_a_likely_meaning() {
        let error = parse("spp=2&depht=3&x=1&SPP=1", KNOWN).unwrap_err();
        assert_eq!(
            error,
            QueryError::Unknown {
                names: vec![
                    ("depht".into(), Some("depth")),
                    ("x".into(), None),
                    ("SPP".into(), Some("spp")),
                ],
                known: NAMES.to_vec(),
            }
        );
        assert_eq!(
            error.to_string(),
            "unknown query parameters \"depht\" (did you mean \"depth\"?), \"x\", \"SPP\" \
             (did you mean \"spp\"?); the parameters are format, spp, depth, region, rules"
        );
        let one = parse("sp=4", KNOWN).unwrap_err().to_string();
        assert!(
            one.starts_with("unknown query parameter \"sp\" (did you mean \"spp\"?);"),
            "{one}"
        );
    }

    #[test]
    fn far_names_get_no_suggestion() {
        for (name, suggestion) in [
            ("s", None),
            ("quality", None),
            ("fmt", None),
            ("formt", Some("format")),
            ("rule", Some("rules")),
            ("dpeth", Some("depth")),
        ] {
            assert_eq!(closest(name, NAMES), suggestion, "{name}");
        }
    }

    #[test]
    fn a_repeated_name_is_refused() {
        assert_eq!(
            parse("spp=2&depth=1&spp=3", KNOWN),
            Err(QueryError::Repeated { name: "spp" })
        );
        assert_eq!(
            parse("spp=2&sp%70=3", KNOWN).unwrap_err().to_string(),
            "query parameter \"spp\" is given more than once"
        );
    }
}
