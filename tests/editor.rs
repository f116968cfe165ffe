//! The editor's protocol: the token and the Host/Origin checks, a move answered by motions, a
//! release by the final transfer on the proxy, and a saved spec that the CLI deforms to the
//! shape the editor showed.

mod common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::time::Duration;

use rigidcells::edit::server::Server;
use rigidcells::edit::{Editor, Scene};
use rigidcells::pipeline::DeformParams;
use serde_json::json;
use tungstenite::Message;

/// The editor of the 10×1×1 bar (cells of 0.25), served on a free port.
fn serve(dir: &Path) -> (Server, std::path::PathBuf) {
    let input = dir.join("bar.ply");
    data_gen::write_ply(&input, &data_gen::bar([10.0, 1.0, 1.0], 4.0), true).unwrap();
    let scene = Scene::load(&input, 1 << 20, &rigidcells::progress::Silent).unwrap();
    let mut params = DeformParams::default();
    params.build.cell_size = Some(0.5);
    params.transfer = rigidcells::field::Transfer::Pu;
    (
        Server::bind(Editor::new(scene, params).unwrap(), 0).unwrap(),
        input,
    )
}

/// A raw GET with the given Host and Origin; returns the status code and the body.
fn get(port: u16, target: &str, host: &str, origin: Option<&str>) -> (u16, Vec<u8>) {
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    let origin = origin.map_or(String::new(), |o| format!("Origin: {o}\r\n"));
    write!(s, "GET {target} HTTP/1.1\r\nHost: {host}\r\n{origin}\r\n").unwrap();
    let mut out = Vec::new();
    s.read_to_end(&mut out).unwrap();
    let head_end = out.windows(4).position(|w| w == b"\r\n\r\n").unwrap() + 4;
    let status = std::str::from_utf8(&out[9..12]).unwrap().parse().unwrap();
    (status, out[head_end..].to_vec())
}

/// A view whose screen is the x–y plane of the bar's relative coordinates, x/5 and y/1.
fn flat_view() -> serde_json::Value {
    json!([[0.2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0.1, 0], [0, 0, 0, 1]])
}

fn ends(translate: [f64; 3], degrees: f64) -> serde_json::Value {
    json!({
        "fixed": [{"polygon": [[-1.1, -1.1], [-0.92, -1.1], [-0.92, 1.1], [-1.1, 1.1]], "view": flat_view()}],
        "handles": [{
            "selections": [{"polygon": [[0.92, -1.1], [1.1, -1.1], [1.1, 1.1], [0.92, 1.1]], "view": flat_view()}],
            "translate": translate, "axis": [0, 1, 0], "degrees": degrees, "pivot": [4.8, 0, 0]
        }]
    })
}

fn next_binary(ws: &mut tungstenite::WebSocket<TcpStream>) -> Vec<u8> {
    loop {
        match ws.read().unwrap() {
            Message::Binary(b) => return b.to_vec(),
            Message::Text(t) => {
                let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
                assert_ne!(v["type"], "error", "{t}");
            }
            _ => {}
        }
    }
}

fn next_text(ws: &mut tungstenite::WebSocket<TcpStream>) -> serde_json::Value {
    loop {
        if let Message::Text(t) = ws.read().unwrap() {
            return serde_json::from_str(t.as_str()).unwrap();
        }
    }
}

fn u32_at(b: &[u8], i: usize) -> u32 {
    u32::from_le_bytes(b[4 * i..4 * i + 4].try_into().unwrap())
}

fn f32s(b: &[u8]) -> Vec<f32> {
    b.chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

#[test]
fn the_token_host_and_origin_are_enforced() {
    let dir = tempfile::tempdir().unwrap();
    let (server, _) = serve(dir.path());
    let (port, token) = (server.port(), server.token().to_string());
    std::thread::spawn(move || server.run());
    let host = format!("127.0.0.1:{port}");
    let page = format!("/?t={token}");
    let (status, body) = get(port, &page, &host, None);
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&body).contains("<canvas id=\"gl\">"));
    assert_eq!(get(port, "/", &host, None).0, 403, "no token");
    assert_eq!(get(port, "/?t=00", &host, None).0, 403, "a wrong token");
    assert_eq!(
        get(port, &page, "evil.example:80", None).0,
        403,
        "a rebound host"
    );
    let evil = Some("http://evil.example");
    assert_eq!(get(port, &page, &host, evil).0, 403, "a foreign origin");
    let own = format!("http://{host}");
    assert_eq!(get(port, &page, &host, Some(&own)).0, 200);
    assert_eq!(
        get(port, &format!("/etc/passwd?t={token}"), &host, None).0,
        404
    );
    let (status, points) = get(port, &format!("/points.bin?t={token}"), &host, None);
    assert_eq!(status, 200);
    assert!(points.len() > 12 && points.len().is_multiple_of(12));
    // The WebSocket without the token is refused at the handshake.
    let stream = TcpStream::connect(("127.0.0.1", port)).unwrap();
    assert!(tungstenite::client(format!("ws://{host}/ws"), stream).is_err());
}

