//! `voxtrace render` within bounds: endless and huge inputs end at once with
//! a clear message (checked by their message and exit code, under a memory
//! limit that reading them whole would break, never by the clock), the
//! scene file is never written over, OUTPUT names only a plain file, and a
//! PNG never goes to a terminal.

mod support;

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_voxtrace");

fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxtrace-bounds-{tag}-{}", std::process::id()));
    fs::create_dir_all(&dir).unwrap();
    dir
}

fn scene_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name)
}

fn voxtrace(dir: &Path, args: &[&str]) -> Output {
    Command::new(BIN)
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap()
}

/// `voxtrace` with its address space limited to `kib` KiB, so that a read
/// of the whole input fails instead of succeeding slowly.
fn voxtrace_within(kib: u64, dir: &Path, args: &[&str]) -> Output {
    Command::new("sh")
        .current_dir(dir)
        .arg("-c")
        .arg(format!("ulimit -v {kib} && exec \"$0\" \"$@\""))
        .arg(BIN)
        .args(args)
        .output()
        .unwrap()
}

/// Half a GiB: a few times what rendering a small scene takes, a quarter
/// of the 2 GiB inputs below.
const MEMORY_KIB: u64 = 512 * 1024;

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn dev_zero_is_refused_as_binary_on_its_first_line() {
    let dir = temp_dir("zero");
    let out = voxtrace_within(
        MEMORY_KIB,
        &dir,
        &["render", "/dev/zero", "--threads", "1", "-o", "out.ppm"],
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(
            "voxtrace: byte 0x00 is a control character: this looks like a binary file, not a scene\n --> /dev/zero:1:1\n"
        ),
        "{}",
        stderr(&out)
    );
    assert!(!dir.join("out.ppm").exists());
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_sparse_2_gib_file_is_refused_for_its_size_and_read_no_further_than_its_error() {
    let dir = temp_dir("sparse");
    let path = dir.join("huge.txt");
    let file = fs::File::create(&path).unwrap();
    file.set_len(2 << 30).unwrap();
    drop(file);
    let run = |extra: &[&str]| {
        let mut args = vec!["render", "huge.txt", "--threads", "1", "-o", "out.ppm"];
        args.extend_from_slice(extra);
        voxtrace_within(MEMORY_KIB, &dir, &args)
    };

    let out = run(&[]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(
            "huge.txt: the scene has 2147483648 bytes, more than the limit of 1610612736; --max-scene-bytes raises the limit"
        ),
        "{}",
        stderr(&out)
    );

    // Allowed in, its zeros are binary data from the first byte.
    let raised = ["--max-scene-bytes", "4294967296"];
    let out = run(&raised);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("byte 0x00 is a control character: this looks like a binary file, not a scene\n --> huge.txt:1:1\n"),
        "{}",
        stderr(&out)
    );

    // A bad first line ends the read there, with that line's error.
    fs::write(&path, "NEAR x\n").unwrap();
    fs::File::options()
        .write(true)
        .open(&path)
        .unwrap()
        .set_len(2 << 30)
        .unwrap();
    let out = run(&raised);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(concat!(
            "voxtrace: expected a number for the distance to the image plane (NEAR), found \"x\"\n",
            " --> huge.txt:1:6\n",
            "  |\n",
            "1 | NEAR x\n",
            "  |      ^\n"
        )),
        "{}",
        stderr(&out)
    );
    assert!(!dir.join("out.ppm").exists());
    fs::remove_dir_all(&dir).unwrap();
}

/// A copy of `testShadow.txt` named `name` in `dir`, its OUTPUT line set to `output`.
fn scene_named(dir: &Path, name: &str, output: &str) -> Vec<u8> {
    let text = fs::read_to_string(scene_path("testShadow.txt")).unwrap();
    let text: String = text
        .lines()
        .filter(|l| !l.starts_with("OUTPUT"))
        .map(|l| format!("{l}\n"))
        .collect();
    let text = format!("{text}OUTPUT {output}\n").into_bytes();
    fs::write(dir.join(name), &text).unwrap();
    text
}

