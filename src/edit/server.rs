//! The editor's local server: the page, the scene's data, and one WebSocket per page.
//!
//! Plain threads over `std::net` (one per connection) and `tungstenite` for the WebSocket:
//! the work is one solver and one page, so an async runtime would only add weight. `httparse`
//! reads the request line and headers; a request is peeked first, so that a WebSocket upgrade
//! is handed to `tungstenite` whole.
//!
//! Safety: the listener binds 127.0.0.1 only. Every request must carry the session's random
//! token (`?t=…`, 128 bits from the system's generator) and a `Host` naming this server
//! (`127.0.0.1:PORT` or `localhost:PORT`; a DNS-rebinding page carries its own host name), and
//! any `Origin` must be this server's; a WebSocket upgrade must carry an `Origin` (a browser
//! always sends one; without it nothing says which page asks); otherwise 403 and nothing else.
//! Only GET is served, and only the page and the scene's data; the page is sent with
//! `Referrer-Policy: no-referrer` (the token is in its address) and `frame-ancestors 'none'`
//! (no other page may frame it). A WebSocket message or frame is at most [`MAX_MESSAGE`]
//! bytes.
//!
//! Files: the token lives in the browser's history, so the server is no general file writer.
//! *Save edit* and *Apply* write into one folder chosen when the editor starts ([`Outputs`]:
//! the input's folder, or `--out-dir`), under a plain file name ([`check_name`]) with the
//! extension of what is written (`.toml` for a spec; for *Apply* the formats `deform` writes
//! for this input, checked before any work). A file there that this editor did not write is
//! replaced only when the page says its user confirmed it (`"overwrite": true`; otherwise the
//! answer is `exists` and the page asks); a symbolic link or anything but a regular file is
//! never replaced, nor the input. Writes go to a temporary file renamed over the target, which
//! keeps the replaced file's permission bits.
//!
//! The solver runs on its own thread and takes commands in order; of several pose updates
//! waiting, only the newest is solved (a drag sends one per frame; the solver answers as fast
//! as it can and the page always sees the latest pose). *Apply* runs on a thread of its own and
//! reports progress to the page.
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

use std::collections::HashSet;
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Deserialize;
use tungstenite::Message;
use tungstenite::protocol::WebSocketConfig;

use super::{Edit, Editor, Selection};
use crate::error::{Error, Result};

/// The page, with its script and styles, built into the binary.
const PAGE: &str = include_str!("page.html");

/// The largest WebSocket message (and frame) the server reads, in bytes: 1 MiB. The largest
/// message is an edit (`edit`, `save`, `apply`), its selections' polygons most of it. The page
/// keeps a lasso's vertices at least 3 pixels apart and at most 4,096, in normalized
/// coordinates of 6 decimals: at most 22 bytes of JSON a vertex, 91 kB a lasso with its view
/// (a lasso around a whole 4K screen at 3 pixels is 4,000 vertices; one around an object on it
/// a few hundred). 1 MiB holds 11 such lassos and a handful of regions many times over (a box
/// is 4 vertices, 0.5 kB with its view); the page refuses a selection that would make its
/// messages larger. An edit at the cap raises the server's peak memory by about 55 MB (its
/// spec's text, written and parsed as the CLI reads it), a fixed bound.
pub const MAX_MESSAGE: usize = 1 << 20;

/// The scene's data as served: computed once.
struct Assets {
    scene_json: String,
    points: Vec<u8>,
    colors: Vec<u8>,
    classes: Vec<u8>,
    triangles: Vec<u8>,
    cells: Vec<u8>,
    blend: Vec<u8>,
}

/// What the page sends; the solver thread takes each with where to answer.
#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
enum Command {
    Edit {
        seq: u32,
        edit: Edit,
    },
    Release {
        seq: u32,
    },
    Select {
        seq: u32,
        selection: Selection,
    },
    Save {
        name: String,
        edit: Edit,
        #[serde(default)]
        overwrite: bool,
    },
    Apply {
        name: String,
        edit: Edit,
        #[serde(default)]
        overwrite: bool,
    },
}

/// The one folder the editor writes into, and the names it wrote there.
#[derive(Debug)]
pub struct Outputs {
    dir: PathBuf,
    input: PathBuf,
    written: Mutex<HashSet<String>>,
}

/// Why a file is not written.
#[derive(Debug)]
enum Refusal {
    /// The file exists, this editor did not write it, and the page did not say its user
    /// confirmed replacing it.
    Exists(PathBuf),
    /// Never written (a bad name, a link, the input…).
    Error(Error),
}

