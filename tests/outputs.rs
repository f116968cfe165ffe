//! Outputs that cannot be hijacked or half-written: temporaries created new under random
//! names (a planted link is never followed), a result set per run (concurrent runs keep each
//! other's outputs), every output renamed into place at the run's end (a killed run leaves none
//! under its final name), and the library's own refusal to write over its input.

mod common;

use std::path::{Path, PathBuf};

use rigidcells::Silent;
use rigidcells::internal::io::{ResultSet, TempFile};
use rigidcells::internal::pipeline::{self, ApplyParams, CHUNK, Options, Outputs};
use rigidcells::read_spec;

/// The names in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

fn params() -> pipeline::DeformParams {
    Options {
        cell_size: Some(0.5),
        ..Default::default()
    }
    .params()
    .unwrap()
}

/// A link planted beside the output, at the name a temporary used to take (`.NAME.PID.tmp`)
/// and at names of the same shape, is left alone: the file it points to, outside the folder,
/// keeps its bytes, and the run's output is a new regular file.
#[cfg(unix)]
#[test]
fn a_link_planted_beside_the_output_is_never_followed() {
    let dir = tempfile::tempdir().unwrap();
    let outside = tempfile::tempdir().unwrap();
    let victim = outside.path().join("victim.txt");
    std::fs::write(&victim, b"precious").unwrap();
    let (input, out, edit) = common::lifted_bar(dir.path(), 4.0);
    let field = dir.path().join("bar.field");
    let report = dir.path().join("bar.json");
    let pid = std::process::id();
    for name in ["out.ply", "bar.field", "bar.json"] {
        for planted in [format!(".{name}.{pid}.tmp"), format!(".{name}.tmp")] {
            std::os::unix::fs::symlink(&victim, dir.path().join(planted)).unwrap();
        }
    }
    let spec = read_spec::<3>(&edit).unwrap();
    let outputs = Outputs {
        save_field: Some(&field),
        report: Some(&report),
        preview: None,
        keep_existing: false,
        chunk: None,
    };
    pipeline::deform_file_with(&input, &out, &spec, &params(), &outputs, &Silent).unwrap();
    assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
    for path in [&out, &field, &report] {
        let meta = std::fs::symlink_metadata(path).unwrap();
        assert!(meta.file_type().is_file(), "{}", path.display());
        assert!(meta.len() > 0, "{}", path.display());
    }
    // The planted links are still links to the victim, and no temporary is left.
    let left: Vec<String> = names(dir.path())
        .into_iter()
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert_eq!(left.len(), 6, "{left:?}");
}

/// Two temporaries for one target have different, unguessable names, and each is a regular
/// file created new.
#[test]
fn temporaries_have_random_names() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("out.las");
    let (a, _wa) = TempFile::create(&target).unwrap();
    let (b, _wb) = TempFile::create(&target).unwrap();
    assert_ne!(a.path(), b.path());
    for t in [&a, &b] {
        let name = t.path().file_name().unwrap().to_string_lossy().into_owned();
        assert!(
            name.starts_with(".out.las.") && name.ends_with(".tmp"),
            "{name}"
        );
        assert!(!name.contains(&std::process::id().to_string()), "{name}");
        assert!(std::fs::symlink_metadata(t.path()).unwrap().is_file());
    }
    drop((a, b));
    assert_eq!(names(dir.path()), Vec::<String>::new());
}

/// Each run has its own set: a set dropped uncommitted removes its own temporaries and
/// nothing of another's, committed before, after or between.
#[test]
fn result_sets_of_two_runs_are_independent() {
    let dir = tempfile::tempdir().unwrap();
    let (kept, lost) = (ResultSet::new(), ResultSet::new());
    kept.write(&dir.path().join("a.txt"), b"a").unwrap();
    lost.write(&dir.path().join("b.txt"), b"b").unwrap();
    kept.write(&dir.path().join("c.txt"), b"c").unwrap();
    // Nothing is under its final name before the commit.
    assert!(names(dir.path()).iter().all(|n| n.ends_with(".tmp")));
    kept.commit().unwrap();
    drop(lost);
    assert_eq!(names(dir.path()), ["a.txt", "c.txt"]);
}

