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
//! any `Origin` must be this server's; otherwise 403 and nothing else. Only GET is served, and
//! only the page and the scene's data. Files are written only where the page's user names
//! them (*Save edit*, *Apply*), never over the input.
//!
//! The solver runs on its own thread and takes commands in order; of several pose updates
//! waiting, only the newest is solved (a drag sends one per frame; the solver answers as fast
//! as it can and the page always sees the latest pose). *Apply* runs on a thread of its own and
//! reports progress to the page.
//!
//! ## Wire format
//! Page → server: text JSON `{"type": "edit", "seq": n, "edit": Edit}`, `{"type": "release",
//! "seq": n}`, `{"type": "save", "path": p, "edit": Edit}`, `{"type": "apply", "output": p,
//! "edit": Edit}`. Server → page: binary messages, little-endian, starting with a `u32` kind —
//! 1 motions `[1, seq, cells, iterations, seconds: f32, maps: 12·cells f32, strain: cells f32]`,
//! 2 released `[2, seq, samples, folded, checked, positions: 3·samples f32]` — and text JSON
//! for `saved`, `progress`, `applied`, `warning` and `error`.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Deserialize;
use tungstenite::Message;

use super::{Edit, Editor};
use crate::error::{Error, Result};

/// The page, with its script and styles, built into the binary.
const PAGE: &str = include_str!("page.html");

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

/// A command for the solver thread, with where to answer.
enum Command {
    Edit { seq: u32, edit: Edit },
    Release { seq: u32 },
    Save { path: PathBuf, edit: Edit },
    Apply { output: PathBuf, edit: Edit },
}

/// What the page sends.
#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "lowercase")]
enum Request {
    Edit { seq: u32, edit: Edit },
    Release { seq: u32 },
    Save { path: String, edit: Edit },
    Apply { output: String, edit: Edit },
}

/// The editor's server, bound and ready.
pub struct Server {
    listener: TcpListener,
    token: String,
    port: u16,
    assets: Arc<Assets>,
    commands: Sender<(Command, Sender<Message>)>,
}

impl Server {
    /// Binds 127.0.0.1:`port` (0: any free port) and starts the solver thread over `editor`.
    pub fn bind(editor: Editor, port: u16) -> Result<Self> {
        let listener = TcpListener::bind(("127.0.0.1", port))
            .map_err(|e| Error::Param(format!("--port {port}: cannot listen on it: {e}")))?;
        let port = listener
            .local_addr()
            .map_err(|e| Error::Solver(format!("the listener's address: {e}")))?
            .port();
        let assets = Arc::new(assets(&editor)?);
        let (commands, queue) = mpsc::channel();
        std::thread::spawn(move || solver(editor, queue));
        Ok(Self {
            listener,
            token: token()?,
            port,
            assets,
            commands,
        })
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

fn assets(editor: &Editor) -> Result<Assets> {
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
        "transfer": format!("{:?}", editor.params().transfer),
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
    if admitted && upgrade && path == "/ws" && request.method == Some("GET") {
        return websocket(stream, commands);
    }
    // Consume the request before answering it (unread bytes would reset the connection).
    let mut consumed = vec![0u8; len];
    stream.read_exact(&mut consumed)?;
    if request.method != Some("GET") {
        return respond(&mut stream, 405, "text/plain", b"only GET");
    }
    if !admitted {
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
         Content-Security-Policy: default-src 'self' 'unsafe-inline'; connect-src 'self' ws://127.0.0.1:* ws://localhost:*\r\n\
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
    let mut ws = match tungstenite::accept(stream) {
        Ok(ws) => ws,
        Err(_) => return Ok(()),
    };
    ws.get_mut()
        .set_read_timeout(Some(Duration::from_millis(2)))?;
    let (answers, outbox) = mpsc::channel::<Message>();
    loop {
        match ws.read() {
            Ok(Message::Text(text)) => {
                let command = match serde_json::from_str::<Request>(text.as_str()) {
                    Ok(r) => command(r),
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

fn command(r: Request) -> Command {
    match r {
        Request::Edit { seq, edit } => Command::Edit { seq, edit },
        Request::Release { seq } => Command::Release { seq },
        Request::Save { path, edit } => Command::Save {
            path: PathBuf::from(path),
            edit,
        },
        Request::Apply { output, edit } => Command::Apply {
            output: PathBuf::from(output),
            edit,
        },
    }
}

fn error(text: &str) -> Message {
    Message::text(serde_json::json!({"type": "error", "message": text}).to_string())
}

fn text(value: serde_json::Value) -> Message {
    Message::text(value.to_string())
}

/// The solver thread: commands in order; of consecutive edits only the newest is solved.
fn solver(mut editor: Editor, queue: Receiver<(Command, Sender<Message>)>) {
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
                Command::Save { path, edit } => vec![save(&editor, &path, &edit)],
                Command::Apply { output, edit } => {
                    let text = editor.spec_text(&edit);
                    apply(
                        editor_input.clone(),
                        output,
                        text,
                        params,
                        reply.clone(),
                        applying.clone(),
                    );
                    Vec::new()
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

/// *Save edit*: the spec of `edit` to `path` (atomically; never over the input).
fn save(editor: &Editor, path: &Path, edit: &Edit) -> Message {
    let result = crate::io::refuse_overwrite(&editor.scene().input, path)
        .and_then(|_| crate::io::write_atomic(path, editor.spec_text(edit).as_bytes()));
    match result {
        Ok(()) => text(serde_json::json!({"type": "saved", "path": path.display().to_string()})),
        Err(e) => error(&e.to_string()),
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

/// *Apply*: `deform` of the whole input under the spec `text`, on a thread of its own.
fn apply(
    input: PathBuf,
    output: PathBuf,
    spec_text: String,
    params: crate::pipeline::DeformParams,
    reply: Sender<Message>,
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
            Ok((_, info)) => text(serde_json::json!({
                "type": "applied",
                "output": output.display().to_string(),
                "samples": info.samples,
                "seconds": start.elapsed().as_secs_f64(),
                "warnings": info.deform.warnings,
            })),
            Err(e) => error(&e.to_string()),
        };
        let _ = reply.send(message);
        *applying.lock().expect("not poisoned") = false;
    });
}
