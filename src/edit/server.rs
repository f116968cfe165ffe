//! The editor's local server: the page, the scene's data, and one WebSocket per page.
//!
//! Plain threads over `std::net` and `tungstenite` for the WebSocket: the work is one solver
//! and one page, so an async runtime would only add weight. At most [`MAX_CONNECTIONS`]
//! connections are served at once, a thread each (two for a WebSocket: one reads the page's
//! messages, one writes the answers; each blocks on its socket or its channel, neither polls);
//! one more is answered 503 and closed, by one thread for all. `httparse` reads the request
//! line and headers, read within `HEAD_TIME`; the server answers a WebSocket upgrade itself
//! (RFC 6455's accept key) and hands the socket to `tungstenite`.
//!
//! Safety: the listener binds 127.0.0.1 only. Every request must carry the session's random
//! token (`?t=…`, 128 bits from the system's generator, compared in constant time) and a
//! `Host` naming this server (`127.0.0.1:PORT` or `localhost:PORT`; a DNS-rebinding page
//! carries its own host name), and any `Origin` must be this server's; a WebSocket upgrade
//! must carry an `Origin` (a browser always sends one; without it nothing says which page
//! asks); otherwise 403 and nothing else. Only GET is served, and only the page (its markup,
//! script and styles as three files) and the scene's data. Every answer carries a
//! Content-Security-Policy that runs only the server's own script and styles (nothing inline),
//! connects only to the server's own address (`ws://127.0.0.1:PORT`, `ws://localhost:PORT`)
//! and lets no other page frame it, and `Referrer-Policy: no-referrer` (the token is in the
//! page's address). A WebSocket message or frame is at most [`MAX_MESSAGE`] bytes, and an
//! edit or a selection within the page's limits ([`crate::edit::Edit::check`]): refused with
//! a message before any work.
//!
//! Files: the token lives in the browser's history, so the server is no general file writer.
//! *Save edit* and *Apply* write into one folder chosen when the editor starts ([`OutputFolder`]:
//! the input's folder, or `--out-dir`), under a plain file name ([`check_name`]) with the
//! extension of what is written (`.toml` for a spec; for *Apply* the formats `deform` writes
//! for this input, checked before any work). A file there that this editor did not write is
//! replaced only when the page says its user confirmed it (`"overwrite": true`; otherwise the
//! answer is `exists` and the page asks); a symbolic link or anything but a regular file is
//! never replaced, nor the input. Writes go to a temporary file renamed over the target, which
//! keeps the replaced file's permission bits.
//!
//! The solver runs on its own thread (`solver`) and takes commands in order from a bounded
//! queue (`queue`: at most [`MAX_QUEUED`] wait, one more is refused with a message, a
//! newer pose replaces one waiting); a failure there is the page's message and the session
//! starts again, never a dead session.
//!
//! ## Wire format
//! Page → server: text JSON `{"type": "edit", "seq": n, "edit": Edit}`, `{"type": "release",
//! "seq": n}`, `{"type": "select", "seq": n, "selection": Selection}`, `{"type": "save",
//! "name": f, "edit": Edit, "overwrite": false}`, `{"type": "apply", "name": f, "edit": Edit,
//! "overwrite": false}`. Server → page: binary messages, little-endian, starting with a `u32`
//! kind — 1 motions `[1, seq, cells, iterations, seconds: f32, maps: 12·cells f32, strain:
//! cells f32]`, 2 released `[2, seq, samples, folded, checked, positions: 3·samples f32]`, 3
//! selected `[3, seq, samples, count, bits: one per sample, bit i % 8 of byte i / 8]` (which
//! proxy samples a selection holds, as the library selects them: [`Editor::selected`]) — and
//! text JSON for `saved`, `exists` (`name`, `action`: the file is there and was not written by
//! this editor; ask, and send again with `"overwrite": true`), `progress`, `applied`, `warning`
//! and `error` (with `select: seq` when it answers a selection).

#![cfg(feature = "editor")]

mod gate;
mod outputs;
mod queue;
mod solver;

use std::io::{Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver};
use std::time::Duration;

use tungstenite::protocol::{Role, WebSocketConfig};
use tungstenite::{Message, WebSocket};