/// A set that keeps existing files (the editor's *Apply* to a name that was free) replaces no
/// file that appeared under an output's name while it worked: the commit fails naming it, that
/// file keeps its bytes, and the outputs renamed before it are taken back.
#[test]
fn a_set_that_keeps_existing_files_replaces_none() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.txt"), dir.path().join("b.txt"));
    let set = ResultSet::new();
    set.keep_existing();
    set.write(&a, b"ours").unwrap();
    set.write(&b, b"ours").unwrap();
    std::fs::write(&b, b"theirs").unwrap();
    let e = set.commit().unwrap_err();
    assert!(e.to_string().contains("b.txt"), "{e}");
    assert_eq!(std::fs::read(&b).unwrap(), b"theirs");
    assert_eq!(names(dir.path()), ["b.txt"]);
    // Without anything in the way, it commits as any set does.
    let set = ResultSet::new();
    set.keep_existing();
    set.write(&a, b"ours").unwrap();
    set.commit().unwrap();
    assert_eq!(std::fs::read(&a).unwrap(), b"ours");
    assert_eq!(names(dir.path()), ["a.txt", "b.txt"]);
}

/// Two threads deform at once, one failing at its very end (its preview's name is taken by a
/// folder, so the rename of its complete preview fails after its field was renamed into
/// place), the other with a saved field and a report: the other's outputs are all there, the
/// failing one's are not, its field taken back. Two threads writing one output path both
/// succeed.
#[test]
fn concurrent_runs_keep_each_others_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let (input, _, edit) = common::lifted_bar(dir.path(), 4.0);
    let good = read_spec::<3>(&edit).unwrap();
    for round in 0..4 {
        let out = dir.path().join(format!("good{round}.ply"));
        let field = dir.path().join(format!("good{round}.field"));
        let report = dir.path().join(format!("good{round}.json"));
        let failed = dir.path().join(format!("bad{round}.ply"));
        let failed_field = dir.path().join(format!("bad{round}.field"));
        let taken = dir.path().join(format!("bad{round}.png"));
        std::fs::create_dir(&taken).unwrap();
        std::fs::write(taken.join("inside"), b"x").unwrap();
        std::thread::scope(|s| {
            let ok = s.spawn(|| {
                let outputs = Outputs {
                    save_field: Some(&field),
                    report: Some(&report),
                    preview: None,
                    keep_existing: false,
                    chunk: Some(97),
                };
                pipeline::deform_file_with(&input, &out, &good, &params(), &outputs, &Silent)
            });
            let err = s.spawn(|| {
                let outputs = Outputs {
                    save_field: Some(&failed_field),
                    report: None,
                    preview: Some((&taken, Default::default(), false)),
                    keep_existing: false,
                    chunk: Some(97),
                };
                pipeline::deform_file_with(&input, &failed, &good, &params(), &outputs, &Silent)
            });
            ok.join().unwrap().unwrap();
            let e = err.join().unwrap().unwrap_err();
            assert!(e.to_string().contains("bad"), "{e}");
        });
        for path in [&out, &field, &report] {
            assert!(
                path.exists(),
                "round {round}: {} was removed",
                path.display()
            );
        }
        assert!(
            !failed.exists(),
            "round {round}: the failed run's output is in place"
        );
        assert!(
            !failed_field.exists(),
            "round {round}: the failed run's field is in place"
        );
        assert!(taken.join("inside").exists());
    }
    // One output path, two writers at once: neither collides with the other's temporary.
    let same = dir.path().join("same.ply");
    std::thread::scope(|s| {
        let runs: Vec<_> = (0..2)
            .map(|_| s.spawn(|| pipeline::deform_file(&input, &same, &good, &params(), &Silent)))
            .collect();
        for r in runs {
            r.join().unwrap().unwrap();
        }
    });
    assert!(same.exists());
    assert!(names(dir.path()).iter().all(|n| !n.ends_with(".tmp")));
}

