//! COPC out: `-o out.copc.laz` writes a valid COPC — LAS 1.4, the info VLR first,
//! the hierarchy EVLR, one LAZ chunk per octree node, the CRS kept — holding exactly the
//! records of the plain LAZ output, read back by our reader and by laspy's `CopcReader`.

mod common;

use common::{arg, deform, records, shared};
use rigidcells::internal::io::{Chunk, LasSource, Source};

/// Every record's position, classification, intensity and color, sorted (COPC reorders the
/// points and may change the point format).
#[allow(clippy::type_complexity)]
fn sorted(path: &std::path::Path) -> Vec<([i64; 3], u8, [u8; 2], [u16; 3])> {
    let mut src = LasSource::open(path).unwrap();
    let header = src.header().clone();
    let mut chunk = Chunk::default();
    let mut out = Vec::new();
    while src.read(50_000, &mut chunk).unwrap() > 0 {
        let records = chunk.raw.chunks_exact(chunk.record_len);
        for ((p, c), rec) in chunk.positions.iter().zip(&chunk.classes).zip(records) {
            out.push((
                [0, 1, 2].map(|a| (p[a] * 100.0).round() as i64),
                *c,
                [rec[12], rec[13]],
                header.color(rec),
            ));
        }
    }
    out.sort_unstable();
    out
}

fn le_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

fn le_u64(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

#[test]
fn copc_out_holds_the_plain_outputs_records_in_octree_nodes() {
    let dir = tempfile::tempdir().unwrap();
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [636000, 848900, 0], max = [636300, 849500, 1000] }\n\
         [[handle]]\nbox = { min = [636900, 848900, 0], max = [637200, 849500, 1000] }\n\
         translate = [0, 0, 5]\n",
    )
    .unwrap();
    for input in ["las/autzen_trim.laz", "las/1.2-with-color.copc.laz"] {
        let input = shared(input);
        let (plain, copc) = (dir.path().join("o.laz"), dir.path().join("o.copc.laz"));
        for out in [&plain, &copc] {
            let r = deform(&input, out, &edit, &["--cells", "500"]);
            assert_eq!(r.code, 0, "{}", r.stderr);
        }
        // The same records (positions and classes; COPC stores them in octree order).
        assert_eq!(sorted(&plain), sorted(&copc), "{}", input.display());
        let bytes = std::fs::read(&copc).unwrap();
        assert_eq!(&bytes[24..26], &[1, 4]);
        assert!(matches!(bytes[104] & 0x3f, 6..=8));
        // The COPC info VLR comes first, right after the 375-byte header.
        assert_eq!(&bytes[375 + 2..375 + 6], b"copc");
        assert_eq!(u16::from_le_bytes([bytes[375 + 18], bytes[375 + 19]]), 1);
        // The hierarchy EVLR: where the info says, entries of 32 bytes whose chunks lie in the
        // point data and whose counts add up to the points.
        let info = 375 + 54;
        let (at, len) = (
            le_u64(&bytes, info + 40) as usize,
            le_u64(&bytes, info + 48) as usize,
        );
        assert_eq!(&bytes[at - 60 + 2..at - 60 + 6], b"copc");
        assert_eq!(len % 32, 0);
        let offset = le_u32(&bytes, 96) as u64;
        let mut total = 0u64;
        for e in bytes[at..at + len].chunks_exact(32) {
            let (chunk_at, size, count) = (
                le_u64(e, 16),
                i32::from_le_bytes(e[24..28].try_into().unwrap()),
                i32::from_le_bytes(e[28..32].try_into().unwrap()),
            );
            assert!(chunk_at > offset && size > 0 && count > 0);
            assert!(chunk_at + size as u64 <= at as u64);
            total += count as u64;
        }
        assert_eq!(total, le_u64(&bytes, 247));
        // The CRS is kept.
        let (h, _, _, _) = records(&copc);
        assert!(h.vlrs.iter().any(|v| v.is_crs()));
        // A third-party reader, where one is installed (CI installs laspy and lazrs).
        check_with_laspy(&copc);
    }
}

