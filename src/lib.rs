//! voxtrace: a fast, exact ray tracer for spheres and ellipsoids.
//!
//! Data flows one way: scene text → [`scene::Scene`] → an index
//! ([`index::SphereIndex`]) → [`render`] → [`output::Image`] → PNG/PPM, over
//! the command line ([`cli`]) or HTTP ([`service`]). `docs/architecture.md`
//! says what each module owns.
//!
//! # Rendering a scene
//!
//! [`scene::parse`] reads either dialect of the scene text; it touches no
//! file, the caller reads the bytes. [`render::render_scene`] traces it on
//! the current rayon pool, so run it inside a pool of the size you want
//! ([`threads::pool`]), parsing included: the parser is parallel too.
//!
//! ```
//! use voxtrace::output::Format;
//! use voxtrace::render::{render_scene, RenderOptions};
//! use voxtrace::threads::{pool, Threads};
//!
//! let text = b"NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 32 24\n\
//!     SPHERE ball 0 0 -10 2 2 2 0.8 0.2 0.1 0.2 0.7 0.5 0.1 20\n\
//!     LIGHT sun 10 10 0 0.9 0.9 0.9\n\
//!     BACK 0.1 0.1 0.2\nAMBIENT 0.3 0.3 0.3\nOUTPUT ball.png\n";
//! let pool = pool(Threads::exactly(2).unwrap())?;
//! let scene = pool.install(|| voxtrace::scene::parse(text))?;
//! let options = RenderOptions { spp: 4, ..RenderOptions::default() };
//! let rendered = pool.install(|| render_scene(&scene, &options, &|_rows| {}))?;
//! assert_eq!((rendered.image.width, rendered.image.height), (32, 24));
//! let png = rendered.image.encode(Format::Png)?;
//! assert!(png.starts_with(b"\x89PNG"));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! A malformed scene is refused with its line and column:
//!
//! ```
//! let error = voxtrace::scene::parse(b"NEAR 1\nLEFT abc\n").unwrap_err();
//! assert_eq!((error.line, error.column), (2, 6));
//! ```
//!
//! # Serving renders over HTTP
//!
//! [`service::Server`] binds an address (port 0 picks a free one) and
//! serves `POST /render` and the upload page until stopped; `spawn` runs it
//! on its own thread and hands back a handle that stops it.
//!
//! ```
//! use std::io::{Read, Write};
//! use voxtrace::service::{Server, ServiceConfig};
//!
//! let config = ServiceConfig {
//!     addr: "127.0.0.1:0".into(),
//!     ..ServiceConfig::default()
//! };
//! let server = Server::bind(config)?.spawn()?;
//! let mut client = std::net::TcpStream::connect(server.addr())?;
//! client.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")?;
//! let mut reply = String::new();
//! client.read_to_string(&mut reply)?;
//! assert!(reply.starts_with("HTTP/1.1 200"));
//! server.stop();
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! The service's render path without HTTP is [`service::render_request`]:
//! the query string and the scene text in, the encoded image out, refused
//! exactly as `POST /render` refuses. [`remote::render`] renders a frame in
//! tiles on such services (`POST /render?region=…`) and stitches them.

pub mod bounded;
pub mod cli;
pub mod geometry;
pub mod index;
pub mod limits;
pub mod names;
pub mod output;
pub mod remote;
pub mod render;
pub mod rng;
pub mod scene;
pub mod service;
pub mod threads;
pub mod tools;