use super::Editor;
use crate::error::{Error, Result};
use crate::said::{Opt, Said};
use gate::{Gate, header, read_head, respond, token};
use outputs::Refusal;
pub use outputs::{OutputFolder, check_name};
pub use queue::MAX_QUEUED;
use queue::{Commands, Refused};
use solver::{Command, Request};

/// The page's markup; `__TOKEN__` stands for the session's token in the addresses of its
/// script and styles.
const PAGE: &str = include_str!("page.html");
/// The page's script.
const SCRIPT: &str = include_str!("page.js");
/// The page's styles.
const STYLE: &str = include_str!("page.css");

/// The largest WebSocket message (and frame) the server reads, in bytes: 1 MiB. The largest
/// message is an edit (`edit`, `save`, `apply`), its selections' polygons most of it. The page
/// keeps a lasso's vertices at least 3 pixels apart and at most
/// [`MAX_POLYGON`](crate::edit::MAX_POLYGON), in normalized coordinates of 6 decimals: at most
/// 22 bytes of JSON a vertex, 91 kB a lasso with its view (a lasso around a whole 4K screen at
/// 3 pixels is 4,000 vertices; one around an object on it a few hundred). 1 MiB holds 11 such
/// lassos and a handful of regions many times over (a box is 4 vertices, 0.5 kB with its
/// view); the page refuses a selection that would make its messages larger. An edit at the cap
/// raises the server's peak memory by about 55 MB (its spec's text, written and parsed as the
/// CLI reads it), a fixed bound.
pub const MAX_MESSAGE: usize = 1 << 20;

/// The most connections served at once: a page opens one WebSocket and fetches its seven files
/// over at most six connections (a browser's limit per host); a reload or a second tab doubles
/// that.
pub const MAX_CONNECTIONS: usize = 32;

/// How long a request's head may take to arrive (and the most bytes it may have: 16 KiB).
pub(crate) const HEAD_TIME: Duration = Duration::from_secs(10);
pub(super) const HEAD_BYTES: usize = 16 << 10;

/// How long a write to the page may block (a page that reads nothing frees its connection).
const WRITE_TIME: Duration = Duration::from_secs(30);

/// The scene's data as served: computed once.
struct Assets {
    scene_json: String,
    /// The page's markup with the token in its addresses.
    page: String,
    points: Vec<u8>,
    colors: Vec<u8>,
    classes: Vec<u8>,
    triangles: Vec<u8>,
    cells: Vec<u8>,
    blend: Vec<u8>,
}

/// The editor's server, bound and ready.
pub struct Server {
    listener: TcpListener,
    token: String,
    port: u16,
    assets: Arc<Assets>,
    commands: Commands<Request>,
    out_dir: PathBuf,
    log: Log,
}

/// Where the server says what it did, a line at a time (the command line prints them on
/// stderr): the page loaded, connected and gone, each request refused and why, each file saved
/// or applied, each error and warning the page was shown.
pub type Log = Arc<dyn Fn(&str) + Send + Sync>;

impl Server {
    /// Binds 127.0.0.1:`port` (0: any free port) and starts the solver thread over `editor`;
    /// *Save edit* and *Apply* write into `out_dir` (`None`: the input's folder), which must be
    /// a folder.
    pub fn bind(editor: Editor, port: u16, out_dir: Option<&Path>) -> Result<Self> {
        let outputs = Arc::new(OutputFolder::new(&editor.scene().input, out_dir)?);
        let listener = TcpListener::bind(("127.0.0.1", port)).map_err(|e| {
            Error::param(
                Said::new()
                    .set(Opt::Port, port)
                    .text(format!(": cannot listen on it: {e}")),
            )
        })?;
        let port = listener
            .local_addr()
            .map_err(|e| Error::solver(format!("the listener's address: {e}")))?
            .port();
        let token = token()?;
        let assets = Arc::new(assets(&editor, &outputs, &token)?);
        let (commands, queue) = queue::queue();
        let out_dir = outputs.dir().to_path_buf();
        std::thread::spawn(move || solver::run(editor, outputs, queue));
        Ok(Self {
            listener,
            token,
            port,
            assets,
            commands,
            out_dir,
            log: Arc::new(|_: &str| {}),
        })
    }

    /// Says what it does to `log` (by default, to no one).
    pub fn logging(self, log: Log) -> Self {
        Self { log, ..self }
    }

