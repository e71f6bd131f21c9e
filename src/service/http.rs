//! HTTP/1.1 on a `TcpStream`: reading a request head and body under
//! deadlines, and writing a response. Framing only; what a request means is
//! decided in `routes`.

use super::admission::BodyCharge;
use super::memory_budget::Charge;
use crate::limits;
use std::cell::Cell;
use std::fmt::Write as _;
use std::io::{self, IoSlice, Read, Write};
use std::net::{Shutdown, TcpStream};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Bytes asked of the socket per read of a head, or of a discarded body.
const READ_CHUNK: usize = 4096;
/// A body's buffer (and its charge against the body budget) starts at this
/// size and doubles as its bytes arrive, so it is never more than twice
/// what arrived (plus this) and a large body is moved only a few times.
const BODY_CHUNK: usize = 64 * 1024;
/// Bytes handed to the socket per write of a response, so that the time
/// left is judged between writes.
const WRITE_CHUNK: usize = 64 * 1024;
/// How long the `100 Continue` that tells a half-closed client from a
/// departed one may take to write: it is a few bytes into an empty buffer.
const PROBE_WRITE: Duration = Duration::from_millis(100);
/// The shortest socket read or write timeout (std refuses zero, which to
/// the OS means none at all).
const MIN_SOCKET_TIMEOUT: Duration = Duration::from_millis(1);

/// How long each phase of a request may take. Each is a deadline on the
/// phase's whole time, not on one read: a client that trickles a byte at a
/// time is cut off just the same. A read blocks with the time left as its
/// socket timeout, so a waiting connection costs no CPU.
#[derive(Clone, Copy, Debug)]
pub struct Timeouts {
    /// From the end of the previous response (or the accept) to the first
    /// byte of the next request.
    pub idle: Duration,
    /// From the first byte of a request to the end of its head.
    pub head: Duration,
}

/// Why no request could be read.
#[derive(Debug)]
pub enum NoRequest {
    /// The client closed the connection or went idle, or the server is
    /// stopping, between requests: close without a word.
    Closed,
    /// The client started a request and stalled (408).
    Stalled,
    /// The head is larger than [`limits::MAX_HEAD_BYTES`] or has more than
    /// [`limits::MAX_HEADERS`] lines (431).
    HeadTooLarge,
    /// Not HTTP/1.x (400).
    Malformed(String),
    /// The body would have taken the bodies held in memory past their
    /// budget; it was read and thrown away (503).
    OverBudget,
    /// The connection failed (reset, or a socket error).
    Io,
}

/// The request line and headers. Header names are lower case.
#[derive(Debug)]
pub struct RequestHead {
    pub method: String,
    /// The path without the query, e.g. `/render`.
    pub path: String,
    /// What follows `?`, without it; empty if none.
    pub query: String,
    /// 0 for HTTP/1.0, 1 for HTTP/1.1.
    pub minor_version: u8,
    pub headers: Vec<(String, String)>,
}

/// How the request says its body is framed.
#[derive(Debug, PartialEq, Eq)]
pub enum BodyFraming {
    /// No body, or `Content-Length` bytes.
    Length(u64),
    /// No `Content-Length` (and no body).
    Absent,
    /// `Transfer-Encoding` of any kind: refused with 411.
    Encoded,
    /// A `Content-Length` that is not one decimal number (400).
    Invalid,
}

impl RequestHead {
    /// The value of the first header named `name` (lower case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }

