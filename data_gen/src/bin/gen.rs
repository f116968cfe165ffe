//! `cargo run --release -p data_gen --bin gen -- terrain N OUT.las|OUT.laz|OUT.ply [ORDER]`: a
//! synthetic scan of N points (terrain, buildings, a bridge) for benchmarks and memory checks;
//! a LAS or LAZ scan's records `scan` (default), `shuffled` or sorted into 1 m `strips`.
//! `gen corridor N OUT.las|OUT.laz`: N points of a 1 km × 200 m road corridor, z over ~50 m
//! (the scale benchmark's large-extent scan).
//! `gen vegetation N OUT.las|OUT.laz`: a 1 km × 200 m strip of rolling ground under up to 3 m of
//! low vegetation, so that every cell is a boundary cell (the solver benchmark's scene).
//! `gen rough N OUT.las|OUT.laz [SPAN] [WAVELENGTH] [SEED]`: the vegetation strip over seeded
//! hills spanning SPAN metres (default 50) WAVELENGTH metres apart (default 100), steep enough
//! that the cells form a corrugated sheet (`data_gen::Relief`).
//! `gen tube OUT.ply`: the closed 480k-vertex tube of the `--cells 5500` benchmark
//! (10 × 2 × 2, wall 0.2; binary PLY).

fn main() {
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some(scene @ ("terrain" | "corridor" | "vegetation"))
            if args.len() == 4 || args.len() == 5 =>
        {
            let n: u64 = args[2].parse().expect("N is a point count");
            let out = std::path::Path::new(&args[3]);
            let order: data_gen::Order = match args.get(4) {
                Some(o) => o.parse().unwrap_or_else(|e| panic!("{e}")),
                None => data_gen::Order::Scan,
            };
            let ext = out
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase());
            let t = std::time::Instant::now();
            match ext.as_deref() {
                Some("ply") if scene == "terrain" => {
                    data_gen::write_ply_terrain(out, n).expect("writing the scan")
                }
                Some("ply") => panic!("the {scene} is written as LAS or LAZ"),
                ext => {
                    let terrain = match scene {
                        "corridor" => data_gen::Terrain::corridor(n),
                        "vegetation" => data_gen::Terrain::vegetation(n),
                        _ => data_gen::Terrain::new(n),
                    };
                    data_gen::write_las_ordered(out, terrain, n, ext == Some("laz"), order)
                        .expect("writing the scan")
                }
            }
            println!(
                "{n} points -> {} in {:.1} s",
                out.display(),
                t.elapsed().as_secs_f64()
            );
        }
        Some("rough") if (4..=7).contains(&args.len()) => {
            let n: u64 = args[2].parse().expect("N is a point count");
            let out = std::path::Path::new(&args[3]);
            let number = |i: usize, default: f64| {
                args.get(i).map_or(default, |a| {
                    a.parse().expect("SPAN and WAVELENGTH are metres")
                })
            };
            let seed = args
                .get(6)
                .map_or(1, |a| a.parse().expect("SEED is a number"));
            let relief = data_gen::Relief::new(number(4, 50.0), number(5, 100.0), seed);
            let laz = out
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("laz"));
            let t = std::time::Instant::now();
            data_gen::write_las(out, data_gen::Terrain::rough(n, relief), n, laz)
                .expect("writing the scan");
            println!(
                "{n} points -> {} in {:.1} s",
                out.display(),
                t.elapsed().as_secs_f64()
            );
        }
        Some("tube") if args.len() == 3 => {
            let out = std::path::Path::new(&args[2]);
            let mesh = data_gen::tube(10.0, 1.0, 0.8, 400, 599);
            data_gen::write_ply(out, &mesh, true).expect("writing the tube");
            println!("{} vertices -> {}", mesh.vertices.len(), out.display());
        }
        _ => {
            eprintln!(
                "usage: gen terrain N OUT.las|OUT.laz|OUT.ply [scan|shuffled|strips] | \
                 gen corridor|vegetation N OUT.las|OUT.laz [ORDER] | \
                 gen rough N OUT.las|OUT.laz [SPAN] [WAVELENGTH] [SEED] | gen tube OUT.ply"
            );
            std::process::exit(2);
        }
    }
}
