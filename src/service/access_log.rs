//! The access log (`serve --access-log PATH|-`): one line per request, in
//! nginx's `combined` format with the request time appended, so the tools
//! that read nginx logs read this one:
//!
//! ```text
//! 127.0.0.1 - - [01/Dec/2026:21:25:31 +0000] "POST /render?spp=4 HTTP/1.1" 200 48213 "-" "curl/8.5.0" 0.412
//! ```
//!
//! (peer, no identity, no user, the time in UTC, the request line, status,
//! body bytes sent, `Referer`, `User-Agent`, seconds from the head read to
//! the response written.) Requests never wait for the log: lines go
//! through a bounded queue to a thread of their own that writes each with
//! one call; a full queue or a failed write drops the line and counts it,
//! and serving goes on.

use super::http::RequestHead;
use crate::limits;
use prometheus_client::metrics::counter::Counter;
use std::fs::OpenOptions;
use std::io::{self, Write};
use std::net::IpAddr;
use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Mutex, PoisonError};
use std::thread;
use std::time::{Duration, Instant, SystemTime};
use time::format_description::BorrowedFormatItem;
use time::macros::format_description;
use time::OffsetDateTime;

/// nginx's `$time_local`, always in UTC.
const TIME_FORMAT: &[BorrowedFormatItem<'static>] =
    format_description!("[day]/[month repr:short]/[year]:[hour]:[minute]:[second] +0000");

/// Where the access log goes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum AccessLogTarget {
    /// `-`: standard output.
    Stdout,
    /// A file, appended to (created if missing).
    File(PathBuf),
}

impl std::str::FromStr for AccessLogTarget {
    type Err = std::convert::Infallible;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(match s {
            "-" => AccessLogTarget::Stdout,
            path => AccessLogTarget::File(path.into()),
        })
    }
}

impl std::fmt::Display for AccessLogTarget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AccessLogTarget::Stdout => write!(f, "standard output"),
            AccessLogTarget::File(path) => write!(f, "{}", path.display()),
        }
    }
}

/// One answered request, as the log tells it.
pub struct Entry<'a> {
    pub peer: Option<IpAddr>,
    /// `None` when no request could be read (a malformed or late head, a
    /// connection turned away).
    pub head: Option<&'a RequestHead>,
    pub code: u16,
    /// Body bytes written: 0 for HEAD, or when the response was cut off.
    pub bytes: u64,
    /// From the head read to the response written.
    pub took: Duration,
    /// When it ended.
    pub at: SystemTime,
}

/// The log line of `entry`, without its line end.
pub fn format_line(entry: &Entry) -> String {
    let time = OffsetDateTime::from(entry.at)
        .format(TIME_FORMAT)
        .unwrap_or_else(|_| "-".into());
    let peer = entry.peer.map_or_else(|| "-".into(), |ip| ip.to_string());
    let (request, referer, agent) = match entry.head {
        Some(head) => {
            let target = if head.query.is_empty() {
                head.path.clone()
            } else {
                format!("{}?{}", head.path, head.query)
            };
            let request = format!(
                "{} {} HTTP/1.{}",
                field(&head.method),
                field(&target),
                head.minor_version
            );
            let header = |name| head.header(name).map_or_else(|| "-".into(), field);
            (request, header("referer"), header("user-agent"))
        }
        None => ("-".into(), "-".into(), "-".into()),
    };
    format!(
        "{peer} - - [{time}] \"{request}\" {} {} \"{referer}\" \"{agent}\" {:.3}",
        entry.code,
        entry.bytes,
        entry.took.as_secs_f64()
    )
}

/// A client's text made safe for a quoted field, as nginx escapes it:
/// quotes, backslashes, control bytes and bytes past ASCII as `\xHH`; cut
/// at [`limits::ACCESS_LOG_FIELD_BYTES`] (then ending in `...`).
fn field(text: &str) -> String {
    let mut out = String::new();
    for &byte in text.as_bytes() {
        if out.len() >= limits::ACCESS_LOG_FIELD_BYTES {
            out.push_str("...");
            break;
        }
        match byte {
            b'"' | b'\\' | 0..=0x1f | 0x7f.. => out.push_str(&format!("\\x{byte:02X}")),
            _ => out.push(char::from(byte)),
        }
    }
    out
}

