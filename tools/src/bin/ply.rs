//! Reading a binary PLY point cloud: `ply-rs-bw` against our header parse plus memory-mapped
//! fast path (`rigidcells::internal::io::PlyStream`) and our record walker (`PlyRecordStream`, which
//! checks every record as it opens, as when the file is read whole), on the same file in the
//! same run.
//!
//! `cargo run --release -p rigidcells-tools --bin ply [N]` writes a synthetic terrain of `N`
//! points (default 2 000 000; `ply-rs-bw` builds a hash map per vertex, so keep N moderate) as
//! binary PLY with double `x y z`, colors, class and intensity, then reads its positions with
//! each reader. Prints seconds, points/s and whether the positions agree.

use std::time::Instant;

use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property};
use rigidcells::Vect;
use rigidcells::internal::io::{Chunk, Document, PlyRecordStream, PlyStream, Source};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: u64 = std::env::args()
        .nth(1)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(2_000_000);
    let path = std::env::temp_dir().join(format!("rigidcells-ply-bench-{n}.ply"));
    data_gen::write_ply_terrain(&path, n)?;

    let t = Instant::now();
    let mut file = std::io::BufReader::with_capacity(1 << 20, std::fs::File::open(&path)?);
    let ply = Parser::<DefaultElement>::new().read_ply(&mut file)?;
    let value = |e: &DefaultElement, k: &str| match e.get(k) {
        Some(Property::Double(v)) => *v,
        Some(Property::Float(v)) => *v as f64,
        _ => f64::NAN,
    };
    let by_crate: Vec<Vect<3>> = ply.payload["vertex"]
        .iter()
        .map(|e| Vect::<3>::new(value(e, "x"), value(e, "y"), value(e, "z")))
        .collect();
    let t_crate = t.elapsed().as_secs_f64();
    drop(ply);

    let t = Instant::now();
    let mut stream = PlyStream::open(&path)?.ok_or("the file should stream")?;
    let mut chunk = Chunk::default();
    let mut streamed = Vec::with_capacity(n as usize);
    while stream.read(1 << 20, &mut chunk)? > 0 {
        streamed.extend_from_slice(&chunk.positions);
    }
    let t_stream = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let whole = Document::drain(&mut PlyRecordStream::open(&path)?)?;
    let t_whole = t.elapsed().as_secs_f64();

    let agree = by_crate == streamed && whole.positions() == &streamed[..];
    std::fs::remove_file(&path)?;
    println!("binary PLY, {n} points (double x y z, rgb, class, intensity)");
    println!("| reader | seconds | points/s | vs ply-rs-bw |\n|---|---|---|---|");
    for (name, s) in [
        ("ply-rs-bw read_ply", t_crate),
        ("PlyStream (header + mmap fast path)", t_stream),
        ("PlyRecordStream (record walker)", t_whole),
    ] {
        println!(
            "| {name} | {s:.3} | {:.2e} | {:.1}× |",
            n as f64 / s,
            t_crate / s
        );
    }
    println!("positions agree: {agree}");
    if !agree {
        return Err("the readers disagree".into());
    }
    Ok(())
}