/// Runs `tests/copc_check.py` with `$RIGIDCELLS_PYTHON` (CI's venv) or a `python3` that has
/// laspy and lazrs; says so and returns when none has them.
fn check_with_laspy(copc: &std::path::Path) {
    check_with_laspy_and_crs(copc, None);
}

/// [`check_with_laspy`], which with `epsg` also checks that the CRS is a WKT of that code.
fn check_with_laspy_and_crs(copc: &std::path::Path, epsg: Option<u32>) {
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/copc_check.py");
    let python = std::env::var("RIGIDCELLS_PYTHON").ok();
    let required = python.is_some();
    let python = python.unwrap_or_else(|| "python3".into());
    let has = std::process::Command::new(&python)
        .args(["-c", "import laspy, lazrs"])
        .status()
        .is_ok_and(|s| s.success());
    if !has {
        assert!(!required, "{python} lacks laspy and lazrs");
        eprintln!("note: no python with laspy and lazrs; the COPC is checked by our reader only");
        return;
    }
    let out = std::process::Command::new(&python)
        .arg(&script)
        .arg(arg(copc))
        .args(epsg.map(|c| c.to_string()))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "laspy: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Every LAS/LAZ file of `../shared/data` (up to 200,000 points) written as a COPC holds the
/// records of its plain LAZ output — formats 0–5 moved to 6 or 7, 9 and 10 to 6 and 8 — and
/// passes laspy's checks where it is installed.
#[test]
fn every_las_file_becomes_a_valid_copc() {
    let dir = tempfile::tempdir().unwrap();
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        "[[handle]]\nplane = { point = [0, 0, 0], normal = [0, 0, 1e-4] }\ntranslate = [1.5, -2.25, 0.75]\n\
         [[handle]]\nplane = { point = [0, 0, 0], normal = [0, 0, -1e-4] }\ntranslate = [1.5, -2.25, 0.75]\n",
    )
    .unwrap();
    let mut checked = 0;
    let mut inputs: Vec<_> = std::fs::read_dir(shared("las"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    inputs.sort();
    for input in inputs {
        let Ok(header) = rigidcells::internal::io::LasHeader::read(&input) else {
            continue;
        };
        if header.count > 200_000 || header.version.1 > 4 {
            continue;
        }
        let (plain, copc) = (dir.path().join("o.laz"), dir.path().join("o.copc.laz"));
        for out in [&plain, &copc] {
            let r = deform(&input, out, &edit, &["--transfer", "blend"]);
            assert_eq!(r.code, 0, "{}: {}", input.display(), r.stderr);
        }
        assert_eq!(sorted(&plain), sorted(&copc), "{}", input.display());
        check_with_laspy(&copc);
        checked += 1;
    }
    assert!(checked >= 35, "{checked}");
}

/// A legacy LAS (formats 0-5) whose CRS is GeoTIFF keys naming an EPSG code becomes a COPC
/// (format 6-8) that states it as the WKT of that code: the global encoding's WKT bit set, a
/// WKT VLR naming the code, the keys kept. Keys that also name a vertical system keep it alone,
/// with a note; keys that name no code stay as they are, with a note; an input's own WKT is
/// kept as it is.
#[test]
fn copc_out_states_a_legacy_crs_as_wkt() {
    let dir = tempfile::tempdir().unwrap();
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        "[[handle]]\nbox = { min = [-1e12, -1e12, -1e12], max = [1e12, 1e12, 1e12] }\n\
         translate = [1, 0, 0]\n",
    )
    .unwrap();
    let wkt_of = |path: &std::path::Path| {
        let records = LasSource::open(path).unwrap().vlr_records();
        records
            .iter()
            .find(|r| r.is("LASF_Projection", 2112))
            .map(|r| r.data.clone())
    };
    // The input, the EPSG code its keys name, and what the summary notes.
    let cases = [
        (
            "las/certainty3d-color-utm-feet-navd88.las",
            Some(2229),
            None,
        ),
        ("las/epsg_4326.las", Some(4326), None),
        ("las/point-version-1-point-wise.laz", Some(32128), None),
        (
            "las/32-1-472-150-76.laz",
            Some(25832),
            Some("their vertical system, EPSG:5941, is in the keys only"),
        ),
        (
            "las/extra_byte.las",
            None,
            Some("kept as the input's GeoTIFF keys (they name no EPSG code"),
        ),
    ];
    for (name, code, note) in cases {
        let input = shared(name);
        let copc = dir.path().join("o.copc.laz");
        let r = common::deform_verbose(&input, &copc, &edit, &["--cells", "200"]);
        assert_eq!(r.code, 0, "{name}: {}", r.stderr);
        let bytes = std::fs::read(&copc).unwrap();
        let wkt_bit = u16::from_le_bytes([bytes[6], bytes[7]]) & 0x10 != 0;
        let records = LasSource::open(&copc).unwrap().vlr_records();
        assert!(
            records.iter().any(|r| r.is("LASF_Projection", 34735)),
            "{name}: the GeoTIFF keys are kept"
        );
        let crs = rigidcells::internal::info::crs(&records).unwrap();
        match code {
            Some(code) => {
                assert!(wkt_bit, "{name}: the WKT bit");
                assert_eq!((crs.from, crs.epsg), ("WKT", Some(code)), "{name}");
                let wkt = wkt_of(&copc).unwrap();
                assert_eq!(wkt.last(), Some(&0), "{name}: a null-terminated WKT");
                let text = String::from_utf8(wkt).unwrap();
                let authority = format!("AUTHORITY[\"EPSG\",\"{code}\"]]\0");
                assert!(text.ends_with(&authority), "{name}: {text}");
                check_with_laspy_and_crs(&copc, Some(code));
            }
            None => {
                assert!(!wkt_bit, "{name}: no WKT, no WKT bit");
                assert_eq!(crs.from, "GeoTIFF keys", "{name}");
                assert!(wkt_of(&copc).is_none(), "{name}");
            }
        }
        match note {
            Some(note) => assert!(r.stdout.contains(note), "{name}: {}", r.stdout),
            None => assert!(!r.stdout.contains("GeoTIFF"), "{name}: {}", r.stdout),
        }
    }
    // An input with a WKT of its own (and GeoTIFF keys) keeps it byte for byte.
    let input = shared("las/autzen_trim.las");
    let copc = dir.path().join("autzen.copc.laz");
    let r = deform(&input, &copc, &edit, &["--cells", "200"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let bytes = std::fs::read(&copc).unwrap();
    assert_ne!(u16::from_le_bytes([bytes[6], bytes[7]]) & 0x10, 0);
    assert_eq!(wkt_of(&copc), wkt_of(&input));
}

/// A COPC of a waveform file (point format 4, whose packets COPC's formats cannot hold) keeps
/// none of the records that describe or hold wave packets: the input's waveform packet
/// descriptor goes with the packets, and the other records stay.
#[test]
fn copc_of_a_waveform_file_keeps_no_waveform_records() {
    let dir = tempfile::tempdir().unwrap();
    let input = shared("las/fwf.laz");
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [433960, 103960, 0], max = [433985, 104040, 100] }\n\
         [[handle]]\nbox = { min = [434015, 103960, 0], max = [434040, 104040, 100] }\n\
         translate = [0, 0, 1]\n",
    )
    .unwrap();
    let waveform =
        |r: &&rigidcells::internal::io::VlrRecord| r.user_id == "LASF_Spec" && r.record_id >= 100;
    let before = LasSource::open(&input).unwrap().vlr_records();
    assert!(before.iter().any(|r| r.is("LASF_Spec", 100)));
    let copc = dir.path().join("o.copc.laz");
    let r = common::deform_verbose(&input, &copc, &edit, &["--cells", "300"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .contains("the wave packets of format 4 are dropped"),
        "{}",
        r.stdout
    );
    let after = LasSource::open(&copc).unwrap().vlr_records();
    let left: Vec<_> = after.iter().filter(waveform).collect();
    assert!(left.is_empty(), "{left:?}");
    for kept in before.iter().filter(|r| r.user_id == "LeicaGeo") {
        assert!(
            after.contains(kept),
            "{} {} kept",
            kept.user_id,
            kept.record_id
        );
    }
}
