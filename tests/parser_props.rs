//! The parser never panics, whatever it is fed, and reads back what the
//! writer writes.

use proptest::prelude::*;
use voxtrace::scene::{parse, write_scene, SceneErrorKind};

const VALID: &str = include_str!("../scenes/testSample.txt");

fn token() -> impl Strategy<Value = String> {
    prop_oneof![
        prop::sample::select(vec![
            "NEAR", "LEFT", "RIGHT", "BOTTOM", "TOP", "RES", "SPHERE", "LIGHT", "BACK", "AMBIENT",
            "OUTPUT", "sphere", "s1", "#", "nan", "inf", "-inf", "1e999", "-0", "0", "1", "-1",
            "0.5", "600", "\t", "\r", "", "é", "\u{0}", "1e-320", "+.5", "5.", "-", "e5",
        ])
        .prop_map(str::to_owned),
        any::<f64>().prop_map(|x| x.to_string()),
        "[ -~]{0,8}",
    ]
}

fn line() -> impl Strategy<Value = String> {
    prop::collection::vec(token(), 0..20).prop_map(|t| t.join(" "))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn token_soup_never_panics(lines in prop::collection::vec(line(), 0..12), crlf in any::<bool>()) {
        let text = lines.join(if crlf { "\r\n" } else { "\n" });
        let _ = parse(&text);
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let _ = parse(&bytes);
    }

    /// Valid scenes with bytes replaced, inserted or deleted: errors, when
    /// they come, point inside the text.
    #[test]
    fn mutated_valid_scenes_never_panic(edits in prop::collection::vec((any::<prop::sample::Index>(), 0u8..3, any::<u8>()), 1..6)) {
        let mut bytes = VALID.as_bytes().to_vec();
        for (at, op, byte) in edits {
            let i = at.index(bytes.len().max(1));
            match op {
                0 if !bytes.is_empty() => bytes[i] = byte,
                1 => bytes.insert(i.min(bytes.len()), byte),
                _ if !bytes.is_empty() => { bytes.remove(i); }
                _ => {}
            }
        }
        if let Err(e) = parse(&bytes) {
            let lines = bytes.split(|&b| b == b'\n').count();
            if matches!(e.kind, SceneErrorKind::Empty | SceneErrorKind::MissingDirective { .. }) {
                prop_assert!((e.line, e.column) == (0, 0), "no line is to blame: {e}");
            } else {
                prop_assert!(e.line >= 1 && e.line <= lines.max(1), "{e}");
                prop_assert!(e.column >= 1);
            }
        }
    }
}

#[test]
fn written_scenes_read_back_equal() {
    let scene = parse(VALID).unwrap();
    let mut text = Vec::new();
    write_scene(&mut text, &scene).unwrap();
    assert_eq!(parse(&text).unwrap(), scene);
}
