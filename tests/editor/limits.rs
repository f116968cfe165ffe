//! The editor's bounds on the work a page can ask for: edits within the page's own limits
//! (pins, handles, selections, polygon vertices), a spec of many entries read in linear time,
//! at most `MAX_CONNECTIONS` connections at once, and no thread that wakes while the page is
//! idle.

use std::net::TcpStream;
use std::path::Path;
use std::time::{Duration, Instant};

use rigidcells::internal::edit::{MAX_HANDLES, MAX_PINS, MAX_POLYGON, MAX_SELECTIONS};
use serde_json::json;
use tungstenite::Message;

use super::{connect, flat_view, get, next_binary, next_text, running, send, strip, u32_at};

/// The error the server answers next (after any other message).
fn next_error(ws: &mut tungstenite::WebSocket<TcpStream>) -> serde_json::Value {
    loop {
        let m = next_text(ws);
        if m["type"] == "error" {
            return m;
        }
    }
}

/// An edit past any of the page's limits is refused with a message naming the limit, at once
/// (40,000 pins in one message held the solver for minutes); the page is told the limits; an
/// edit within them is solved after.
#[test]
fn edits_past_the_pages_limits_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let (port, token) = running(dir.path());
    let host = format!("127.0.0.1:{port}");
    let (_, scene) = get(port, &format!("/scene.json?t={token}"), &host, None);
    let scene: serde_json::Value = serde_json::from_slice(&scene).unwrap();
    assert_eq!(scene["max_pins"], MAX_PINS);
    assert_eq!(scene["max_handles"], MAX_HANDLES);
    assert_eq!(scene["max_selections"], MAX_SELECTIONS);
    assert_eq!(scene["max_polygon"], MAX_POLYGON);
    let mut ws = connect(port, &token);

    let start = Instant::now();
    let pins = vec![[0.1, 0.2, 0.3]; 40_000];
    send(
        &mut ws,
        json!({"type": "edit", "seq": 1, "edit": {"pins": pins}}),
    );
    let m = next_error(&mut ws);
    let said = m["message"].as_str().unwrap();
    assert!(said.contains(&format!("at most {MAX_PINS}")), "{m}");
    assert!(
        start.elapsed() < Duration::from_secs(20),
        "{:?}",
        start.elapsed()
    );

    let handle = json!({"selections": [strip(0.9, 1.1)], "translate": [0, 0, 1]});
    let handles = vec![handle; MAX_HANDLES + 1];
    send(
        &mut ws,
        json!({"type": "edit", "seq": 2, "edit": {"handles": handles}}),
    );
    let m = next_error(&mut ws);
    assert!(
        m["message"]
            .as_str()
            .unwrap()
            .contains(&format!("at most {MAX_HANDLES}"))
    );

    let fixed = vec![strip(-1.1, -0.9); MAX_SELECTIONS + 1];
    send(
        &mut ws,
        json!({"type": "save", "name": "a.toml", "edit": {"fixed": fixed}}),
    );
    let m = next_error(&mut ws);
    assert!(
        m["message"]
            .as_str()
            .unwrap()
            .contains(&format!("at most {MAX_SELECTIONS}"))
    );
    assert!(!dir.path().join("a.toml").exists());

    let ring: Vec<[f64; 2]> = (0..=MAX_POLYGON)
        .map(|k| {
            let a = k as f64 / MAX_POLYGON as f64 * std::f64::consts::TAU;
            [a.cos(), a.sin()]
        })
        .collect();
    let lasso = json!({"polygon": ring, "view": flat_view()});
    send(
        &mut ws,
        json!({"type": "select", "seq": 7, "selection": lasso}),
    );
    let m = next_error(&mut ws);
    assert_eq!(m["select"], 7, "{m}");
    assert!(
        m["message"]
            .as_str()
            .unwrap()
            .contains(&format!("at most {MAX_POLYGON}"))
    );

    // Within the limits: solved.
    let pins = vec![[0.0, 0.0, 0.0]; 1];
    let edit = json!({"fixed": [strip(-1.1, -0.9)], "pins": pins,
        "handles": [{"selections": [strip(0.9, 1.1)], "translate": [0, 0, 1]}]});
    send(&mut ws, json!({"type": "edit", "seq": 9, "edit": edit}));
    let b = next_binary(&mut ws);
    assert_eq!((u32_at(&b, 0), u32_at(&b, 1)), (1, 9));
    assert!(u32_at(&b, 2) > 0);
}