    /// The values of every header named `name` (lower case) as one list,
    /// as RFC 9110 §5.3 combines repeated list headers; `None` if there is none.
    pub fn list_header(&self, name: &str) -> Option<String> {
        let values: Vec<&str> = self
            .headers
            .iter()
            .filter(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
            .collect();
        (!values.is_empty()).then(|| values.join(", "))
    }

    /// Whether a `Connection` header lists `token`.
    fn connection_has(&self, token: &str) -> bool {
        self.headers
            .iter()
            .filter(|(n, _)| n == "connection")
            .flat_map(|(_, v)| v.split(','))
            .any(|t| t.trim().eq_ignore_ascii_case(token))
    }

    /// HTTP/1.1 keeps the connection unless told `close`; HTTP/1.0 closes
    /// it unless told `keep-alive`.
    pub fn wants_keep_alive(&self) -> bool {
        if self.minor_version >= 1 {
            !self.connection_has("close")
        } else {
            self.connection_has("keep-alive")
        }
    }

    pub fn expects_continue(&self) -> bool {
        self.header("expect")
            .is_some_and(|v| v.trim().eq_ignore_ascii_case("100-continue"))
    }

    /// Whether the client takes a JSON error body.
    pub fn accepts_json(&self) -> bool {
        self.list_header("accept")
            .is_some_and(|v| v.to_ascii_lowercase().contains("application/json"))
    }

    pub fn body_framing(&self) -> BodyFraming {
        if self.header("transfer-encoding").is_some() {
            return BodyFraming::Encoded;
        }
        let mut lengths = self
            .headers
            .iter()
            .filter(|(n, _)| n == "content-length")
            .map(|(_, v)| v.trim());
        let Some(first) = lengths.next() else {
            return BodyFraming::Absent;
        };
        // Repeated headers must agree (RFC 9112 §6.3); a list or a sign is invalid.
        let parsed = (!first.is_empty() && first.bytes().all(|b| b.is_ascii_digit()))
            .then(|| first.parse::<u64>().ok())
            .flatten();
        match parsed {
            Some(n) if lengths.all(|other| other == first) => BodyFraming::Length(n),
            _ => BodyFraming::Invalid,
        }
    }
}

/// A client connection and the bytes received on it but not yet consumed
/// (the start of a body, or a pipelined next request). The buffer never
/// holds more than a head's worth plus one read.
pub struct Connection {
    /// Shared with the registry of open connections, which shuts its
    /// reading side down when the server stops.
    pub stream: Arc<TcpStream>,
    pending: Vec<u8>,
    /// Since when the connection has been ready for its next request: its
    /// accept, then the end of each response.
    ready_since: Instant,
    /// A `100 Continue` has gone out to tell a half-closed client from a
    /// departed one (see [`Connection::client_gone`]).
    probed: Cell<bool>,
    /// The client was found gone.
    gone: Cell<bool>,
}

impl Connection {
    pub fn new(stream: Arc<TcpStream>, accepted: Instant) -> Self {
        Connection {
            stream,
            pending: Vec::new(),
            ready_since: accepted,
            probed: Cell::new(false),
            gone: Cell::new(false),
        }
    }

    /// Marks the end of a response: the idle clock starts again.
    pub fn request_done(&mut self) {
        self.ready_since = Instant::now();
        self.probed.set(false);
    }

    /// Reads the next request head: its first byte within `timeouts.idle`
    /// of the connection becoming ready (its accept, or the previous
    /// response), the rest within `timeouts.head` of the first byte. What
    /// already arrived is always read once before a deadline is judged.
    pub fn read_head(&mut self, timeouts: &Timeouts) -> Result<RequestHead, NoRequest> {
        let mut head_started = (!self.pending.is_empty()).then(Instant::now);
        let mut read_once = false;
        loop {
            if !self.pending.is_empty() {
                if let Some(head) = self.parse_pending()? {
                    return Ok(head);
                }
            }
            let deadline = match head_started {
                None => self.ready_since + timeouts.idle,
                Some(t) => t + timeouts.head,
            };
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() && read_once {
                return Err(match head_started {
                    None => NoRequest::Closed,
                    Some(_) => NoRequest::Stalled,
                });
            }
            read_once = true;
            match self.read_some(left) {
                Ok(0) => return Err(NoRequest::Closed),
                Ok(_) => {
                    head_started.get_or_insert_with(Instant::now);
                }
                Err(e) if is_timeout(&e) => {}
                Err(_) => return Err(NoRequest::Io),
            }
        }
    }

    /// Parses the pending bytes: a whole head (consumed), `None` if more
    /// bytes are needed, or why they can never make a head.
    fn parse_pending(&mut self) -> Result<Option<RequestHead>, NoRequest> {
        let mut headers = [httparse::EMPTY_HEADER; limits::MAX_HEADERS];
        let mut request = httparse::Request::new(&mut headers);
        match request.parse(&self.pending) {
            Ok(httparse::Status::Complete(len)) if len > limits::MAX_HEAD_BYTES => {
                Err(NoRequest::HeadTooLarge)
            }
            Ok(httparse::Status::Complete(len)) => {
                let head = to_head(&request);
                self.pending.drain(..len);
                Ok(Some(head))
            }
            Ok(httparse::Status::Partial) if self.pending.len() > limits::MAX_HEAD_BYTES => {
                Err(NoRequest::HeadTooLarge)
            }
            Ok(httparse::Status::Partial) => Ok(None),
            Err(httparse::Error::TooManyHeaders) => Err(NoRequest::HeadTooLarge),
            Err(e) => Err(NoRequest::Malformed(format!("malformed request head: {e}"))),
        }
    }

