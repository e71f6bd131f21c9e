//! Malformed scenes: each gives the right error kind at the right line and
//! column, through the library and through `voxtrace render` (exit code 2).

mod support;

use std::process::Command;
use support::cli::{scratch_dir, stderr, voxtrace_in};
use voxtrace::scene::{parse, SceneErrorKind as K};

const HEAD: &str = "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 4 4\n";
const NEAR: &str = "the distance to the image plane (NEAR)";
const SPHERE: &str = "SPHERE s1 0 0 -10 2 4 2 0.5 0 0 1 1 0.9 0 50";

struct Case {
    name: &'static str,
    text: Vec<u8>,
    line: usize,
    column: usize,
    kind: fn(&K) -> bool,
}

fn case(
    name: &'static str,
    text: impl Into<Vec<u8>>,
    line: usize,
    column: usize,
    kind: fn(&K) -> bool,
) -> Case {
    Case {
        name,
        text: text.into(),
        line,
        column,
        kind,
    }
}

fn with_head(tail: &str) -> String {
    format!("{HEAD}{tail}\n")
}

fn cases() -> Vec<Case> {
    vec![
        case(
            "comma decimal",
            with_head("SPHERE s1 0 0 -10 2 2,0 2 0.5 0 0 1 1 0.9 0 50"),
            7,
            21,
            |k| matches!(k, K::ExpectedNumber { field: "the sphere's y scale", found } if found == "2,0"),
        ),
        case(
            "missing field",
            with_head("SPHERE s1 0 0 -10 2 4 2 0.5 0 0 1 1 0.9 0"),
            7,
            42,
            |k| matches!(k, K::MissingField { field: "the sphere's specular exponent" }),
        ),
        case(
            "extra token",
            with_head(&format!("{SPHERE} 0.5 1.5 7")),
            7,
            54,
            |k| matches!(k, K::ExtraToken { found } if found == "7"),
        ),
        case("NaN", with_head("LIGHT l1 0 NaN 0 1 1 1"), 7, 12, |k| {
            matches!(
                k,
                K::NotFinite {
                    field: "the light's y position",
                    ..
                }
            )
        }),
        case("inf", with_head("BACK 1 inf 0"), 7, 8, |k| {
            matches!(k, K::NotFinite { field: "the background's green component", .. })
        }),
        case("1e999", with_head("AMBIENT 1e999 0 0"), 7, 9, |k| {
            matches!(k, K::NotFinite { field: "the ambient light's red intensity", .. })
        }),
        case(
            "zero scale",
            with_head("SPHERE s1 0 0 -10 2 0 2 0.5 0 0 1 1 0.9 0 50"),
            7,
            21,
            |k| {
                matches!(
                    k,
                    K::OutOfRange {
                        field: "the sphere's y scale",
                        ..
                    }
                )
            },
        ),
        case(
            "fractional RES",
            "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 600 60.5\n",
            6,
            9,
            |k| matches!(k, K::NotWhole { field: "the number of rows", .. }),
        ),
        case(
            "zero RES",
            "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 0 600\n",
            6,
            5,
            |k| matches!(k, K::OutOfRange { field: "the number of columns", .. }),
        ),
        case(
            "LEFT >= RIGHT",
            "NEAR 1\nLEFT 1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 4 4\n",
            3,
            7,
            |k| {
                matches!(
                    k,
                    K::EmptyExtent {
                        low: "LEFT",
                        high: "RIGHT",
                        ..
                    }
                )
            },
        ),
        case(
            "BOTTOM >= TOP, BOTTOM last",
            "NEAR 1\nLEFT -1\nRIGHT 1\nTOP 1\nRES 4 4\nBOTTOM 2\n",
            6,
            8,
            |k| {
                matches!(
                    k,
                    K::EmptyExtent {
                        low: "BOTTOM",
                        high: "TOP",
                        ..
                    }
                )
            },
        ),
        case(
            "NEAR <= 0",
            "NEAR 0\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 4 4\n",
            1,
            6,
            |k| matches!(k, K::OutOfRange { field: NEAR, .. }),
        ),
        case("negative NEAR", "NEAR -2\n", 1, 6, |k| {
            matches!(k, K::OutOfRange { field: NEAR, .. })
        }),
        case("duplicate NEAR", format!("{HEAD}NEAR 2\n"), 7, 1, |k| {
            matches!(
                k,
                K::Duplicate {
                    keyword: "NEAR",
                    first_line: 1
                }
            )
        }),
        case("duplicate RES", format!("{HEAD}\n\nres 8 8\n"), 9, 1, |k| {
            matches!(
                k,
                K::Duplicate {
                    keyword: "RES",
                    first_line: 6
                }
            )
        }),
        case(
            "unknown keyword",
            with_head("SPHERES s1 0 0 -10"),
            7,
            1,
            |k| matches!(k, K::UnknownKeyword { found, suggestion: Some("SPHERE") } if found == "SPHERES"),
        ),
        case("empty file", "", 0, 0, |k| matches!(k, K::Empty)),
        case("blank lines and comments only", "\n  \n# nothing\n", 0, 0, |k| {
            matches!(k, K::Empty)
        }),
        case("only BACK", "BACK 0 0 0\n", 0, 0, |k| {
            matches!(k, K::MissingDirective { keyword: "NEAR", .. })
        }),
        case(
            "missing RES",
            "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\n",
            0,
            0,
            |k| matches!(k, K::MissingDirective { keyword: "RES", .. }),
        ),
        case(
            "binary garbage",
            b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR".to_vec(),
            1,
            1,
            |k| {
                matches!(
                    k,
                    K::Binary {
                        byte: 0x89,
                        format: Some("a PNG image")
                    }
                )
            },
        ),
        case(
            "name-less classic line",
            with_head(&format!(
                "{SPHERE}\nSPHERE 4 4 -10 1 2 1 0 0.5 0 1 1 0.9 0 50"
            )),
            8,
            1,
            |k| matches!(k, K::MixedDialects { first_line: 7 }),
        ),
        case(
            "15-number browser line",
            with_head("SPHERE 0 0 -10 2 4 2 0.5 0 0 1 0 0 50 0 0"),
            7,
            42,
            |k| {
                matches!(
                    k,
                    K::MissingField {
                        field: "the sphere's index of refraction"
                    }
                )
            },
        ),
        case(
            "truncated last line",
            format!("{HEAD}LIGHT l1 0 0 0 0.9 0.9"),
            7,
            23,
            |k| matches!(k, K::MissingField { field: "the light's blue intensity" }),
        ),
        case(
            "negative colour",
            with_head("SPHERE s1 0 0 -10 2 4 2 0.5 -0.1 0 1 1 0.9 0 50"),
            7,
            29,
            |k| matches!(k, K::OutOfRange { field: "the sphere's green component", .. }),
        ),
        case(
            "refraction pair cut in half",
            with_head(&format!("{SPHERE} 0.5")),
            7,
            49,
            |k| matches!(k, K::MissingField { field: "the sphere's index of refraction" }),
        ),
        case(
            "zero ior",
            with_head(&format!("{SPHERE} 0.5 0")),
            7,
            50,
            |k| matches!(k, K::OutOfRange { field: "the sphere's index of refraction", .. }),
        ),
        case(
            "OUTPUT without a name",
            with_head("OUTPUT   "),
            7,
            10,
            |k| matches!(k, K::BadOutputName),
        ),
        case(
            "CRLF and TABs keep columns",
            "NEAR\t1\r\nLEFT\t-1\r\nRIGHT\tx\r\n",
            3,
            7,
            |k| matches!(k, K::ExpectedNumber { field: "the right edge of the image plane", .. }),
        ),
        case(
            "a centre beyond f32's range",
            with_head("SPHERE far 1e39 0 -10 1 1 1 0.5 0 0 1 1 0.9 0 50"),
            7,
            12,
            |k| matches!(k, K::TooLong { field: "the sphere's x position", value } if *value == 1e39),
        ),
        case(
            "a light whose distance squared overflows f32",
            with_head("LIGHT sun 1e20 1e20 0 1 1 1"),
            7,
            11,
            |k| matches!(k, K::TooLong { field: "the light's x position", .. }),
        ),
        case(
            "a scale whose inverse squared underflows",
            with_head("SPHERE wall 0 0 -10 1e19 1e19 1e19 0.5 0 0 1 1 0.9 0 50"),
            7,
            21,
            |k| matches!(k, K::TooLong { field: "the sphere's x scale", .. }),
        ),
        case(
            "a scale whose inverse squared overflows",
            with_head("SPHERE dust 0 0 -1e-18 1e-19 1e-19 1e-19 0.5 0 0 1 1 0.9 0 50"),
            7,
            24,
            |k| matches!(k, K::TooThin { field: "the sphere's x scale", .. }),
        ),
        case(
            "an image plane beyond f32's range",
            "NEAR 1\nLEFT -1e19\n",
            2,
            6,
            |k| matches!(k, K::TooLong { field: "the left edge of the image plane", .. }),
        ),
        case(
            "an ellipsoid too flat for f32",
            with_head("SPHERE disc 0 0 -10 2 2e-13 2 0.5 0 0 1 1 0.9 0 50"),
            7,
            23,
            |k| {
                matches!(
                    k,
                    K::AxisRatio {
                        thin_field: "the sphere's y scale",
                        wide_field: "the sphere's x scale",
                        ..
                    }
                )
            },
        ),
        case(
            "a far light and a small sphere, the light last",
            with_head(&format!("{SPHERE}\nSPHERE dot 0 0 -5 0.01 0.01 0.01 1 1 1 1 1 0 0 1\nLIGHT sun 0 1e17 0 1 1 1")),
            9,
            13,
            |k| {
                matches!(
                    k,
                    K::LengthRatio { small, large }
                        if (small.field, small.line, large.field, large.line) == ("the sphere's x scale", 8, "the light's y position", 9)
                )
            },
        ),
        case(
            "a small sphere given after a far one",
            with_head("SPHERE far 0 0 -1e17 1e16 1e16 1e16 1 1 1 1 1 0 0 1\nSPHERE dot 0 0 -5 0.01 0.01 0.01 1 1 1 1 1 0 0 1"),
            8,
            19,
            |k| matches!(k, K::LengthRatio { small, large } if small.value == 0.01 && large.value == -1e17),
        ),
        case(
            "a sphere too wide for NEAR, NEAR last",
            "LEFT -1e-10\nRIGHT 1e-10\nBOTTOM -1e-10\nTOP 1e-10\nRES 4 4\nSPHERE room 0 0 0 1e9 1e9 1e9 1 1 1 1 1 0 0 1\nNEAR 1e-10\n",
            7,
            6,
            |k| matches!(k, K::LengthRatio { small, large } if small.field == NEAR && large.field == "the sphere's x scale"),
        ),
        case(
            "a NUL byte near the start",
            format!("{HEAD}# x\0y\n"),
            7,
            4,
            |k| matches!(k, K::Binary { byte: 0, format: None }),
        ),
        case(
            "a line past the limit",
            format!("{HEAD}# {}\n", "x".repeat(voxtrace::limits::MAX_LINE_BYTES)),
            7,
            voxtrace::limits::MAX_LINE_BYTES + 1,
            |k| matches!(k, K::LineTooLong),
        ),
        case(
            "column counts characters",
            with_head("LIGHT lümière 0 0 0 1 1 é"),
            7,
            25,
            |k| matches!(k, K::ExpectedNumber { field: "the light's blue intensity", .. }),
        ),
    ]
}

