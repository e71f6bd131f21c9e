//! One HTTP/1.1 request and its response on a kept-alive connection, and
//! what can go wrong on the way.

use std::fmt;
use std::io::{self, BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::Duration;

/// What went wrong below HTTP.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum TransportError {
    Connect,
    Timeout,
    /// The server closed the connection before the whole response.
    Closed,
    /// Not an HTTP/1.x response.
    Protocol,
    Io,
    /// Closed before the first byte of the response; only ever reported as
    /// `Closed`, after a retry on a fresh connection.
    Stale,
}

impl TransportError {
    pub fn name(self) -> &'static str {
        match self {
            TransportError::Connect => "connect",
            TransportError::Timeout => "timeout",
            TransportError::Closed | TransportError::Stale => "closed",
            TransportError::Protocol => "protocol",
            TransportError::Io => "io",
        }
    }

    fn from_io(e: &io::Error) -> Self {
        match e.kind() {
            io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut => TransportError::Timeout,
            io::ErrorKind::UnexpectedEof
            | io::ErrorKind::ConnectionReset
            | io::ErrorKind::BrokenPipe => TransportError::Closed,
            _ => TransportError::Io,
        }
    }
}

/// A transport error with what the system said about it, for the report's sample.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Failure {
    pub error: TransportError,
    pub detail: String,
}

impl Failure {
    fn new(error: TransportError, detail: impl fmt::Display) -> Failure {
        Failure {
            error,
            detail: detail.to_string(),
        }
    }

    fn io(e: &io::Error) -> Failure {
        Failure::new(TransportError::from_io(e), e)
    }
}

/// A whole response; its body is left in the caller's scratch buffer.
pub struct Answer {
    pub status: u16,
    pub retry_after: bool,
    /// Bytes received, head and body.
    pub bytes: u64,
    /// The render's rays (`X-Rays`), 0 if none.
    pub rays: u64,
    /// The server will close the connection after this response.
    pub close: bool,
}

/// Opens a connection within `timeout`, with `timeout` on every read and write.
pub fn connect(addr: SocketAddr, timeout: Duration) -> Result<BufReader<TcpStream>, Failure> {
    let stream = TcpStream::connect_timeout(&addr, timeout)
        .map_err(|e| Failure::new(TransportError::Connect, format!("{addr}: {e}")))?;
    let _ = stream.set_nodelay(true);
    let _ = stream.set_read_timeout(Some(timeout));
    let _ = stream.set_write_timeout(Some(timeout));
    Ok(BufReader::with_capacity(64 * 1024, stream))
}

/// Sends `request` and reads the whole response into `body`.
pub fn send(
    reader: &mut BufReader<TcpStream>,
    request: &[u8],
    body: &mut Vec<u8>,
) -> Result<Answer, Failure> {
    match reader.get_mut().write_all(request) {
        Ok(()) => read_response(reader, body),
        Err(e) => Err(Failure::new(TransportError::Stale, e)),
    }
}

fn read_line(reader: &mut BufReader<TcpStream>, line: &mut Vec<u8>) -> Result<u64, Failure> {
    line.clear();
    match reader.read_until(b'\n', line) {
        Ok(0) => Err(Failure::new(
            TransportError::Closed,
            "the server closed the connection mid-response",
        )),
        Ok(n) => Ok(n as u64),
        Err(e) => Err(Failure::io(&e)),
    }
}

fn read_response(reader: &mut BufReader<TcpStream>, body: &mut Vec<u8>) -> Result<Answer, Failure> {
    let mut line = Vec::with_capacity(128);
    let mut bytes = match read_line(reader, &mut line) {
        Err(f) if f.error == TransportError::Closed => {
            return Err(Failure::new(
                TransportError::Stale,
                "the server closed the connection without answering",
            ))
        }
        other => other?,
    };
    let status = status_of(&line)?;
    let (mut length, mut rays, mut close, mut retry_after) = (None, 0, false, false);
    loop {
        bytes += read_line(reader, &mut line)?;
        let text = String::from_utf8_lossy(&line);
        let text = text.trim_end();
        if text.is_empty() {
            break;
        }
        let Some((name, value)) = text.split_once(':') else {
            return Err(Failure::new(
                TransportError::Protocol,
                format!("a header line without a colon: {text:?}"),
            ));
        };
        let value = value.trim();
        if name.eq_ignore_ascii_case("content-length") {
            length = Some(value.parse::<u64>().map_err(|_| {
                Failure::new(
                    TransportError::Protocol,
                    format!("Content-Length {value:?} is not a number"),
                )
            })?);
        } else if name.eq_ignore_ascii_case("x-rays") {
            rays = value.parse().unwrap_or(0);
        } else if name.eq_ignore_ascii_case("retry-after") {
            retry_after = true;
        } else if name.eq_ignore_ascii_case("connection") {
            close = value.eq_ignore_ascii_case("close");
        }
    }
    body.clear();
    let received = match length {
        Some(n) => reader.by_ref().take(n).read_to_end(body),
        None => {
            close = true;
            reader.read_to_end(body)
        }
    }
    .map_err(|e| Failure::io(&e))? as u64;
    if let Some(n) = length.filter(|&n| n != received) {
        return Err(Failure::new(
            TransportError::Closed,
            format!("the server closed the connection after {received} of {n} body bytes"),
        ));
    }
    Ok(Answer {
        status,
        retry_after,
        bytes: bytes + received,
        rays,
        close,
    })
}

fn status_of(line: &[u8]) -> Result<u16, Failure> {
    std::str::from_utf8(line)
        .ok()
        .filter(|l| l.starts_with("HTTP/1."))
        .and_then(|l| l.split(' ').nth(1))
        .and_then(|s| s.parse::<u16>().ok())
        .ok_or_else(|| {
            let shown = String::from_utf8_lossy(&line[..line.len().min(64)]).into_owned();
            Failure::new(
                TransportError::Protocol,
                format!("not an HTTP/1.x status line: {:?}", shown.trim_end()),
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_status_line_gives_its_code_and_anything_else_is_a_protocol_error() {
        assert_eq!(status_of(b"HTTP/1.1 404 Not Found\r\n"), Ok(404));
        let failure = status_of(b"SSH-2.0-OpenSSH_9.2\r\n").unwrap_err();
        assert_eq!(failure.error, TransportError::Protocol);
        assert!(failure.detail.contains("SSH-2.0"), "{}", failure.detail);
    }
}