impl From<Error> for Refusal {
    fn from(e: Error) -> Self {
        Self::Error(e)
    }
}

impl Outputs {
    /// Writes into `dir` (`None`: the folder of `input`), which must be a folder.
    pub fn new(input: &Path, dir: Option<&Path>) -> Result<Self> {
        let (dir, named) = match dir {
            Some(d) => (d.to_path_buf(), true),
            None => match input.parent() {
                Some(p) if !p.as_os_str().is_empty() => (p.to_path_buf(), false),
                _ => (PathBuf::from("."), false),
            },
        };
        let shown = if named {
            format!("--out-dir {}", dir.display())
        } else {
            dir.display().to_string()
        };
        let canonical = std::fs::canonicalize(&dir)
            .map_err(|e| Error::Param(format!("{shown}: not a folder to write into: {e}")))?;
        if !canonical.is_dir() {
            return Err(Error::Param(format!("{shown}: not a folder to write into")));
        }
        Ok(Self {
            dir: canonical,
            input: input.to_path_buf(),
            written: Mutex::new(HashSet::new()),
        })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Where `name` is written, when it may be: a plain name with one of the extensions
    /// `extensions` ([`check_name`]), not the input, not a link or anything but a regular file,
    /// and not a file this editor did not write unless `overwrite` (the user confirmed).
    fn target(&self, name: &str, extensions: &[&str], overwrite: bool) -> Result<PathBuf, Refusal> {
        check_name(name, extensions)?;
        let path = self.dir.join(name);
        crate::io::refuse_overwrite(&self.input, &path)?;
        match std::fs::symlink_metadata(&path) {
            Ok(m) if m.file_type().is_symlink() => Err(Error::Param(format!(
                "{}: a symbolic link; the editor does not replace links, choose another name",
                path.display()
            ))
            .into()),
            Ok(m) if !m.is_file() => Err(Error::Param(format!(
                "{}: not a regular file; choose another name",
                path.display()
            ))
            .into()),
            Ok(_) if !overwrite && !self.wrote(name) => Err(Refusal::Exists(path)),
            Ok(_) => Ok(path),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(path),
            Err(e) => Err(Error::write(&path, e).into()),
        }
    }

    fn wrote(&self, name: &str) -> bool {
        self.written.lock().expect("not poisoned").contains(name)
    }

    fn record(&self, name: &str) {
        self.written
            .lock()
            .expect("not poisoned")
            .insert(name.to_string());
    }
}

/// Checks that `name` is a plain file name with one of `extensions` (lowercase, compared
/// without case): not empty, at most 255 bytes, no `/` or `\\` (no folder), no leading `.`
/// (no hidden file, no `.` or `..`; the editor's temporary files start with one), no control
/// character.
pub fn check_name(name: &str, extensions: &[&str]) -> Result<()> {
    let bad = |why: &str| Err(Error::Param(format!("{name:?}: {why}")));
    if name.is_empty() {
        return Err(Error::Param("a file name is needed".into()));
    }
    if name.len() > 255 {
        return bad("a file name of at most 255 bytes is needed");
    }
    if name.contains(['/', '\\']) {
        return bad("a plain file name is needed, without a folder");
    }
    if name.starts_with('.') {
        return bad("a name starting with '.' is not written");
    }
    if name.chars().any(char::is_control) {
        return bad("a file name without control characters is needed");
    }
    let ext = crate::io::extension(Path::new(name));
    if !ext.is_some_and(|e| extensions.contains(&e.as_str())) {
        let list: Vec<String> = extensions.iter().map(|e| format!(".{e}")).collect();
        return bad(&format!("the file must be {}", list.join(" or ")));
    }
    Ok(())
}

/// The editor's server, bound and ready.
pub struct Server {
    listener: TcpListener,
    token: String,
    port: u16,
    assets: Arc<Assets>,
    commands: Sender<(Command, Sender<Message>)>,
    out_dir: PathBuf,
}

impl Server {
    /// Binds 127.0.0.1:`port` (0: any free port) and starts the solver thread over `editor`;
    /// *Save edit* and *Apply* write into `out_dir` (`None`: the input's folder), which must be
    /// a folder.
    pub fn bind(editor: Editor, port: u16, out_dir: Option<&Path>) -> Result<Self> {
        let outputs = Arc::new(Outputs::new(&editor.scene().input, out_dir)?);
        let listener = TcpListener::bind(("127.0.0.1", port))
            .map_err(|e| Error::Param(format!("--port {port}: cannot listen on it: {e}")))?;
        let port = listener
            .local_addr()
            .map_err(|e| Error::Solver(format!("the listener's address: {e}")))?
            .port();
        let assets = Arc::new(assets(&editor, &outputs)?);
        let (commands, queue) = mpsc::channel();
        let out_dir = outputs.dir().to_path_buf();
        std::thread::spawn(move || solver(editor, outputs, queue));
        Ok(Self {
            listener,
            token: token()?,
            port,
            assets,
            commands,
            out_dir,
        })
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

    /// Serves until the process ends, a thread per connection.
    pub fn run(self) -> Result<()> {
        let gate = Arc::new(Gate {
            token: self.token.clone(),
            port: self.port,
        });
        for stream in self.listener.incoming() {
            let Ok(stream) = stream else { continue };
            let (gate, assets, commands) =
                (gate.clone(), self.assets.clone(), self.commands.clone());
            std::thread::spawn(move || {
                let _ = connection(stream, &gate, &assets, &commands);
            });
        }
        Ok(())
    }
}

/// 128 random bits as hex, from the system's generator.
fn token() -> Result<String> {
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut bytes))
        .map_err(|e| Error::Solver(format!("no random token: /dev/urandom: {e}")))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn u32_bytes(v: &[u32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn assets(editor: &Editor, outputs: &Outputs) -> Result<Assets> {
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
    })
    .to_string();
    let (cells, weights) = editor.blend()?;
    let mut blend = u32_bytes(&cells);
    blend.extend(f32_bytes(&weights));
    Ok(Assets {
        scene_json,
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

/// What a request must carry.
struct Gate {
    token: String,
    port: u16,
}

impl Gate {
    /// Whether the request's token, `Host` and `Origin` are this server's.
    fn admits(&self, query: &str, headers: &[httparse::Header<'_>]) -> bool {
        let token_ok = query
            .split('&')
            .filter_map(|kv| kv.split_once('='))
            .any(|(k, v)| k == "t" && v.as_bytes() == self.token.as_bytes());
        let header = |name: &str| {
            headers
                .iter()
                .find(|h| h.name.eq_ignore_ascii_case(name))
                .map(|h| String::from_utf8_lossy(h.value).into_owned())
        };
        let hosts = [
            format!("127.0.0.1:{}", self.port),
            format!("localhost:{}", self.port),
        ];
        let host_ok = header("host").is_some_and(|h| hosts.contains(&h));
        let origin_ok =
            header("origin").is_none_or(|o| hosts.iter().any(|h| o == format!("http://{h}")));
        token_ok && host_ok && origin_ok
    }
}

/// One connection: a GET of the page or data, or the WebSocket.
fn connection(
    mut stream: TcpStream,
    gate: &Gate,
    assets: &Assets,
    commands: &Sender<(Command, Sender<Message>)>,
) -> std::io::Result<()> {
    stream.set_read_timeout(Some(Duration::from_secs(10)))?;
    // Peek until the header is whole, so that a WebSocket upgrade reaches tungstenite intact.
    let mut buf = vec![0u8; 16 << 10];
    let start = Instant::now();
    let len = loop {
        let n = stream.peek(&mut buf)?;
        if n == 0 {
            return Ok(());
        }
        if let Some(at) = buf[..n].windows(4).position(|w| w == b"\r\n\r\n") {
            break at + 4;
        }
        if n == buf.len() || start.elapsed() > Duration::from_secs(10) {
            return respond(
                &mut stream,
                431,
                "text/plain",
                b"request header too large or slow",
            );
        }
        std::thread::sleep(Duration::from_millis(2));
    };
    let mut headers = [httparse::EMPTY_HEADER; 64];
    let mut request = httparse::Request::new(&mut headers);
    if !matches!(
        request.parse(&buf[..len]),
        Ok(httparse::Status::Complete(_))
    ) {
        return respond(&mut stream, 400, "text/plain", b"bad request");
    }
    let target = request.path.unwrap_or("/").to_string();
    let (path, query) = target.split_once('?').unwrap_or((&target, ""));
    let admitted = gate.admits(query, request.headers);
    let upgrade = request.headers.iter().any(|h| {
        h.name.eq_ignore_ascii_case("upgrade") && h.value.eq_ignore_ascii_case(b"websocket")
    });
    // A browser sends an Origin with every WebSocket; one without says nothing of its page.
    let origin = request
        .headers
        .iter()
        .any(|h| h.name.eq_ignore_ascii_case("origin"));
    if admitted && origin && upgrade && path == "/ws" && request.method == Some("GET") {
        return websocket(stream, commands);
    }
    // Consume the request before answering it (unread bytes would reset the connection).
    let mut consumed = vec![0u8; len];
    stream.read_exact(&mut consumed)?;
    if request.method != Some("GET") {
        return respond(&mut stream, 405, "text/plain", b"only GET");
    }
    if !admitted || upgrade {
        return respond(
            &mut stream,
            403,
            "text/plain",
            b"forbidden: token, Host or Origin",
        );
    }
    let (kind, body): (&str, &[u8]) = match path {
        "/" => ("text/html; charset=utf-8", PAGE.as_bytes()),
        "/scene.json" => ("application/json", assets.scene_json.as_bytes()),
        "/points.bin" => ("application/octet-stream", &assets.points),
        "/colors.bin" => ("application/octet-stream", &assets.colors),
        "/classes.bin" => ("application/octet-stream", &assets.classes),
        "/triangles.bin" => ("application/octet-stream", &assets.triangles),
        "/cells.bin" => ("application/octet-stream", &assets.cells),
        "/blend.bin" => ("application/octet-stream", &assets.blend),
        _ => return respond(&mut stream, 404, "text/plain", b"not found"),
    };
    respond(&mut stream, 200, kind, body)
}

fn respond(stream: &mut TcpStream, status: u16, kind: &str, body: &[u8]) -> std::io::Result<()> {
    let reason = match status {
        200 => "OK",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        _ => "Request Header Fields Too Large",
    };
    write!(
        stream,
        "HTTP/1.1 {status} {reason}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\n\
         Cache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\n\
         Referrer-Policy: no-referrer\r\n\
         Content-Security-Policy: default-src 'self' 'unsafe-inline'; connect-src 'self' ws://127.0.0.1:* ws://localhost:*; frame-ancestors 'none'\r\n\
         Connection: close\r\n\r\n",
        body.len()
    )?;
    stream.write_all(body)?;
    stream.flush()
}

/// The page's WebSocket: requests in, answers out, on one thread (reads poll every 2 ms).
fn websocket(
    stream: TcpStream,
    commands: &Sender<(Command, Sender<Message>)>,
) -> std::io::Result<()> {
    let config = WebSocketConfig::default()
        .max_message_size(Some(MAX_MESSAGE))
        .max_frame_size(Some(MAX_MESSAGE));
    let mut ws = match tungstenite::accept_with_config(stream, Some(config)) {
        Ok(ws) => ws,
        Err(_) => return Ok(()),
    };
    ws.get_mut()
        .set_read_timeout(Some(Duration::from_millis(2)))?;
    let (answers, outbox) = mpsc::channel::<Message>();
    loop {
        match ws.read() {
            Ok(Message::Text(text)) => {
                let command = match serde_json::from_str::<Command>(text.as_str()) {
                    Ok(c) => c,
                    Err(e) => {
                        let _ = ws.send(error(&format!("bad request: {e}")));
                        continue;
                    }
                };
                if commands.send((command, answers.clone())).is_err() {
                    return Ok(());
                }
            }
            Ok(Message::Close(_)) => return Ok(()),
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => return Ok(()),
        }
        while let Ok(m) = outbox.try_recv() {
            if ws.send(m).is_err() {
                return Ok(());
            }
        }
    }
}

fn error(text: &str) -> Message {
    Message::text(serde_json::json!({"type": "error", "message": text}).to_string())
}

fn text(value: serde_json::Value) -> Message {
    Message::text(value.to_string())
}

/// The solver thread: commands in order; of consecutive edits only the newest is solved.
fn solver(mut editor: Editor, outputs: Arc<Outputs>, queue: Receiver<(Command, Sender<Message>)>) {
    let editor_input = editor.scene().input.clone();
    let params = *editor.params();
    let applying = Arc::new(Mutex::new(false));
    // Where the last edit's answer went: the idle solver's iterations go there too.
    let mut last: Option<(u32, Sender<Message>)> = None;
    // Whether no pose came for [`IDLE`]: then the solver iterates until converged.
    let mut idle = false;
    loop {
        let first = match (&last, editor.converged()) {
            (Some((seq, reply)), false) => match next(&queue, idle) {
                Ok(c) => {
                    idle = false;
                    c
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    idle = true;
                    let answer = match editor.refine() {
                        Ok(m) => motions_message(*seq, m),
                        Err(e) => vec![error(&e.to_string())],
                    };
                    for m in answer {
                        let _ = reply.send(m);
                    }
                    continue;
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => return,
            },
            _ => match queue.recv() {
                Ok(c) => c,
                Err(_) => return,
            },
        };
        let mut pending = vec![first];
        pending.extend(queue.try_iter());
        // An edit followed at once by another is stale: edits carry the whole state.
        let stale: Vec<bool> = (0..pending.len())
            .map(|i| {
                matches!(pending[i].0, Command::Edit { .. })
                    && matches!(pending.get(i + 1), Some((Command::Edit { .. }, _)))
            })
            .collect();
        for ((command, reply), stale) in pending.into_iter().zip(stale) {
            let answer = match command {
                Command::Edit { .. } if stale => continue,
                Command::Edit { seq, edit } => {
                    last = Some((seq, reply.clone()));
                    match editor.solve(&edit) {
                        Ok(m) => motions_message(seq, m),
                        Err(e) => vec![error(&e.to_string())],
                    }
                }
                Command::Release { seq } => match editor.release() {
                    Ok(r) => released_message(seq, r),
                    Err(e) => vec![error(&e.to_string())],
                },
                Command::Select { seq, selection } => match editor.selected(&selection) {
                    Ok(mask) => vec![selected_message(seq, &mask)],
                    Err(e) => vec![text(serde_json::json!({
                        "type": "error", "message": e.to_string(), "select": seq
                    }))],
                },
                Command::Save {
                    name,
                    edit,
                    overwrite,
                } => vec![save(&editor, &outputs, &name, &edit, overwrite)],
                Command::Apply {
                    name,
                    edit,
                    overwrite,
                } => {
                    let extensions = crate::io::output_extensions(&editor_input);
                    match outputs.target(&name, extensions, overwrite) {
                        Ok(output) => {
                            let text = editor.spec_text(&edit);
                            apply(
                                editor_input.clone(),
                                (output, name),
                                text,
                                params,
                                (reply.clone(), outputs.clone()),
                                applying.clone(),
                            );
                            Vec::new()
                        }
                        Err(r) => vec![refused(r, &name, "apply")],
                    }
                }
            };
            for m in answer {
                let _ = reply.send(m);
            }
        }
    }
}

fn motions_message(seq: u32, m: Option<super::Motions>) -> Vec<Message> {
    let Some(m) = m else {
        let mut bytes = u32_bytes(&[1, seq, 0, 0]);
        bytes.extend(0f32.to_le_bytes());
        return vec![Message::binary(bytes)];
    };
    let cells = m.strain.len() as u32;
    let mut bytes = u32_bytes(&[1, seq, cells, m.iterations as u32]);
    bytes.extend((m.seconds as f32).to_le_bytes());
    bytes.extend(f32_bytes(&m.maps));
    bytes.extend(f32_bytes(&m.strain));
    let mut out = vec![Message::binary(bytes)];
    for w in m.warnings {
        out.push(text(serde_json::json!({"type": "warning", "message": w})));
    }
    out
}

/// Which samples a selection holds, one bit each.
fn selected_message(seq: u32, mask: &[bool]) -> Message {
    let count = mask.iter().filter(|&&m| m).count() as u32;
    let mut bytes = u32_bytes(&[3, seq, mask.len() as u32, count]);
    bytes.extend(mask.chunks(8).map(|bits| {
        bits.iter()
            .enumerate()
            .fold(0u8, |byte, (i, &b)| byte | (u8::from(b) << i))
    }));
    Message::binary(bytes)
}

/// The answer to a save or apply that was not done: `exists` (the page asks its user) or an
/// error.
fn refused(r: Refusal, name: &str, action: &str) -> Message {
    match r {
        Refusal::Exists(path) => text(serde_json::json!({
            "type": "exists", "name": name, "action": action,
            "path": path.display().to_string(),
        })),
        Refusal::Error(e) => error(&e.to_string()),
    }
}

fn released_message(seq: u32, r: super::Released) -> Vec<Message> {
    let n = (r.positions.len() / 3) as u32;
    let mut bytes = u32_bytes(&[2, seq, n, r.foldovers.1 as u32, r.foldovers.0 as u32]);
    bytes.extend(f32_bytes(&r.positions));
    let mut out = vec![Message::binary(bytes)];
    for w in r.warnings {
        out.push(text(serde_json::json!({"type": "warning", "message": w})));
    }
    out
}

/// *Save edit*: the spec of `edit` as `name` in the editor's folder ([`Outputs::target`];
/// atomically).
fn save(editor: &Editor, outputs: &Outputs, name: &str, edit: &Edit, overwrite: bool) -> Message {
    let result = outputs.target(name, &["toml"], overwrite).and_then(|path| {
        crate::io::write_atomic(&path, editor.spec_text(edit).as_bytes())?;
        Ok(path)
    });
    match result {
        Ok(path) => {
            outputs.record(name);
            text(serde_json::json!({
                "type": "saved", "name": name, "path": path.display().to_string()
            }))
        }
        Err(r) => refused(r, name, "save"),
    }
}

/// How long the solver waits for the next pose of a drag before it converges the last one:
/// a drag sends a pose every few tens of milliseconds, and an iteration started between two
/// would delay the next pose's answer by its length.
const IDLE: Duration = Duration::from_millis(150);

/// The next command: at once when `idle` (or a timeout), else within [`IDLE`].
fn next(
    queue: &Receiver<(Command, Sender<Message>)>,
    idle: bool,
) -> std::result::Result<(Command, Sender<Message>), mpsc::RecvTimeoutError> {
    if idle {
        queue.try_recv().map_err(|e| match e {
            mpsc::TryRecvError::Empty => mpsc::RecvTimeoutError::Timeout,
            mpsc::TryRecvError::Disconnected => mpsc::RecvTimeoutError::Disconnected,
        })
    } else {
        queue.recv_timeout(IDLE)
    }
}

/// Reports *Apply*'s progress to the page, at most every 100 ms.
struct Progress {
    reply: Sender<Message>,
    state: Mutex<(String, u64, u64, Instant)>,
}

impl crate::progress::Observer for Progress {
    fn stage(&self, name: &str, len: u64) {
        let mut s = self.state.lock().expect("not poisoned");
        *s = (name.to_string(), len, 0, Instant::now());
        self.send(&s);
    }
    fn advance(&self, n: u64) {
        let mut s = self.state.lock().expect("not poisoned");
        s.2 += n;
        if s.3.elapsed() > Duration::from_millis(100) {
            s.3 = Instant::now();
            self.send(&s);
        }
    }
}

impl Progress {
    fn send(&self, (stage, len, done, _): &(String, u64, u64, Instant)) {
        let _ = self.reply.send(text(serde_json::json!({
            "type": "progress", "stage": stage, "total": len, "done": done
        })));
    }
}

/// *Apply*: `deform` of the whole input under the spec `text` into `output` (named `name` in
/// the editor's folder, checked), on a thread of its own.
fn apply(
    input: PathBuf,
    (output, name): (PathBuf, String),
    spec_text: String,
    params: crate::pipeline::DeformParams,
    (reply, outputs): (Sender<Message>, Arc<Outputs>),
    applying: Arc<Mutex<bool>>,
) {
    {
        let mut busy = applying.lock().expect("not poisoned");
        if *busy {
            let _ = reply.send(error("an Apply is already running"));
            return;
        }
        *busy = true;
    }
    std::thread::spawn(move || {
        let start = Instant::now();
        let progress = Progress {
            reply: reply.clone(),
            state: Mutex::new((String::new(), 0, 0, Instant::now())),
        };
        let result = crate::io::refuse_overwrite(&input, &output).and_then(|_| {
            let name = output.with_extension("edit.toml");
            let spec = crate::spec::parse_spec::<3>(&spec_text, Path::new("."), &name)?;
            let params = crate::pipeline::DeformParams {
                proxy_samples: Some(0),
                ..params
            };
            crate::pipeline::deform_file(
                &input,
                &output,
                &spec,
                &params,
                crate::pipeline::CHUNK,
                None,
                &progress,
            )
        });
        let message = match result {
            Ok((_, info)) => {
                outputs.record(&name);
                text(serde_json::json!({
                "type": "applied",
                "output": output.display().to_string(),
                "samples": info.samples,
                "seconds": start.elapsed().as_secs_f64(),
                "warnings": info.deform.warnings,
                }))
            }
            Err(e) => error(&e.to_string()),
        };
        let _ = reply.send(message);
        *applying.lock().expect("not poisoned") = false;
    });
}
