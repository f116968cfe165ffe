//! Property tests of the two parsers that read what a user (or an attacker) hands
//! over whole: the edit-spec parser and the field-file loader. Neither may panic; the spec
//! parser's errors are the spec's (exit 4) and what it accepts is finite; the loader's errors
//! are format errors naming the file (exit 3), and what it accepts builds a deformer.

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use proptest::prelude::*;
use rigidcells::Error;
use rigidcells::parse_spec;
use rigidcells::{Outside, SavedField};

/// A TOML number, often one that must be refused.
fn number() -> BoxedStrategy<String> {
    prop_oneof![
        (-20.0..20.0f64).prop_map(|v| format!("{v:?}")),
        any::<f64>().prop_map(|v| format!("{v:?}")),
        any::<i64>().prop_map(|v| v.to_string()),
        prop::sample::select(vec![
            "nan", "inf", "-inf", "1e308", "-1e308", "0", "-0.0", "1", "-1", "5e-324", "90", "360",
            "1e-300",
        ])
        .prop_map(str::to_string),
    ]
    .boxed()
}

/// A TOML value of the shapes the spec's keys take, and some they do not.
fn value() -> impl Strategy<Value = String> {
    let vector = prop::collection::vec(number(), 0..5)
        .prop_map(|v| format!("[{}]", v.join(", ")))
        .boxed();
    let leaf = prop_oneof![
        number(),
        vector.clone(),
        prop::collection::vec(vector.clone(), 0..5).prop_map(|m| format!("[{}]", m.join(", "))),
        prop::sample::select(vec![
            "\"good.csv\"",
            "\"bad.csv\"",
            "\"ids.txt\"",
            "\"missing.csv\"",
            "\"\"",
            "true",
            "[2, 6]",
            "[300]",
        ])
        .prop_map(str::to_string),
    ]
    .boxed();
    let key = prop::sample::select(vec![
        "min", "max", "center", "radius", "point", "normal", "axis", "degrees", "angle",
    ]);
    prop_oneof![
        3 => leaf.clone(),
        1 => prop::collection::vec((key, leaf), 0..4).prop_map(|kv| {
            let body: Vec<String> = kv.into_iter().map(|(k, v)| format!("{k} = {v}")).collect();
            format!("{{ {} }}", body.join(", "))
        }),
    ]
}

/// An edit spec: entries of the spec's sections with keys of its vocabulary.
fn spec_text() -> impl Strategy<Value = String> {
    let section = prop::sample::select(vec![
        "fixed",
        "handle",
        "pin",
        "target",
        "stiffness",
        "file",
    ]);
    let key = prop::sample::select(vec![
        "box",
        "sphere",
        "plane",
        "indices",
        "classification",
        "polygon",
        "polygon_file",
        "z",
        "invert",
        "snap",
        "file",
        "translate",
        "rotate",
        "scale",
        "pivot",
        "matrix",
        "point",
        "to",
        "from",
        "weight",
        "value",
        "stiffness",
    ]);
    let entry = (section, prop::collection::vec((key, value()), 0..5)).prop_map(|(s, kv)| {
        let mut text = format!("[[{s}]]\n");
        for (k, v) in kv {
            text.push_str(&format!("{k} = {v}\n"));
        }
        text
    });
    prop::collection::vec(entry, 0..4).prop_map(|e| e.concat())
}

/// A float as TOML writes it (`nan`, `inf`), mostly finite and small.
fn float() -> BoxedStrategy<f64> {
    prop_oneof![
        12 => -20.0..20.0f64,
        1 => any::<f64>(),
        1 => prop::sample::select(vec![f64::NAN, f64::INFINITY, -f64::INFINITY, 1e308, 0.0]),
    ]
    .boxed()
}

fn toml_float(v: f64) -> String {
    match v {
        v if v.is_nan() => "nan".into(),
        v if v.is_infinite() => if v > 0.0 { "inf" } else { "-inf" }.into(),
        v => format!("{v:?}"),
    }
}

fn vector(dim: usize) -> BoxedStrategy<String> {
    prop::collection::vec(float(), dim)
        .prop_map(|v| {
            let v: Vec<String> = v.into_iter().map(toml_float).collect();
            format!("[{}]", v.join(", "))
        })
        .boxed()
}

