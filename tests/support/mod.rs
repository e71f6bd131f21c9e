//! What the behaviour tests of `voxtrace serve` share: a server in process
//! or as a child process, a raw HTTP/1.1 client, `/metrics` readers, and
//! the attack scenes of `bench/attacks.py`.

#![allow(dead_code)]

pub mod cli;
pub mod scripted;
pub mod whitted;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Ipv4Addr, Shutdown, SocketAddr, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use voxtrace::service::{Server, ServerHandle, ServiceConfig};

/// How long any wait of a test may last before it fails: far beyond what
/// any of them needs, so only a service that never answers trips it.
pub const PATIENCE: Duration = Duration::from_secs(30);

/// A service in this process on an ephemeral loopback port.
pub fn start(config: ServiceConfig) -> ServerHandle {
    let config = ServiceConfig {
        addr: "127.0.0.1:0".into(),
        ..config
    };
    Server::bind(config).unwrap().spawn().unwrap()
}

pub fn sample(name: &str) -> Vec<u8> {
    std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenes")
            .join(name),
    )
    .unwrap()
}

/// Two nested glass spheres that reflect and refract everything, under a
/// light: at `?depth=64` the ray tree of an eye ray that enters doubles
/// every other bounce or so, without end.
pub fn nested_glass() -> Vec<u8> {
    b"NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 64 64\n\
      SPHERE a 0 0 -4 2 2 2 1 1 1 0 0 0.5 1 1 1 1.5\n\
      SPHERE b 0 0 -4 1 1 1 1 1 1 0 0 0 1 1 1 1.5\n\
      LIGHT l 0 5 0 1 1 1\n"
        .to_vec()
}

/// A scene of no spheres whose image is as large as the service renders.
pub fn largest_empty_image() -> Vec<u8> {
    b"NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 4096 4096\n".to_vec()
}

/// A request with a Host header and the body's Content-Length.
pub fn request_bytes(method: &str, target: &str, headers: &[&str], body: &[u8]) -> Vec<u8> {
    let mut head = format!("{method} {target} HTTP/1.1\r\nHost: test\r\n");
    for h in headers {
        head += &format!("{h}\r\n");
    }
    if !body.is_empty() || method == "POST" {
        head += &format!("Content-Length: {}\r\n", body.len());
    }
    head += "\r\n";
    let mut bytes = head.into_bytes();
    bytes.extend_from_slice(body);
    bytes
}

/// A client connection that reads responses one after another.
pub struct Client {
    pub reader: BufReader<TcpStream>,
}

#[derive(Debug)]
pub struct Reply {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Reply {
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }

    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    pub fn json(&self) -> serde_json::Value {
        assert_eq!(self.header("content-type"), Some("application/json"));
        serde_json::from_slice(&self.body).unwrap()
    }
}

impl Client {
    pub fn connect(addr: SocketAddr) -> Client {
        Client::over(TcpStream::connect(addr).unwrap())
    }

    /// A client from the loopback address `source` (any of 127/8), which
    /// the server sees as another peer than 127.0.0.1.
    pub fn connect_from(source: Ipv4Addr, addr: SocketAddr) -> Client {
        Client::over(connect_from(source, addr))
    }

    fn over(stream: TcpStream) -> Client {
        stream.set_read_timeout(Some(PATIENCE)).unwrap();
        Client {
            reader: BufReader::new(stream),
        }
    }

    pub fn send(&mut self, bytes: &[u8]) {
        self.reader.get_mut().write_all(bytes).unwrap();
    }

    pub fn request(&mut self, method: &str, target: &str, headers: &[&str], body: &[u8]) -> Reply {
        self.send(&request_bytes(method, target, headers, body));
        self.read_reply(method == "HEAD")
    }

    /// Shuts down the sending side, as a client does that has said all it will.
    pub fn half_close(&mut self) {
        self.reader.get_ref().shutdown(Shutdown::Write).unwrap();
    }

