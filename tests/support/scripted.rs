//! A stand-in HTTP server whose every answer is scripted: for what the real
//! service never does on purpose (close a connection without answering,
//! take a fixed time over each answer).

use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// What the server does with one request.
#[derive(Clone, Copy, Debug)]
pub enum Script {
    /// Wait this long, then answer `200 ok` and keep the connection.
    Answer(Duration),
    /// Close the connection without a byte of answer.
    Hang,
}

/// A server on an ephemeral loopback port; `script(n)` says what to do with
/// the `n`th request (from 0, over all connections). It runs until the
/// test process ends.
pub fn serve(script: impl Fn(usize) -> Script + Send + Sync + 'static) -> SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let script = Arc::new(script);
    let count = Arc::new(AtomicUsize::new(0));
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let (script, count) = (script.clone(), count.clone());
            std::thread::spawn(move || answer_all(stream, &*script, &count));
        }
    });
    addr
}

fn answer_all(stream: TcpStream, script: &dyn Fn(usize) -> Script, count: &AtomicUsize) {
    let mut reader = BufReader::new(stream);
    while read_head(&mut reader) {
        match script(count.fetch_add(1, Ordering::SeqCst)) {
            Script::Hang => return,
            Script::Answer(wait) => {
                std::thread::sleep(wait);
                let reply = b"HTTP/1.1 200 OK\r\nContent-Length: 2\r\n\r\nok";
                if reader.get_mut().write_all(reply).is_err() {
                    return;
                }
            }
        }
    }
}

/// Reads one request head (the requests here have no body); false at the
/// end of the stream.
fn read_head(reader: &mut BufReader<TcpStream>) -> bool {
    let mut line = String::new();
    loop {
        line.clear();
        match reader.read_line(&mut line) {
            Ok(0) | Err(_) => return false,
            Ok(_) if line.trim_end().is_empty() => return true,
            Ok(_) => {}
        }
    }
}