#[test]
fn library_reports_kind_line_and_column() {
    let cases = cases();
    assert!(cases.len() >= 20);
    for c in &cases {
        let err = parse(&c.text).expect_err(c.name);
        assert!((c.kind)(&err.kind), "{}: wrong kind: {err}", c.name);
        assert_eq!(
            (err.line, err.column),
            (c.line, c.column),
            "{}: {err}",
            c.name
        );
        let message = err.to_string();
        if err.is_located() {
            let at = format!("line {}, column {}: ", c.line, c.column);
            assert!(message.starts_with(&at), "{message}");
        } else {
            assert!(
                !message.starts_with("line "),
                "no line is blamed: {message}"
            );
        }
        // Fields are named in words, not by the format's placeholders.
        assert!(!message.contains('<'), "{}: {message}", c.name);
    }
}

#[test]
fn cli_exits_2_with_the_message_on_stderr() {
    let dir = std::env::temp_dir().join(format!("voxtrace-errors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (i, c) in cases().iter().enumerate() {
        let path = dir.join(format!("case{i}.txt"));
        std::fs::write(&path, &c.text).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
            .args(["render", path.to_str().unwrap(), "-o"])
            .arg(dir.join("out.png"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{}: {stderr}", c.name);
        let at = if c.line > 0 {
            format!(" --> {}:{}:{}\n", path.display(), c.line, c.column)
        } else {
            format!("voxtrace: {}: the scene ", path.display())
        };
        assert!(stderr.contains(&at), "{}: {stderr}", c.name);
        assert!(out.stdout.is_empty());
    }
    assert!(!dir.join("out.png").exists(), "no output for a bad scene");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cli_usage_errors_exit_2_and_missing_files_exit_1() {
    let bin = env!("CARGO_BIN_EXE_voxtrace");
    let status = |args: &[&str]| Command::new(bin).args(args).output().unwrap().status.code();
    assert_eq!(status(&["render"]), Some(2), "no scene given");
    assert_eq!(status(&["render", "x.txt", "--spp", "many"]), Some(2));
    assert_eq!(status(&["frobnicate"]), Some(2));
    assert_eq!(status(&["render", "/nonexistent/scene.txt"]), Some(1));
    assert_eq!(status(&["--help"]), Some(0));
}

/// The message `voxtrace render` gives for `text` read from the file
/// `name` (or from standard input when `name` is `-`), without the
/// trailing newline, and its exit code.
fn cli_message(name: &str, text: &[u8]) -> (String, Option<i32>) {
    let dir = scratch_dir(&format!("message-{}", name.replace('.', "-")));
    let out = if name == "-" {
        voxtrace_in(&dir, &["render", "-", "-o", "out.png"], Some(text))
    } else {
        std::fs::write(dir.join(name), text).unwrap();
        voxtrace_in(&dir, &["render", name, "-o", "out.png"], None)
    };
    assert!(!dir.join("out.png").exists(), "no image for a bad scene");
    std::fs::remove_dir_all(&dir).unwrap();
    let message = stderr(&out).trim_end_matches('\n').to_owned();
    (message, out.status.code())
}

#[test]
fn the_line_is_shown_with_carets_under_the_column_as_rustc_shows_it() {
    let bad = with_head("SPHERE s1 0 0 -10 2 2,0 2 0.5 0 0 1 1 0.9 0 50");
    assert_eq!(
        cli_message("bad.txt", bad.as_bytes()),
        (
            [
                "voxtrace: expected a number for the sphere's y scale, found \"2,0\"",
                " --> bad.txt:7:21",
                "  |",
                "7 | SPHERE s1 0 0 -10 2 2,0 2 0.5 0 0 1 1 0.9 0 50",
                "  |                     ^^^",
            ]
            .join("\n"),
            Some(2)
        )
    );
    // A TAB before the column widens the line as a terminal does, and the
    // caret moves with it; from standard input the origin is `<stdin>`.
    let tabbed = "NEAR\t1\nLEFT\t-1\nRIGHT\t\tx\n";
    assert_eq!(
        cli_message("-", tabbed.as_bytes()).0,
        [
            "voxtrace: expected a number for the right edge of the image plane, found \"x\"",
            " --> <stdin>:3:8",
            "  |",
            "3 | RIGHT        x",
            "  |              ^",
        ]
        .join("\n")
    );
}

#[test]
fn a_long_line_is_cut_around_the_column_and_a_wide_line_number_widens_the_gutter() {
    let mut text = String::from(HEAD);
    for i in 0..5 {
        text += &format!("# comment {i}\n");
    }
    let name = "x".repeat(150);
    let line = format!("LIGHT {name} 0 0 0 1 1 oops # {}", "y".repeat(150));
    text += &format!("{line}\n");
    let (message, code) = cli_message("long.txt", text.as_bytes());
    assert_eq!(code, Some(2));
    // The 100 characters around "oops", at index 167: 50 before it.
    assert_eq!(&line[167..171], "oops");
    assert_eq!(
        message,
        [
            "voxtrace: expected a number for the light's blue intensity, found \"oops\"".to_owned(),
            "  --> long.txt:12:168".to_owned(),
            "   |".to_owned(),
            format!("12 | ...{}...", &line[117..217]),
            format!("   | {}^^^^", " ".repeat(3 + 50)),
        ]
        .join("\n")
    );
}

#[test]
fn a_misspelt_keyword_gets_the_nearest_one() {
    let (message, code) = cli_message("typo.txt", format!("{HEAD}BAKC 0 0 0\n").as_bytes());
    assert_eq!(code, Some(2));
    assert!(
        message.starts_with(
            "voxtrace: unknown directive \"BAKC\": did you mean BACK?\n --> typo.txt:7:1\n"
        ),
        "{message}"
    );
    let e = parse(format!("{HEAD}CAMERA 0 0 0\n")).unwrap_err();
    assert_eq!(
        e.kind,
        K::UnknownKeyword {
            found: "CAMERA".into(),
            suggestion: None
        },
        "nothing near: the whole list instead"
    );
    assert!(e.to_string().contains("(expected NEAR, LEFT,"), "{e}");
}

#[test]
fn binary_files_are_named_for_their_kind_and_not_shown() {
    let elf = b"\x7fELF\x02\x01\x01\x00\x00\x00\x00\x00\x00\x00\x00\x00\x03\x00>\x00\n\x01";
    let png = b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x00\x10";
    for (bytes, kind) in [(&elf[..], "an ELF executable"), (&png[..], "a PNG image")] {
        let e = parse(bytes).unwrap_err();
        assert!(
            matches!(e.kind, K::Binary { format: Some(k), .. } if k == kind),
            "{e}"
        );
        assert_eq!(
            cli_message("-", bytes),
            (
                format!(
                    "voxtrace: this looks like a binary file ({kind}), not a scene\n --> <stdin>:1:1"
                ),
                Some(2)
            )
        );
    }
}

#[test]
fn a_missing_res_is_reported_as_missing_with_the_line_to_add() {
    let text = "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\n# the end\n";
    let e = parse(text).unwrap_err();
    assert!(!e.is_located());
    assert_eq!(
        e.to_string(),
        "the scene has no RES line: add one, such as `RES 512 512`"
    );
    assert_eq!(
        cli_message("nores.txt", text.as_bytes()),
        (
            "voxtrace: nores.txt: the scene has no RES line: add one, such as `RES 512 512`".into(),
            Some(2)
        )
    );
}

#[test]
fn fields_are_spelled_out_in_words() {
    for (line, message) in [
        (
            "NEAR x",
            "expected a number for the distance to the image plane (NEAR), found \"x\"",
        ),
        (
            "NEAR -1",
            "the distance to the image plane (NEAR) must be > 0, found -1",
        ),
        (
            "LEFT",
            "expected the left edge of the image plane, found the end of the line",
        ),
        (
            "RES 0 4",
            "the number of columns must be between 1 and 16384, found 0",
        ),
        (
            "RES 4 4.5",
            "the number of rows must be a whole number, found \"4.5\"",
        ),
        (
            "BACK 1 -1 0",
            "the background's green component must be ≥ 0, found -1",
        ),
        (
            "AMBIENT x 0 0",
            "expected a number for the ambient light's red intensity, found \"x\"",
        ),
        (
            "LIGHT l 0 0 0 1 1",
            "expected the light's blue intensity, found the end of the line",
        ),
        (
            "SPHERE s 0 0 -5 1 0 1 1 1 1 1 1 1 0 50",
            "the sphere's y scale must be non-zero, found 0",
        ),
        (
            "SPHERE s 0 0 -5 1 1 1 1 1 1 1 1 1 0 x",
            "expected a number for the sphere's specular exponent, found \"x\"",
        ),
        (
            "SPHERE 0 0 -5 1 1 1 1 1 1 1 1 1 50 x 0 1",
            "expected a number for the sphere's reflectivity, found \"x\"",
        ),
        (
            "SPHERE s 0 0 -5 1 1 1 1 1 1 1 1 1 0 50 0.5 0",
            "the sphere's index of refraction must be > 0, found 0",
        ),
    ] {
        let text = if line.starts_with("NEAR") {
            format!("{line}\n")
        } else {
            format!("NEAR 1\n{line}\n")
        };
        let e = parse(&text).unwrap_err();
        assert_eq!(e.kind.to_string(), message, "{line}");
    }
}

/// An error found once the whole text is read, on a line long gone from
/// memory (the text is read 8 MiB at a time): the line is read again.
#[test]
fn a_line_far_behind_the_end_of_a_large_file_is_still_shown() {
    let mut text = String::from("NEAR 1\nLEFT 1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 4 4\n");
    let comment = format!("# {}\n", "x".repeat(1000));
    while text.len() < 9 << 20 {
        text += &comment;
    }
    let (message, code) = cli_message("large.txt", text.as_bytes());
    assert_eq!(code, Some(2));
    assert_eq!(
        message,
        [
            "voxtrace: LEFT (1) must be less than RIGHT (1)",
            " --> large.txt:3:7",
            "  |",
            "3 | RIGHT 1",
            "  |       ^",
        ]
        .join("\n")
    );
}
