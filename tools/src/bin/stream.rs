//! Streaming throughput: `deform` with blend on a LAS/LAZ file against a plain read-and-write
//! copy with the `las` crate, in the same run.
//!
//! `cargo run --release -p rigidcells-tools --bin stream -- FILE.las|laz [EDIT.toml]`
//! (default edit: fix the western 15 %, lift and turn the eastern 15 %).

use std::path::{Path, PathBuf};
use std::time::Instant;

use las::{Builder, LazParallelism, PointDataBuilder, ReaderOptions, WriterOptions};
use rigidcells::Silent;
use rigidcells::Transfer;
use rigidcells::{Options, deform_file};
use rigidcells::{parse_spec, read_spec};

/// Points per batch of the plain copy: its fastest (the crate decompresses and compresses the
/// LAZ chunks of a batch in parallel; 64k-point batches made the LAZ copy 45 % slower).
const COPY_CHUNK: u64 = 1 << 20;

/// A plain copy of `input` into `output` with the `las` crate; with `sync`, the output is
/// flushed to disk before returning, as `deform` does before renaming its temporary file.
fn plain_copy(input: &Path, output: &Path, sync: bool) -> u64 {
    let opts = ReaderOptions::default().with_laz_parallelism(LazParallelism::Yes);
    let file = std::io::BufReader::with_capacity(1 << 20, std::fs::File::open(input).unwrap());
    let mut r = las::Reader::with_options(file, opts).unwrap();
    let mut b = Builder::from(r.header().clone());
    b.point_format.is_compressed = output.extension().is_some_and(|e| e == "laz");
    b.vlrs
        .retain(|v| !(v.user_id == "laszip encoded" && v.record_id == 22204));
    let out = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(output).unwrap());
    let mut w = las::Writer::with_options(
        out,
        b.into_header().unwrap(),
        WriterOptions::default().with_laz_parallelism(LazParallelism::Yes),
    )
    .unwrap();
    let mut pd = PointDataBuilder::new().for_header(r.header()).build();
    let mut n = 0;
    while r.fill_points(COPY_CHUNK, &mut pd).unwrap() > 0 {
        n += pd.len() as u64;
        w.write_points(&pd).unwrap();
    }
    w.close().unwrap();
    let out = w.into_inner().unwrap();
    if sync {
        out.into_inner().unwrap().sync_all().unwrap();
    }
    n
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let input = PathBuf::from(args.get(1).expect("usage: stream FILE.las|laz [EDIT.toml]"));
    let ext = input.extension().unwrap().to_str().unwrap().to_string();
    let dir = std::env::temp_dir();
    let spec = match args.get(2) {
        Some(p) => read_spec::<3>(Path::new(p)).unwrap(),
        None => {
            let h = rigidcells::internal::io::LasHeader::read(&input).unwrap();
            let w = h.max[0] - h.min[0];
            let text = data_gen::end_lift_spec(h.min, h.max, 0.15, 0.025 * w, -10.0);
            parse_spec::<3>(&text, Path::new("."), Path::new("<default edit>")).unwrap()
        }
    };
    let copy_out = dir.join(format!("rigidcells-stream-copy.{ext}"));
    let out = dir.join(format!("rigidcells-stream-deform.{ext}"));
    let params = Options {
        transfer: Transfer::Blend,
        ..Default::default()
    }
    .params()
    // As the CLI: a proxy for the fold-over check.
    .and_then(|p| p.with_proxy_samples(rigidcells::internal::pipeline::FOLDOVER_SAMPLES))
    .unwrap();
    // Alternating runs, medians reported: the copy writes as many bytes as the deform and its
    // time swings with page-cache writeback. `deform` syncs its output before the rename (so
    // that a crash never leaves a file under the output's name that is not whole), so the copy
    // is timed both ways.
    let (mut copies, mut synced, mut deforms, mut n, mut last) =
        (Vec::new(), Vec::new(), Vec::new(), 0, None);
    for _ in 0..RUNS {
        for (sync, times) in [(false, &mut copies), (true, &mut synced)] {
            let t = Instant::now();
            n = plain_copy(&input, &copy_out, sync);
            times.push(t.elapsed().as_secs_f64());
            let _ = std::fs::remove_file(&copy_out);
        }
        let t = Instant::now();
        let (_, info) = deform_file(&input, &out, &spec, &params, &Silent).unwrap();
        deforms.push(t.elapsed().as_secs_f64());
        let _ = std::fs::remove_file(&out);
        last = Some(info);
    }
    let info = last.expect("RUNS > 0");
    let (copy_s, synced_s, deform_s) = (
        median(&mut copies),
        median(&mut synced),
        median(&mut deforms),
    );
    println!(
        "{} ({n} points), {} threads, median of {RUNS} alternating runs",
        input.display(),
        rayon::current_num_threads()
    );
    println!("| run | seconds (runs) | points/s |\n|---|---|---|");
    println!(
        "| plain copy (las crate) | {copy_s:.2} ({}) | {:.2e} |",
        list(&copies),
        n as f64 / copy_s
    );
    println!(
        "| plain copy (las crate), synced to disk | {synced_s:.2} ({}) | {:.2e} |",
        list(&synced),
        n as f64 / synced_s
    );
    println!(
        "| deform, blend (last run: pass 1 {:.2} s, solve {:.2} s, pass 2 {:.2} s) | {deform_s:.2} ({}) | {:.2e} |",
        info.seconds_read,
        info.deform.solver.seconds,
        info.seconds_write,
        list(&deforms),
        n as f64 / deform_s
    );
    println!(
        "deform / copy throughput: {:.2} (against the synced copy: {:.2})",
        copy_s / deform_s,
        synced_s / deform_s
    );
}

const RUNS: usize = 3;

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn list(v: &[f64]) -> String {
    v.iter()
        .map(|s| format!("{s:.2}"))
        .collect::<Vec<_>>()
        .join(", ")
}
