//! Progress and cancellation for the Python calls ([`PyObserver`]), and who a call runs for
//! ([`caller`]): a progress callback runs on behalf of the call that reports to it, on
//! whatever thread the library reports from, so that a `Session` can tell a callback that
//! calls back into it (which would wait for itself) from another thread (which waits its turn).

use std::cell::Cell;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use rigidcells::Error;
use rigidcells::Observer;

use crate::py_err;

/// The next thread's token (0 is no caller).
static NEXT: AtomicU64 = AtomicU64::new(1);

thread_local! {
    /// This thread's token, drawn on first use.
    static THREAD: u64 = NEXT.fetch_add(1, Ordering::Relaxed);
    /// The caller a callback on this thread runs for, while it runs.
    static FOR: Cell<Option<u64>> = const { Cell::new(None) };
}

/// The caller the running code works for: the thread's own token, or, inside a progress
/// callback, the token of the call that reports to it. Never 0.
pub(crate) fn caller() -> u64 {
    FOR.with(Cell::get).unwrap_or_else(|| THREAD.with(|t| *t))
}

/// The caller's token for Python code (`Session`'s lock): equal for a call and the progress
/// callbacks it runs, different on another thread.
#[pyfunction]
#[pyo3(name = "caller")]
pub(crate) fn py_caller() -> u64 {
    caller()
}

/// `f` run on behalf of `origin` (restored after, also when `f` unwinds).
fn on_behalf_of<T>(origin: u64, f: impl FnOnce() -> T) -> T {
    struct Restore(Option<u64>);
    impl Drop for Restore {
        fn drop(&mut self) {
            FOR.with(|c| c.set(self.0));
        }
    }
    let _restore = Restore(FOR.with(|c| c.replace(Some(origin))));
    f()
}

/// Reports progress to a Python callable `(stage, done, total)` and asks Python's signal
/// handlers between the library's steps: Ctrl-C (`KeyboardInterrupt`), or an exception the
/// callable raises, stops the call at the next step and is raised in its place.
pub(crate) struct PyObserver {
    progress: Option<Py<PyAny>>,
    /// The caller whose call reports here: its callbacks run on its behalf.
    origin: u64,
    stopped: Mutex<Option<PyErr>>,
    /// The stage's name, units done and its length (0: unknown).
    at: Mutex<(String, u64, u64)>,
    reported: Mutex<Instant>,
}

/// Progress is reported at most this often (and at each stage's start and end).
const REPORT_EVERY: Duration = Duration::from_millis(100);

impl PyObserver {
    pub(crate) fn new(progress: Option<Py<PyAny>>) -> Self {
        Self {
            progress,
            origin: caller(),
            stopped: Mutex::new(None),
            at: Mutex::new((String::new(), 0, 0)),
            reported: Mutex::new(Instant::now()),
        }
    }

    /// Calls the progress callable with where the work is (always with `now`, else at most
    /// every [`REPORT_EVERY`]).
    fn report(&self, now: bool) {
        let Some(progress) = &self.progress else {
            return;
        };
        {
            let mut last = self.reported.lock().expect("not poisoned");
            if !now && last.elapsed() < REPORT_EVERY {
                return;
            }
            *last = Instant::now();
        }
        let (stage, done, len) = self.at.lock().expect("not poisoned").clone();
        let total = (len > 0).then_some(len);
        let called = on_behalf_of(self.origin, || {
            Python::attach(|py| progress.call1(py, (stage, done, total)).map(drop))
        });
        if let Err(e) = called {
            self.stop(e);
        }
    }

    fn stop(&self, e: PyErr) {
        let mut stopped = self.stopped.lock().expect("not poisoned");
        if stopped.is_none() {
            *stopped = Some(e);
        }
    }

    /// The result of a call that writes nothing, with the exception the callable raised in
    /// its place, also when the call ended before its next check.
    pub(crate) fn finished<T>(&self, result: rigidcells::Result<T>) -> PyResult<T> {
        if let Some(e) = self.stopped.lock().expect("not poisoned").take() {
            return Err(e);
        }
        self.result(result)
    }

    /// The library's result, with the exception that stopped it in place of its
    /// `Cancelled`.
    pub(crate) fn result<T>(&self, result: rigidcells::Result<T>) -> PyResult<T> {
        match result {
            Err(Error::Cancelled) => Err(self
                .stopped
                .lock()
                .expect("not poisoned")
                .take()
                .unwrap_or_else(|| PyRuntimeError::new_err("cancelled"))),
            other => other.map_err(py_err),
        }
    }
}

impl Observer for PyObserver {
    fn stage(&self, name: &str, len: u64) {
        *self.at.lock().expect("not poisoned") = (name.to_string(), 0, len);
        self.report(true);
    }

    fn advance(&self, n: u64) {
        self.at.lock().expect("not poisoned").1 += n;
        self.report(false);
    }

    fn finish(&self) {
        {
            let mut at = self.at.lock().expect("not poisoned");
            at.1 = at.1.max(at.2);
        }
        self.report(true);
    }

    fn cancelled(&self) -> bool {
        if self.stopped.lock().expect("not poisoned").is_some() {
            return true;
        }
        // Python runs signal handlers on its main thread only; elsewhere this asks nothing.
        let checked = on_behalf_of(self.origin, || Python::attach(|py| py.check_signals()));
        if let Err(e) = checked {
            self.stop(e);
            return true;
        }
        false
    }
}
