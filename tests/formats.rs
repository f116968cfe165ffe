//! Every shared LAS/LAZ, PLY and OBJ file through the CLI: nothing but coordinates changes;
//! malformed files give their specific errors; saved fields applied to tiles reproduce the whole.

mod common;

use std::path::{Path, PathBuf};

use common::{arg, deform, records, run, shared};
use rigidcells::Vect;
use rigidcells::internal::io::{
    Accepted, Chunk, Document, LasHeader, PlyRecordStream, PlyStream, Source, XyzStream,
};

/// The translation: exact in one decimal, the fewest any text input here has.
const T: [f64; 3] = [1.5, -2.5, 0.5];

/// Translates everything by `T`: two handles with the same motion over the half-spaces above
/// and below z = 0, which share the cells on the plane.
fn translate_spec(dir: &Path) -> PathBuf {
    let p = dir.join("translate.toml");
    let half = |nz: f64| {
        format!(
            "[[handle]]\nplane = {{ point = [0.0, 0.0, 0.0], normal = [0.0, 0.0, {nz}] }}\ntranslate = {T:?}\n"
        )
    };
    std::fs::write(&p, half(1e-4) + &half(-1e-4)).unwrap();
    p
}

/// Runs the translation on `input` into `dir`. Returns the file's name and the output, or
/// `None` after checking that an input listed in `refused` fails with its message (exit 3, no
/// output).
fn translate(
    dir: &Path,
    spec: &Path,
    input: &Path,
    refused: &[(&str, &str)],
) -> Option<(String, PathBuf)> {
    let name = input.file_name().unwrap().to_str().unwrap().to_string();
    // A COPC input round-trips to a plain LAZ in its own point order (`*.copc.laz` would
    // write a COPC, in octree order: tests/copc.rs).
    let output = dir.join(format!("out_{}", name.replace(".copc.laz", ".plain.laz")));
    let r = deform(input, &output, spec, &["--transfer", "blend"]);
    if let Some((_, msg)) = refused.iter().find(|(f, _)| *f == name) {
        assert_eq!(r.code, 3, "{name}: {}", r.stderr);
        assert!(r.stderr.contains(msg), "{name}: {}", r.stderr);
        assert!(!output.exists(), "{name}: no output");
        return None;
    }
    assert_eq!(r.code, 0, "{name}: {}", r.stderr);
    Some((name, output))
}

fn files(dir: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(shared(dir))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    v.sort();
    v
}

/// Refused LAS inputs, each with its message.
const LAS_REFUSED: [(&str, &str); 1] = [("pdrf9-1.5.las", "LAS 1.5 is not supported")];

#[test]
fn every_las_file_round_trips_a_translation() {
    let dir = tempfile::tempdir().unwrap();
    let spec = translate_spec(dir.path());
    for input in files("las") {
        let Some((name, output)) = translate(dir.path(), &spec, &input, &LAS_REFUSED) else {
            continue;
        };
        let (hin, rin, pin, rl) = records(&input);
        let (hout, rout, pout, rl2) = records(&output);
        assert_eq!(
            (hin.count, rl, hin.format),
            (hout.count, rl2, hout.format),
            "{name}"
        );
        assert_eq!(rin.len(), rout.len(), "{name}");
        for (k, (a, b)) in rin.chunks_exact(rl).zip(rout.chunks_exact(rl)).enumerate() {
            assert_eq!(a[12..], b[12..], "{name}: record {k} changed beyond X Y Z");
        }
        for (k, (a, b)) in pin.iter().zip(&pout).enumerate() {
            for ax in 0..3 {
                let err = (b[ax] - a[ax] - T[ax]).abs();
                let tol = 0.5 * hout.scale[ax] + 1e-9 * a[ax].abs().max(1.0);
                assert!(err <= tol, "{name}: point {k} axis {ax} off by {err}");
            }
        }
        // The header's bounds are those of the records as stored, exactly, whichever writer
        // wrote them.
        for ax in 0..3 {
            let lo = pout.iter().map(|p| p[ax]).fold(f64::INFINITY, f64::min);
            let hi = pout.iter().map(|p| p[ax]).fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(
                (hout.min[ax], hout.max[ax]),
                (lo, hi),
                "{name}: axis {ax}: the header's bounds against the records'"
            );
        }
        if !hin.compressed {
            // LAS -> LAS: header and VLRs verbatim but for the generating software and
            // scale/offset/bounds, and the bytes after the points (waveform data, EVLRs)
            // verbatim.
            let (a, b) = (
                std::fs::read(&input).unwrap(),
                std::fs::read(&output).unwrap(),
            );
            assert_eq!(a.len(), b.len(), "{name}");
            assert_eq!(a[..58], b[..58], "{name}: header start");
            assert_eq!(a[90..131], b[90..131], "{name}: header start");
            let off = hin.point_offset as usize;
            assert_eq!(a[227..off], b[227..off], "{name}: VLRs");
            let end = off + hin.count as usize * rl;
            assert_eq!(a[end..], b[end..], "{name}: bytes after the points");
        } else {
            let names = |h: &LasHeader| {
                h.vlrs
                    .iter()
                    .filter(|v| v.user_id != "laszip encoded" && v.user_id != "copc")
                    .map(|v| (v.user_id.clone(), v.record_id, v.len))
                    .collect::<Vec<_>>()
            };
            assert_eq!(names(&hin), names(&hout), "{name}: VLRs");
        }
    }
}

/// Mesh inputs without anything to deform, each with its message.
const MESH_REFUSED: [(&str, &str); 1] = [("all_atomic_types_ok_ascii.ply", "no `vertex` element")];

#[test]
fn every_mesh_file_round_trips_a_translation() {
    let dir = tempfile::tempdir().unwrap();
    let spec = translate_spec(dir.path());
    for input in files("meshes") {
        let Some((name, output)) = translate(dir.path(), &spec, &input, &MESH_REFUSED) else {
            continue;
        };
        let a = Document::read(&input).unwrap();
        let b = Document::read(&output).unwrap();
        assert_eq!(a.positions().len(), b.positions().len(), "{name}");
        assert_eq!(a.triangles(), b.triangles(), "{name}");
        for (p, q) in a.positions().iter().zip(b.positions()) {
            for ax in 0..3 {
                let tol = 1e-6 * (p[ax].abs() + 3.0);
                assert!(
                    (q[ax] - p[ax] - T[ax]).abs() <= tol,
                    "{name}: {p:?} -> {q:?}"
                );
            }
        }
        if let (Some(na), Some(nb)) = (a.normals(), b.normals()) {
            for (m, n) in na.iter().zip(nb) {
                assert!((m - n).norm() <= 1e-5 * m.norm().max(1.0), "{name}: normal");
            }
        }
        // Everything but the numbers of vertex lines is kept: binary PLY keeps its header and
        // length, text files their line count, and OBJ every line that is not `v` or `vn`.
        let (ba, bb) = (
            std::fs::read(&input).unwrap(),
            std::fs::read(&output).unwrap(),
        );
        let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
        if text(&ba[..ba.len().min(300)]).contains("format binary") {
            assert_eq!(ba.len(), bb.len(), "{name}");
            let header = ba.windows(10).position(|w| w == b"end_header").unwrap();
            assert_eq!(ba[..header], bb[..header], "{name}: header changed");
        } else {
            let lines = |b: &[u8]| b.split(|&c| c == b'\n').count();
            assert_eq!(lines(&ba), lines(&bb), "{name}: line count");
            if name.ends_with(".obj") {
                let other = |s: String| {
                    s.lines()
                        .filter(|l| !l.starts_with("v ") && !l.starts_with("vn "))
                        .map(str::to_string)
                        .collect::<Vec<_>>()
                };
                assert_eq!(
                    other(text(&ba)),
                    other(text(&bb)),
                    "{name}: non-vertex lines"
                );
            }
        }
    }
}