#[test]
fn a_move_returns_motions_and_the_saved_spec_reproduces_the_shape() {
    let dir = tempfile::tempdir().unwrap();
    let (server, input) = serve(dir.path());
    let (port, token) = (server.port(), server.token().to_string());
    std::thread::spawn(move || server.run());
    let stream = TcpStream::connect(("127.0.0.1", port)).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(60)))
        .unwrap();
    let (mut ws, _) =
        tungstenite::client(format!("ws://127.0.0.1:{port}/ws?t={token}"), stream).unwrap();
    let send = |ws: &mut tungstenite::WebSocket<TcpStream>, v: serde_json::Value| {
        ws.send(Message::text(v.to_string())).unwrap()
    };

    // Nothing selected: an empty answer.
    send(&mut ws, json!({"type": "edit", "seq": 1, "edit": {}}));
    let b = next_binary(&mut ws);
    assert_eq!((u32_at(&b, 0), u32_at(&b, 1), u32_at(&b, 2)), (1, 1, 0));

    // The ends selected, the handle lifted: motions for every cell; the handle's cells
    // carried up by 1, the fixed cells at rest.
    send(
        &mut ws,
        json!({"type": "edit", "seq": 2, "edit": ends([0.0, 0.0, 1.0], 0.0)}),
    );
    let b = next_binary(&mut ws);
    let cells = u32_at(&b, 2) as usize;
    assert_eq!((u32_at(&b, 0), u32_at(&b, 1)), (1, 2));
    assert!(cells > 50, "{cells} cells");
    let maps = f32s(&b[20..20 + 48 * cells]);
    let lift = |c: usize| maps[12 * c + 11];
    let lifts: Vec<f32> = (0..cells).map(lift).collect();
    let top = lifts.iter().cloned().fold(f32::MIN, f32::max);
    let bottom = lifts.iter().cloned().fold(f32::MAX, f32::min);
    assert!(
        (top - 1.0).abs() < 1e-4 && bottom.abs() < 1e-4,
        "{bottom} … {top}"
    );

    // Moved again (the same selections): a warm update.
    send(
        &mut ws,
        json!({"type": "edit", "seq": 3, "edit": ends([0.0, 0.0, 2.0], 20.0)}),
    );
    let b = next_binary(&mut ws);
    assert_eq!(u32_at(&b, 1), 3);
    assert_eq!(u32_at(&b, 3) as usize, rigidcells::edit::DRAG_ITERATIONS);
    let maps = f32s(&b[20..20 + 48 * cells]);
    let top = (0..cells)
        .map(|c| maps[12 * c + 11])
        .fold(f32::MIN, f32::max);
    assert!(top > 1.5, "the handle's cells rose only {top}");

    // Released: the final transfer on the proxy.
    send(&mut ws, json!({"type": "release", "seq": 3}));
    let b = next_binary(&mut ws);
    assert_eq!((u32_at(&b, 0), u32_at(&b, 1)), (2, 3));
    let n = u32_at(&b, 2) as usize;
    let shown = f32s(&b[20..20 + 12 * n]);

    // Saved: a spec the CLI reads, and deforms to what the editor showed.
    let spec = dir.path().join("bar.edit.toml");
    send(
        &mut ws,
        json!({"type": "save", "path": spec.to_str().unwrap(), "edit": ends([0.0, 0.0, 2.0], 20.0)}),
    );
    assert_eq!(next_text(&mut ws)["type"], "saved");
    let text = std::fs::read_to_string(&spec).unwrap();
    assert!(
        text.contains("view = ") && text.contains("pivot = "),
        "{text}"
    );
    let out = dir.path().join("bent.ply");
    let r = common::deform(&input, &out, &spec, &["--cell-size", "0.5"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let doc = rigidcells::io::Document::read(&out).unwrap();
    let center = Scene::load(&input, 1 << 20, &rigidcells::progress::Silent)
        .unwrap()
        .center;
    assert_eq!(doc.positions().len(), n);
    let mut worst = 0f64;
    for (i, p) in doc.positions().iter().enumerate() {
        for a in 0..3 {
            worst = worst.max((p[a] - center[a] - shown[3 * i + a] as f64).abs());
        }
    }
    assert!(worst < 1e-4, "the CLI's shape is {worst} from the editor's");

    // Apply: the whole file deformed by the server, with progress, as the CLI does it.
    let applied = dir.path().join("applied.ply");
    send(
        &mut ws,
        json!({"type": "apply", "output": applied.to_str().unwrap(), "edit": ends([0.0, 0.0, 2.0], 20.0)}),
    );
    let mut progress = 0;
    let done = loop {
        let m = next_text(&mut ws);
        match m["type"].as_str() {
            Some("progress") => progress += 1,
            Some("applied") => break m,
            _ => panic!("{m}"),
        }
    };
    assert!(progress > 0 && done["samples"] == n, "{done}");
    assert_eq!(
        std::fs::read(&applied).unwrap(),
        std::fs::read(&out).unwrap()
    );

    // Never over the input.
    send(
        &mut ws,
        json!({"type": "save", "path": input.to_str().unwrap(), "edit": ends([0.0; 3], 0.0)}),
    );
    assert_eq!(next_text(&mut ws)["type"], "error");
}

/// A selection by LAS class alone (the page's *Select classes*) and one narrowed by a class: the
/// ground of autzen fixed, a screen box over its east end a handle. All the ground fixed
/// conflicts with the handle (an error naming both, as the page shows it); the ground of the
/// west half does not, and solves.
#[test]
fn a_class_selection_fixes_the_ground() {
    let input = common::shared("las/autzen_trim.las");
    let scene = Scene::load(&input, 1 << 20, &rigidcells::progress::Silent).unwrap();
    assert!(scene.classes.contains(&2));
    let mut params = DeformParams::default();
    params.build.target_cells = Some(800);
    let (lo, hi) = (scene.bounds.0 - scene.center, scene.bounds.1 - scene.center);
    let view = json!([
        [2.0 / (hi[0] - lo[0]), 0, 0, 0],
        [0, 2.0 / (hi[1] - lo[1]), 0, 0],
        [0, 0, 0, 0],
        [0, 0, 0, 1]
    ]);
    let mut editor = Editor::new(scene, params).unwrap();
    let edit: rigidcells::edit::Edit = serde_json::from_value(json!({
        "fixed": [{"classification": [2]}, {"classification": [2], "polygon": [[-1.1, -1.1], [0.0, -1.1], [0.0, 1.1], [-1.1, 1.1]], "view": view}],
        "handles": [{"selections": [{"polygon": [[0.9, -1.1], [1.1, -1.1], [1.1, 1.1], [0.9, 1.1]], "view": view}],
                     "translate": [0, 0, 5], "axis": [0, 0, 1], "degrees": 0, "pivot": [0, 0, 0]}]
    }))
    .unwrap();
    assert!(editor.spec_text(&edit).contains("classification = [2]"));
    let mut all_ground = edit.clone();
    all_ground.fixed.truncate(1);
    let e = editor
        .solve(&all_ground)
        .expect_err("a conflict")
        .to_string();
    assert!(e.contains("fixed #1") && e.contains("handle #1"), "{e}");
    let mut west = edit.clone();
    west.fixed.remove(0);
    let m = editor.solve(&west).unwrap().expect("motions");
    assert!(!m.strain.is_empty());
    let spec = editor.last_parsed().unwrap();
    assert_eq!((spec.fixed.len(), spec.handles.len()), (1, 1));
    let text = editor.last_spec().unwrap();
    assert!(
        text.contains("view = ") && text.contains("classification = [2]"),
        "{text}"
    );
}

/// The `view` key of a screen selection: only with a `polygon`, 4 × 4 finite numbers, no `z`;
/// a point behind the camera is never selected.
#[test]
fn screen_selections_parse_strictly() {
    use rigidcells::spec::parse_spec;
    let parse = |t: &str| parse_spec::<3>(t, Path::new("."), Path::new("e.toml"));
    let view = "view = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 0], [0, 0, -1, 0]]";
    let square = "polygon = [[-1, -1], [1, -1], [1, 1], [-1, 1]]";
    let spec = parse(&format!("[[fixed]]\n{square}\n{view}\n")).unwrap();
    let region = &spec.fixed[0].region;
    // w = −z: in front of this camera is z < 0; x/w and y/w must lie in the square.
    let at =
        |x: f64, y: f64, z: f64| region.contains_point(&rigidcells::rigid::Vect::<3>::new(x, y, z));
    assert!(at(0.5, 0.5, -1.0) && !at(0.5, 0.5, 1.0) && !at(3.0, 0.0, -1.0) && at(3.0, 0.0, -4.0));
    for bad in [
        format!("[[fixed]]\nbox = {{ min = [0, 0, 0], max = [1, 1, 1] }}\n{view}\n"),
        format!("[[fixed]]\n{square}\nview = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n"),
        format!("[[fixed]]\n{square}\n{view}\nz = [0, 1]\n"),
    ] {
        let e = parse(&bad).expect_err(&bad).to_string();
        assert!(e.contains("view"), "{e}");
    }
}

/// A mesh with more vertices than the proxy holds is streamed every k-th vertex (points, no
/// triangles), not read whole; one within it keeps its triangles.
#[test]
fn a_mesh_larger_than_the_proxy_is_decimated() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bar.ply");
    data_gen::write_ply(&input, &data_gen::bar([10.0, 1.0, 1.0], 4.0), true).unwrap();
    let all = Scene::load(&input, 1 << 20, &rigidcells::progress::Silent).unwrap();
    assert!(!all.triangles.is_empty() && all.total == all.points.len() as u64);
    let few = Scene::load(&input, 500, &rigidcells::progress::Silent).unwrap();
    assert!(few.triangles.is_empty() && few.points.len() <= 500 && few.total == all.total);
    assert_eq!(few.points[1], all.points[few.total.div_ceil(500) as usize]);
}