    /// Reads exactly `len` body bytes within `timeout` (of the whole
    /// body). The buffer grows, and `charge` with it, only as bytes arrive;
    /// if the budget cannot take them, the rest of the body is thrown away.
    pub fn read_body(
        &mut self,
        len: usize,
        timeout: Duration,
        charge: &mut BodyCharge,
    ) -> Result<Vec<u8>, NoRequest> {
        let deadline = Instant::now() + timeout;
        let mut body = Vec::new();
        let mut filled = 0;
        while filled < len {
            if filled == body.len() {
                let more = (len - filled).min(filled.max(BODY_CHUNK));
                if !charge.grow(more as u64) {
                    drop(body);
                    self.discard(len - filled, deadline)?;
                    return Err(NoRequest::OverBudget);
                }
                body.reserve_exact(more);
                body.resize(filled + more, 0);
            }
            if !self.pending.is_empty() {
                let n = self.pending.len().min(body.len() - filled);
                body[filled..filled + n].copy_from_slice(&self.pending[..n]);
                self.pending.drain(..n);
                filled += n;
                continue;
            }
            let end = body.len();
            filled += self.read_before(deadline, &mut body[filled..end])?;
        }
        Ok(body)
    }

    /// Reads and throws away `len` body bytes within `timeout`: a body no
    /// route needs is never held.
    pub fn discard_body(&mut self, len: usize, timeout: Duration) -> Result<(), NoRequest> {
        self.discard(len, Instant::now() + timeout)
    }

    fn discard(&mut self, len: usize, deadline: Instant) -> Result<(), NoRequest> {
        let from_pending = len.min(self.pending.len());
        self.pending.drain(..from_pending);
        let mut left = len - from_pending;
        let mut chunk = [0u8; READ_CHUNK];
        while left > 0 {
            let want = left.min(chunk.len());
            left -= self.read_before(deadline, &mut chunk[..want])?;
        }
        Ok(())
    }

    /// One read of at most `buf.len()` bytes (at least one) before `deadline`.
    fn read_before(&mut self, deadline: Instant, buf: &mut [u8]) -> Result<usize, NoRequest> {
        loop {
            let Some(left) = deadline.checked_duration_since(Instant::now()) else {
                return Err(NoRequest::Stalled);
            };
            self.stream
                .set_read_timeout(Some(left.max(MIN_SOCKET_TIMEOUT)))
                .map_err(|_| NoRequest::Io)?;
            match (&*self.stream).read(buf) {
                Ok(0) => return Err(NoRequest::Closed),
                Ok(n) => return Ok(n),
                Err(e) if is_timeout(&e) => {}
                Err(_) => return Err(NoRequest::Io),
            }
        }
    }

    /// Ends a connection the server closes after an answer: shuts the
    /// sending side (the client sees the answer end), then reads and throws
    /// away what the client still sends until it closes its side, or for
    /// [`limits::LINGER_MS`] or [`limits::LINGER_BYTES`], whichever comes
    /// first. Closed with bytes unread, a connection is reset: the client's
    /// next write fails, and some systems discard the answer it has not
    /// read yet.
    pub fn linger(&mut self) {
        if self.stream.shutdown(Shutdown::Write).is_err() {
            return;
        }
        let deadline = Instant::now() + Duration::from_millis(limits::LINGER_MS);
        discard(|chunk| self.read_before(deadline, chunk).ok());
    }

    /// Ends a connection the server closes without answering, as it stops:
    /// takes in what the client has already sent (a request begun, say),
    /// so that the close reaches the client as an end and not as a reset.
    /// Never waits: the reading side is shut first, and what arrives after
    /// that is not looked for.
    pub fn close_unanswered(&mut self) {
        if self.stream.shutdown(Shutdown::Read).is_err()
            || self.stream.set_nonblocking(true).is_err()
        {
            return;
        }
        discard(|chunk| (&*self.stream).read(chunk).ok());
    }