#[test]
fn malformed_files_give_their_specific_errors() {
    let dir = tempfile::tempdir().unwrap();
    let spec = translate_spec(dir.path());
    let expected = [
        ("1.2-no-points.las", "the file holds 0 complete records"),
        ("1.2-with-color-clipped.las", "holds 1064 complete records"),
        ("bad_vlr_count.las", "VLR count"),
        ("broken_coder.laz", "uses coder 15"),
        ("broken_compressor.laz", "names compressor 16"),
        ("broken_version.laz", "in version 6 of their encoding"),
        (
            "crash-30d6d0f7c529b3b66b4131700b7a4580cd7082df.ply",
            "no `end_header`",
        ),
        (
            "cube-ply-1.0_ascii-comment_renamed_to_remark-invalid.ply",
            "unknown header keyword `remark`",
        ),
        ("empty.obj", "no vertices"),
        ("empty.ply", "not a PLY file"),
        ("fuze_ascii.ply", "is not a Int"),
        ("issue623.ply", "is not a UChar"),
        ("malformed.obj", "vertex index 12 is out of range"),
        ("no-points.las", "holds no points"),
        ("payload_JVN42386607.ply", "bad header"),
        ("ply_empty_header.ply", "no `vertex` element"),
        ("points_emptyascii.ply", "data after the last element"),
        // Two 2-property records in a 5-byte body: refused by the counts before the elements.
        ("single_elements_err_ascii.ply", "cannot fit"),
        ("unsized_dims.ply", "moves float or double coordinates"),
    ];
    assert_eq!(expected.len(), files("malformed").len());
    for (file, msg) in expected {
        let input = shared(&format!("malformed/{file}"));
        let out_dir = dir.path().join(file);
        std::fs::create_dir(&out_dir).unwrap();
        let output = out_dir.join(format!("out_{file}"));
        let r = deform(&input, &output, &spec, &[]);
        assert_eq!(r.code, 3, "{file}: {}", r.stderr);
        assert!(r.stderr.contains(msg), "{file}: {}", r.stderr);
        assert!(r.stderr.contains(file), "{file}: the error names the file");
        assert!(!r.stderr.contains("panicked"), "{file}: {}", r.stderr);
        assert_eq!(
            std::fs::read_dir(&out_dir).unwrap().count(),
            0,
            "{file}: wrote an output or left a temporary file"
        );
    }
}

#[test]
fn georeferenced_coordinates_survive_identity_and_small_edits() {
    let dir = tempfile::tempdir().unwrap();
    let identity = dir.path().join("identity.toml");
    std::fs::write(
        &identity,
        "[[fixed]]\nbox = { min = [-1e12, -1e12, -1e12], max = [1e12, 1e12, 1e12] }\n",
    )
    .unwrap();
    let small = dir.path().join("small.toml");
    std::fs::write(
        &small,
        "[[handle]]\nbox = { min = [-1e12, -1e12, -1e12], max = [1e12, 1e12, 1e12] }\ntranslate = [0.001, -0.002, 0.0005]\n",
    )
    .unwrap();
    for name in [
        "certainty3d-color-utm-feet-navd88.las",
        "test1_4.las",
        "Topography.laz",
    ] {
        let input = shared(&format!("las/{name}"));
        for transfer in ["blend", "rbf"] {
            let out = dir.path().join(format!("id_{transfer}_{name}"));
            let r = deform(&input, &out, &identity, &["--transfer", transfer]);
            assert_eq!(r.code, 0, "{}", r.stderr);
            let ((_, a, _, rl), (_, b, _, _)) = (records(&input), records(&out));
            assert_eq!(a.len(), b.len());
            for (x, y) in a.chunks_exact(rl).zip(b.chunks_exact(rl)) {
                assert_eq!(
                    x[..12],
                    y[..12],
                    "{name} {transfer}: identity moved a point"
                );
            }
        }
        let out = dir.path().join(format!("small_{name}"));
        let r = deform(&input, &out, &small, &["--transfer", "rbf"]);
        assert_eq!(r.code, 0, "{}", r.stderr);
        let ((_, _, p, _), (h, _, q, _)) = (records(&input), records(&out));
        let t = [0.001, -0.002, 0.0005];
        for (a, b) in p.iter().zip(&q) {
            for ax in 0..3 {
                assert!((b[ax] - a[ax] - t[ax]).abs() <= 0.5 * h.scale[ax] + 1e-9);
            }
        }
    }
}

/// `rigidcells apply FIELD INPUT -o OUTPUT -q`, which must succeed.
fn apply(field: &Path, input: &Path, output: &Path) {
    let p = |p: &Path| p.to_str().unwrap().to_string();
    let a = run(&["apply", &p(field), &p(input), "-o", &p(output), "-q"]);
    assert_eq!(a.code, 0, "{}", a.stderr);
}

/// Writes the records `keep` of the LAS 1.2 file `input` as a LAS file (header and VLRs
/// copied, count patched; the header's bounds `bounds`, as a tiler would write them: `apply`
/// reads the part of a field they need).
fn write_tile(input: &Path, keep: &[usize], bounds: (Vect<3>, Vect<3>), out: &Path) {
    let h = LasHeader::read(input).unwrap();
    let bytes = std::fs::read(input).unwrap();
    let off = h.point_offset as usize;
    let rl = h.record_len as usize;
    let mut tile = bytes[..off].to_vec();
    tile[107..111].copy_from_slice(&(keep.len() as u32).to_le_bytes());
    for a in 0..3 {
        let at = 179 + 16 * a;
        tile[at..at + 8].copy_from_slice(&bounds.1[a].to_le_bytes());
        tile[at + 8..at + 16].copy_from_slice(&bounds.0[a].to_le_bytes());
    }
    for &k in keep {
        tile.extend_from_slice(&bytes[off + k * rl..off + (k + 1) * rl]);
    }
    std::fs::write(out, tile).unwrap();
}