/// The library refuses what the command line refuses: an output over the input (`deform_file`,
/// `apply_file` over the input or the field), a saved field over the output, an `.xy` output
/// over its input; nothing is written and the input keeps its bytes.
#[test]
fn the_library_never_writes_over_its_input() {
    let dir = tempfile::tempdir().unwrap();
    let (input, out, edit) = common::lifted_bar(dir.path(), 4.0);
    let bytes = std::fs::read(&input).unwrap();
    let spec = read_spec::<3>(&edit).unwrap();
    let field = dir.path().join("bar.field");
    let refused = |r: rigidcells::Result<()>| {
        let e = r.unwrap_err();
        assert!(matches!(e, rigidcells::Error::Param(_)), "{e}");
        e.to_string()
    };
    let m = refused(pipeline::deform_file(&input, &input, &spec, &params(), &Silent).map(|_| ()));
    assert!(m.contains("overwrite the input"), "{m}");
    let with_field = |field| Outputs {
        save_field: Some(field),
        ..Default::default()
    };
    let m = refused(
        pipeline::deform_file_with(&input, &out, &spec, &params(), &with_field(&out), &Silent)
            .map(|_| ()),
    );
    assert!(m.contains("name the same file"), "{m}");
    assert!(!out.exists());
    pipeline::deform_file_with(&input, &out, &spec, &params(), &with_field(&field), &Silent)
        .unwrap();
    let field_bytes = std::fs::read(&field).unwrap();
    let apply = |to: &PathBuf| {
        pipeline::apply_file(&field, &out, to, &ApplyParams::default(), CHUNK, &Silent).map(|_| ())
    };
    refused(apply(&out));
    refused(apply(&field));
    assert_eq!(std::fs::read(&input).unwrap(), bytes);
    assert_eq!(std::fs::read(&field).unwrap(), field_bytes);
}

/// The library checks what the command line checks, before any work (under a memory budget of
/// 1 KiB, any work would fail on the budget first): an output of another format, an output in
/// a missing folder, a chunk of 0 samples; and a target name of 255 bytes gets a temporary.
#[test]
fn the_library_checks_its_arguments_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let (input, out, edit) = common::lifted_bar(dir.path(), 4.0);
    let spec = read_spec::<3>(&edit).unwrap();
    let tiny = Options {
        cell_size: Some(0.5),
        memory_limit: Some(1024),
        ..Default::default()
    }
    .params()
    .unwrap();
    let run = |output: &Path, chunk: usize| {
        let outputs = Outputs {
            chunk: Some(chunk),
            ..Default::default()
        };
        pipeline::deform_file_with(&input, output, &spec, &tiny, &outputs, &Silent)
            .map(|_| ())
            .unwrap_err()
    };
    let e = run(&dir.path().join("out.las"), CHUNK);
    assert!(matches!(e, rigidcells::Error::Param(_)), "{e}");
    assert!(e.to_string().contains("the input's format (.ply)"), "{e}");
    let e = run(&dir.path().join("missing").join("out.ply"), CHUNK);
    assert!(matches!(e, rigidcells::Error::Write { .. }), "{e}");
    let e = run(&out, 0);
    assert!(e.to_string().contains("--chunk 0"), "{e}");
    let long = dir.path().join(format!("{}.ply", "é".repeat(125)));
    assert_eq!(long.file_name().unwrap().len(), 254);
    pipeline::deform_file(&input, &long, &spec, &params(), &Silent).unwrap();
    assert!(long.exists());
}

/// SIGKILL while the output is being written: the field and the report, complete by then, are
/// not under their names either (they are renamed with the output at the run's end).
#[cfg(unix)]
#[test]
fn a_killed_run_leaves_no_output_under_its_name() {
    let dir = tempfile::tempdir().unwrap();
    let (mut child, outputs) = common::long_run(dir.path());
    // The output's temporary appears when pass 2 starts, after the field was written.
    common::wait_for_file(dir.path(), &mut child, ".out.las.");
    child.kill().unwrap();
    child.wait().unwrap();
    for path in &outputs {
        assert!(
            !path.exists(),
            "{} is in place after a kill",
            path.display()
        );
    }
}
