//! The library's named choices ([`crate::names`]) as clap values: the names
//! and the values come from the library, each value's help line is the
//! command line's own.

use crate::names::Named;
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};

/// A value parser accepting exactly `T`'s names, listing each with `help`.
pub fn choice<T: Named + Send + Sync>(
    help: fn(T) -> &'static str,
) -> impl TypedValueParser<Value = T> {
    let values = T::ALL
        .iter()
        .map(move |&value| PossibleValue::new(value.name()).help(help(value)));
    PossibleValuesParser::new(values).try_map(|name| T::from_name(&name))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::IndexKind;
    use clap::Parser;

    #[derive(Parser)]
    struct Args {
        #[arg(long, value_parser = choice(|_: IndexKind| "an index"))]
        index: IndexKind,
    }

    #[test]
    fn names_parse_to_values_and_others_are_refused() {
        let args = Args::try_parse_from(["x", "--index", "brute"]).unwrap();
        assert_eq!(args.index, IndexKind::Brute);
        let e = Args::try_parse_from(["x", "--index", "octree"])
            .err()
            .unwrap();
        assert!(
            e.to_string()
                .contains("[possible values: grid, walk, brute]"),
            "{e}"
        );
    }
}