/// The indices of `pos` in the four quadrants about the medians of x and y.
fn quadrants(pos: &[Vect<3>]) -> Vec<Vec<usize>> {
    let mid = |ax: usize| {
        let mut v: Vec<f64> = pos.iter().map(|p| p[ax]).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (mx, my) = (mid(0), mid(1));
    (0..4)
        .map(|q| {
            (0..pos.len())
                .filter(|&k| ((pos[k].x >= mx) as usize) + 2 * ((pos[k].y >= my) as usize) == q)
                .collect()
        })
        .collect()
}

/// The bounds of the samples `keep` of `pos`.
fn bounds_of(pos: &[Vect<3>], keep: &[usize]) -> (Vect<3>, Vect<3>) {
    let lo = keep.iter().fold(pos[keep[0]], |a, &k| a.inf(&pos[k]));
    let hi = keep.iter().fold(pos[keep[0]], |a, &k| a.sup(&pos[k]));
    (lo, hi)
}

#[test]
fn saved_field_applied_to_tiles_equals_deform_of_the_whole() {
    let dir = tempfile::tempdir().unwrap();
    let input = shared("las/autzen_trim.las");
    let spec = dir.path().join("bend.toml");
    // Lift the east end by 20 m and turn it, keeping the west end fixed.
    std::fs::write(
        &spec,
        "[[fixed]]\nbox = { min = [636000, 848900, 0], max = [636300, 849600, 1000] }\n\
         [[handle]]\nbox = { min = [636900, 848900, 0], max = [637200, 849600, 1000] }\n\
         translate = [0, 0, 20]\nrotate = { axis = [0, 1, 0], degrees = 5 }\n",
    )
    .unwrap();
    let field = dir.path().join("bend.field");
    let whole = dir.path().join("whole.las");
    let r = deform(
        &input,
        &whole,
        &spec,
        &["--save-field", field.to_str().unwrap(), "--chunk", "7777"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    // The same field applied by `apply` (another chunking) gives the same bytes.
    let again = dir.path().join("again.las");
    apply(&field, &input, &again);
    assert_eq!(
        std::fs::read(&whole).unwrap(),
        std::fs::read(&again).unwrap()
    );

    // Four spatial tiles, each applied alone, merge into the whole.
    let (_, raw, pos, rl) = records(&input);
    let (_, moved, _, _) = records(&whole);
    let mut covered = 0;
    for (q, keep) in quadrants(&pos).into_iter().enumerate() {
        let (lo, hi) = bounds_of(&pos, &keep);
        // The tile's own bounds; for the last tile, bounds that miss a part of it (a wrong
        // header), after which `apply` reads the whole field.
        let wrong = (lo, (lo + hi) * 0.5);
        for (name, bounds) in [("", (lo, hi)), ("wrong", wrong)] {
            if q < 3 && name == "wrong" {
                continue;
            }
            let tile = dir.path().join(format!("tile{q}{name}.las"));
            let out = dir.path().join(format!("tile{q}{name}_out.las"));
            write_tile(&input, &keep, bounds, &tile);
            apply(&field, &tile, &out);
            let (_, tile_raw, _, _) = records(&out);
            for (i, &k) in keep.iter().enumerate() {
                assert_eq!(
                    tile_raw[i * rl..(i + 1) * rl],
                    moved[k * rl..(k + 1) * rl],
                    "tile {q}{name} record {i}"
                );
            }
        }
        covered += keep.len();
    }
    assert_eq!(covered, raw.len() / rl);
    // And the bend happened: the east end rose.
    let (_, _, out_pos, _) = records(&whole);
    let east = pos.iter().zip(&out_pos).filter(|(p, _)| p.x > 637000.0);
    let rise: Vec<f64> = east.map(|(p, q)| q.z - p.z).collect();
    let mean = rise.iter().sum::<f64>() / rise.len() as f64;
    assert!(mean > 10.0, "east end rose by {mean}");
}

/// `solve` over four tiles cut from one scan builds the field `deform` builds
/// for the merged file; `apply` of it to each tile gives, record for record, what `deform`
/// gives on the merged file.
#[test]
fn solve_over_tiles_then_apply_equals_deform_of_the_merged_file() {
    let dir = tempfile::tempdir().unwrap();
    let input = shared("las/autzen_trim.las");
    let spec = dir.path().join("bend.toml");
    std::fs::write(
        &spec,
        "[[fixed]]\nbox = { min = [636000, 848900, 0], max = [636300, 849600, 1000] }\n\
         [[handle]]\nbox = { min = [636900, 848900, 0], max = [637200, 849600, 1000] }\n\
         translate = [0, 0, 20]\nrotate = { axis = [0, 1, 0], degrees = 5 }\n",
    )
    .unwrap();
    let (_, _, pos, rl) = records(&input);
    // Four tiles by quadrant; the merged file is their records in tile order.
    let quadrants = quadrants(&pos);
    let mut tiles = Vec::new();
    for (q, keep) in quadrants.iter().enumerate() {
        let tile = dir.path().join(format!("tile{q}.las"));
        write_tile(&input, keep, bounds_of(&pos, keep), &tile);
        tiles.push(tile);
    }
    let order: Vec<usize> = quadrants.concat();
    let merged = dir.path().join("merged.las");
    write_tile(&input, &order, bounds_of(&pos, &order), &merged);
    let merged_out = dir.path().join("merged_out.las");
    let r = deform(&merged, &merged_out, &spec, &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let field = dir.path().join("tiles.field");
    let mut args = vec!["solve"];
    args.extend(tiles.iter().map(|t| t.to_str().unwrap()));
    args.extend([
        "--edit",
        spec.to_str().unwrap(),
        "--save-field",
        field.to_str().unwrap(),
        "-q",
    ]);
    let r = common::run(&args);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let (_, moved, _, _) = records(&merged_out);
    let mut at = 0;
    for (q, tile) in tiles.iter().enumerate() {
        let out = dir.path().join(format!("tile{q}_out.las"));
        apply(&field, tile, &out);
        let (_, raw, _, _) = records(&out);
        assert_eq!(raw, moved[at * rl..at * rl + raw.len()], "tile {q}");
        at += raw.len() / rl;
    }
    assert_eq!(at, pos.len());
    // Solving a mesh among tiles, or writing the tiles, is refused.
    let mesh = dir.path().join("bar.ply");
    data_gen::write_ply(&mesh, &data_gen::bar([1.0, 1.0, 1.0], 2.0), true).unwrap();
    let r = common::run(&[
        "solve",
        tiles[0].to_str().unwrap(),
        mesh.to_str().unwrap(),
        "--edit",
        spec.to_str().unwrap(),
        "--save-field",
        field.to_str().unwrap(),
    ]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("bar.ply"), "{}", r.stderr);
}

/// The lines of a summary from the control points' table to the constraints' residuals.
fn control_table(stdout: &str) -> String {
    let from = stdout.find("control points:").expect(stdout);
    let to = stdout[from..].find("  constraints:").expect(stdout);
    stdout[from..from + to].to_string()
}

/// `solve --report --preview --strain --check-gcp` over two tiles reports what `deform` with the
/// same options reports for the merged file — the counts, the residuals on the proxy, the
/// fold-overs, the control points and their leave-one-out errors (but for the rounding of the
/// output `deform` writes) — prints the same control-point table, and draws the same preview,
/// from a proxy across both tiles.
#[test]
fn solve_over_tiles_reports_what_deform_reports_for_the_merged_file() {
    let dir = tempfile::tempdir().unwrap();
    let input = shared("las/autzen_trim.las");
    std::fs::write(
        dir.path().join("gcp.csv"),
        "id,x,y,z,X,Y,Z\nP1,636500,849100,430,636500,849100,433\n\
         P2,636700,849300,430,636700.5,849300,432\nP3,636600,849450,430,636600,849450,434\n",
    )
    .unwrap();
    let spec = dir.path().join("bend.toml");
    std::fs::write(
        &spec,
        "[[fixed]]\nbox = { min = [636000, 848900, 0], max = [636300, 849600, 1000] }\n\
         [[handle]]\nbox = { min = [636900, 848900, 0], max = [637200, 849600, 1000] }\n\
         translate = [0, 0, 20]\n[[target]]\nfile = \"gcp.csv\"\nsnap = 60\nweight = 10\n",
    )
    .unwrap();
    let (_, _, pos, _) = records(&input);
    // Two tiles, west and east halves; the merged file is their records in tile order.
    let q = quadrants(&pos);
    let halves = [
        [&q[0][..], &q[1][..]].concat(),
        [&q[2][..], &q[3][..]].concat(),
    ];
    let mut tiles = Vec::new();
    for (k, keep) in halves.iter().enumerate() {
        let tile = dir.path().join(format!("half{k}.las"));
        write_tile(&input, keep, bounds_of(&pos, keep), &tile);
        tiles.push(tile);
    }
    let order = halves.concat();
    let merged = dir.path().join("merged.las");
    write_tile(&input, &order, bounds_of(&pos, &order), &merged);
    let (deformed, solved) = (dir.path().join("d.json"), dir.path().join("s.json"));
    let merged_preview = dir.path().join("merged.png");
    let r = common::deform_verbose(
        &merged,
        &dir.path().join("merged_out.las"),
        &spec,
        &[
            "--cells",
            "3000",
            "--check-gcp",
            "--report",
            arg(&deformed),
            "--preview",
            arg(&merged_preview),
            "--strain",
            "--size",
            "200x150",
        ],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let preview = dir.path().join("tiles.png");
    let mut args = vec!["solve"];
    args.extend(tiles.iter().map(|t| arg(t)));
    let field = dir.path().join("tiles.field");
    args.extend([
        "--edit",
        arg(&spec),
        "--save-field",
        arg(&field),
        "--cells",
        "3000",
        "--check-gcp",
        "--report",
        arg(&solved),
        "--preview",
        arg(&preview),
        "--strain",
        "--size",
        "200x150",
    ]);
    let s = common::run(&args);
    assert_eq!(s.code, 0, "{}", s.stderr);
    assert!(field.exists());
    // The leave-one-out table, as deform prints it for the merged file.
    assert!(s.stdout.contains("then left out"), "{}", s.stdout);
    assert!(s.stdout.contains("leave-one-out RMSE"), "{}", s.stdout);
    // The same rows in the same order; deform's residuals are measured on its output as
    // written (to autzen's 0.01), solve's on the field (each tile's apply rounds to its own).
    let ids = |t: String| -> Vec<String> {
        t.lines()
            .skip(2)
            .map_while(|l| l.strip_prefix("  ").filter(|l| !l.starts_with("RMSE")))
            .map(|l| l.split_whitespace().next().unwrap().to_string())
            .collect()
    };
    let ids_deformed = ids(control_table(&r.stdout));
    assert_eq!(ids(control_table(&s.stdout)), ids_deformed);
    assert_eq!(ids_deformed.len(), 3, "{}", r.stdout);
    assert!(
        control_table(&r.stdout).contains("residuals as written, to the output's scale 0.01")
            && !control_table(&s.stdout).contains("as written"),
        "{}",
        s.stdout
    );
    assert!(s.stdout.contains("2 files -> "), "{}", s.stdout);
    let json = |p: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let (d, s) = (json(&deformed), json(&solved));
    for key in [
        "points",
        "cells",
        "cells_initial",
        "cell_size",
        "cell_levels",
        "cell_roles",
        "iterations",
        "energy",
        "residual_max",
        "residual_samples",
        "target_residual_max",
        "foldovers",
        "foldovers_checked",
        "control_rmse_left_out",
        "control_trend",
        "warnings",
    ] {
        assert_eq!(d[key], s[key], "{key}");
    }
    // The control points: the same but for the rounding of where the output puts them.
    let (dp, sp) = (
        d["control_points"].as_array().unwrap(),
        s["control_points"].as_array().unwrap(),
    );
    assert_eq!(dp.len(), sp.len());
    for (a, b) in dp.iter().zip(sp) {
        for key in [
            "id", "from", "wanted", "snapped", "left_out", "check", "exact",
        ] {
            assert_eq!(a[key], b[key], "{key}");
        }
        let residual = |p: &serde_json::Value| p["residual"].as_f64().unwrap();
        assert!(
            (residual(a) - residual(b)).abs() <= 0.005 * 3f64.sqrt(),
            "{a} {b}"
        );
    }
    let rmse = |j: &serde_json::Value| j["control_rmse"].as_f64().unwrap();
    assert!((rmse(&d) - rmse(&s)).abs() <= 0.005 * 3f64.sqrt());
    assert_eq!(d["points"], pos.len());
    assert!(d["residual_samples"].as_u64().unwrap() > 0);
    assert_eq!(s["control_points"].as_array().unwrap().len(), 3);
    assert!(s["control_points"][0]["left_out"].is_f64(), "{s}");
    let inputs: Vec<&str> = tiles.iter().map(|t| arg(t)).collect();
    assert_eq!(s["inputs"], serde_json::json!(inputs));
    assert_eq!(s["output"], arg(&field));
    assert_eq!(s["timings_s"]["write"], 0.0);
    // Three panels (before, after, strain) of 200×150 pixels, 2 pixels apart.
    let png = std::fs::read(&preview).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let picture = rigidcells::internal::image::Raster::read_png(&preview).unwrap();
    assert_eq!((picture.width, picture.height), (604, 150));
    // The same proxy, the same cells: the same picture.
    assert!(png == std::fs::read(&merged_preview).unwrap());
    // Two outputs under one name, or a preview that is not a PNG, are refused before any work,
    // and nothing is written.
    let fresh = dir.path().join("fresh.field");
    for (flag, path, said) in [
        ("--report", arg(&fresh), "name the same file"),
        ("--preview", "p.jpg", "p.jpg"),
    ] {
        let mut args = vec!["solve"];
        args.extend(tiles.iter().map(|t| arg(t)));
        args.extend([
            "--edit",
            arg(&spec),
            "--save-field",
            arg(&fresh),
            flag,
            path,
        ]);
        let r = common::run(&args);
        assert_eq!(r.code, 4, "{}", r.stderr);
        assert!(r.stderr.contains(said), "{}", r.stderr);
        assert!(!fresh.exists());
    }
}

/// Translates every sample of `source` by `T` into `out`, `chunk` samples at a time; returns
/// the positions read and the bytes written.
fn translate_stream(
    mut source: Box<dyn Source>,
    chunk: usize,
    out: &Path,
) -> (Vec<Vect<3>>, Vec<u8>) {
    let shift = Vect::<3>::from(T);
    let mut sink = source.sink(out, None).unwrap();
    let mut buffer = Chunk::default();
    let mut positions = Vec::new();
    while source.read(chunk, &mut buffer).unwrap() > 0 {
        let moved: Vec<Vect<3>> = buffer.positions.iter().map(|p| p + shift).collect();
        positions.extend_from_slice(&buffer.positions);
        let accepted = sink.write(&buffer, &moved, &buffer.normals).unwrap();
        assert_eq!(accepted, Accepted::Yes);
    }
    let set = rigidcells::internal::io::ResultSet::new();
    sink.finish(&set).unwrap();
    set.commit().unwrap();
    (positions, std::fs::read(out).unwrap())
}

/// Every PLY streams (binary with fixed-size vertex records from the map, any PLY by walking
/// its records): each stream decodes the positions and triangles of the file read whole, and
/// its sink, fed in small chunks, writes the bytes the record walker's sink writes when fed
/// the whole file as one chunk.
#[test]
fn ply_streams_agree_with_the_whole_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut inputs: Vec<PathBuf> = files("meshes");
    for big in [false, true] {
        let path = dir.path().join(format!("vertex_lists_{big}.ply"));
        std::fs::write(&path, binary_ply_with_vertex_lists(big)).unwrap();
        inputs.push(path);
    }
    let (mut streamed, mut walked_binary) = (0, 0);
    for input in inputs {
        if input.extension().is_none_or(|e| e != "ply") {
            continue;
        }
        let name = input.file_name().unwrap().to_string_lossy().to_string();
        let Ok(fixed) = PlyStream::open(&input) else {
            continue;
        };
        let Ok(walked) = PlyRecordStream::open(&input) else {
            assert!(
                fixed.is_none(),
                "{name}: the walker fails where the map does not"
            );
            continue;
        };
        // The generated files are the binary ones with vertex lists.
        walked_binary += usize::from(fixed.is_none() && input.starts_with(dir.path()));
        let whole = Document::read(&input).unwrap();
        let one = Box::new(PlyRecordStream::open(&input).unwrap());
        let (_, want) = translate_stream(one, usize::MAX, &dir.path().join(format!("w_{name}")));
        let mut streams: Vec<Box<dyn Source>> = vec![Box::new(walked)];
        streams.extend(fixed.map(|s| Box::new(s) as Box<dyn Source>));
        for (k, stream) in streams.into_iter().enumerate() {
            assert_eq!(stream.triangles(), whole.triangles(), "{name}");
            let out = dir.path().join(format!("s{k}_{name}"));
            let (positions, bytes) = translate_stream(stream, 1000, &out);
            assert_eq!(positions, whole.positions(), "{name}");
            assert!(bytes == want, "{name}: bytes differ");
        }
        streamed += 1;
    }
    assert!(streamed >= 22, "only {streamed} PLY files streamed");
    assert_eq!(
        walked_binary, 2,
        "both binary files with vertex lists are walked"
    );
}

/// A binary PLY whose vertices carry a list property between their coordinates (records of
/// varying size), with doubles, floats, a face and a trailing element.
fn binary_ply_with_vertex_lists(big: bool) -> Vec<u8> {
    let format = if big { "big" } else { "little" };
    let mut out = format!(
        "ply\nformat binary_{format}_endian 1.0\ncomment walked records\nelement vertex 5\n\
         property float x\nproperty list uchar int tags\nproperty double y\nproperty float z\n\
         property uchar flag\nelement face 2\nproperty list uchar int vertex_indices\n\
         element extra 1\nproperty short s\nend_header\n"
    )
    .into_bytes();
    let f32b = |v: f32| {
        if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let f64b = |v: f64| {
        if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let i32b = |v: i32| {
        if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    for k in 0..5 {
        out.extend_from_slice(&f32b(k as f32 * 0.5));
        out.push(k as u8 % 3);
        for t in 0..(k % 3) {
            out.extend_from_slice(&i32b(100 * k + t));
        }
        out.extend_from_slice(&f64b(1.0 + k as f64 / 3.0));
        out.extend_from_slice(&f32b(-(k as f32)));
        out.push(200 + k as u8);
    }
    for face in [[0, 1, 2], [2, 3, 4]] {
        out.push(3);
        for v in face {
            out.extend_from_slice(&i32b(v));
        }
    }
    out.extend_from_slice(
        &(if big {
            7i16.to_be_bytes()
        } else {
            7i16.to_le_bytes()
        }),
    );
    out
}

/// An XYZ file with a header comment, `//` comments, blank lines, CRLF line ends, commas,
/// extra columns and no newline at the end streams in chunks of 7 points the positions of the
/// file read whole, and to the same bytes as one chunk of all of them; through the CLI, every
/// line but the numbers is kept.
#[test]
fn xyz_streams_like_the_whole_file() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("cloud.xyz");
    let mut text = String::from("# x y z r g b\n\n");
    for i in 0..100 {
        let (x, y, z) = (i as f64 * 0.1, (i % 7) as f64 * 0.3, (i % 3) as f64 * 0.05);
        match i % 4 {
            0 => text += &format!("{x} {y} {z} 255 0 {i}\n"),
            1 => text += &format!("  {x},{y},{z}\r\n"),
            2 => text += &format!("{x}\t{y}\t{z}\t0.5\n// a comment\n"),
            _ => text += &format!("{x} {y} {z}\n\n"),
        }
    }
    text += "1 2 3 end";
    std::fs::write(&input, &text).unwrap();
    let whole = Document::read(&input).unwrap();
    let stream = XyzStream::open(&input).unwrap();
    assert_eq!(stream.len(), 101);
    let out = dir.path().join("streamed.xyz");
    let (positions, bytes) = translate_stream(Box::new(stream), 7, &out);
    assert_eq!(positions, whole.positions());
    let one = Box::new(XyzStream::open(&input).unwrap());
    let (_, want) = translate_stream(one, usize::MAX, &dir.path().join("one.xyz"));
    assert!(bytes == want);
    let shift = Vect::<3>::from(T);

    let spec = translate_spec(dir.path());
    let (_, output) = translate(dir.path(), &spec, &input, &[]).unwrap();
    let after = std::fs::read_to_string(&output).unwrap();
    let (a, b): (Vec<&str>, Vec<&str>) = (text.split('\n').collect(), after.split('\n').collect());
    assert_eq!(a.len(), b.len());
    for (before, after) in a.iter().zip(&b) {
        let words = |l: &str| {
            l.split([' ', ',', '\t'])
                .filter(|w| !w.is_empty())
                .skip(3)
                .map(str::to_string)
                .collect::<Vec<_>>()
        };
        if before.trim().is_empty() || before.starts_with('#') || before.starts_with("//") {
            assert_eq!(before, after);
        } else {
            assert_eq!(words(before), words(after), "{before:?} -> {after:?}");
        }
    }
    let moved_cli = Document::read(&output).unwrap();
    for (p, q) in whole.positions().iter().zip(moved_cli.positions()) {
        assert!((q - p - shift).norm() < 1e-9, "{p:?} -> {q:?}");
    }
}

/// Pass 1's preview proxy is every `stride`-th sample, within its bound, and its deformed copy
/// is what the output holds for those samples (to the LAS scale).
#[test]
fn the_preview_proxy_samples_the_input_and_the_output() {
    use rigidcells::internal::field::Transfer;
    use rigidcells::internal::pipeline::Options;
    use rigidcells::internal::progress::Silent;
    use rigidcells::internal::spec::read_spec;
    let dir = tempfile::tempdir().unwrap();
    let input = shared("las/autzen_trim.las");
    let (header, _, rest, _) = records(&input);
    let spec_path = dir.path().join("bend.toml");
    let (lo, hi) = (header.min, header.max);
    let w = hi[0] - lo[0];
    std::fs::write(
        &spec_path,
        data_gen::end_lift_spec(lo, hi, 0.2, 0.1 * w, 0.0),
    )
    .unwrap();
    let spec = read_spec::<3>(&spec_path).unwrap();
    let output = dir.path().join("bent.las");
    let max = 1000;
    let params = Options {
        transfer: Transfer::Blend,
        ..Default::default()
    }
    .params()
    .and_then(|p| p.with_proxy_samples(max))
    .unwrap();
    let outputs = rigidcells::internal::pipeline::Outputs {
        chunk: Some(4099),
        ..Default::default()
    };
    let (_, info, _) = rigidcells::internal::pipeline::deform_file_with(
        &input, &output, &spec, &params, &outputs, &Silent,
    )
    .unwrap();
    let proxy = &info.proxy;
    let n = rest.len() as u64;
    assert_eq!(proxy.stride, n.div_ceil(max as u64));
    assert!(proxy.stride > 1 && proxy.before.len() <= max);
    assert_eq!(proxy.before.len() as u64, n.div_ceil(proxy.stride));
    assert_eq!(proxy.after.len(), proxy.before.len());
    let (out_header, _, moved, _) = records(&output);
    let tolerance = 0.5 * out_header.scale.iter().cloned().fold(0.0, f64::max) + 1e-9;
    let mut lifted = 0;
    for (k, (b, a)) in proxy.before.iter().zip(&proxy.after).enumerate() {
        let i = k * proxy.stride as usize;
        assert_eq!(*b, rest[i], "sample {i} before");
        assert!((a - moved[i]).amax() <= tolerance, "sample {i} after");
        lifted += usize::from(a[2] - b[2] > 0.05 * w);
    }
    assert!(lifted > 0, "the proxy shows the edit");
}

/// `deform` warns about an edit that folds space over (a strip of a terrain pushed 900 m into
/// its fixed end) and not about one that only bends it.
#[test]
fn deform_warns_where_the_edit_folds_space_over() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.las");
    data_gen::write_las_terrain(&scan, 200_000, false).unwrap();
    let spec = |name: &str, handle: &str| {
        let path = dir.path().join(name);
        std::fs::write(
            &path,
            format!(
                "[[fixed]]\nbox = {{ min = [499999, 4999999, 0], max = [500300, 5002001, 200] }}\n\
                 [[handle]]\n{handle}\n"
            ),
        )
        .unwrap();
        path
    };
    let fold = spec(
        "fold.toml",
        "box = { min = [500900, 4999999, 0], max = [501100, 5002001, 200] }\n\
         translate = [-900, 0, 0]",
    );
    let bend = spec(
        "bend.toml",
        "box = { min = [501700, 4999999, 0], max = [502001, 5002001, 200] }\n\
         translate = [0, 0, 50]",
    );
    let output = dir.path().join("out.las");
    let folded = common::deform_verbose(&scan, &output, &fold, &["--transfer", "blend"]);
    assert_eq!(folded.code, 0, "{}", folded.stderr);
    assert!(
        folded.stderr.contains("folds space over"),
        "{}",
        folded.stderr
    );
    let bent = common::deform_verbose(&scan, &output, &bend, &["--transfer", "blend"]);
    assert_eq!(bent.code, 0, "{}", bent.stderr);
    assert!(!bent.stderr.contains("folds space over"), "{}", bent.stderr);
}

/// Digits after the point of a number in plain notation (`None`: an integer), or its
/// significant digits in exponent notation (`Some` with `true`).
fn precision_of(token: &str) -> Option<(usize, bool)> {
    let token = token.trim_start_matches(['-', '+']);
    if let Some(e) = token.find(['e', 'E']) {
        let mantissa: String = token[..e].chars().filter(|c| *c != '.').collect();
        return Some((mantissa.trim_start_matches('0').len().max(1), true));
    }
    token.find('.').map(|p| (token.len() - p - 1, false))
}

/// The number tokens of a text mesh or point cloud, per line: the first `n` after the keyword
/// of `v` (and `vn`) lines of an OBJ, of vertex lines of an ASCII PLY, of point lines of an
/// XYZ. Each line's tokens come with the column of the first.
fn coordinate_tokens(text: &str, name: &str, n: usize) -> Vec<(usize, Vec<String>)> {
    let words = |l: &str, skip: usize| -> Vec<String> {
        l.split([' ', '\t', ','])
            .filter(|w| !w.is_empty())
            .skip(skip)
            .take(n)
            .map(str::to_string)
            .collect()
    };
    if name.ends_with(".obj") {
        text.lines()
            .filter_map(|l| match l.split_whitespace().next() {
                Some("v") => Some((0, words(l, 1))),
                Some("vn") => Some((3, words(l, 1))),
                _ => None,
            })
            .collect()
    } else if name.ends_with(".ply") {
        let vertices: usize = text
            .lines()
            .find_map(|l| l.strip_prefix("element vertex "))
            .unwrap()
            .trim()
            .parse()
            .unwrap();
        text.lines()
            .skip_while(|l| *l != "end_header")
            .skip(1)
            .take(vertices)
            .map(|l| (0, words(l, 0)))
            .collect()
    } else {
        text.lines()
            .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
            .map(|l| (0, words(l, 0)))
            .collect()
    }
}

#[test]
fn outputs_name_rigidcells_and_text_numbers_keep_the_inputs_precision() {
    let dir = tempfile::tempdir().unwrap();
    let spec = translate_spec(dir.path());
    // LAS through the raw sink and LAZ through the `las` writer: the generating software is
    // ours, the system identifier the input's.
    for name in ["las/autzen_trim.las", "las/autzen_trim.laz"] {
        let input = shared(name);
        let (_, output) = translate(dir.path(), &spec, &input, &[]).unwrap();
        let (before, _, _, _) = common::records(&input);
        let (after, _, _, _) = common::records(&output);
        assert_eq!(after.software, rigidcells::internal::io::SOFTWARE, "{name}");
        assert_eq!(after.system, before.system, "{name}");
    }
    // A text cloud made here: plain numbers of 3 and 1 decimals in x, of 2 decimals and
    // integers in y, exponent notation of 2 and 4 significant digits in z.
    let cloud = dir.path().join("cloud.xyz");
    let mut text = String::new();
    for i in 0..400 {
        let f = i as f64;
        let x = match i % 2 {
            0 => format!("{:.3}", f * 0.011),
            _ => format!("{:.1}", f * 0.1),
        };
        let y = match i % 4 {
            0 => format!("{}", i % 9),
            _ => format!("{:.2}", f * 0.07),
        };
        let z = match i % 3 {
            0 => format!("{:.1e}", 1.0 + f),
            _ => format!("{:.3E}", 0.5 + f * 0.01),
        };
        text += &format!("{x} {y} {z} 7\n");
    }
    std::fs::write(&cloud, text).unwrap();
    // Every coordinate (and normal) a rotation moves (the right of the shape turned by 10°, the
    // left fixed) is written with the decimals of its column, or in exponent notation with the
    // significant digits of the column's numbers in that notation; one of a column of
    // integers, as the shortest text that reads back as it. Numbers that did not move keep
    // their text.
    let inputs = [
        shared("meshes/spot.obj"),
        shared("meshes/tree1.obj"),
        shared("meshes/Wuson.ply"),
        shared("meshes/dragon_21k_ascii.ply"),
        cloud,
    ];
    for input in inputs {
        let name = input.file_name().unwrap().to_str().unwrap().to_string();
        let doc = Document::read(&input).unwrap();
        let (lo, hi) = doc.positions().iter().fold(
            (
                Vect::<3>::repeat(f64::INFINITY),
                Vect::<3>::repeat(f64::NEG_INFINITY),
            ),
            |(lo, hi), p| (lo.inf(p), hi.sup(p)),
        );
        let (left, right) = (lo[0] + 0.3 * (hi[0] - lo[0]), hi[0] - 0.3 * (hi[0] - lo[0]));
        let mid = 0.5 * (lo[0] + hi[0]);
        let turn = dir.path().join("turn.toml");
        std::fs::write(
            &turn,
            format!(
                "[[fixed]]\nbox = {{ min = [-1e9, -1e9, -1e9], max = [{left}, 1e9, 1e9] }}\n\
                 [[handle]]\nbox = {{ min = [{right}, -1e9, -1e9], max = [1e9, 1e9, 1e9] }}\n\
                 rotate = {{ axis = [1, 2, 3], degrees = 10, center = [{mid}, 0, 0] }}\n"
            ),
        )
        .unwrap();
        let output = dir.path().join(format!("turned_{name}"));
        let r = deform(&input, &output, &turn, &["--transfer", "blend"]);
        assert_eq!(r.code, 0, "{name}: {}", r.stderr);
        let before = std::fs::read_to_string(&input).unwrap();
        let after = std::fs::read_to_string(&output).unwrap();
        let (a, b) = (
            coordinate_tokens(&before, &name, 6),
            coordinate_tokens(&after, &name, 6),
        );
        assert_eq!(a.len(), b.len(), "{name}");
        // The most decimals (plain) and significant digits (exponent) of each input column.
        let mut most = [[None::<usize>; 2]; 6];
        for (first, tokens) in &a {
            for (k, t) in tokens.iter().enumerate() {
                if let Some((d, exp)) = precision_of(t) {
                    let slot = &mut most[first + k][usize::from(exp)];
                    *slot = Some(slot.map_or(d, |m| m.max(d)));
                }
            }
        }
        let mut moved = 0;
        for ((first, old), (_, new)) in a.iter().zip(&b) {
            for (k, (o, n)) in old.iter().zip(new).enumerate() {
                if o == n {
                    continue;
                }
                moved += 1;
                // Exponent notation only where the column has numbers in it.
                let exp = n.contains(['e', 'E']);
                match most[first + k][usize::from(exp)] {
                    Some(want) => assert_eq!(
                        precision_of(n).map(|p| p.0),
                        Some(want),
                        "{name}: `{o}` -> `{n}` in column {}",
                        first + k
                    ),
                    None => {
                        let v: f64 = n.parse().unwrap();
                        let shortest = [format!("{v}"), format!("{}", v as f32)];
                        assert!(shortest.contains(n), "{name}: `{o}` -> `{n}`");
                    }
                }
            }
        }
        assert!(moved > 100, "{name}: {moved} numbers moved");
        // The file grows by no more than the few digits some numbers gain.
        assert!(
            after.len() as f64 <= 1.05 * before.len() as f64,
            "{name}: {} -> {} bytes",
            before.len(),
            after.len()
        );
    }
}

/// A legacy LAS header counts returns 1 to 5; a scan with returns 6 and 7 is written as LAS 1.4
/// by a LAZ output. `deform` learns it in pass 1; `apply` reads no pass 1, so its first writer
/// meets the records only halfway and the output is made again by a writer for them. Both give
/// the same records, and an output coordinate past the input's frame (a 1e7 m lift) gets a new
/// offset in a plain LAS, a LAZ and a COPC alike.
#[test]
fn outputs_are_made_again_for_what_the_records_hold() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("returns.las");
    data_gen::write_las_terrain(&input, 20_000, false).unwrap();
    let h = LasHeader::read(&input).unwrap();
    let (off, rl) = (h.point_offset as usize, h.record_len as usize);
    let mut bytes = std::fs::read(&input).unwrap();
    for i in (12_000..20_000).step_by(97) {
        // Return 6 (or 7) of 7.
        bytes[off + i * rl + 14] = (6 + (i % 2) as u8) | 7 << 3;
    }
    std::fs::write(&input, &bytes).unwrap();
    let p = |p: &Path| p.to_str().unwrap().to_string();
    // The east edge lifted 5 m (the west edge fixed); the whole scan lifted 1e7 m.
    let fixed =
        "[[fixed]]\nbox = { min = [499990, 4999990, -100], max = [500300, 5002010, 1000] }\n";
    for (lift, west, outputs) in [
        (5.0, 501700, &["d.laz", "a.laz", "a.las"][..]),
        (1e7, 499990, &["d.las", "d.laz", "d.copc.laz"][..]),
    ] {
        let spec = dir.path().join("lift.toml");
        std::fs::write(
            &spec,
            format!(
                "{}[[handle]]\nbox = {{ min = [{west}, 4999990, -100], max = [502010, 5002010, 1000] }}\n\
                 translate = [0, 0, {lift}]\n",
                if lift < 1e3 { fixed } else { "" }
            ),
        )
        .unwrap();
        let field = dir.path().join("lift.field");
        let mut reference = None;
        for name in outputs {
            let out = dir.path().join(name);
            let r = if name.starts_with('a') {
                run(&["apply", &p(&field), &p(&input), "-o", &p(&out)])
            } else {
                let f = p(&field);
                common::deform_verbose(&input, &out, &spec, &["--cells", "300", "--save-field", &f])
            };
            assert_eq!(r.code, 0, "{name}: {}", r.stderr);
            // Notes are a part of the summary, on stdout.
            let said = |what: &str| r.stdout.contains(what);
            let (header, raw, pos, out_rl) = records(&out);
            let laz = name.ends_with(".laz") && !name.contains("copc");
            if lift == 5.0 && laz {
                assert_eq!(header.version, (1, 4), "{name}");
                assert!(said("the output header is LAS 1.4"), "{name}: {}", r.stdout);
            }
            if lift == 1e7 {
                assert!(
                    said("overflow the input's encoding"),
                    "{name}: {}",
                    r.stdout
                );
                let top = pos.iter().map(|q| q[2]).fold(f64::MIN, f64::max);
                assert!((top - 1e7).abs() < 1e3, "{name}: top {top}");
            }
            // The same points (a COPC reorders them and converts the records).
            let mut pos = pos;
            pos.sort_by(|a, b| a.iter().partial_cmp(b.iter()).unwrap());
            let returns: Vec<u8> = raw.chunks_exact(out_rl).map(|r| r[14] & 7).collect();
            match &reference {
                None => reference = Some((pos, returns)),
                Some((p0, r0)) => {
                    assert_eq!(&pos, p0, "{name}");
                    if !name.contains("copc") {
                        assert_eq!(&returns, r0, "{name}");
                    }
                }
            }
        }
    }
}

/// The data of the LASzip VLR of the LAZ file `bytes`.
fn laszip_vlr(bytes: &[u8]) -> usize {
    let u16_at = |at: usize| u16::from_le_bytes([bytes[at], bytes[at + 1]]) as usize;
    let mut at = u16_at(94);
    for _ in 0..u32::from_le_bytes(bytes[100..104].try_into().unwrap()) {
        if bytes[at + 2..at + 16] == *b"laszip encoded" {
            return at + 54;
        }
        at += 54 + u16_at(at + 20);
    }
    panic!("no LASzip VLR")
}

/// LAZ files whose LASzip VLR names what no LAZ version defines (an item type, an item
/// version, a compressor, a coder) are refused (exit 3) in words that say what the file holds
/// and why it cannot be read, naming the file once: LASzip's three test files and two made
/// here, through `deform` and `info`.
#[test]
fn laz_errors_say_what_the_file_holds() {
    let dir = tempfile::tempdir().unwrap();
    let spec = translate_spec(dir.path());
    let mut item22 = std::fs::read(shared("las/point10.laz")).unwrap();
    let at = laszip_vlr(&item22) + 34;
    item22[at..at + 2].copy_from_slice(&22u16.to_le_bytes());
    let mut version7 = std::fs::read(shared("las/autzen_trim.laz")).unwrap();
    let at = laszip_vlr(&version7) + 34 + 4;
    version7[at..at + 2].copy_from_slice(&7u16.to_le_bytes());
    let (item22_path, version7_path) = (dir.path().join("item22.laz"), dir.path().join("v7.laz"));
    std::fs::write(&item22_path, item22).unwrap();
    std::fs::write(&version7_path, version7).unwrap();
    let newer = "the file is damaged or was written by a newer tool";
    let cases = [
        (
            item22_path,
            "its LAZ compression uses item type 22, which no LAZ version defines",
        ),
        (
            version7_path,
            "its LAZ compression stores its point fields (formats 0-5) in version 7 of their \
             encoding, which no LAZ version defines for them",
        ),
        (
            shared("malformed/broken_version.laz"),
            "stores its point fields (formats 0-5) in version 6 of their encoding",
        ),
        (
            shared("malformed/broken_compressor.laz"),
            "its LAZ compression names compressor 16, which no LAZ version defines",
        ),
        (
            shared("malformed/broken_coder.laz"),
            "its LAZ compression uses coder 15, which no LAZ version defines",
        ),
    ];
    for (input, words) in cases {
        let name = input.file_name().unwrap().to_str().unwrap().to_string();
        let output = dir.path().join("out.laz");
        let info = run(&["info", input.to_str().unwrap()]);
        for r in [deform(&input, &output, &spec, &[]), info] {
            assert_eq!(r.code, 3, "{name}: {}", r.stderr);
            assert!(r.stderr.contains(words), "{name}: {}", r.stderr);
            assert!(r.stderr.contains(newer), "{name}: {}", r.stderr);
            assert_eq!(r.stderr.matches(&name).count(), 1, "{name}: {}", r.stderr);
            assert!(!r.stderr.contains("LAZ:"), "{name}: {}", r.stderr);
            assert!(!output.exists(), "{name}");
        }
    }
}

/// A PLY element that declares two properties of one name (or two elements of one name) is a
/// format error (exit 3): its values are found by name, so one property was read in place of
/// the other, the records misread, and the normals came out as NaN.
#[test]
fn a_ply_that_declares_a_name_twice_is_a_format_error() {
    let dir = tempfile::tempdir().unwrap();
    let spec = translate_spec(dir.path());
    // Three vertices of 7 floats (the last a NaN where a quality is unknown) and a triangle.
    let mut body = Vec::new();
    for p in [[0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for v in p.iter().chain(&[0.0, 0.0, 1.0, f32::NAN]) {
            body.extend_from_slice(&v.to_le_bytes());
        }
    }
    body.push(3);
    for i in [0i32, 1, 2] {
        body.extend_from_slice(&i.to_le_bytes());
    }
    let header = |props: &str, more: &str| {
        let mut bytes = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex 3\n{props}element face 1\n\
             property list uchar int vertex_indices\n{more}end_header\n"
        )
        .into_bytes();
        bytes.extend_from_slice(&body);
        bytes
    };
    let props = |last: &str| {
        format!(
            "property float x\nproperty float y\nproperty float z\nproperty float nx\n\
             property float ny\nproperty float nz\nproperty float {last}\n"
        )
    };
    let cases = [
        (
            "twice.ply",
            header(&props("nx"), ""),
            "element `vertex` has two properties named `nx`",
        ),
        (
            "elements.ply",
            header(&props("quality"), "element face 0\nproperty uchar flag\n"),
            "two elements are named `face`",
        ),
    ];
    for (name, text, words) in cases {
        let input = dir.path().join(name);
        std::fs::write(&input, text).unwrap();
        let output = dir.path().join(format!("out_{name}"));
        let r = deform(&input, &output, &spec, &[]);
        assert_eq!(r.code, 3, "{name}: {}", r.stderr);
        assert!(r.stderr.contains(words), "{name}: {}", r.stderr);
        assert_eq!(r.stderr.matches(name).count(), 1, "{name}: {}", r.stderr);
        assert!(!output.exists(), "{name}");
    }
    // The same file without the second `nx` reads.
    let input = dir.path().join("once.ply");
    std::fs::write(&input, header(&props("quality"), "")).unwrap();
    let r = deform(&input, &dir.path().join("out_once.ply"), &spec, &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
}

/// A binary PLY grid of single-precision normals of every length: unit, 2, 0.5, zero, 1e37 per
/// component, and past what a float holds once turned.
fn normals_grid(path: &Path) -> (Vec<Vect<3>>, Vec<Vect<3>>) {
    let kinds = [
        [0.0, 0.0, 1.0],
        [0.0, 2.0, 0.0],
        [0.3, 0.4, 0.0],
        [0.0, 0.0, 0.0],
        [1e37, 0.0, 0.0],
        [1e37, 1e37, 1e37],
        [3e38, 3e38, 0.0],
        [0.6, 0.0, 0.8],
    ];
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    let mut body = Vec::new();
    for i in 0..21 {
        for j in 0..21 {
            for k in 0..3 {
                let p = [i as f32 / 20.0, j as f32 / 20.0, k as f32 / 20.0];
                let n: [f32; 3] = kinds[(i + j + k) % kinds.len()];
                for v in p.iter().chain(&n) {
                    body.extend_from_slice(&v.to_le_bytes());
                }
                points.push(Vect::<3>::from(p.map(f64::from)));
                normals.push(Vect::<3>::from(n.map(f64::from)));
            }
        }
    }
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\n\
         property float y\nproperty float z\nproperty float nx\nproperty float ny\n\
         property float nz\nend_header\n",
        points.len()
    )
    .into_bytes();
    bytes.extend_from_slice(&body);
    std::fs::write(path, bytes).unwrap();
    (points, normals)
}

/// Normals keep their length: the right end of a grid turned 30° about z (the left end fixed,
/// a free band between) turns each normal and keeps its length, whatever it is, with every
/// transfer; a zero normal stays zero, and huge single-precision normals stay finite (those
/// past what a float holds once turned are scaled down to fit, keeping their direction).
#[test]
fn normals_keep_their_length() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("grid.ply");
    let (points, normals) = normals_grid(&input);
    let spec = dir.path().join("turn.toml");
    std::fs::write(
        &spec,
        "[[fixed]]\nbox = { min = [-1, -1, -1], max = [0.2, 2, 2] }\n\
         [[handle]]\nbox = { min = [0.8, -1, -1], max = [2, 2, 2] }\n\
         rotate = { axis = [0, 0, 1], degrees = 30, center = [1, 0, 0] }\n",
    )
    .unwrap();
    let turn = nalgebra::Rotation3::from_axis_angle(&Vect::<3>::z_axis(), 30f64.to_radians());
    for transfer in ["blend", "rbf", "pu"] {
        let output = dir.path().join(format!("{transfer}.ply"));
        let r = deform(&input, &output, &spec, &["--transfer", transfer]);
        assert_eq!(r.code, 0, "{transfer}: {}", r.stderr);
        let out = Document::read(&output).unwrap();
        let (mut turned, mut free) = (0, 0);
        for ((p, n), m) in points.iter().zip(&normals).zip(out.normals().unwrap()) {
            let at = format!("{transfer}: {n:?} at {p:?} -> {m:?}");
            assert!(
                m.iter()
                    .all(|v| v.is_finite() && v.abs() <= f32::MAX as f64),
                "{at}"
            );
            let (a, b) = (n.norm(), m.norm());
            if a == 0.0 {
                assert_eq!(*m, *n, "{at}");
            } else if a > f32::MAX as f64 {
                // Scaled down to fit a float, in the direction it was turned to.
                assert!(b <= a && b > 0.5 * f32::MAX as f64, "{at}");
            } else {
                assert!((b - a).abs() <= 1e-6 * a, "{at}: length {a} -> {b}");
            }
            if p[0] >= 0.8 && a > 0.0 {
                let want = (turn * n).normalize();
                assert!((m / b - want).norm() < 1e-5, "{at}: turned");
                turned += 1;
            }
            free += usize::from(p[0] > 0.2 && p[0] < 0.8 && (m / b - n / a).norm() > 1e-3);
        }
        assert!(
            turned > 100 && free > 50,
            "{transfer}: {turned} turned, {free} free"
        );
    }
}