enum Message {
    Line(String),
    /// Write what came before, then say so and end.
    Close,
}

/// An open access log and its writer thread.
pub struct AccessLog {
    lines: SyncSender<Message>,
    /// Answers once the writer has written everything before a close.
    closed: Mutex<Option<Receiver<()>>>,
    dropped: Counter,
}

impl AccessLog {
    /// Opens `target` (a file is created if missing, and appended to) and
    /// starts its writer. `dropped` counts the lines that are not written.
    pub fn open(target: &AccessLogTarget, dropped: Counter) -> io::Result<AccessLog> {
        let sink: Box<dyn Write + Send> = match target {
            AccessLogTarget::Stdout => Box::new(io::stdout()),
            AccessLogTarget::File(path) => {
                Box::new(OpenOptions::new().create(true).append(true).open(path)?)
            }
        };
        let (lines, queued) = mpsc::sync_channel(limits::ACCESS_LOG_QUEUE_LINES);
        let (done, closed) = mpsc::channel();
        let counter = dropped.clone();
        thread::Builder::new()
            .name("voxtrace-access-log".into())
            .spawn(move || write_lines(&queued, sink, &counter, &done))?;
        Ok(AccessLog {
            lines,
            closed: Mutex::new(Some(closed)),
            dropped,
        })
    }

    /// Queues the line of `entry`, or drops and counts it if the queue is
    /// full: never waits.
    pub fn record(&self, entry: &Entry) {
        let queued = self.lines.try_send(Message::Line(format_line(entry)));
        if let Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) = queued {
            self.dropped.inc();
        }
    }

    /// Waits for the lines queued so far to be written, for
    /// [`limits::ACCESS_LOG_CLOSE_TIMEOUT_MS`] at most; later lines are
    /// dropped.
    pub fn close(&self) {
        let Some(closed) = self
            .closed
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take()
        else {
            return;
        };
        let deadline = Instant::now() + Duration::from_millis(limits::ACCESS_LOG_CLOSE_TIMEOUT_MS);
        // The queue may be full of lines the writer is still taking.
        let mut close = Message::Close;
        loop {
            match self.lines.try_send(close) {
                Ok(()) => break,
                Err(TrySendError::Disconnected(_)) => return,
                Err(TrySendError::Full(back)) if Instant::now() < deadline => {
                    close = back;
                    thread::sleep(CLOSE_POLL);
                }
                Err(TrySendError::Full(_)) => return,
            }
        }
        let left = deadline.saturating_duration_since(Instant::now());
        match closed.recv_timeout(left) {
            Ok(()) | Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => {}
        }
    }
}

/// How often a close retries a full queue: it only bounds how late the
/// close notices room.
const CLOSE_POLL: Duration = Duration::from_millis(5);

