//! One tile request: an HTTP/1.1 POST and its whole response, under one
//! deadline.
//!
//! Written on `std::net` with `httparse` for the response head, as the
//! service itself is: a tile is one request on its own connection
//! (`Connection: close`), with a `Content-Length` body or one that ends
//! with the connection, so a full HTTP client crate would bring TLS, pools
//! and an async runtime for nothing this needs.

use crate::limits;
use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::Instant;

/// Why no response came back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transport {
    /// The connection could not be made (refused, unreachable).
    Connect,
    /// The deadline passed.
    TimedOut,
    /// The connection broke or closed before the whole response.
    Broken,
    /// The response was not HTTP, or larger than it may be.
    Protocol,
}

impl Transport {
    pub fn name(self) -> &'static str {
        match self {
            Transport::Connect => "connect",
            Transport::TimedOut => "timeout",
            Transport::Broken => "broken",
            Transport::Protocol => "protocol",
        }
    }

    fn from_io(error: &io::Error) -> Transport {
        match error.kind() {
            io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock => Transport::TimedOut,
            _ => Transport::Broken,
        }
    }
}

/// A response: its status, the headers voxtrace reads, and its body.
#[derive(Debug, Default)]
pub struct Reply {
    pub status: u16,
    /// `X-Worker`: who rendered it.
    pub worker: Option<String>,
    /// `X-Render-Ms`: how long the worker traced.
    pub render_ms: Option<f64>,
    /// `Retry-After`, in seconds.
    pub retry_after: Option<u64>,
    pub body: Vec<u8>,
}

/// What to send where.
pub struct Request<'a> {
    pub addr: SocketAddr,
    /// `host:port`, for the `Host` header.
    pub authority: &'a str,
    /// Path and query.
    pub target: &'a str,
    pub body: &'a [u8],
    /// The largest successful (2xx) body accepted.
    pub max_body: usize,
}

/// Sends `request` and reads its response, all before `deadline`.
pub fn post(request: &Request, deadline: Instant) -> Result<Reply, Transport> {
    let left = || {
        deadline
            .checked_duration_since(Instant::now())
            .filter(|d| !d.is_zero())
            .ok_or(Transport::TimedOut)
    };
    let mut stream =
        TcpStream::connect_timeout(&request.addr, left()?).map_err(|_| Transport::Connect)?;
    let _ = stream.set_nodelay(true);
    let head = format!(
        "POST {} HTTP/1.1\r\nHost: {}\r\nContent-Type: text/plain\r\nAccept: text/plain\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n",
        request.target,
        request.authority,
        request.body.len()
    );
    for part in [head.as_bytes(), request.body] {
        for chunk in part.chunks(1 << 20) {
            stream
                .set_write_timeout(Some(left()?))
                .map_err(|_| Transport::Broken)?;
            stream
                .write_all(chunk)
                .map_err(|e| Transport::from_io(&e))?;
        }
    }
    let mut buffer = Vec::with_capacity(4096);
    let (mut reply, head_len, length) = read_head(&mut stream, &mut buffer, &left)?;
    let limit = if (200..300).contains(&reply.status) {
        request.max_body
    } else {
        limits::MAX_REMOTE_ERROR_BYTES
    };
    if length.is_some_and(|n| n > limit) {
        return Err(Transport::Protocol);
    }
    buffer.drain(..head_len);
    read_body(&mut stream, &mut buffer, length, limit, &left)?;
    reply.body = buffer;
    Ok(reply)
}

/// Reads until the response head is complete (interim 1xx responses
/// skipped); the reply's fields, the head's length in `buffer`, and the
/// body's `Content-Length`.
fn read_head(
    stream: &mut TcpStream,
    buffer: &mut Vec<u8>,
    left: &dyn Fn() -> Result<std::time::Duration, Transport>,
) -> Result<(Reply, usize, Option<usize>), Transport> {
    loop {
        let mut headers = [httparse::EMPTY_HEADER; limits::MAX_HEADERS];
        let mut response = httparse::Response::new(&mut headers);
        match response.parse(buffer) {
            Ok(httparse::Status::Complete(len)) => {
                let status = response.code.unwrap_or(0);
                if (100..200).contains(&status) {
                    buffer.drain(..len);
                    continue;
                }
                let (reply, length) = reply_of(status, response.headers)?;
                return Ok((reply, len, length));
            }
            Ok(httparse::Status::Partial) if buffer.len() < limits::MAX_HEAD_BYTES => {}
            _ => return Err(Transport::Protocol),
        }
        if fill(stream, buffer, left)? == 0 {
            return Err(Transport::Broken);
        }
    }
}

/// The fields voxtrace reads from a response head, and its `Content-Length`.
fn reply_of(
    status: u16,
    headers: &[httparse::Header],
) -> Result<(Reply, Option<usize>), Transport> {
    let mut reply = Reply {
        status,
        ..Reply::default()
    };
    let mut length = None;
    for header in headers {
        let value = std::str::from_utf8(header.value)
            .map_err(|_| Transport::Protocol)?
            .trim();
        let name = header.name;
        if name.eq_ignore_ascii_case("content-length") {
            length = Some(value.parse().map_err(|_| Transport::Protocol)?);
        } else if name.eq_ignore_ascii_case("x-worker") {
            reply.worker = Some(value.chars().take(200).collect());
        } else if name.eq_ignore_ascii_case("x-render-ms") {
            reply.render_ms = value.parse().ok();
        } else if name.eq_ignore_ascii_case("retry-after") {
            reply.retry_after = value.parse().ok();
        } else if name.eq_ignore_ascii_case("transfer-encoding") {
            // Neither the service nor nginx in front of it chunks a
            // response of known length; anything else is not ours.
            return Err(Transport::Protocol);
        }
    }
    Ok((reply, length))
}

/// Reads the body into `buffer` (which may hold its start already): `length`
/// bytes, or to the end of the stream when none is given, never more than `limit`.
fn read_body(
    stream: &mut TcpStream,
    buffer: &mut Vec<u8>,
    length: Option<usize>,
    limit: usize,
    left: &dyn Fn() -> Result<std::time::Duration, Transport>,
) -> Result<(), Transport> {
    if let Some(n) = length {
        buffer.reserve(n.saturating_sub(buffer.len()));
    }
    loop {
        match length {
            Some(n) if buffer.len() >= n => {
                buffer.truncate(n);
                return Ok(());
            }
            _ if buffer.len() > limit => return Err(Transport::Protocol),
            _ => {}
        }
        if fill(stream, buffer, left)? == 0 {
            return match length {
                None => Ok(()),
                Some(_) => Err(Transport::Broken),
            };
        }
    }
}

/// One read of at most 64 KiB onto the end of `buffer`, within the time left.
fn fill(
    stream: &mut TcpStream,
    buffer: &mut Vec<u8>,
    left: &dyn Fn() -> Result<std::time::Duration, Transport>,
) -> Result<usize, Transport> {
    stream
        .set_read_timeout(Some(left()?))
        .map_err(|_| Transport::Broken)?;
    let start = buffer.len();
    buffer.resize(start + 64 * 1024, 0);
    let read = stream.read(&mut buffer[start..]);
    buffer.truncate(start + *read.as_ref().unwrap_or(&0));
    read.map_err(|e| Transport::from_io(&e))
}
