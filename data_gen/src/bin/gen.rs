//! `cargo run --release -p data_gen --bin gen -- terrain N OUT.las|OUT.laz|OUT.ply`: a synthetic
//! scan of N points (terrain, buildings, a bridge) for benchmarks and memory checks.

fn main() {
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some("terrain") if args.len() == 4 => {
            let n: u64 = args[2].parse().expect("N is a point count");
            let out = std::path::Path::new(&args[3]);
            let ext = out
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase());
            let t = std::time::Instant::now();
            match ext.as_deref() {
                Some("ply") => data_gen::write_ply_terrain(out, n).expect("writing the scan"),
                Some("laz") => data_gen::write_las_terrain(out, n, true).expect("writing the scan"),
                _ => data_gen::write_las_terrain(out, n, false).expect("writing the scan"),
            }
            println!(
                "{n} points -> {} in {:.1} s",
                out.display(),
                t.elapsed().as_secs_f64()
            );
        }
        _ => {
            eprintln!("usage: gen terrain N OUT.las|OUT.laz|OUT.ply");
            std::process::exit(2);
        }
    }
}
