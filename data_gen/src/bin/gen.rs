//! `cargo run --release -p data_gen --bin gen -- terrain N OUT.las|OUT.laz`: a synthetic scan of
//! N points (terrain, buildings, a bridge) for benchmarks and memory checks.

fn main() {
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some("terrain") if args.len() == 4 => {
            let n: u64 = args[2].parse().expect("N is a point count");
            let out = std::path::Path::new(&args[3]);
            let laz = out
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("laz"));
            let t = std::time::Instant::now();
            data_gen::write_las_terrain(out, n, laz).expect("writing the scan");
            println!(
                "{n} points -> {} in {:.1} s",
                out.display(),
                t.elapsed().as_secs_f64()
            );
        }
        _ => {
            eprintln!("usage: gen terrain N OUT.las|OUT.laz");
            std::process::exit(2);
        }
    }
}
