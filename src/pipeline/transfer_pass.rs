//! Pass 2 of a streamed file: chunks read, warped and written by three threads at once, and
//! the restarts a sink asks for (an output encoding that overflows, a
//! header that must be made from the records).

use std::path::Path;
use std::sync::mpsc;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::field::{FieldMap, Order, Warp, apply_in_order};
use crate::io::{Accepted, Bounds, Chunk, ResultSet, Sink, Source};
use crate::progress::Observer;
use crate::rigid::Vect;
use crate::said::Said;

use super::checks::{check_moved, refuse_outside};

/// Buffers of one chunk on its way through pass 2.
#[derive(Default)]
struct Job {
    chunk: Chunk,
    /// The order the chunk's samples are warped in, made by the reader.
    order: Order,
    moved: Vec<Vect<3>>,
    normals: Vec<Vect<3>>,
}

/// Chunks in flight in pass 2: one being read, one warped, one written, and one queued
/// between each two stages.
const IN_FLIGHT: usize = 5;

/// Pass 2: streams the source through `warp` into `output`. A sink that refuses a chunk
/// ([`Accepted`]) is dropped, with its temporary file, and the pass runs again with a sink made
/// for what the refusal showed: after an overflow of the output's encoding the pass first
/// finishes computing the moved bounds. Each refusal is allowed once: a sink framed for the
/// moved bounds fits them, and a source that has seen the records makes a header for them.
/// The finished output is handed to `set`, to be renamed into place with the run's other
/// outputs; samples beyond the field's margin, when `warp` refuses them, fail the pass before.
///
/// `moved`, when given, holds every sample already moved by `warp`, in file order (a mesh's
/// vertices, moved for the fold-over check): the pass copies them rather than warp them again,
/// except in chunks with normals, which need the warp's Jacobian. The copied samples are not
/// counted beyond the margin here (the caller counted them when it moved them), so `moved` is
/// taken only where `warp` extends the transfer there, never where it refuses such samples.
///
/// `probe` (moved points, world coordinates: the control points) is rounded as the finished
/// output stores its samples ([`Sink::written`]); returned with the notes is what they were
/// rounded to, in words ([`Sink::rounding`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn transfer_pass(
    source: &mut dyn Source,
    (output, set): (&Path, &ResultSet),
    warp: &FieldMap<3>,
    origin: &Vect<3>,
    moved: Option<&[Vect<3>]>,
    probe: &mut [Vect<3>],
    chunk_len: usize,
    observer: &dyn Observer,
) -> Result<(Vec<Said>, Option<String>)> {
    let mut bounds = None;
    let mut restarted = false;
    let moved = moved.filter(|m| {
        m.len() as u64 == source.len() && warp.outside_policy() == crate::field::Outside::Extend
    });
    loop {
        source.rewind()?;
        warp.reset_outside();
        let sink = source.sink(output, bounds)?;
        let (pass, moved_bounds) =
            pipelined_pass(source, sink, warp, origin, moved, chunk_len, observer)?;
        match pass {
            Pass::Refused(Accepted::Overflow) if bounds.is_none() => bounds = Some(moved_bounds),
            Pass::Refused(Accepted::Restart) if !restarted => restarted = true,
            Pass::Refused(refusal) => {
                return Err(Error::solver(format!(
                    "{}: the output's writer refused the samples twice ({refusal:?})",
                    output.display()
                )));
            }
            Pass::Written(mut s) => {
                if warp.beyond_window() > 0 {
                    // A window of the field met samples outside it: the caller reads the whole
                    // field and starts again; the abandoned output is removed.
                    return Ok((Vec::new(), None));
                }
                refuse_outside(source.path(), warp)?;
                let loose: Vec<Vect<3>> = source
                    .loose_normals()
                    .iter()
                    .map(|(at, n)| warp.warp_normal(&(at - origin), n))
                    .collect();
                s.loose_normals(loose);
                for p in probe.iter_mut() {
                    *p = s.written(p);
                }
                let rounding = s.rounding();
                // Finishing may be long (a COPC sorts and compresses every point there).
                observer.stage("finishing", 0);
                let finished = s.finish(set);
                observer.finish();
                return Ok((finished?.into_iter().map(Said::from).collect(), rounding));
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

/// Three stages over chunks in flight, so that no core waits on another stage: this thread
/// reads (decodes) chunks and puts each in its evaluation [`Order`], a second warps them (in
/// parallel, [`apply_in_order`]), a third writes them (the sink's encoding, compression and
/// system calls). Returns how the sink took the chunks and the moved bounds: of every sample,
/// also after an overflow (the reader goes on), but not after a [`Accepted::Restart`] (the
/// reader stops).
fn pipelined_pass(
    source: &mut dyn Source,
    sink: Box<dyn Sink>,
    warp: &impl Warp<3>,
    origin: &Vect<3>,
    known: Option<&[Vect<3>]>,
    chunk_len: usize,
    observer: &dyn Observer,
) -> Result<(Pass, Bounds)> {
    observer.stage("writing", source.len());
    let raw = sink.needs_raw();
    let (pass, moved_bounds) = std::thread::scope(|scope| -> Result<(Pass, Bounds)> {
        let (read, to_warp) = mpsc::sync_channel::<Job>(1);
        let (warped, to_write) = mpsc::sync_channel::<Job>(1);
        let (done, empty) = mpsc::channel::<Job>();
        for _ in 0..IN_FLIGHT {
            done.send(Job::default()).expect("the receiver is alive");
        }
        let writer = scope.spawn(move || -> Result<Pass> {
            let mut pass = Pass::Written(sink);
            for job in to_write {
                if let Pass::Written(s) = &mut pass {
                    match s.write(&job.chunk, &job.moved, &job.normals)? {
                        Accepted::Yes => {}
                        // Dropping the receiver stops the warper, and so the reader.
                        Accepted::Restart => return Ok(Pass::Refused(Accepted::Restart)),
                        Accepted::Overflow => pass = Pass::Refused(Accepted::Overflow),
                    }
                }
                observer.advance(job.chunk.len() as u64);
                // The reader may have stopped early on an error of its own.
                let _ = done.send(job);
            }
            Ok(pass)
        });
        let warper = scope.spawn(move || -> Result<Bounds> {
            let mut bounds = (
                Vect::<3>::repeat(f64::INFINITY),
                Vect::<3>::repeat(f64::NEG_INFINITY),
            );
            for mut job in to_warp {
                let Job {
                    chunk,
                    order,
                    moved,
                    normals,
                } = &mut job;
                match known {
                    Some(known) if chunk.normals.is_empty() => {
                        let first = chunk.first as usize;
                        moved.clear();
                        moved.extend_from_slice(&known[first..first + chunk.len()]);
                    }
                    _ => apply_in_order(
                        warp,
                        origin,
                        &chunk.positions,
                        &chunk.normals,
                        order,
                        moved,
                        normals,
                    ),
                }
                check_moved(chunk.first, moved)?;
                let (lo, hi) = moved_bounds(moved);
                bounds = (bounds.0.inf(&lo), bounds.1.sup(&hi));
                if warped.send(job).is_err() {
                    break;
                }
            }
            Ok(bounds)
        });
        // `recv` fails only when the writer stopped, and `send` only when the warper did: on
        // an error, which `join` returns, or on a refusal.
        let mut reading = Ok(());
        while let Ok(mut job) = empty.recv() {
            // Asked on the calling thread, where an observer may look at the caller's signals.
            if let Err(e) = crate::progress::stop_if_cancelled(observer) {
                reading = Err(e);
                break;
            }
            let got = if raw {
                source.read(chunk_len, &mut job.chunk)
            } else {
                source.read_samples(chunk_len, &mut job.chunk)
            };
            match got {
                Ok(0) => break,
                Ok(_) if known.is_some() && job.chunk.normals.is_empty() => {
                    job.order.order.clear();
                }
                Ok(_) => job.order.compute(&job.chunk.positions),
                Err(e) => {
                    reading = Err(e);
                    break;
                }
            }
            if read.send(job).is_err() {
                break;
            }
        }
        drop(read);
        let bounds = warper.join().expect("the warping thread does not panic");
        let pass = writer.join().expect("the writer thread does not panic");
        reading?;
        Ok((pass?, bounds?))
    })?;
    observer.finish();
    Ok((pass, moved_bounds))
}

/// The bounds of `points`, in parallel.
fn moved_bounds(points: &[Vect<3>]) -> Bounds {
    let empty = || {
        (
            Vect::<3>::repeat(f64::INFINITY),
            Vect::<3>::repeat(f64::NEG_INFINITY),
        )
    };
    points
        .par_chunks(1 << 12)
        .map(|run| {
            run.iter()
                .fold(empty(), |(lo, hi), p| (lo.inf(p), hi.sup(p)))
        })
        .reduce(empty, |a, b| (a.0.inf(&b.0), a.1.sup(&b.1)))
}
