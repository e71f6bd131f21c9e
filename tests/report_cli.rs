//! `voxtrace report` end to end, on the hard-case family only (small scenes)
//! with one repetition and a tiny antialiasing size, to stay fast.

use std::process::Command;

#[test]
fn report_writes_tables_and_plot_for_the_hard_cases() {
    let out = std::env::temp_dir().join(format!("voxtrace-report-{}", std::process::id()));
    let status = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args([
            "report",
            "--families",
            "hard",
            "--reps",
            "1",
            "--aa-size",
            "16",
            "--out",
        ])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    for section in [
        "## Summary by scene family",
        "## f32 against f64",
        "## Index against brute force",
        "## The adaptive cut-off: rays by kind",
        "## Translation and scale",
        "## Every scene",
    ] {
        assert!(md.contains(section), "{section}");
    }
    // Every hard scene but the moved-eye ones, with every variant.
    for scene in [
        "hard/planet",
        "hard/glass_shell",
        "hard/mirrors",
        "hard/zero_terms",
    ] {
        assert!(
            md.contains(&format!("| {scene} | recursion | f32 depth 5 |")),
            "{scene}"
        );
        assert!(
            md.contains(&format!("| {scene} | antialiasing | f32 spp 64 |")),
            "{scene}"
        );
    }
    assert!(!md.contains("| hard/translated_1e5 |"));
    // The reference is exact against itself; an index matches brute force.
    assert!(md.contains("| precision | f64 (reference) |"));
    assert!(md.contains("| f32 index brute | 22 | 22 | 22 |"), "{md}");
    let svg = std::fs::read_to_string(out.join("time-vs-error.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("Pareto front"));
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn report_with_a_missing_suite_fails_with_exit_code_1() {
    let status = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .args([
            "report",
            "--families",
            "hard",
            "--hard",
            "/nonexistent/voxtrace",
            "--out",
        ])
        .arg(std::env::temp_dir().join("voxtrace-report-missing"))
        .status()
        .unwrap();
    assert_eq!(status.code(), Some(1));
}

/// Run from anywhere, the report finds the scenes that ship in the source
/// tree it was built from, as it does in the tree itself.
#[test]
fn report_runs_outside_the_source_tree() {
    let elsewhere =
        std::env::temp_dir().join(format!("voxtrace-report-away-{}", std::process::id()));
    std::fs::create_dir_all(&elsewhere).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .current_dir(&elsewhere)
        .args([
            "report",
            "--families",
            "hard",
            "--reps",
            "1",
            "--aa-size",
            "8",
        ])
        .args(["--out", "away"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let md = std::fs::read_to_string(elsewhere.join("away/report.md")).unwrap();
    assert!(md.contains("| hard/planet | recursion | f32 depth 5 |"));
    std::fs::remove_dir_all(&elsewhere).unwrap();
}