    /// The next response, interim (1xx) ones included.
    pub fn read_reply(&mut self, head_only: bool) -> Reply {
        let mut line = String::new();
        self.reader.read_line(&mut line).unwrap();
        let status = line
            .split(' ')
            .nth(1)
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("bad status line {line:?}"));
        let mut headers = Vec::new();
        loop {
            line.clear();
            self.reader.read_line(&mut line).unwrap();
            let line = line.trim_end();
            if line.is_empty() {
                break;
            }
            let (name, value) = line.split_once(':').unwrap();
            headers.push((name.to_owned(), value.trim().to_owned()));
        }
        let mut reply = Reply {
            status,
            headers,
            body: Vec::new(),
        };
        if !head_only && status >= 200 {
            let length: usize = reply.header("content-length").unwrap().parse().unwrap();
            reply.body = vec![0; length];
            self.reader.read_exact(&mut reply.body).unwrap();
        }
        reply
    }

    /// The next final response, skipping interim ones as HTTP/1.1 clients must.
    pub fn read_final_reply(&mut self) -> Reply {
        loop {
            let reply = self.read_reply(false);
            if reply.status >= 200 {
                return reply;
            }
        }
    }

    /// Whether the server has ended the connection, cleanly: it reads what
    /// is left of a refused request before it closes, so the kernel ends
    /// the connection rather than resetting it. A read that times out is
    /// no close.
    pub fn closed(&mut self) -> bool {
        let mut rest = Vec::new();
        matches!(self.reader.read_to_end(&mut rest), Ok(0))
    }
}

/// A TCP connection to `server` from the loopback address `source`: std
/// cannot bind a socket before connecting it, so this asks the OS itself.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn connect_from(source: Ipv4Addr, server: SocketAddr) -> TcpStream {
    use std::os::fd::{FromRawFd, OwnedFd};
    let SocketAddr::V4(server) = server else {
        panic!("{server} is not IPv4");
    };
    let address = |ip: Ipv4Addr, port: u16| libc::sockaddr_in {
        sin_family: libc::AF_INET as libc::sa_family_t,
        sin_port: port.to_be(),
        sin_addr: libc::in_addr {
            s_addr: u32::from(ip).to_be(),
        },
        sin_zero: [0; 8],
    };
    let length = std::mem::size_of::<libc::sockaddr_in>() as libc::socklen_t;
    // SAFETY: socket() takes no pointers; its result is checked before use.
    let fd = unsafe { libc::socket(libc::AF_INET, libc::SOCK_STREAM | libc::SOCK_CLOEXEC, 0) };
    assert!(fd >= 0, "socket: {}", std::io::Error::last_os_error());
    // SAFETY: `fd` is a socket just created and owned by nothing else, so
    // the OwnedFd is its only owner and closes it exactly once.
    let owned = unsafe { OwnedFd::from_raw_fd(fd) };
    let local = address(source, 0);
    // SAFETY: `local` is a valid sockaddr_in that lives across the call,
    // and `length` is its size.
    let bound = unsafe { libc::bind(fd, (&raw const local).cast(), length) };
    assert_eq!(bound, 0, "bind: {}", std::io::Error::last_os_error());
    let remote = address(*server.ip(), server.port());
    // SAFETY: as for bind: a valid sockaddr_in and its size; the socket is
    // blocking, so connect returns once connected or failed.
    let connected = unsafe { libc::connect(fd, (&raw const remote).cast(), length) };
    assert_eq!(connected, 0, "connect: {}", std::io::Error::last_os_error());
    TcpStream::from(owned)
}

/// The value of `metric` (the whole series name, labels included) in `/metrics`.
pub fn metric(addr: SocketAddr, metric: &str) -> Option<u64> {
    let text = Client::connect(addr)
        .request("GET", "/metrics", &[], b"")
        .text();
    text.lines()
        .find_map(|l| l.strip_prefix(metric)?.strip_prefix(' ')?.parse().ok())
}

/// The value of `metric` (the whole series name, labels included) in
/// `/metrics`, for a value that need not be a whole number (seconds).
pub fn metric_value(addr: SocketAddr, metric: &str) -> Option<f64> {
    let text = Client::connect(addr)
        .request("GET", "/metrics", &[], b"")
        .text();
    text.lines()
        .find_map(|l| l.strip_prefix(metric)?.strip_prefix(' ')?.parse().ok())
}

