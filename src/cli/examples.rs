//! The examples at the end of each subcommand's `--help`, as ripgrep and
//! cargo show them: each a command line and what it does. A test parses
//! every one, so none drifts from the flags.

/// One example: the shell line (a `voxtrace` command, perhaps with a pipe
/// or a redirection around it) and what it does.
type Example = (&'static str, &'static str);

pub const RENDER: &[Example] = &[
    (
        "voxtrace render scenes/testSample.txt -o sample.png",
        "render a scene to PNG",
    ),
    (
        "voxtrace render scene.txt --size 160 -o preview.png",
        "a quick preview 160 pixels wide, RES's aspect kept",
    ),
    (
        "voxtrace render scene.txt --spp 16 --depth 8 --adaptive -o smooth.png",
        "antialiased and deeper, cheaply",
    ),
    (
        "cat scene.txt | voxtrace render - -o - > image.png",
        "from standard input to standard output",
    ),
    (
        "voxtrace render scene.txt --remote http://127.0.0.1:8080 -o out.png",
        "render in tiles on a running service",
    ),
];

pub const SERVE: &[Example] = &[
    (
        "voxtrace serve",
        "serve on 127.0.0.1:8080, upload page at /",
    ),
    (
        "voxtrace serve --addr 0.0.0.0:9000 --renders 2 --threads 4",
        "every interface, two renders at once on four threads",
    ),
];

pub const LOAD: &[Example] = &[
    (
        "voxtrace load --url http://127.0.0.1:8080/render --scene scenes/testSample.txt -c 4 -d 10s",
        "four clients back to back for ten seconds",
    ),
    (
        "voxtrace load --url http://127.0.0.1:8080/render --scene scenes/testSample.txt --rate 50 -d 10s",
        "an open loop at 50 requests a second",
    ),
];

pub const GEN: &[Example] = &[(
    "voxtrace gen --spheres 1000000 --dist clustered --seed 1 --res 512 512 -o million.txt",
    "a million clustered spheres",
)];

pub const BENCH: &[Example] = &[
    (
        "voxtrace bench",
        "the built-in scenes, grid against brute force",
    ),
    (
        "voxtrace bench --scene million.txt --json",
        "one scene, as JSON",
    ),
];

pub const REPORT: &[Example] = &[
    ("voxtrace report", "the whole report, into docs/report"),
    (
        "voxtrace report --families hard --reps 1 --out /tmp/report",
        "the hard cases only, quickly, elsewhere",
    ),
];

pub const COMPLETIONS: &[Example] = &[
    (
        "voxtrace completions bash > ~/.local/share/bash-completion/completions/voxtrace",
        "bash",
    ),
    (
        "voxtrace completions zsh > ~/.zfunc/_voxtrace",
        "zsh (with ~/.zfunc on $fpath)",
    ),
    (
        "voxtrace completions fish > ~/.config/fish/completions/voxtrace.fish",
        "fish",
    ),
];

/// The `Examples:` section that ends a subcommand's help.
pub fn help(examples: &[Example]) -> String {
    let mut text = String::from("Examples:\n");
    for (line, what) in examples {
        text += &format!("  # {what}\n  {line}\n");
    }
    text.pop();
    text
}

/// The arguments of the `voxtrace` command in an example's shell line:
/// its words from `voxtrace` up to a pipe or a redirection.
#[cfg(test)]
fn arguments(line: &str) -> Vec<&str> {
    line.split_whitespace()
        .skip_while(|&word| word != "voxtrace")
        .take_while(|word| !["|", ">", "<"].contains(word))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn every_example_parses() {
        let all = [RENDER, SERVE, LOAD, GEN, BENCH, REPORT, COMPLETIONS];
        for (line, _) in all.into_iter().flatten() {
            let args = arguments(line);
            assert_eq!(args.first(), Some(&"voxtrace"), "{line}");
            if let Err(e) = super::super::Cli::try_parse_from(&args) {
                panic!("{line}: {e}");
            }
        }
    }

    #[test]
    fn the_arguments_stop_at_the_shell() {
        assert_eq!(
            arguments("cat s | voxtrace render - -o - > x.png"),
            ["voxtrace", "render", "-", "-o", "-"]
        );
    }
}