    /// Whether body bytes have already arrived (then `100 Continue` is moot).
    pub fn has_pending(&self) -> bool {
        !self.pending.is_empty()
    }

    fn read_some(&mut self, timeout: Duration) -> io::Result<usize> {
        self.stream
            .set_read_timeout(Some(timeout.max(MIN_SOCKET_TIMEOUT)))?;
        let mut chunk = [0u8; READ_CHUNK];
        let n = (&*self.stream).read(&mut chunk)?;
        self.pending.extend_from_slice(&chunk[..n]);
        Ok(n)
    }

    /// Whether the client has left: reset the connection, or closed it
    /// altogether. An end of stream alone does not say so: a client that
    /// shut down only its sending side (after its request, as many do) still
    /// waits for the answer. So the first time the end is seen, a `100
    /// Continue` goes out, which an HTTP/1.1 client must take and skip
    /// (RFC 9110 §15.2) whether it expected one or not; a client that closed
    /// its socket answers it with a reset, seen at a later call. Without
    /// `may_probe` (an HTTP/1.0 client, which must not be sent a 1xx) an end
    /// of stream is taken as a half-close. Pipelined bytes or nothing to
    /// read mean it is still there.
    pub fn client_gone(&self, may_probe: bool) -> bool {
        if self.gone.get() {
            return true;
        }
        let gone = match self.peek_end() {
            End::Open => false,
            End::Reset => true,
            End::Closed if self.stream.take_error().ok().flatten().is_some() => true,
            End::Closed if !may_probe || self.probed.get() => false,
            End::Closed => {
                self.probed.set(true);
                let soon = Instant::now() + PROBE_WRITE;
                write_before(&self.stream, CONTINUE, &[], soon).is_err()
            }
        };
        self.gone.set(gone);
        gone
    }

    /// What a non-blocking peek finds at the connection's receiving end.
    fn peek_end(&self) -> End {
        if self.stream.set_nonblocking(true).is_err() {
            return End::Open;
        }
        let mut probe = [0u8; 1];
        let end = match self.stream.peek(&mut probe) {
            Ok(0) => End::Closed,
            Ok(_) => End::Open,
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
                ) =>
            {
                End::Open
            }
            Err(_) => End::Reset,
        };
        let _ = self.stream.set_nonblocking(false);
        end
    }
}

/// The receiving end of a connection, as a peek finds it.
enum End {
    /// Bytes to read, or none yet.
    Open,
    /// The end of the stream: the client closed its socket, or only its
    /// sending side.
    Closed,
    /// Reset, or another error.
    Reset,
}

/// Reads and throws away what `read` gives, [`limits::LINGER_BYTES`] at
/// most, until it gives nothing (an end, an error, a deadline).
fn discard(mut read: impl FnMut(&mut [u8]) -> Option<usize>) {
    let mut chunk = [0u8; READ_CHUNK];
    let mut left = limits::LINGER_BYTES;
    while left > 0 {
        match read(&mut chunk) {
            Some(n) if n > 0 => left = left.saturating_sub(n),
            _ => return,
        }
    }
}

fn is_timeout(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
    )
}

fn to_head(request: &httparse::Request) -> RequestHead {
    let target = request.path.unwrap_or("/");
    // The absolute form (`http://host/path`) names the same resource as its path.
    let target = match target.split_once("://") {
        Some((_, rest)) => rest.find('/').map_or("/", |i| &rest[i..]),
        None => target,
    };
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    RequestHead {
        method: request.method.unwrap_or("").to_owned(),
        path: path.to_owned(),
        query: query.to_owned(),
        minor_version: request.version.unwrap_or(1),
        headers: request
            .headers
            .iter()
            .map(|h| {
                (
                    h.name.to_ascii_lowercase(),
                    String::from_utf8_lossy(h.value).into_owned(),
                )
            })
            .collect(),
    }
}

/// A response ready to be written: status, headers, and the whole body.
#[derive(Debug)]
pub struct Response {
    pub status: u16,
    pub headers: Vec<(&'static str, String)>,
    pub body: Vec<u8>,
    /// The kind of error it reports, if it is one (counted in `/metrics`).
    pub error: Option<&'static str>,
    /// The body's charge against the memory budget, given back once the
    /// response has been written (or given up on) and dropped.
    pub hold: Option<Charge>,
}

impl Response {
    pub fn new(status: u16, content_type: &str, body: impl Into<Vec<u8>>) -> Self {
        Response {
            status,
            headers: vec![("Content-Type", content_type.to_owned())],
            body: body.into(),
            error: None,
            hold: None,
        }
    }