/// A spec of many entries is read in time linear in its length (the line of each entry is
/// found by a binary search, not by counting from the start).
#[test]
fn a_spec_of_many_pins_is_read_in_linear_time() {
    let mut text = String::new();
    for k in 0..60_000 {
        let x = f64::from(k) * 1e-3;
        text += &format!("\n[[pin]]\npoint = [{x:?}, 0.5, 0.5]\nto = [{x:?}, 0.5, 0.5]\n");
    }
    let start = Instant::now();
    let spec =
        rigidcells::internal::spec::parse_spec::<3>(&text, Path::new("."), Path::new("p.toml"))
            .unwrap();
    let took = start.elapsed();
    assert_eq!(spec.pins.len(), 60_000);
    assert_eq!(spec.pins[59_999].line, 4 * 59_999 + 2);
    assert!(
        took < Duration::from_secs(15),
        "60,000 pins read in {took:?}"
    );
}

/// At most `MAX_CONNECTIONS` connections are served at once (a thread each): one more is
/// answered 503 at once, and served again once the others close.
///
/// Nothing but the idle connections holds the server's slots when the next one comes: the
/// server accepts in the order of connecting, and no earlier request of this test is still
/// finishing on its thread (an answered request frees its slot only after the page has read
/// the answer, so one just before the idle connections could leave one of them refused).
#[test]
fn connections_are_capped() {
    use rigidcells::internal::edit::server::MAX_CONNECTIONS;
    let dir = tempfile::tempdir().unwrap();
    let (port, token) = running(dir.path());
    let host = format!("127.0.0.1:{port}");
    let page = format!("/?t={token}");
    // Connections that send nothing hold their threads (until the head's time runs out).
    let idle: Vec<TcpStream> = (0..MAX_CONNECTIONS)
        .map(|_| TcpStream::connect(("127.0.0.1", port)).unwrap())
        .collect();
    assert_eq!(get(port, &page, &host, None).0, 503);
    drop(idle);
    let start = Instant::now();
    while get(port, &page, &host, None).0 != 200 {
        assert!(start.elapsed() < Duration::from_secs(5), "not served again");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// How often the thread named `name` of this process went to sleep
/// (`voluntary_ctxt_switches`), if there is one.
#[cfg(target_os = "linux")]
fn sleeps(name: &str) -> Option<u64> {
    std::fs::read_dir("/proc/self/task")
        .ok()?
        .flatten()
        .find(|task| {
            std::fs::read_to_string(task.path().join("comm")).is_ok_and(|n| n.trim() == name)
        })
        .and_then(|task| {
            let status = std::fs::read_to_string(task.path().join("status")).ok()?;
            status
                .lines()
                .find_map(|l| l.strip_prefix("voluntary_ctxt_switches:"))
                .and_then(|v| v.trim().parse().ok())
        })
}

/// While the page sends nothing, the threads of its WebSocket (`edit-PORT` reads, `edit-w-PORT`
/// writes, PORT the page's end) sleep until something comes: a thread that polled would wake
/// hundreds of times a second.
#[cfg(target_os = "linux")]
#[test]
fn an_idle_page_wakes_no_thread() {
    let dir = tempfile::tempdir().unwrap();
    let (port, token) = running(dir.path());
    let mut ws = connect(port, &token);
    send(&mut ws, json!({"type": "edit", "seq": 1, "edit": {}}));
    assert_eq!(u32_at(&next_binary(&mut ws), 1), 1);
    let page = ws.get_ref().local_addr().unwrap().port();
    let names = [format!("edit-{page}"), format!("edit-w-{page}")];
    let first: Vec<Option<u64>> = names.iter().map(|n| sleeps(n)).collect();
    std::thread::sleep(Duration::from_millis(500));
    for (name, first) in names.iter().zip(first) {
        let woke = sleeps(name).zip(first).map(|(then, first)| then - first);
        assert!(
            woke.is_some_and(|w| w < 5),
            "{name}: woke {woke:?} times in 0.5 s while the page was idle"
        );
    }
    let _ = ws.send(Message::Close(None));
}
