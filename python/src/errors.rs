//! The library's errors as Python exceptions, in the package's terms: keyword arguments and
//! dict keys, not the command line's flags and spec lines. The library's messages carry their
//! options and spec lines as data ([`rigidcells::said`]); this renders them.

use pyo3::create_exception;
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rigidcells::Error;
use rigidcells::said::{Kind, Opt, Part, Said, Terms};

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

/// The package's terms: `cell_size=0.02`, `outside="keep"`, Python's names of types. A spec's
/// line stays `line 7` here; the package says it as a dict's key path where the spec was one
/// ([`parts`]).
struct Package;

impl Terms for Package {
    fn option(&self, o: Opt) -> String {
        o.keyword().to_string()
    }

    fn set(&self, o: Opt, value: &str) -> String {
        // A picture's size is a (width, height) tuple here.
        if let (Opt::Size, Some((w, h))) = (o, value.split_once('x')) {
            return format!("size=({w}, {h})");
        }
        if value.parse::<f64>().is_ok() {
            format!("{}={value}", o.keyword())
        } else {
            format!("{}=\"{value}\"", o.keyword())
        }
    }

    fn mismatch(&self, expected: &Kind, found: &Kind) -> String {
        format!("expected {}, got {}", kind(expected), kind(found))
    }
}

/// A spec value's kind as Python names its type.
fn kind(k: &Kind) -> String {
    match k {
        Kind::Table => "a dict".into(),
        Kind::Array => "a list".into(),
        Kind::Text => "a str".into(),
        Kind::Float => "a float".into(),
        Kind::Integer => "an int".into(),
        Kind::Boolean => "a bool".into(),
        k => k.toml_words(),
    }
}

/// A message in the package's terms.
pub(crate) fn python_terms(said: &Said) -> String {
    Package.render(said)
}

/// A message as a list of the package's words (`str`), the spec's lines (`int`), the
/// options it names (`(keyword, value, said)`: the value a `str` as the user would write it,
/// or None, and the package's way of saying both) and the spec entries it names (a `dict` of
/// `entry` (the kind), `index`, `line` and `said`), an aside ([`Part::Aside`]) as a list of
/// its own parts, for the package to say each line and entry
/// as a dict spec's key path or as `line N`, and for the Blender add-on to say an option and an
/// entry by its panel's names.
pub(crate) fn parts<'py>(py: Python<'py>, said: &Said) -> PyResult<Bound<'py, PyList>> {
    let out = PyList::empty(py);
    let mut words = String::new();
    for p in said.parts() {
        let data = match p {
            Part::Line(n) => (*n).into_pyobject(py)?.into_any(),
            Part::Opt(o) => (o.keyword(), None::<&str>, o.keyword())
                .into_pyobject(py)?
                .into_any(),
            Part::Set(o, v) => (o.keyword(), Some(v.as_str()), Package.set(*o, v))
                .into_pyobject(py)?
                .into_any(),
            Part::Aside(aside) => parts(py, aside)?.into_any(),
            Part::Entry { kind, index, line } => {
                let entry = PyDict::new(py);
                entry.set_item("entry", *kind)?;
                entry.set_item("index", *index)?;
                entry.set_item("line", *line)?;
                entry.set_item("said", Package.part(p))?;
                entry.into_any()
            }
            p => {
                words.push_str(&Package.part(p));
                continue;
            }
        };
        if !words.is_empty() {
            out.append(std::mem::take(&mut words))?;
        }
        out.append(data)?;
    }
    if !words.is_empty() {
        out.append(words)?;
    }
    Ok(out)
}

/// Messages for the user, each as its [`parts`].
pub(crate) fn said<'py>(py: Python<'py>, messages: &[Said]) -> PyResult<Bound<'py, PyList>> {
    let out = PyList::empty(py);
    for m in messages {
        out.append(parts(py, m)?)?;
    }
    Ok(out)
}

/// Messages for the user in the package's terms, each as text (for messages that name no
/// spec line: a field applied to a file).
pub(crate) fn said_text(messages: &[Said]) -> Vec<String> {
    messages.iter().map(python_terms).collect()
}

/// The library's error as a Python exception, by its exit code's class, in the package's
/// terms (keyword arguments, not the command line's flags). Its `parts` attribute is the
/// message as [`parts`]; a spec's error has `spec_line` (or None) and `spec_message` (the
/// message after the spec's name and line, as parts), so that a dict spec's error can name
/// the key instead.
pub(crate) fn py_err(e: Error) -> PyErr {
    if let Error::TurnNotHeld(r) = &e {
        return turn_not_held(r);
    }
    let said = e.said().trimmed();
    let text = python_terms(&said);
    let err = match (&e, e.exit_code()) {
        (Error::Io { .. } | Error::Write { .. }, _) => PyOSError::new_err(text),
        (Error::Input(_), _) => PyValueError::new_err(text),
        (_, 3) => FormatError::new_err(text),
        (_, 4) => PyValueError::new_err(text),
        _ => PyRuntimeError::new_err(text),
    };
    Python::attach(|py| {
        let value = err.value(py);
        let fields = || -> PyResult<()> {
            value.setattr("parts", parts(py, &said)?)?;
            if let Error::Spec { line, message, .. } = &e {
                value.setattr("spec_line", *line)?;
                value.setattr("spec_message", parts(py, &message.clone().trimmed())?)?;
            }
            Ok(())
        };
        match fields() {
            Ok(()) => err,
            Err(e) => e,
        }
    })
}

/// A refused turn as a `TurnNotHeldError` with the refusal's fields, so that a face names the
/// handle its own way without reading the message: `handle` (its index in the spec's
/// handles), `line`, `kind` ("bend" or "twist"), `asked_degrees`, `held_degrees`,
/// `other_way_degrees` (or None) and `said` (the message after the handle's name).
pub(crate) fn turn_not_held(r: &rigidcells::internal::solve::TurnRefusal) -> PyErr {
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