/// The writer thread: each line with one write (a whole line, appended, so
/// lines never interleave), until the log is closed or dropped. A failed
/// write is told once on stderr, and again only after a write succeeded.
fn write_lines(
    queued: &Receiver<Message>,
    mut sink: Box<dyn Write + Send>,
    dropped: &Counter,
    done: &mpsc::Sender<()>,
) {
    let mut failing = false;
    while let Ok(message) = queued.recv() {
        let Message::Line(mut line) = message else {
            let _ = done.send(());
            return;
        };
        line.push('\n');
        match sink.write_all(line.as_bytes()).and_then(|()| sink.flush()) {
            Ok(()) => failing = false,
            Err(error) => {
                dropped.inc();
                if !failing {
                    eprintln!("voxtrace: access log: {error}; its lines are dropped until a write succeeds");
                }
                failing = true;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn head(method: &str, path: &str, query: &str, headers: &[(&str, &str)]) -> RequestHead {
        RequestHead {
            method: method.into(),
            path: path.into(),
            query: query.into(),
            minor_version: 1,
            headers: headers
                .iter()
                .map(|(n, v)| ((*n).to_owned(), (*v).to_owned()))
                .collect(),
        }
    }

    fn at(seconds: u64) -> SystemTime {
        SystemTime::UNIX_EPOCH + Duration::from_secs(seconds)
    }

    #[test]
    fn a_line_is_nginx_combined_with_the_request_time() {
        let head = head(
            "POST",
            "/render",
            "spp=4",
            &[("user-agent", "curl/8.5.0"), ("referer", "http://x/")],
        );
        let entry = Entry {
            peer: Some("127.0.0.1".parse().unwrap()),
            head: Some(&head),
            code: 200,
            bytes: 48213,
            took: Duration::from_micros(412_345),
            at: at(1_796_159_131),
        };
        assert_eq!(
            format_line(&entry),
            "127.0.0.1 - - [01/Dec/2026:21:05:31 +0000] \"POST /render?spp=4 HTTP/1.1\" 200 48213 \"http://x/\" \"curl/8.5.0\" 0.412"
        );
    }

    #[test]
    fn no_request_and_hostile_text_stay_one_parseable_line() {
        let entry = Entry {
            peer: None,
            head: None,
            code: 400,
            bytes: 0,
            took: Duration::ZERO,
            at: at(0),
        };
        assert_eq!(
            format_line(&entry),
            "- - - [01/Jan/1970:00:00:00 +0000] \"-\" 400 0 \"-\" \"-\" 0.000"
        );
        let long = "a".repeat(3 * limits::ACCESS_LOG_FIELD_BYTES);
        let head = head(
            "GET",
            &format!("/{long}"),
            "",
            &[("user-agent", "x\"\n\\é")],
        );
        let line = format_line(&Entry {
            head: Some(&head),
            ..entry
        });
        assert!(line.contains("\"x\\x22\\x0A\\x5C\\xC3\\xA9\""), "{line}");
        assert!(!line.contains('\n'));
        let request = line.split('"').nth(1).unwrap();
        assert!(request.ends_with("... HTTP/1.1"), "{request}");
        assert!(request.len() < limits::ACCESS_LOG_FIELD_BYTES + 32);
    }

    #[test]
    fn dash_is_standard_output_and_anything_else_a_path() {
        assert_eq!("-".parse(), Ok(AccessLogTarget::Stdout));
        assert_eq!(
            "logs/a.log".parse(),
            Ok(AccessLogTarget::File("logs/a.log".into()))
        );
    }

    /// A sink that fails every write, then succeeds: the log counts the
    /// lost lines and keeps going.
    struct Flaky {
        fail: usize,
        written: std::sync::Arc<Mutex<Vec<u8>>>,
    }

    impl Write for Flaky {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            if self.fail > 0 {
                self.fail -= 1;
                return Err(io::Error::other("disk full"));
            }
            self.written.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }

        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn failed_writes_are_counted_and_writing_goes_on() {
        let written = std::sync::Arc::new(Mutex::new(Vec::new()));
        let sink = Flaky {
            fail: 2,
            written: written.clone(),
        };
        let dropped = Counter::default();
        let (lines, queued) = mpsc::sync_channel(8);
        let (done, closed) = mpsc::channel();
        for i in 0..5 {
            lines.send(Message::Line(format!("line {i}"))).unwrap();
        }
        lines.send(Message::Close).unwrap();
        write_lines(&queued, Box::new(sink), &dropped, &done);
        assert_eq!(closed.try_recv(), Ok(()));
        assert_eq!(dropped.get(), 2);
        let text = String::from_utf8(written.lock().unwrap().clone()).unwrap();
        assert_eq!(text, "line 2\nline 3\nline 4\n");
    }

    #[test]
    fn a_full_queue_drops_lines_instead_of_waiting() {
        let (lines, _queued) = mpsc::sync_channel(1);
        let (_done, closed) = mpsc::channel();
        let log = AccessLog {
            lines,
            closed: Mutex::new(Some(closed)),
            dropped: Counter::default(),
        };
        let entry = Entry {
            peer: None,
            head: None,
            code: 200,
            bytes: 0,
            took: Duration::ZERO,
            at: at(0),
        };
        for _ in 0..4 {
            log.record(&entry);
        }
        assert_eq!(log.dropped.get(), 3);
    }
}