    /// The folder *Save edit* and *Apply* write into.
    pub fn out_dir(&self) -> &Path {
        &self.out_dir
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// The session's token.
    pub fn token(&self) -> &str {
        &self.token
    }

    /// The page's address.
    pub fn url(&self) -> String {
        format!("http://127.0.0.1:{}/?t={}", self.port, self.token)
    }

    /// Serves until the process ends: a thread per connection (named `edit-PORT` for the
    /// page's end of it), at most [`MAX_CONNECTIONS`] at once; one more is answered 503 and
    /// closed (`refuse_all`, one thread for all).
    pub fn run(self) -> Result<()> {
        let gate = Arc::new(Gate {
            token: self.token.clone(),
            port: self.port,
        });
        let open = Arc::new(AtomicUsize::new(0));
        let (refuse, refused) = mpsc::sync_channel::<TcpStream>(MAX_CONNECTIONS);
        std::thread::Builder::new()
            .name("edit-refuse".into())
            .spawn(move || refuse_all(refused))
            .map_err(|e| Error::solver(format!("no thread to refuse connections: {e}")))?;
        for stream in self.listener.incoming() {
            let Ok(stream) = stream else { continue };
            let Some(slot) = Slot::take(&open) else {
                // Closed at once when even the refusals are many.
                let _ = refuse.try_send(stream);
                continue;
            };
            let (gate, assets, commands, log) = (
                gate.clone(),
                self.assets.clone(),
                self.commands.clone(),
                self.log.clone(),
            );
            // Named for the page's end of the connection (`edit-PORT`), as its writer is.
            let peer = stream.peer_addr().map_or(0, |a| a.port());
            let _ = std::thread::Builder::new()
                .name(format!("edit-{peer}"))
                .spawn(move || {
                    let _slot = slot;
                    let _ = connection(stream, &gate, &assets, &commands, &log);
                });
        }
        Ok(())
    }
}

/// Answers each connection past [`MAX_CONNECTIONS`] 503, one after another: its request is
/// read first (for at most [`REFUSE_TIME`]), as a socket closed with bytes unread is reset, and
/// the answer lost with it.
fn refuse_all(refused: Receiver<TcpStream>) {
    for mut stream in refused {
        let _ = stream.set_read_timeout(Some(REFUSE_TIME));
        let _ = stream.set_write_timeout(Some(REFUSE_TIME));
        let _ = stream.read(&mut [0u8; HEAD_BYTES]);
        let _ = respond(&mut stream, 503, "text/plain", b"too many connections", 0);
        let _ = stream.shutdown(Shutdown::Write);
        // The rest of the request, if it was longer, before the socket closes.
        let _ = stream.read(&mut [0u8; HEAD_BYTES]);
    }
}

/// How long the refusal of a connection past [`MAX_CONNECTIONS`] may wait on it.
const REFUSE_TIME: Duration = Duration::from_millis(200);

/// One of the [`MAX_CONNECTIONS`] served at once, given back when dropped.
struct Slot(Arc<AtomicUsize>);

impl Slot {
    fn take(open: &Arc<AtomicUsize>) -> Option<Self> {
        open.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| {
            (n < MAX_CONNECTIONS).then_some(n + 1)
        })
        .ok()
        .map(|_| Self(open.clone()))
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn u32_bytes(v: &[u32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn assets(editor: &Editor, outputs: &OutputFolder, token: &str) -> Result<Assets> {
    let scene = editor.scene();
    let (lo, hi) = scene.bounds;
    let c = scene.center;
    let name = scene
        .input
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut classes: Vec<u8> = scene.classes.clone();
    classes.sort_unstable();
    classes.dedup();
    let scene_json = serde_json::json!({
        "name": name,
        "input": scene.input.display().to_string(),
        "samples": scene.points.len(),
        "total": scene.total,
        "center": [c[0], c[1], c[2]],
        "lo": [lo[0] - c[0], lo[1] - c[1], lo[2] - c[2]],
        "hi": [hi[0] - c[0], hi[1] - c[1], hi[2] - c[2]],
        "triangles": scene.triangles.len(),
        "classes": classes,
        "cells": editor.complex().len(),
        "up": scene.up,
        "transfer": editor.params().transfer.to_string(),
        "out_dir": outputs.dir().display().to_string(),
        "outputs": crate::io::output_extensions(&scene.input),
        "max_message": MAX_MESSAGE,
        "max_polygon": super::MAX_POLYGON,
        "max_selections": super::MAX_SELECTIONS,
        "max_handles": super::MAX_HANDLES,
        "max_pins": super::MAX_PINS,
    })
    .to_string();
    let (cells, weights) = editor.blend()?;
    let mut blend = u32_bytes(&cells);
    blend.extend(f32_bytes(&weights));
    Ok(Assets {
        scene_json,
        page: PAGE.replace("__TOKEN__", token),
        points: f32_bytes(&scene.relative()),
        colors: scene.colors.iter().flatten().copied().collect(),
        classes: scene.classes.clone(),
        triangles: u32_bytes(
            &scene
                .triangles
                .iter()
                .flatten()
                .copied()
                .collect::<Vec<_>>(),
        ),
        cells: f32_bytes(&editor.cells()),
        blend,
    })
}

/// One connection: a GET of the page or data, or the WebSocket.
fn connection(
    mut stream: TcpStream,
    gate: &Gate,
    assets: &Assets,
    commands: &Commands<Request>,
    log: &Log,
) -> std::io::Result<()> {
    stream.set_write_timeout(Some(WRITE_TIME))?;
    let port = gate.port;
    let Some((head, rest)) = read_head(&mut stream)? else {
        return respond(
            &mut stream,
            431,
            "text/plain",
            b"request header too large or slow",
            port,
        );
    };
    let mut headers = [httparse::EMPTY_HEADER; 64];
    let mut request = httparse::Request::new(&mut headers);
    if !matches!(request.parse(&head), Ok(httparse::Status::Complete(_))) {
        return respond(&mut stream, 400, "text/plain", b"bad request", port);
    }
    let target = request.path.unwrap_or("/").to_string();
    let (path, query) = target.split_once('?').unwrap_or((&target, ""));
    // A browser asks for an icon without the page's token: there is none, and nothing to guard.
    if path == "/favicon.ico" && request.method == Some("GET") {
        return respond(&mut stream, 204, "", b"", port);
    }
    let admitted = gate.admits(query, request.headers);
    let upgrade =
        header(request.headers, "upgrade").is_some_and(|v| v.eq_ignore_ascii_case("websocket"));
    // A browser sends an Origin with every WebSocket; one without says nothing of its page.
    let origin = header(request.headers, "origin").is_some();
    if admitted && origin && upgrade && path == "/ws" && request.method == Some("GET") {
        let key = header(request.headers, "sec-websocket-key");
        let version = header(request.headers, "sec-websocket-version");
        return match key {
            Some(key) if version.as_deref() == Some("13") => {
                websocket(stream, &key, rest, commands, log)
            }
            _ => respond(
                &mut stream,
                400,
                "text/plain",
                b"bad WebSocket request",
                port,
            ),
        };
    }
    let method = request.method.unwrap_or("?");
    if method != "GET" {
        log(&format!("refused {method} {path}: only GET is served"));
        return respond(&mut stream, 405, "text/plain", b"only GET", port);
    }
    if !admitted || upgrade {
        log(&format!(
            "refused GET {path}: without the editor's token, or from another host or page"
        ));
        return respond(
            &mut stream,
            403,
            "text/plain",
            b"forbidden: token, Host or Origin",
            port,
        );
    }
    let (kind, body): (&str, &[u8]) = match path {
        "/" => ("text/html; charset=utf-8", assets.page.as_bytes()),
        "/page.js" => ("text/javascript; charset=utf-8", SCRIPT.as_bytes()),
        "/page.css" => ("text/css; charset=utf-8", STYLE.as_bytes()),
        "/scene.json" => ("application/json", assets.scene_json.as_bytes()),
        "/points.bin" => ("application/octet-stream", &assets.points),
        "/colors.bin" => ("application/octet-stream", &assets.colors),
        "/classes.bin" => ("application/octet-stream", &assets.classes),
        "/triangles.bin" => ("application/octet-stream", &assets.triangles),
        "/cells.bin" => ("application/octet-stream", &assets.cells),
        "/blend.bin" => ("application/octet-stream", &assets.blend),
        _ => {
            log(&format!("not found: {path}"));
            return respond(&mut stream, 404, "text/plain", b"not found", port);
        }
    };
    if path == "/" {
        log("page loaded");
    }
    respond(&mut stream, 200, kind, body, port)
}

/// The reading half of a WebSocket's socket: `tungstenite` writes its replies to pings and
/// closes through the stream it reads, and this half drops them, so that the writing thread is
/// the socket's one writer (the reader hands it a ping's pong).
struct ReadHalf(TcpStream);

impl Read for ReadHalf {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.0.read(buf)
    }
}

impl Write for ReadHalf {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The page's WebSocket (the upgrade with `key` accepted; `rest` the bytes read after the
/// request): this thread reads the page's messages, blocked on the socket, and a second one
/// writes the answers, blocked on their channel.
fn websocket(
    mut stream: TcpStream,
    key: &str,
    rest: Vec<u8>,
    commands: &Commands<Request>,
    log: &Log,
) -> std::io::Result<()> {
    write!(
        stream,
        "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Accept: {}\r\n\r\n",
        tungstenite::handshake::derive_accept_key(key.as_bytes())
    )?;
    stream.flush()?;
    stream.set_read_timeout(None)?;
    let config = WebSocketConfig::default()
        .max_message_size(Some(MAX_MESSAGE))
        .max_frame_size(Some(MAX_MESSAGE));
    let mut reader = WebSocket::from_partially_read(
        ReadHalf(stream.try_clone()?),
        rest,
        Role::Server,
        Some(config),
    );
    let writer = WebSocket::from_raw_socket(stream.try_clone()?, Role::Server, Some(config));
    let (answers, outbox) = mpsc::channel::<Message>();
    let peer = stream.peer_addr()?.port();
    let answers_log = log.clone();
    let writing = std::thread::Builder::new()
        .name(format!("edit-w-{peer}"))
        .spawn(move || write_answers(writer, outbox, &answers_log))?;
    log("page connected");
    loop {
        match reader.read() {
            Ok(Message::Text(text)) => match Command::parse(text.as_str()) {
                Ok(command) => match commands.send((command, answers.clone())) {
                    Ok(()) => {}
                    Err(Refused::Full(request)) => {
                        let _ = answers.send(solver::busy(&request.0));
                    }
                    Err(Refused::Closed) => break,
                },
                Err(refusal) => {
                    let _ = answers.send(refusal);
                }
            },
            Ok(Message::Ping(data)) => {
                let _ = answers.send(Message::Pong(data));
            }
            Ok(Message::Close(_)) => break,
            Ok(_) => {}
            Err(_) => {
                let _ = stream.shutdown(Shutdown::Both);
                break;
            }
        }
    }
    let _ = answers.send(Message::Close(None));
    let _ = writing.join();
    log("page closed");
    Ok(())
}

/// What the page is told that the terminal hears too: files saved, applied or found in the way,
/// warnings and errors (not progress).
fn said_to_the_page(text: &str) -> Option<String> {
    let v: serde_json::Value = serde_json::from_str(text).ok()?;
    let field = |k: &str| v[k].as_str().unwrap_or("").to_string();
    Some(match v["type"].as_str()? {
        "saved" => format!("saved {}", field("path")),
        "applied" => {
            let samples = v["samples"].as_u64().unwrap_or(0);
            let seconds = v["seconds"].as_f64().unwrap_or(0.0);
            let mut line = format!(
                "applied: {} ({} samples, {:.1} s)",
                field("output"),
                crate::human::count(samples),
                seconds
            );
            for w in v["warnings"].as_array().into_iter().flatten() {
                line += &format!("\n  warning: {}", w.as_str().unwrap_or(""));
            }
            line
        }
        "exists" => format!(
            "{} exists: the page asks before replacing it",
            field("name")
        ),
        "warning" => format!("warning: {}", field("message")),
        "error" => format!("error: {}", field("message")),
        _ => return None,
    })
}

/// Writes the answers in `outbox` to the page until a close (which it sends) or a failed
/// write; then closes the socket, which ends the reading thread too.
fn write_answers(mut ws: WebSocket<TcpStream>, outbox: Receiver<Message>, log: &Log) {
    for message in outbox {
        if let Message::Text(text) = &message
            && let Some(line) = said_to_the_page(text.as_str())
        {
            log(&line);
        }
        let sent = match message {
            Message::Close(_) => {
                let _ = ws.close(None).and_then(|()| ws.flush());
                break;
            }
            m => ws.send(m),
        };
        if sent.is_err() {
            break;
        }
    }
    let _ = ws.get_ref().shutdown(Shutdown::Both);
}
