//! The editor's solver thread: the page's commands in order, each answered on the connection
//! that sent it; of several pose updates waiting only the newest is solved (a drag sends one
//! per frame; the solver answers as fast as it can and the page always sees the latest pose:
//! [`super::queue`], which also bounds the commands waiting).
//! While no pose comes, the last one is converged an iteration at a time. *Apply* runs on a
//! thread of its own and reports progress.
//!
//! A failure never ends the thread: an error is the page's message and ends the live session
//! (its next edit is solved from rest: a failed step may leave constraints it did not solve),
//! and a panic is caught, said to the page the same way, and the live deformation built again
//! ([`Editor::restart`]), so the next edit is solved as on a fresh start.

use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Deserialize;
use tungstenite::Message;

use super::queue::{Inbox, MAX_QUEUED};
use super::{OutputFolder, Refusal, f32_bytes, u32_bytes};
use crate::edit::{Edit, Editor, Motions, PageNames, Released, Selection};
use crate::error::{Error, Result};
use crate::said::Terms;

/// What the page sends; the solver thread takes each with where to answer.
#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub(super) enum Command {
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

/// A command with where its answers go.
pub(super) type Request = (Command, Sender<Message>);

impl super::queue::Newest for Request {
    /// An edit carries the whole state: it makes an edit waiting before it stale.
    fn replaces(&self, older: &Self) -> bool {
        matches!(
            (&self.0, &older.0),
            (Command::Edit { .. }, Command::Edit { .. })
        )
    }
}

impl Command {
    /// The command in the page's message `text`, within the page's limits ([`Edit::check`],
    /// [`Selection::check`]); else the error to answer, sent before any work.
    pub(super) fn parse(text: &str) -> std::result::Result<Self, Message> {
        let command: Command =
            serde_json::from_str(text).map_err(|e| error(&format!("bad request: {e}")))?;
        let checked = match &command {
            Command::Edit { edit, .. }
            | Command::Save { edit, .. }
            | Command::Apply { edit, .. } => edit.check(),
            Command::Select { seq, selection } => {
                return match selection.check() {
                    Ok(()) => Ok(command),
                    Err(e) => Err(select_error(*seq, &e)),
                };
            }
            Command::Release { .. } => Ok(()),
        };
        checked.map(|()| command).map_err(|e| error(&e.to_string()))
    }
}

/// An error for the page to show.
pub(super) fn error(text: &str) -> Message {
    Message::text(serde_json::json!({"type": "error", "message": text}).to_string())
}

/// The answer to `command` when [`MAX_QUEUED`] commands already wait: the command is not
/// taken (for a selection, an error the page pairs with it).
pub(super) fn busy(command: &Command) -> Message {
    let e = Error::param(format!(
        "the editor is busy: {MAX_QUEUED} commands wait for the solver; this one was not \
         taken, try it again when the editor answers"
    ));
    match command {
        Command::Select { seq, .. } => select_error(*seq, &e),
        _ => error(&e.to_string()),
    }
}

/// An error answering the selection `seq` (the page stops waiting for its samples).
fn select_error(seq: u32, e: &Error) -> Message {
    text(serde_json::json!({"type": "error", "message": e.to_string(), "select": seq}))
}

fn text(value: serde_json::Value) -> Message {
    Message::text(value.to_string())
}

/// What a caught panic said.
fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic".into())
}

/// `work` on `editor`, its failures made errors: an error ends the live session when
/// `solving` (the next edit is solved from rest), a panic builds the live deformation again.
pub(super) fn guarded<T>(
    editor: &mut Editor,
    solving: bool,
    work: impl FnOnce(&mut Editor) -> Result<T>,
) -> Result<T> {
    match std::panic::catch_unwind(AssertUnwindSafe(|| work(editor))) {
        Ok(Ok(value)) => Ok(value),
        Ok(Err(e)) => {
            if solving {
                editor.reset();
            }
            Err(e)
        }
        Err(panic) => {
            let what = panic_message(panic.as_ref());
            let restarted = std::panic::catch_unwind(AssertUnwindSafe(|| editor.restart()))
                .unwrap_or_else(|p| Err(Error::solver(panic_message(p.as_ref()))));
            Err(Error::solver(match restarted {
                Ok(()) => format!(
                    "{what}; the editor started its session again: the next edit is solved \
                     from rest"
                ),
                Err(e) => format!("{what}; the editor could not start its session again: {e}"),
            }))
        }
    }
}