    pub fn with_header(mut self, name: &'static str, value: impl Into<String>) -> Self {
        self.headers.push((name, value.into()));
        self
    }

    /// The status line and headers (Content-Length included, also for a
    /// HEAD response, which has no body).
    pub fn head(&self, keep_alive: bool) -> Vec<u8> {
        let mut head = format!("HTTP/1.1 {} {}\r\n", self.status, reason(self.status));
        for (name, value) in &self.headers {
            let _ = write!(head, "{name}: {value}\r\n");
        }
        let _ = write!(head, "Content-Length: {}\r\n", self.body.len());
        head.push_str(if keep_alive {
            "Connection: keep-alive\r\n\r\n"
        } else {
            "Connection: close\r\n\r\n"
        });
        head.into_bytes()
    }

    /// Writes the response, all of it before `deadline` (see
    /// [`write_before`]); head and body leave together, without copying the
    /// body into one buffer with the head.
    pub fn write_to(
        &self,
        stream: &TcpStream,
        head_only: bool,
        keep_alive: bool,
        deadline: Instant,
    ) -> io::Result<()> {
        let body: &[u8] = if head_only { &[] } else { &self.body };
        write_before(stream, &self.head(keep_alive), body, deadline)
    }
}

/// Writes all of `head` then `body` before `deadline`, or fails with
/// [`io::ErrorKind::TimedOut`]. The deadline bounds the whole write, not
/// each call: a client that reads a byte at a time makes every single
/// write progress, yet is cut off at the deadline like one that reads
/// nothing. Each (vectored) write of at most [`WRITE_CHUNK`] bytes blocks
/// with the time left as its socket timeout.
pub fn write_before(
    mut stream: &TcpStream,
    head: &[u8],
    body: &[u8],
    deadline: Instant,
) -> io::Result<()> {
    let total = head.len() + body.len();
    let mut sent = 0;
    while sent < total {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "the client did not take the response in time",
            ));
        }
        stream.set_write_timeout(Some(left.max(MIN_SOCKET_TIMEOUT)))?;
        let end = total.min(sent + WRITE_CHUNK);
        let in_head = &head[sent.min(head.len())..end.min(head.len())];
        let in_body = &body[sent.saturating_sub(head.len())..end.saturating_sub(head.len())];
        match stream.write_vectored(&[IoSlice::new(in_head), IoSlice::new(in_body)]) {
            Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
            Ok(n) => sent += n,
            Err(e) if is_timeout(&e) => {}
            Err(e) => return Err(e),
        }
    }
    stream.flush()
}

/// The interim response that tells a client to send the body it announced.
pub const CONTINUE: &[u8] = b"HTTP/1.1 100 Continue\r\n\r\n";

