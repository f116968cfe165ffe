//! The editor's figures: how long `rigidcells edit` takes to be ready on a file
//! (proxy, cells, blend weights, served data), how many warm solver updates per second a drag
//! gets, and the round trip of one pose through the server's WebSocket to the motions back.
//! The page's own frame time is measured in the browser (`tests/browser/editor_test.py`).
//!
//! `cargo run --release -p rigidcells-tools --bin editor -- FILE [CELLS] [UPDATES]`: fixes the
//! west tenth of FILE (along x) and drags the east tenth up in UPDATES steps of 0.5 % of the
//! extent each, at about CELLS cells (default 5000), as a page's drag sends them.

use std::net::TcpStream;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use rigidcells::internal::edit::server::Server;
use rigidcells::internal::edit::{Edit, Editor, HandleEdit, Scene, Selection};
use rigidcells::internal::pipeline::{Options, PROXY_SAMPLES};
use tungstenite::Message;

/// The west and east tenths of the scene as screen selections of a view looking down z.
fn ends(scene: &Scene, lift: f64) -> Edit {
    let (lo, hi) = (scene.bounds.0 - scene.center, scene.bounds.1 - scene.center);
    let (ex, ey) = (hi[0] - lo[0], hi[1] - lo[1]);
    // NDC x = 2 x / ex, y = 2 y / ey (relative coordinates are centered).
    let view = [
        [2.0 / ex, 0.0, 0.0, 0.0],
        [0.0, 2.0 / ey, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let strip = |a: f64, b: f64| Selection {
        polygon: Some(vec![[a, -1.1], [b, -1.1], [b, 1.1], [a, 1.1]]),
        view: Some(view),
        ..Default::default()
    };
    Edit {
        fixed: vec![strip(-1.1, -0.8)],
        handles: vec![HandleEdit {
            selections: vec![strip(0.8, 1.1)],
            translate: [0.0, 0.0, lift],
            axis: [0.0, 1.0, 0.0],
            degrees: 0.0,
            pivot: [0.45 * ex, 0.0, 0.0],
        }],
        pins: Vec::new(),
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let input = PathBuf::from(args.next().ok_or("usage: editor FILE [CELLS] [UPDATES]")?);
    let cells: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(5000);
    let updates: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(30);
    let options = Options {
        cells: Some(cells),
        transfer: rigidcells::internal::field::Transfer::Pu,
        ..Default::default()
    };

    let t = Instant::now();
    let scene = Scene::load(
        &input,
        PROXY_SAMPLES,
        &rigidcells::internal::progress::Silent,
    )?;
    let proxy_s = t.elapsed().as_secs_f64();
    let (samples, total) = (scene.points.len(), scene.total);
    let extent = (scene.bounds.1 - scene.bounds.0).amax();
    let t2 = Instant::now();
    let editor = Editor::new(scene.clone(), options)?;
    let cells_s = t2.elapsed().as_secs_f64();
    let n_cells = editor.complex().len();
    let t3 = Instant::now();
    let server = Server::bind(editor, 0, None)?;
    let serve_s = t3.elapsed().as_secs_f64();
    println!(
        "{}: {total} samples, proxy {samples}, {n_cells} cells; ready in {:.2} s \
         (proxy {proxy_s:.2} s, cells {cells_s:.2} s, blend weights and served data {serve_s:.2} s)",
        input.display(),
        t.elapsed().as_secs_f64()
    );

    // Warm updates in the library, as the solver thread runs them.
    let mut editor = Editor::new(scene.clone(), options)?;
    let t = Instant::now();
    let first = editor
        .solve(&ends(&scene, 0.0))?
        .ok_or("nothing selected")?;
    println!(
        "first solve (from rest, load steps): {:.3} s, {} iterations",
        t.elapsed().as_secs_f64(),
        first.iterations
    );
    let mut times = Vec::new();
    let mut iterations = 0;
    let t = Instant::now();
    for k in 1..=updates {
        let s = Instant::now();
        let m = editor
            .solve(&ends(&scene, 0.005 * extent * k as f64))?
            .ok_or("no motions")?;
        times.push(s.elapsed().as_secs_f64());
        iterations += m.iterations;
    }
    let all = t.elapsed().as_secs_f64();
    println!(
        "warm updates: {updates} in {all:.2} s = {:.1} per second (median {:.1} ms, {:.1} iterations each)",
        updates as f64 / all,
        1e3 * median(&mut times),
        iterations as f64 / updates as f64
    );
    let t = Instant::now();
    let released = editor.release()?;
    println!(
        "release (final transfer on the proxy, fold-over check): {:.3} s, {} of {} folded",
        t.elapsed().as_secs_f64(),
        released.foldovers.1,
        released.foldovers.0
    );

    // Round trips through the server.
    let (port, token) = (server.port(), server.token().to_string());
    std::thread::spawn(move || server.run());
    let stream = TcpStream::connect(("127.0.0.1", port))?;
    stream.set_read_timeout(Some(Duration::from_secs(120)))?;
    // The server takes a WebSocket only with an Origin, as a browser sends it.
    let mut request = tungstenite::client::IntoClientRequest::into_client_request(format!(
        "ws://127.0.0.1:{port}/ws?t={token}"
    ))?;
    request.headers_mut().insert(
        "Origin",
        format!("http://127.0.0.1:{port}")
            .parse()
            .expect("a header value"),
    );
    let (mut ws, _) = tungstenite::client(request, stream)?;
    let mut trips = Vec::new();
    for k in 0..=updates {
        let edit = ends(&scene, 0.005 * extent * k as f64);
        let message = serde_json::json!({"type": "edit", "seq": k, "edit": edit_json(&edit)});
        let s = Instant::now();
        ws.send(Message::text(message.to_string()))?;
        loop {
            // The answer to this pose (not an idle iteration on the one before).
            if let Message::Binary(b) = ws.read()?
                && b[0] == 1
                && b[4..8] == (k as u32).to_le_bytes()
            {
                break;
            }
        }
        if k > 0 {
            trips.push(s.elapsed().as_secs_f64());
        }
    }
    println!(
        "round trip pose -> motions through the WebSocket: median {:.1} ms, worst {:.1} ms ({} cells, {} bytes a message)",
        1e3 * median(&mut trips),
        1e3 * trips.last().copied().unwrap_or(0.0),
        n_cells,
        20 + 52 * n_cells
    );
    Ok(())
}

/// The page's JSON of an edit.
fn edit_json(edit: &Edit) -> serde_json::Value {
    let sel = |s: &Selection| serde_json::json!({"polygon": s.polygon, "view": s.view});
    serde_json::json!({
        "fixed": edit.fixed.iter().map(sel).collect::<Vec<_>>(),
        "handles": edit.handles.iter().map(|h| serde_json::json!({
            "selections": h.selections.iter().map(sel).collect::<Vec<_>>(),
            "translate": h.translate, "axis": h.axis, "degrees": h.degrees, "pivot": h.pivot,
        })).collect::<Vec<_>>(),
    })
}
