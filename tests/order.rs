//! The records' order decides no output byte: a scan and the same records shuffled, deformed
//! or applied with any transfer, give the same record for each input record.

mod common;

use std::path::Path;

use common::{arg, deform, records, run, shared};

/// A copy of the LAS file `input` at `output` with its records in the order `perm` (record `k`
/// of the copy is record `perm[k]` of `input`); header, VLRs and anything after the records
/// are kept.
fn permuted_copy(input: &Path, output: &Path, perm: &[usize]) {
    let bytes = std::fs::read(input).unwrap();
    let (header, raw, _, len) = records(input);
    let start = header.point_offset as usize;
    let end = start + raw.len();
    let mut out = bytes[..start].to_vec();
    for &i in perm {
        out.extend_from_slice(&raw[i * len..(i + 1) * len]);
    }
    out.extend_from_slice(&bytes[end..]);
    std::fs::write(output, out).unwrap();
}

/// A permutation of `0..n` (xorshift, Fisher–Yates).
fn shuffle(n: usize) -> Vec<usize> {
    let mut perm: Vec<usize> = (0..n).collect();
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    for i in (1..n).rev() {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        perm.swap(i, (x % (i as u64 + 1)) as usize);
    }
    perm
}

/// The records of `shuffled` (made with `perm`) put back into the order of the original.
fn unshuffled(shuffled: &Path, perm: &[usize]) -> Vec<u8> {
    let (_, raw, _, len) = records(shuffled);
    let mut back = vec![0u8; raw.len()];
    for (k, &i) in perm.iter().enumerate() {
        back[i * len..(i + 1) * len].copy_from_slice(&raw[k * len..(k + 1) * len]);
    }
    back
}

#[test]
fn shuffled_records_deform_and_apply_to_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let input = shared("las/autzen_trim.las");
    let n = records(&input).2.len();
    let perm = shuffle(n);
    let shuffled = dir.path().join("shuffled.las");
    permuted_copy(&input, &shuffled, &perm);
    // The west fifth fixed, the east fifth turned and lifted; the rest bends.
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [636000, 848930, 300], max = [636240, 849500, 600] }\n\
         [[handle]]\nbox = { min = [636940, 848930, 300], max = [637180, 849500, 600] }\n\
         translate = [0, 0, 20]\nrotate = { axis = [0, 1, 0], degrees = 5 }\n",
    )
    .unwrap();
    // A given cell size: `--cells N` searches on the first sample of each voxel in file order.
    let size = ["--cell-size", "12"];
    let (a, b) = (dir.path().join("a.las"), dir.path().join("b.las"));
    let field = dir.path().join("f.field");
    let done = deform(
        &input,
        &a,
        &edit,
        &[&size[..], &["--save-field", arg(&field)]].concat(),
    );
    assert_eq!(done.code, 0, "{}", done.stderr);
    let done = deform(&shuffled, &b, &edit, &size);
    assert_eq!(done.code, 0, "{}", done.stderr);
    let original = records(&a).1;
    assert_eq!(unshuffled(&b, &perm), original, "deform");
    // The rest pose's records differ from the output's: the test sees the edit.
    assert_ne!(records(&input).1, original);
    for transfer in ["pu", "blend", "rbf", "blend-idw"] {
        let (a, b) = (dir.path().join("pa.las"), dir.path().join("pb.las"));
        for (from, to) in [(&input, &a), (&shuffled, &b)] {
            let done = run(&[
                "apply",
                arg(&field),
                arg(from),
                "-o",
                arg(to),
                "--transfer",
                transfer,
                "-q",
            ]);
            assert_eq!(done.code, 0, "{transfer}: {}", done.stderr);
        }
        assert_eq!(
            unshuffled(&b, &perm),
            records(&a).1,
            "apply --transfer {transfer}"
        );
    }
}