/// The sum of every series of the family sample `name` (`voxtrace_rays_total`
/// over its `kind` labels, say) in `/metrics`.
pub fn metric_sum(addr: SocketAddr, name: &str) -> u64 {
    let text = Client::connect(addr)
        .request("GET", "/metrics", &[], b"")
        .text();
    text.lines()
        .filter_map(|l| {
            let rest = l.strip_prefix(name)?;
            let value = rest
                .strip_prefix(' ')
                .or_else(|| rest.strip_prefix('{')?.split_once("} ").map(|(_, v)| v))?;
            value.parse::<u64>().ok()
        })
        .sum()
}

/// Polls `/metrics` until `ready` holds of the metric's value.
pub fn wait_until(addr: SocketAddr, metric_name: &str, ready: impl Fn(u64) -> bool) -> u64 {
    let started = Instant::now();
    loop {
        let now = metric(addr, metric_name);
        if let Some(value) = now.filter(|&v| ready(v)) {
            return value;
        }
        assert!(
            started.elapsed() < PATIENCE,
            "{metric_name} never got there (it is {now:?})"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Polls `done` until it holds.
pub fn eventually(what: &str, done: impl Fn() -> bool) {
    let started = Instant::now();
    while !done() {
        assert!(started.elapsed() < PATIENCE, "never: {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Polls `/metrics` until `metric` reaches `value`.
pub fn wait_for_metric(addr: SocketAddr, metric_name: &str, value: u64) {
    wait_until(addr, metric_name, |v| v == value);
}

/// `voxtrace serve` as a child process, so that its resident memory is
/// its own; killed when dropped.
pub struct ServeProcess {
    child: Child,
    /// The rest of its standard output, after the `listening on` line.
    stdout: BufReader<std::process::ChildStdout>,
    pub addr: SocketAddr,
}

impl ServeProcess {
    pub fn start(args: &[&str]) -> ServeProcess {
        let mut child = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
            .args(["serve", "--addr", "127.0.0.1:0"])
            .args(args)
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        let mut stdout = BufReader::new(child.stdout.take().unwrap());
        stdout.read_line(&mut line).unwrap();
        let addr = line
            .trim()
            .strip_prefix("listening on http://")
            .unwrap_or_else(|| panic!("the server said {line:?}"))
            .parse()
            .unwrap();
        ServeProcess {
            child,
            stdout,
            addr,
        }
    }

    /// Sends it the signal `signal` (SIGTERM, SIGKILL, …).
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    pub fn signal(&self, signal: libc::c_int) {
        signal_process(self.child.id(), signal);
    }

    /// Waits for it to exit, [`PATIENCE`] at most; its exit status and
    /// what it wrote to stdout after the first line.
    pub fn wait_for_exit(&mut self) -> (std::process::ExitStatus, String) {
        let started = Instant::now();
        let status = loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                break status;
            }
            assert!(started.elapsed() < PATIENCE, "the server never exited");
            std::thread::sleep(Duration::from_millis(10));
        };
        let mut rest = String::new();
        self.stdout.read_to_string(&mut rest).unwrap();
        (status, rest)
    }

    /// A line of `/proc/PID/status` in bytes: `VmRSS` now, `VmHWM` its peak.
    pub fn memory(&self, field: &str) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id())).unwrap();
        let kib: u64 = status
            .lines()
            .find_map(|l| l.strip_prefix(field)?.strip_prefix(':'))
            .unwrap_or_else(|| panic!("no {field}"))
            .trim()
            .trim_end_matches("kB")
            .trim()
            .parse()
            .unwrap();
        kib * 1024
    }
}

impl Drop for ServeProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Sends `signal` to the process `pid`.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub fn signal_process(pid: u32, signal: libc::c_int) {
    // SAFETY: kill() takes no pointers; a pid that has gone is an error
    // it reports, checked here.
    let sent = unsafe { libc::kill(pid as libc::pid_t, signal) };
    assert_eq!(sent, 0, "kill {pid}: {}", std::io::Error::last_os_error());
}
