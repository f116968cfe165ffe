//! The library's errors as Python exceptions, in the package's terms: keyword arguments and
//! dict keys, not the command line's flags and spec lines.

use pyo3::create_exception;
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use rigidcells::Error;
use rigidcells::cells::Inside;
use rigidcells::field::{Outside, Transfer};
use rigidcells::names::Named;
use rigidcells::solve::{LooseParts, Method};

create_exception!(
    _rigidcells,
    FormatError,
    PyValueError,
    "A malformed or unreadable input file."
);

create_exception!(
    _rigidcells,
    TurnNotHeldError,
    PyValueError,
    "A handle's turn that the shape gives way under."
);

/// The library's error as a Python exception, by its exit code's class, in the package's
/// terms (keyword arguments, not the command line's flags).
pub(crate) fn py_err(e: Error) -> PyErr {
    if let Error::TurnNotHeld(r) = &e {
        return turn_not_held(r);
    }
    // A bad argument or array is a ValueError that says what is wrong, without the command
    // line's "invalid parameter:" (a malformed file is a FormatError).
    let text = match &e {
        Error::Param(m) | Error::Input(m) => python_terms(m.trim_end()),
        e => python_terms(e.to_string().trim_end()),
    };
    match (&e, e.exit_code()) {
        (Error::Io { .. } | Error::Write { .. }, _) => PyOSError::new_err(text),
        (Error::Input(_), _) => PyValueError::new_err(text),
        (_, 3) => FormatError::new_err(text),
        (_, 4) => PyValueError::new_err(text),
        _ => PyRuntimeError::new_err(text),
    }
}

/// A refused turn as a `TurnNotHeldError` with the refusal's fields, so that a face names the
/// handle its own way without reading the message: `handle` (its index in the spec's
/// handles), `line`, `kind` ("bend" or "twist"), `asked_degrees`, `held_degrees`,
/// `other_way_degrees` (or None) and `said` (the message after the handle's name).
pub(crate) fn turn_not_held(r: &rigidcells::solve::TurnRefusal) -> PyErr {
    Python::attach(|py| {
        let err = TurnNotHeldError::new_err(r.to_string());
        let value = err.value(py);
        let fields = || -> PyResult<()> {
            value.setattr("handle", r.handle)?;
            value.setattr("line", r.line)?;
            value.setattr("kind", r.kind.name())?;
            value.setattr("asked_degrees", r.asked_degrees)?;
            value.setattr("held_degrees", r.held_degrees)?;
            value.setattr("other_way_degrees", r.other_way_degrees)?;
            value.setattr("said", r.said())
        };
        match fields() {
            Ok(()) => err,
            Err(e) => e,
        }
    })
}

/// The command line's flags in a message as the package's keyword arguments: `--cell-size`
/// becomes `cell_size`, `--outside keep` becomes `outside="keep"` (a flag followed by one of
/// its choices) and `--cells 1000` becomes `cells=1000`.
pub(crate) fn python_terms(text: &str) -> String {
    fn names<T: Named>() -> impl Iterator<Item = &'static str> {
        T::ALL.iter().map(|v| v.name())
    }
    // The names of the library's choices (a flag followed by one is said as `flag="name"`).
    let choices: Vec<&str> = names::<Outside>()
        .chain(names::<LooseParts>())
        .chain(names::<Transfer>())
        .chain(names::<Method>())
        .chain(names::<Inside>())
        .collect();
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find("--") {
        out.push_str(&rest[..at]);
        let after = &rest[at + 2..];
        // A flag starts a word (`a--b` in a file name is not one).
        if !out.is_empty() && !out.ends_with([' ', '(', '`', '"', '\'']) {
            out.push_str("--");
            rest = after;
            continue;
        }
        let len = after
            .find(|c: char| !(c.is_ascii_lowercase() || c == '-'))
            .unwrap_or(after.len());
        let name = after[..len].trim_end_matches('-');
        if name.is_empty() || !name.starts_with(|c: char| c.is_ascii_lowercase()) {
            out.push_str("--");
            rest = after;
            continue;
        }
        let arg = match name {
            "edit" => "spec".to_string(),
            other => other.replace('-', "_"),
        };
        let tail = &after[name.len()..];
        let value = tail.strip_prefix(' ').and_then(|t| {
            choices.iter().find(|c| {
                t.starts_with(**c)
                    && !t[c.len()..].starts_with(|ch: char| ch.is_ascii_alphanumeric() || ch == '-')
            })
        });
        let number = tail.strip_prefix(' ').map(|t| {
            let sign = usize::from(t.starts_with('-'));
            let len = t[sign..]
                .find(|c: char| !(c.is_ascii_digit() || c == '.'))
                .map_or(t.len(), |n| n + sign);
            &t[..len]
        });
        match (value, number) {
            (Some(v), _) => {
                out.push_str(&format!("{arg}=\"{v}\""));
                rest = &tail[1 + v.len()..];
            }
            (None, Some(n))
                if n.trim_start_matches('-')
                    .starts_with(|c: char| c.is_ascii_digit()) =>
            {
                out.push_str(&format!("{arg}={n}"));
                rest = &tail[1 + n.len()..];
            }
            _ => {
                out.push_str(&arg);
                rest = tail;
            }
        }
    }
    out.push_str(rest);
    out
}

/// Messages for the user in the package's terms.
pub(crate) fn said(messages: &[String]) -> Vec<String> {
    messages.iter().map(|m| python_terms(m)).collect()
}