/// A region of the spec's syntax in `dim` dimensions.
fn region(dim: usize) -> BoxedStrategy<String> {
    prop_oneof![
        4 => (prop::collection::vec(float(), dim), prop::collection::vec(-1.0..10.0f64, dim))
            .prop_map(|(lo, ext)| {
                let min: Vec<String> = lo.iter().map(|v| toml_float(*v)).collect();
                let max: Vec<String> =
                    lo.iter().zip(&ext).map(|(v, e)| toml_float(v + e)).collect();
                format!("box = {{ min = [{}], max = [{}] }}", min.join(", "), max.join(", "))
            }),
        2 => (vector(dim), float())
            .prop_map(|(c, r)| format!("sphere = {{ center = {c}, radius = {}}}", toml_float(r))),
        2 => (vector(dim), vector(dim))
            .prop_map(|(p, n)| format!("plane = {{ point = {p}, normal = {n} }}")),
        1 => prop::sample::select(vec![
            "indices = \"ids.txt\"",
            "indices = \"missing.txt\"",
            "classification = [2, 6]",
            "classification = [300]",
            "polygon_file = \"area.geojson\"",
            "polygon_file = \"bad.csv\"",
        ])
        .prop_map(str::to_string),
        1 => (prop::collection::vec((float(), float()), 0..6), any::<bool>()).prop_map(|(ring, invert)| {
            let v: Vec<String> = ring
                .iter()
                .map(|(x, y)| format!("[{}, {}]", toml_float(*x), toml_float(*y)))
                .collect();
            format!("polygon = [{}]\ninvert = {invert}", v.join(", "))
        }),
    ]
    .boxed()
}

/// An edit spec of the spec's own vocabulary in `dim` dimensions, most of it well formed, with
/// numbers that are sometimes not finite or out of range.
fn well_formed_spec(dim: usize) -> BoxedStrategy<String> {
    let motion = prop_oneof![
        vector(dim).prop_map(|v| format!("translate = {v}")),
        (vector(3), float()).prop_map(move |(a, d)| if dim == 3 {
            format!("rotate = {{ axis = {a}, degrees = {} }}", toml_float(d))
        } else {
            format!("rotate = {{ degrees = {} }}", toml_float(d))
        }),
        float().prop_map(|v| format!("scale = {}", toml_float(v))),
        vector(dim).prop_map(|v| format!("pivot = {v}")),
        prop::collection::vec(vector(dim + 1), dim + 1)
            .prop_map(|rows| format!("matrix = [{}]", rows.join(", "))),
    ];
    let entry = prop_oneof![
        3 => region(dim).prop_map(|r| format!("[[fixed]]\n{r}\n")),
        3 => (region(dim), prop::collection::vec(motion, 0..3)).prop_map(|(r, m)| {
            format!("[[handle]]\n{r}\n{}\n", m.join("\n"))
        }),
        1 => (vector(dim), vector(dim))
            .prop_map(|(p, t)| format!("[[pin]]\npoint = {p}\nto = {t}\n")),
        1 => (vector(dim), vector(dim), float()).prop_map(|(f, t, w)| {
            format!("[[target]]\nfrom = {f}\nto = {t}\nweight = {}\n", toml_float(w))
        }),
        1 => prop::sample::select(vec!["good.csv", "bad.csv", "missing.csv"])
            .prop_map(|f| format!("[[target]]\nfile = \"{f}\"\n")),
        1 => (region(dim), float()).prop_map(|(r, v)| {
            format!("[[stiffness]]\n{r}\nscale = {}\n", toml_float(v))
        }),
    ];
    prop::collection::vec(entry, 1..4)
        .prop_map(|e| e.concat())
        .boxed()
}

/// The folder the specs' file names resolve in: a good and a bad target CSV, an index list.
fn base() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("good.csv"), "0,0,0,1,1,1\n1,1,1,2,2,2\n").unwrap();
        std::fs::write(dir.path().join("bad.csv"), "x,y\n1,2\nnan,0,0,0,0,0\n").unwrap();
        std::fs::write(
            dir.path().join("area.geojson"),
            r#"{"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 0]]]}"#,
        )
        .unwrap();
        std::fs::write(dir.path().join("ids.txt"), "0 1 2, 18446744073709551615\n").unwrap();
        dir
    })
    .path()
}

/// Parses `text` in 3D and 2D: no panic; an error is the spec's; an accepted spec is finite.
/// Returns how many of the two parses accepted it.
fn check_spec(text: &str) -> Result<usize, TestCaseError> {
    let name = Path::new("edit.toml");
    let outcomes = [
        parse_spec::<3>(text, base(), name).map(|s| format!("{s:?}")),
        parse_spec::<2>(text, base(), name).map(|s| format!("{s:?}")),
    ];
    let accepted = outcomes.iter().filter(|o| o.is_ok()).count();
    for outcome in outcomes {
        match outcome {
            Ok(debug) => prop_assert!(
                !debug.contains("NaN") && !debug.contains("inf"),
                "accepted a number that is not finite: {text}\n{debug}"
            ),
            Err(e) => prop_assert!(e.exit_code() == 4, "not a spec error ({e:?}) for {text}"),
        }
    }
    Ok(accepted)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn the_spec_parser_refuses_cleanly(text in spec_text()) {
        check_spec(&text)?;
    }

    #[test]
    fn the_spec_parser_accepts_only_finite_specs(
        text in prop_oneof![well_formed_spec(3), well_formed_spec(2)],
    ) {
        check_spec(&text)?;
    }

    #[test]
    fn the_spec_parser_survives_any_text(text in ".{0,200}") {
        check_spec(&text)?;
    }

    #[test]
    fn the_spec_parser_survives_damaged_specs(
        text in prop_oneof![spec_text(), well_formed_spec(3)],
        cuts in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
    ) {
        let mut bytes = text.into_bytes();
        for (at, byte) in cuts {
            if !bytes.is_empty() {
                let i = at.index(bytes.len());
                bytes[i] = byte;
            }
        }
        check_spec(&String::from_utf8_lossy(&bytes))?;
    }
}

