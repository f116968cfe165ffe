//! Interruption and faults. A dependency that panics on hostile bytes is called
//! through [`guarded`]: its panic becomes a format error naming the file, and the panic hook
//! installed by [`remove_temporaries_on_signals`] stays quiet about it. A closed pipe on
//! standard output (`rigidcells info f.las | head`) ends the process as it ends other Unix
//! tools, by SIGPIPE, instead of a panic. A file-size limit (`ulimit -f`, as a full disk) makes
//! the write fail (SIGXFSZ ignored): exit 1 naming the output, and no file left.
//!
//! SIGINT or SIGTERM during a run removes the temporary outputs (hidden `.NAME.*.tmp` files
//! beside the outputs, [`crate::io::TempFile`]) instead of leaving them behind, then exits with
//! 128 + the signal's number, as a shell reports it. A run's outputs are renamed into place
//! together at its end ([`crate::io::ResultSet::commit`]), with no interrupt between the
//! renames: an interrupted run leaves all of its outputs or none.
//!
//! The signals are blocked in every thread ([`remove_temporaries_on_signals`] runs before
//! any other thread starts, and threads inherit the mask) and taken by one thread that waits
//! for them with `sigwait`: it is an ordinary thread, so it may lock the registry and remove
//! files, which a signal handler may not. The module's `unsafe` code is the three libc calls
//! that set this up, on values it owns.

#![allow(unsafe_code)]

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::error::{Error, Result};

/// Calls into a dependency now under [`guarded`] (their panics are not reported).
static GUARDED: AtomicUsize = AtomicUsize::new(0);

/// Runs `f`, a call into a dependency that may panic on hostile bytes of `path` (an assertion
/// or `capacity overflow` inside `laz`'s decompressor): a panic becomes a format error naming
/// `path` and what was being done.
pub fn guarded<T>(path: &Path, doing: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
    GUARDED.fetch_add(1, Ordering::SeqCst);
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    GUARDED.fetch_sub(1, Ordering::SeqCst);
    result.unwrap_or_else(|_| {
        Err(Error::format(
            path,
            format!("the data is damaged (the decoder failed while {doing})"),
        ))
    })
}

/// The temporary files alive now, in every run of the process: what an interrupt removes.
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Creates a temporary file with `create`, which returns it and its path, and notes the path,
/// to be removed if the process is interrupted: under the registry's lock, so that no interrupt
/// comes between the two.
pub(crate) fn create_registered<T>(
    create: impl FnOnce() -> std::io::Result<(T, PathBuf)>,
) -> std::io::Result<(T, PathBuf)> {
    let mut t = TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner());
    let (made, path) = create()?;
    t.push(path.clone());
    Ok((made, path))
}

/// Renames each temporary of `pairs` over its target, in order, under the registry's lock: an
/// interrupt comes before the first rename (and removes every temporary) or after the last
/// (and the run's outputs are all in place), never between. The renamed temporaries are
/// forgotten. With `keep`, no existing target is replaced: the temporary is linked under the
/// target's name, which fails when the name is taken, then unlinked. On an error, how many
/// were renamed before it, and the error.
pub(crate) fn commit_registered(
    pairs: &[(&Path, &Path)],
    keep: bool,
) -> std::result::Result<(), (usize, std::io::Error)> {
    let mut t = TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner());
    for (done, &(tmp, target)) in pairs.iter().enumerate() {
        let moved = match keep {
            true => std::fs::hard_link(tmp, target).and_then(|_| std::fs::remove_file(tmp)),
            false => std::fs::rename(tmp, target),
        };
        moved.map_err(|e| (done, e))?;
        if let Some(i) = t.iter().position(|p| p == tmp) {
            t.swap_remove(i);
        }
    }
    Ok(())
}

/// Forgets the temporary file `path` (committed or removed).
pub(crate) fn forget(path: &Path) {
    if let Ok(mut t) = TEMPORARIES.lock()
        && let Some(i) = t.iter().position(|p| p == path)
    {
        t.swap_remove(i);
    }
}

/// Blocks SIGINT and SIGTERM in this thread (and so in the threads it starts) and starts a
/// thread that, when one arrives, removes the temporary outputs and exits; restores SIGPIPE's
/// default action; and keeps the panic hook quiet inside [`guarded`]. Call it first in `main`,
/// before any other thread exists. The signals' part does nothing where they are not Unix's.
pub fn remove_temporaries_on_signals() {
    let report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if GUARDED.load(Ordering::SeqCst) == 0 {
            report(info);
        }
    }));
    #[cfg(unix)]
    {
        // SAFETY: setting a signal's action to a constant takes no pointers. SIGPIPE gets its
        // default back; SIGXFSZ (a file-size limit reached) is ignored, so the write fails
        // with EFBIG and the output's error path removes the temporary.
        unsafe {
            libc::signal(libc::SIGPIPE, libc::SIG_DFL);
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
        }
        // SAFETY: `set` is a local, initialized by `sigemptyset` before use; the calls only
        // read it and change this thread's signal mask.
        let set = unsafe {
            let mut set: libc::sigset_t = std::mem::zeroed();
            libc::sigemptyset(&mut set);
            libc::sigaddset(&mut set, libc::SIGINT);
            libc::sigaddset(&mut set, libc::SIGTERM);
            if libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut()) != 0 {
                return;
            }
            set
        };
        let spawned = std::thread::Builder::new()
            .name("signals".into())
            .spawn(move || {
                let mut signal: libc::c_int = 0;
                // SAFETY: `set` was initialized above and `signal` is a local to write to.
                if unsafe { libc::sigwait(&set, &mut signal) } != 0 {
                    return;
                }
                let mut removed = false;
                if let Ok(t) = TEMPORARIES.lock() {
                    for path in t.iter() {
                        removed |= std::fs::remove_file(path).is_ok();
                    }
                }
                // (The editor, stopped while idle, has nothing unfinished to speak of.)
                if removed {
                    eprintln!("interrupted: the unfinished output was removed");
                } else {
                    eprintln!("interrupted");
                }
                std::process::exit(128 + signal);
            });
        if spawned.is_err() {
            // Without the thread, let the signals act as they would have.
            // SAFETY: as above.
            unsafe { libc::pthread_sigmask(libc::SIG_UNBLOCK, &set, std::ptr::null_mut()) };
        }
    }
}