/// The solver thread: commands in order (of consecutive edits the queue keeps the newest).
pub(super) fn run(mut editor: Editor, outputs: Arc<OutputFolder>, queue: Inbox<Request>) {
    let applying = Arc::new(AtomicBool::new(false));
    // Where the last edit's answer went: the idle solver's iterations go there too.
    let mut last: Option<(u32, Sender<Message>)> = None;
    // Whether no pose came for [`IDLE`]: then the solver iterates until converged.
    let mut idle = false;
    loop {
        let (command, reply) = match (&last, editor.converged()) {
            (Some((seq, reply)), false) => match next(&queue, idle) {
                Ok(c) => {
                    idle = false;
                    c
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    idle = true;
                    let answer = match guarded(&mut editor, true, Editor::refine) {
                        Ok(m) => motions_message(*seq, m),
                        Err(e) => vec![error(&editor.said(&e.said()))],
                    };
                    for m in answer {
                        let _ = reply.send(m);
                    }
                    continue;
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => return,
            },
            _ => match queue.next(None) {
                Ok(c) => c,
                Err(_) => return,
            },
        };
        if let Command::Edit { seq, .. } = &command {
            last = Some((*seq, reply.clone()));
        }
        for m in answer(&mut editor, command, &reply, &outputs, &applying) {
            let _ = reply.send(m);
        }
    }
}

/// The answers to one command (none for *Apply*, which answers from its own thread).
fn answer(
    editor: &mut Editor,
    command: Command,
    reply: &Sender<Message>,
    outputs: &Arc<OutputFolder>,
    applying: &Arc<AtomicBool>,
) -> Vec<Message> {
    // A solve's errors name the entries as the page does.
    let failed = |editor: &Editor, e: Error| vec![error(&editor.said(&e.said()))];
    match command {
        Command::Edit { seq, edit } => match guarded(editor, true, |e| e.solve(&edit)) {
            Ok(m) => motions_message(seq, m),
            Err(e) => failed(editor, e),
        },
        Command::Release { seq } => match guarded(editor, true, Editor::release) {
            Ok(r) => released_message(seq, r),
            Err(e) => failed(editor, e),
        },
        Command::Select { seq, selection } => {
            match guarded(editor, false, |e| e.selected(&selection)) {
                Ok(mask) => vec![selected_message(seq, &mask)],
                Err(e) => vec![select_error(seq, &e)],
            }
        }
        Command::Save {
            name,
            edit,
            overwrite,
        } => vec![save(editor, outputs, &name, &edit, overwrite)],
        Command::Apply {
            name,
            edit,
            overwrite,
        } => {
            let input = editor.scene().input.clone();
            let extensions = crate::io::output_extensions(&input);
            match outputs.target(&name, extensions, overwrite) {
                Ok(output) => {
                    // A name free now is kept free of other writers' files: Apply replaces
                    // only what its user agreed to replace.
                    let keep_existing = std::fs::symlink_metadata(&output).is_err();
                    let (spec, names) = editor.spec_named(&edit);
                    let job = Job {
                        input,
                        output,
                        keep_existing,
                        name,
                        spec,
                        names,
                        params: *editor.params(),
                    };
                    apply(job, reply.clone(), outputs.clone(), applying.clone());
                    Vec::new()
                }
                Err(r) => vec![refused(r, &name, "apply")],
            }
        }
    }
}

fn motions_message(seq: u32, m: Option<Motions>) -> Vec<Message> {
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

fn released_message(seq: u32, r: Released) -> Vec<Message> {
    let n = (r.positions.len() / 3) as u32;
    let mut bytes = u32_bytes(&[2, seq, n, r.foldovers.1 as u32, r.foldovers.0 as u32]);
    bytes.extend(f32_bytes(&r.positions));
    let mut out = vec![Message::binary(bytes)];
    for w in r.warnings {
        out.push(text(serde_json::json!({"type": "warning", "message": w})));
    }
    out
}

/// *Save edit*: the spec of `edit` as `name` in the editor's folder ([`OutputFolder::target`];
/// atomically).
fn save(
    editor: &Editor,
    outputs: &OutputFolder,
    name: &str,
    edit: &Edit,
    overwrite: bool,
) -> Message {
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
    queue: &Inbox<Request>,
    idle: bool,
) -> std::result::Result<Request, mpsc::RecvTimeoutError> {
    queue.next(Some(if idle { Duration::ZERO } else { IDLE }))
}

/// Reports *Apply*'s progress to the page, at most every 100 ms.
struct Progress {
    reply: Sender<Message>,
    state: Mutex<(String, u64, u64, Instant)>,
}

impl crate::progress::Observer for Progress {
    fn stage(&self, name: &str, len: u64) {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        *s = (name.to_string(), len, 0, Instant::now());
        self.send(&s);
    }
    fn advance(&self, n: u64) {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
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

/// What *Apply* deforms: the input into `output` (named `name` in the editor's folder,
/// checked) under the spec text `spec`, with the editor's parameters.
struct Job {
    input: PathBuf,
    output: PathBuf,
    name: String,
    spec: String,
    /// What the page calls the entries of `spec`, for the warnings and errors.
    names: PageNames,
    params: crate::pipeline::DeformParams,
    /// The output's name was free when Apply was asked: no file that appears there meanwhile
    /// is replaced.
    keep_existing: bool,
}

/// Clears the flag of a running *Apply* when its thread ends, however it ends.
struct Running(Arc<AtomicBool>);

impl Drop for Running {
    fn drop(&mut self) {
        self.0.store(false, Ordering::SeqCst);
    }
}

/// *Apply*: `deform` of the whole input under the job's spec, on a thread of its own, as the
/// CLI runs it ([`crate::pipeline::deform_file_with`], the same parameters and checks): its
/// output is the file `rigidcells deform` writes with the options of [`Editor::flags`].
fn apply(job: Job, reply: Sender<Message>, outputs: Arc<OutputFolder>, applying: Arc<AtomicBool>) {
    if applying.swap(true, Ordering::SeqCst) {
        let _ = reply.send(error("an Apply is already running"));
        return;
    }
    let running = Running(applying);
    std::thread::spawn(move || {
        let _running = running;
        let start = Instant::now();
        let progress = Progress {
            reply: reply.clone(),
            state: Mutex::new((String::new(), 0, 0, Instant::now())),
        };
        let result = std::panic::catch_unwind(AssertUnwindSafe(|| deform(&job, &progress)))
            .unwrap_or_else(|p| Err(Error::solver(panic_message(p.as_ref()))));
        let message = match result {
            Ok((samples, warnings)) => {
                outputs.record(&job.name);
                text(serde_json::json!({
                    "type": "applied",
                    "output": job.output.display().to_string(),
                    "samples": samples,
                    "seconds": start.elapsed().as_secs_f64(),
                    "warnings": warnings,
                }))
            }
            Err(e) => error(&job.names.render(&e.said())),
        };
        let _ = reply.send(message);
    });
}

/// The job deformed: the samples written and the warnings, in the page's words.
fn deform(job: &Job, progress: &Progress) -> Result<(u64, Vec<String>)> {
    crate::io::refuse_overwrite(&job.input, &job.output)?;
    let name = job.output.with_extension("edit.toml");
    let base = name.parent().unwrap_or(Path::new(".")).to_path_buf();
    let spec = crate::spec::parse_spec::<3>(&job.spec, &base, &name)?;
    let (_, info, report) = crate::pipeline::deform_file_with(
        &job.input,
        &job.output,
        &spec,
        &job.params,
        &crate::pipeline::Outputs {
            keep_existing: job.keep_existing,
            ..Default::default()
        },
        progress,
    )?;
    let warnings = report.warnings.iter().map(|w| job.names.render(w));
    Ok((info.samples, warnings.collect()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::edit::Scene;
    use crate::rigid::Vect;

    /// The editor of a 4 × 1 × 1 bar's vertices, cells of 0.5.
    fn editor() -> Editor {
        let bar = data_gen::bar([4.0, 1.0, 1.0], 2.0);
        let points: Vec<Vect<3>> = bar
            .vertices
            .iter()
            .map(|p| Vect::<3>::new(p[0], p[1], p[2]))
            .collect();
        let lo = Vect::<3>::zeros();
        let hi = Vect::<3>::new(4.0, 1.0, 1.0);
        let scene = Scene {
            input: "bar.ply".into(),
            colors: vec![[200; 3]; points.len()],
            total: points.len() as u64,
            points,
            center: (lo + hi) * 0.5,
            bounds: (lo, hi),
            up: 2,
            ..Default::default()
        };
        let options = crate::pipeline::Options {
            cell_size: Some(0.5),
            ..Default::default()
        };
        Editor::new(scene, options).unwrap()
    }

    /// The bar's left corner pinned, its right end a handle lifted by `lift`.
    fn lifted(lift: f64) -> Edit {
        let right = Selection {
            polygon: Some(vec![[0.6, -1.1], [1.1, -1.1], [1.1, 1.1], [0.6, 1.1]]),
            view: Some([
                [0.5, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 0.1, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ]),
            ..Default::default()
        };
        Edit {
            pins: vec![[-2.0, -0.5, -0.5]],
            handles: vec![crate::edit::HandleEdit {
                selections: vec![right],
                translate: [0.0, 0.0, lift],
                axis: [0.0, 0.0, 1.0],
                pivot: [2.0, 0.0, 0.0],
                ..Default::default()
            }],
            ..Default::default()
        }
    }

    /// The solver's warnings and errors name what the user made on the page ("handle 1,
    /// selection 2"), not the entries of the spec the editor wrote for it.
    #[test]
    fn messages_name_selections_as_the_page_does() {
        let mut editor = editor();
        let mut edit = lifted(0.5);
        let nowhere = Selection {
            polygon: Some(vec![[5.0, 5.0], [6.0, 5.0], [6.0, 6.0], [5.0, 6.0]]),
            view: edit.handles[0].selections[0].view,
            ..Default::default()
        };
        edit.handles[0].selections.push(nowhere);
        let m = editor.solve(&edit).unwrap().unwrap();
        assert_eq!(m.warnings, ["handle 1, selection 2 selects no cell"]);
        // The spec itself numbers it as the CLI reads it.
        let spec = editor.last_parsed().unwrap().clone();
        assert_eq!(spec.handles.len(), 2);
        let mut both = lifted(0.5);
        both.fixed = both.handles[0].selections.clone();
        let e = guarded(&mut editor, true, |e| e.solve(&both)).unwrap_err();
        let said = editor.said(&e.said());
        assert!(
            said.contains("fixed, selection 1") && said.contains("handle 1, selection 1"),
            "{said}"
        );
        assert!(e.to_string().contains("handle #1 (line "), "{e}");
    }

    /// A panic in the solver's work is an error for the page, and the editor solves the next
    /// edit as on a fresh start.
    #[test]
    fn a_panic_is_an_error_and_the_session_starts_again() {
        let mut editor = editor();
        assert!(editor.solve(&lifted(0.5)).unwrap().is_some());
        let failed = guarded(&mut editor, true, |e| -> Result<()> {
            e.solve(&lifted(0.6))?;
            panic!("index out of bounds: the len is 1 but the index is 1")
        });
        let said = failed.unwrap_err().to_string();
        assert!(said.contains("index out of bounds"), "{said}");
        assert!(said.contains("started its session again"), "{said}");
        assert!(editor.converged() && editor.last_spec().is_none());
        let motions = guarded(&mut editor, true, |e| e.solve(&lifted(1.0)))
            .unwrap()
            .unwrap();
        assert!(motions.iterations > 1, "not solved from rest: {motions:?}");
    }

    /// An error ends the live session (the next edit is solved from rest); an error outside
    /// the solve leaves it.
    #[test]
    fn an_error_ends_the_session() {
        let mut editor = editor();
        editor.solve(&lifted(0.5)).unwrap();
        let failed = guarded(&mut editor, false, |_| -> Result<()> {
            Err(Error::param("no"))
        });
        assert!(failed.is_err() && editor.last_spec().is_some());
        let failed = guarded(&mut editor, true, |_| -> Result<()> {
            Err(Error::param("no"))
        });
        assert!(failed.is_err() && editor.last_spec().is_none());
        let motions = editor.solve(&lifted(0.6)).unwrap().unwrap();
        assert!(motions.iterations > 1, "not solved from rest: {motions:?}");
    }

    /// A message past the page's limits is refused before it reaches the solver.
    #[test]
    fn commands_past_the_limits_are_refused_as_they_are_read() {
        let pins = vec![[0.0; 3]; crate::edit::MAX_PINS + 1];
        let text = serde_json::json!({"type": "edit", "seq": 1, "edit": {"pins": pins}});
        let Err(Message::Text(said)) = Command::parse(&text.to_string()) else {
            panic!("accepted");
        };
        assert!(said.contains("at most"), "{said}");
        let ok = serde_json::json!({"type": "edit", "seq": 1, "edit": {"pins": [[0, 0, 0]]}});
        assert!(Command::parse(&ok.to_string()).is_ok());
    }

    /// A command past the queue's bound is answered, a selection with its `seq` (the page
    /// stops waiting for its samples).
    #[test]
    fn a_command_past_the_queue_is_answered_busy() {
        let select = r#"{"type": "select", "seq": 4, "selection": {"classification": [2]}}"#;
        for (text, seq) in [
            (select, Some(4)),
            (r#"{"type": "release", "seq": 5}"#, None),
        ] {
            let command = Command::parse(text).unwrap_or_else(|_| panic!("{text}"));
            let Message::Text(said) = busy(&command) else {
                panic!("not text");
            };
            let said: serde_json::Value = serde_json::from_str(said.as_str()).unwrap();
            assert_eq!(said["type"], "error");
            assert!(said["message"].as_str().unwrap().contains("busy"), "{said}");
            assert_eq!(said["select"].as_u64(), seq, "{said}");
        }
    }
}