#[test]
fn the_scene_file_is_never_written_over() {
    let dir = temp_dir("self");
    let original = scene_named(&dir, "self.txt", "self.txt");
    // OUTPUT naming the scene itself becomes self.ppm.
    let out = voxtrace(&dir, &["render", "self.txt"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(fs::read(dir.join("self.txt")).unwrap(), original);
    assert!(fs::read(dir.join("self.ppm")).unwrap().starts_with(b"P6\n"));

    // -o naming it is refused: a `.txt` for its extension, before anything
    // is read.
    let dir_name = dir.file_name().unwrap().to_str().unwrap();
    for output in ["self.txt", "./self.txt", &format!("../{dir_name}/self.txt")] {
        let out = voxtrace(&dir, &["render", "self.txt", "-o", output]);
        assert_eq!(out.status.code(), Some(2), "{output}: {}", stderr(&out));
        assert!(
            stderr(&out).contains("cannot tell the image format from the name"),
            "{}",
            stderr(&out)
        );
        assert_eq!(fs::read(dir.join("self.txt")).unwrap(), original);
    }
    // A scene with an image name, named by -o under any spelling, or a
    // link to a scene: refused for being the scene.
    let shot = scene_named(&dir, "shot.ppm", "other.ppm");
    let mut spellings = vec![
        ("shot.ppm", "shot.ppm".to_owned()),
        ("shot.ppm", "./shot.ppm".to_owned()),
        ("shot.ppm", format!("../{dir_name}/shot.ppm")),
    ];
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(dir.join("self.txt"), dir.join("link.ppm")).unwrap();
        spellings.push(("self.txt", "link.ppm".to_owned()));
    }
    for (scene, output) in &spellings {
        let out = voxtrace(&dir, &["render", scene, "-o", output]);
        assert_eq!(out.status.code(), Some(2), "{output}: {}", stderr(&out));
        assert!(
            stderr(&out).contains(&format!(
                "is the scene file {scene} itself: refusing to write the image over it"
            )),
            "{}",
            stderr(&out)
        );
        assert_eq!(fs::read(dir.join("self.txt")).unwrap(), original);
        assert_eq!(fs::read(dir.join("shot.ppm")).unwrap(), shot, "{output}");
    }

    // A scene whose own name is an image name, OUTPUT naming it.
    let shot = scene_named(&dir, "shot.ppm", "shot.ppm");
    let out = voxtrace(&dir, &["render", "shot.ppm"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_eq!(fs::read(dir.join("shot.ppm")).unwrap(), shot);
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn output_names_only_a_plain_file_in_the_current_directory() {
    let dir = temp_dir("names");
    for (output, expected) in [
        ("a\rb.ppm", "a_b.ppm"),
        ("-", "-.ppm"),
        ("sub/../../x y.PNG", "x_y.png"),
    ] {
        scene_named(&dir, "scene.txt", output);
        let out = voxtrace(&dir, &["render", "scene.txt"]);
        assert!(out.status.success(), "{output:?}: {}", stderr(&out));
        assert!(
            out.stdout.is_empty(),
            "{output:?}: nothing on standard output"
        );
        let bytes = fs::read(dir.join(expected)).unwrap();
        let magic: &[u8] = if expected.ends_with(".png") {
            b"\x89PNG"
        } else {
            b"P6\n"
        };
        assert!(bytes.starts_with(magic), "{output:?}");
    }
    let mut names: Vec<String> = fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["-.ppm", "a_b.ppm", "scene.txt", "x_y.png"]);
    fs::remove_dir_all(&dir).unwrap();
}

/// Standard output on a pseudo-terminal, as in an interactive shell.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[test]
fn a_png_is_never_written_to_a_terminal() {
    use std::os::fd::{FromRawFd, OwnedFd};
    let (mut master, mut slave) = (0, 0);
    // SAFETY: openpty writes two descriptors into the integers it is given;
    // the null name, termios and window size pointers are allowed.
    let status = unsafe {
        libc::openpty(
            &mut master,
            &mut slave,
            std::ptr::null_mut(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(status, 0, "openpty");
    // SAFETY: both descriptors were just opened and nothing else owns them.
    let (master, slave) = unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
    // What reaches the terminal, read as it comes so that a writer never
    // blocks on a full terminal; the read ends (EIO) once the child is gone.
    let screen = std::thread::spawn(move || {
        let mut master = fs::File::from(master);
        let (mut seen, mut buf) = (Vec::new(), [0u8; 4096]);
        while let Ok(n @ 1..) = std::io::Read::read(&mut master, &mut buf) {
            seen.extend_from_slice(&buf[..n]);
        }
        seen
    });
    let dir = temp_dir("tty");
    let out = Command::new(BIN)
        .current_dir(&dir)
        .args([
            "render",
            scene_path("testShadow.txt").to_str().unwrap(),
            "-o",
            "-",
        ])
        .stdout(slave)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("standard output is a terminal: redirect it"),
        "{}",
        stderr(&out)
    );
    assert!(
        screen.join().unwrap().is_empty(),
        "nothing reached the terminal"
    );
    fs::remove_dir_all(&dir).unwrap();
}

/// The same limit reads the same on the command line and over HTTP.
#[test]
fn limits_are_worded_alike_on_the_command_line_and_over_http() {
    let dir = temp_dir("wording");
    let scene = scene_path("testShadow.txt");
    let scene = scene.to_str().unwrap();
    let text = fs::read(scene).unwrap();
    let server = support::start(voxtrace::service::ServiceConfig {
        max_body: 100,
        ..Default::default()
    });
    let mut client = support::Client::connect(server.addr());
    for (flag, value, query) in [("--spp", "5000", "spp=5000"), ("--depth", "65", "depth=65")] {
        let out = voxtrace(&dir, &["render", scene, flag, value]);
        assert_eq!(out.status.code(), Some(2));
        let reply = client.request("POST", &format!("/render?{query}"), &[], b"x");
        assert_eq!(reply.status, 400);
        let message = reply.text();
        assert!(
            stderr(&out).contains(message.trim_end()),
            "{}\n{message}",
            stderr(&out)
        );
    }
    let out = voxtrace(&dir, &["render", scene, "--max-scene-bytes", "100"]);
    assert_eq!(out.status.code(), Some(2));
    let reply = client.request("POST", "/render", &[], &text);
    assert_eq!(reply.status, 413);
    let message = format!(
        "the scene has {} bytes, more than the limit of 100",
        text.len()
    );
    assert_eq!(reply.text(), format!("{message}\n"));
    assert!(stderr(&out).contains(&message), "{}", stderr(&out));
    server.stop();
    fs::remove_dir_all(&dir).unwrap();
}