/// The generator of well-formed specs must make specs the parser accepts, or the property
/// that accepted specs are finite holds for want of any.
#[test]
fn well_formed_specs_are_often_accepted() {
    use proptest::test_runner::TestRunner;
    let mut runner = TestRunner::deterministic();
    let mut accepted = 0;
    for _ in 0..200 {
        let text = well_formed_spec(3).new_tree(&mut runner).unwrap().current();
        accepted += usize::from(parse_spec::<3>(&text, base(), Path::new("edit.toml")).is_ok());
    }
    assert!(
        accepted >= 40,
        "only {accepted} of 200 generated specs were accepted"
    );
}

/// A PU field saved by `deform` from the bar (format 3, with its window section), made once.
fn saved_field() -> &'static [u8] {
    static FIELD: OnceLock<Vec<u8>> = OnceLock::new();
    FIELD.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let (input, output, edit) = common::lifted_bar(dir.path(), 4.0);
        let field: PathBuf = dir.path().join("bar.field");
        let r = common::deform(
            &input,
            &output,
            &edit,
            &[
                "--cell-size",
                "1",
                "--transfer",
                "pu",
                "--save-field",
                common::arg(&field),
            ],
        );
        assert_eq!(r.code, 0, "{}", r.stderr);
        std::fs::read(&field).unwrap()
    })
}

/// A damage to a field file's bytes.
#[derive(Debug, Clone)]
enum Damage {
    /// Bytes set to values.
    Bytes(Vec<(prop::sample::Index, u8)>),
    /// An 8-byte word (at a multiple of 8 past the 17-byte preamble) set to a float.
    Float(prop::sample::Index, f64),
    /// A 4- or 8-byte count set to a large value.
    Count(prop::sample::Index, u64),
    /// The file cut short.
    Truncate(prop::sample::Index),
}

fn damage() -> impl Strategy<Value = Damage> {
    let float = prop_oneof![
        any::<f64>(),
        prop::sample::select(vec![
            f64::NAN,
            f64::INFINITY,
            -f64::INFINITY,
            0.0,
            -0.0,
            1e308,
            5e-324,
            -1.0,
            2.0,
        ]),
    ];
    let count = prop::sample::select(vec![
        0u64,
        1,
        u32::MAX as u64,
        u32::MAX as u64 + 1,
        1 << 40,
        u64::MAX,
        u64::MAX / 8,
    ]);
    prop_oneof![
        prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8)
            .prop_map(Damage::Bytes),
        (any::<prop::sample::Index>(), float).prop_map(|(i, v)| Damage::Float(i, v)),
        (any::<prop::sample::Index>(), count).prop_map(|(i, v)| Damage::Count(i, v)),
        any::<prop::sample::Index>().prop_map(Damage::Truncate),
    ]
}

fn damaged(good: &[u8], damage: &Damage) -> Vec<u8> {
    let mut bytes = good.to_vec();
    let n = bytes.len();
    match damage {
        Damage::Bytes(list) => {
            for (at, b) in list {
                bytes[at.index(n)] = *b;
            }
        }
        Damage::Float(at, v) => {
            let i = 17 + 8 * at.index((n - 17) / 8 - 1);
            bytes[i..i + 8].copy_from_slice(&v.to_le_bytes());
        }
        Damage::Count(at, v) => {
            let i = at.index(n - 8);
            bytes[i..i + 8].copy_from_slice(&v.to_le_bytes());
        }
        Damage::Truncate(at) => bytes.truncate(at.index(n)),
    }
    bytes
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn the_field_loader_refuses_damaged_files_as_format_errors(damage in damage()) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("damaged.field");
        std::fs::write(&path, damaged(saved_field(), &damage)).unwrap();
        let whole = SavedField::<3>::load(&path);
        let window = SavedField::<3>::load_window(
            &path,
            (
                rigidcells::internal::rigid::Vect::<3>::new(8.0, 0.0, 0.0),
                rigidcells::internal::rigid::Vect::<3>::new(10.0, 1.0, 1.0),
            ),
        );
        for loaded in [whole, window] {
            match loaded {
                Ok(field) => {
                    // Accepted: it must build a deformer (or refuse to) without panicking.
                    let _ = field.deformer(None, None, Outside::Keep);
                }
                Err(Error::Format { path: named, .. }) => prop_assert_eq!(&named, &path),
                Err(e) => prop_assert!(false, "not a format error: {e:?} for {damage:?}"),
            }
        }
    }
}
