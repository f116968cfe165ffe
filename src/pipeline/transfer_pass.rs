//! Pass 2 of a streamed file: chunks read and warped on one thread while a second writes the
//! previous ones, and the restarts a sink asks for (an output encoding that overflows, a
//! header that must be made from the records).

use std::path::Path;
use std::sync::mpsc;

use crate::error::{Error, Result};
use crate::field::{Constrained, Warp, apply_into};
use crate::io::{Accepted, Bounds, Chunk, Sink, Source};
use crate::progress::Observer;
use crate::rigid::Vect;

use super::checks::{check_moved, refuse_outside};

/// Buffers of one chunk on its way through pass 2.
#[derive(Default)]
struct Job {
    chunk: Chunk,
    moved: Vec<Vect<3>>,
    normals: Vec<Vect<3>>,
}

/// Chunks in flight in pass 2: one being read and warped, one queued, one being written.
const IN_FLIGHT: usize = 3;

/// Pass 2: streams the source through `warp` into `output`. A sink that refuses a chunk
/// ([`Accepted`]) is dropped, with its temporary file, and the pass runs again with a sink made
/// for what the refusal showed: after an overflow of the output's encoding the pass first
/// finishes computing the moved bounds. Each refusal is allowed once: a sink framed for the
/// moved bounds fits them, and a source that has seen the records makes a header for them.
/// Samples beyond the field's margin, when `warp` refuses them, fail the pass before the output
/// is renamed into place.
pub(super) fn transfer_pass(
    source: &mut dyn Source,
    output: &Path,
    warp: &Constrained<3>,
    origin: &Vect<3>,
    chunk_len: usize,
    observer: &dyn Observer,
) -> Result<Vec<String>> {
    let mut bounds = None;
    let mut restarted = false;
    loop {
        source.rewind()?;
        warp.reset_outside();
        let sink = source.sink(output, bounds)?;
        let (pass, moved_bounds) = pipelined_pass(source, sink, warp, origin, chunk_len, observer)?;
        match pass {
            Pass::Refused(Accepted::Overflow) if bounds.is_none() => bounds = Some(moved_bounds),
            Pass::Refused(Accepted::Restart) if !restarted => restarted = true,
            Pass::Refused(refusal) => {
                return Err(Error::Solver(format!(
                    "{}: the output's writer refused the samples twice ({refusal:?})",
                    output.display()
                )));
            }
            Pass::Written(mut s) => {
                if warp.beyond_window() > 0 {
                    // A window of the field met samples outside it: the caller reads the whole
                    // field and starts again; the abandoned output is removed.
                    return Ok(Vec::new());
                }
                refuse_outside(source.path(), warp)?;
                let loose: Vec<Vect<3>> = source
                    .loose_normals()
                    .iter()
                    .map(|(at, n)| warp.warp_normal(&(at - origin), n))
                    .collect();
                s.loose_normals(loose);
                // Finishing may be long (a COPC sorts and compresses every point there).
                observer.stage("finishing", 0);
                let finished = s.finish();
                observer.finish();
                return finished;
            }
        }
    }
}

/// How one attempt of pass 2 ended.
enum Pass {
    /// Every chunk went into the sink, to be finished.
    Written(Box<dyn Sink>),
    /// The sink refused a chunk (and was dropped).
    Refused(Accepted),
}

/// Reads and warps chunks on this thread while a second thread writes the previous ones, so
/// the sink's encoding, compression and system calls overlap the transfer. Returns how the
/// sink took the chunks and the moved bounds: of every sample, also after an overflow (the
/// reader goes on), but not after a [`Accepted::Restart`] (the reader stops).
fn pipelined_pass(
    source: &mut dyn Source,
    sink: Box<dyn Sink>,
    warp: &impl Warp<3>,
    origin: &Vect<3>,
    chunk_len: usize,
    observer: &dyn Observer,
) -> Result<(Pass, Bounds)> {
    let mut moved_bounds = (
        Vect::<3>::repeat(f64::INFINITY),
        Vect::<3>::repeat(f64::NEG_INFINITY),
    );
    observer.stage("writing", source.len());
    let raw = sink.needs_raw();
    let pass = std::thread::scope(|scope| -> Result<Pass> {
        let (full, queued) = mpsc::sync_channel::<Job>(1);
        let (done, empty) = mpsc::channel::<Job>();
        for _ in 0..IN_FLIGHT {
            done.send(Job::default()).expect("the receiver is alive");
        }
        let writer = scope.spawn(move || -> Result<Pass> {
            let mut pass = Pass::Written(sink);
            for job in queued {
                if let Pass::Written(s) = &mut pass {
                    match s.write(&job.chunk, &job.moved, &job.normals)? {
                        Accepted::Yes => {}
                        // Dropping the receiver stops the reader.
                        Accepted::Restart => return Ok(Pass::Refused(Accepted::Restart)),
                        Accepted::Overflow => pass = Pass::Refused(Accepted::Overflow),
                    }
                }
                // The reader may have stopped early on an error of its own.
                let _ = done.send(job);
            }
            Ok(pass)
        });
        // `recv` fails only when the writer stopped on an error, which `join` returns.
        while let Ok(mut job) = empty.recv() {
            let read = if raw {
                source.read(chunk_len, &mut job.chunk)?
            } else {
                source.read_samples(chunk_len, &mut job.chunk)?
            };
            if read == 0 {
                break;
            }
            let Job {
                chunk,
                moved,
                normals,
            } = &mut job;
            apply_into(
                warp,
                origin,
                &chunk.positions,
                &chunk.normals,
                moved,
                normals,
            );
            check_moved(chunk.first, moved)?;
            for p in moved.iter() {
                moved_bounds.0 = moved_bounds.0.inf(p);
                moved_bounds.1 = moved_bounds.1.sup(p);
            }
            observer.advance(chunk.len() as u64);
            if full.send(job).is_err() {
                break;
            }
        }
        drop(full);
        writer.join().expect("the writer thread does not panic")
    })?;
    observer.finish();
    Ok((pass, moved_bounds))
}