pub fn reason(status: u16) -> &'static str {
    match status {
        100 => "Continue",
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        406 => "Not Acceptable",
        408 => "Request Timeout",
        411 => "Length Required",
        413 => "Content Too Large",
        422 => "Unprocessable Content",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        505 => "HTTP Version Not Supported",
        _ => "Unknown",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn head(raw: &str) -> RequestHead {
        let mut headers = [httparse::EMPTY_HEADER; limits::MAX_HEADERS];
        let mut request = httparse::Request::new(&mut headers);
        assert!(request.parse(raw.as_bytes()).unwrap().is_complete());
        to_head(&request)
    }

    #[test]
    fn splits_path_and_query_and_lowercases_names() {
        let h =
            head("POST /render?format=ppm&spp=2 HTTP/1.1\r\nHost: x\r\nContent-Length: 12\r\n\r\n");
        assert_eq!(
            (h.method.as_str(), h.path.as_str(), h.query.as_str()),
            ("POST", "/render", "format=ppm&spp=2")
        );
        assert_eq!(h.header("content-length"), Some("12"));
        assert_eq!(h.body_framing(), BodyFraming::Length(12));
        let h = head("GET http://example.org/healthz HTTP/1.1\r\n\r\n");
        assert_eq!(h.path, "/healthz");
    }

    #[test]
    fn repeated_list_headers_are_read_as_one_list() {
        let h = head("POST / HTTP/1.1\r\nAccept: image/png;q=0\r\nHost: x\r\nACCEPT: */*\r\n\r\n");
        assert_eq!(
            h.list_header("accept").as_deref(),
            Some("image/png;q=0, */*")
        );
        assert_eq!(h.header("accept"), Some("image/png;q=0"));
        assert_eq!(h.list_header("expect"), None);
        let json = head("GET / HTTP/1.1\r\nAccept: text/plain\r\nAccept: application/json\r\n\r\n");
        assert!(json.accepts_json());
    }

    #[test]
    fn keep_alive_follows_the_version_and_connection_tokens() {
        assert!(head("GET / HTTP/1.1\r\n\r\n").wants_keep_alive());
        assert!(!head("GET / HTTP/1.1\r\nConnection: Close\r\n\r\n").wants_keep_alive());
        assert!(!head("GET / HTTP/1.0\r\n\r\n").wants_keep_alive());
        assert!(head("GET / HTTP/1.0\r\nConnection: foo, keep-alive\r\n\r\n").wants_keep_alive());
    }

    #[test]
    fn body_framing_rejects_what_it_cannot_delimit() {
        let framing = |h: &str| head(&format!("POST / HTTP/1.1\r\n{h}\r\n")).body_framing();
        assert_eq!(framing(""), BodyFraming::Absent);
        assert_eq!(
            framing("Transfer-Encoding: chunked\r\n"),
            BodyFraming::Encoded
        );
        assert_eq!(framing("Content-Length: -1\r\n"), BodyFraming::Invalid);
        assert_eq!(framing("Content-Length: 1, 2\r\n"), BodyFraming::Invalid);
        assert_eq!(
            framing("Content-Length: 5\r\nContent-Length: 6\r\n"),
            BodyFraming::Invalid
        );
        assert_eq!(
            framing("Content-Length: 5\r\nContent-Length: 5\r\n"),
            BodyFraming::Length(5)
        );
        assert_eq!(
            framing("Content-Length: 99999999999999999999999\r\n"),
            BodyFraming::Invalid
        );
    }

    #[test]
    fn write_before_sends_head_then_body_across_many_writes() {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let client = TcpStream::connect(listener.local_addr().unwrap()).unwrap();
        let (server, _) = listener.accept().unwrap();
        let head = b"HTTP/1.1 200 OK\r\n\r\n".to_vec();
        let body: Vec<u8> = (0..3 * WRITE_CHUNK + 7).map(|i| (i % 251) as u8).collect();
        let reader = std::thread::spawn(move || {
            let mut got = Vec::new();
            (&client).read_to_end(&mut got).unwrap();
            got
        });
        let deadline = Instant::now() + Duration::from_secs(10);
        write_before(&server, &head, &body, deadline).unwrap();
        drop(server);
        assert_eq!(reader.join().unwrap(), [head, body].concat());
    }

    #[test]
    fn write_before_gives_up_at_its_deadline() {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        // Connected, never read: the socket buffers fill, then the write waits.
        let _client = TcpStream::connect(listener.local_addr().unwrap()).unwrap();
        let (server, _) = listener.accept().unwrap();
        let body = vec![0u8; 64 * 1024 * 1024];
        let started = Instant::now();
        let deadline = started + Duration::from_millis(200);
        let error = write_before(&server, b"", &body, deadline).unwrap_err();
        assert_eq!(error.kind(), io::ErrorKind::TimedOut);
        let took = started.elapsed();
        assert!(
            took >= Duration::from_millis(200) && took < Duration::from_secs(5),
            "{took:?}"
        );
    }

    #[test]
    fn head_responses_keep_the_length_but_drop_the_body() {
        let r = Response::new(200, "text/plain", "ok\n");
        let full = String::from_utf8([r.head(true), r.body.clone()].concat()).unwrap();
        assert!(full.starts_with("HTTP/1.1 200 OK\r\n"));
        assert!(full.contains("Content-Length: 3\r\n") && full.ends_with("keep-alive\r\n\r\nok\n"));
        let head = String::from_utf8(r.head(false)).unwrap();
        assert!(
            head.contains("Content-Length: 3\r\n") && head.ends_with("Connection: close\r\n\r\n")
        );
    }
}
