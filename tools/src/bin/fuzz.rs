//! A mutation fuzzer for the command line: no file, edit spec or parameter may make
//! `rigidcells` panic, abort, hang, leave a file behind, change its input, write NaN or exit
//! with a code other than the documented one.
//!
//! ```text
//! cargo build --release --bin rigidcells
//! cargo run --release -p rigidcells-tools --bin fuzz -- [--cases N] [--seed S] [--jobs J]
//!     [--timeout SECONDS] [--memory MIB] [--bin PATH] [--data DIR] [--work DIR]
//!     [--keep DIR] [--case I] [--max-seed BYTES] [-v]
//! ```
//!
//! **Seeds.** Every file of `../shared/data` (`las/`, `meshes/`, `malformed/`) up to
//! `--max-seed` bytes, and seeds generated here: the demo's bar, soup and picture, the bar as
//! OBJ and XYZ, a 2D point set, a LAS and a LAZ terrain, and fields saved by `deform
//! --save-field` with each transfer. Each readable seed gets edit specs made from its
//! bounds (end lifts and turns, pins, targets, spheres, planes, classifications, stiffness).
//!
//! **Cases.** Case `I` of seed `S` is drawn from a generator seeded by `(S, I)` alone, so any
//! case runs again by itself with `--case I`. A case is one of:
//! - `file`: the input's bytes mutated (bit flips, interesting values in LAS header, VLR and
//!   LAZ fields, in a PNG's IHDR with its CRC fixed, anywhere in a binary body; numbers,
//!   lines and PLY header words in text; truncation, splices with another seed of the format,
//!   duplicated and deleted spans), run through `deform`, `info`, `render`, `cells` or `image`;
//! - `spec`: a valid input, the edit spec mutated (numbers, lines, keys, truncation, bytes that
//!   are not UTF-8, target CSVs and index files that are malformed or missing, huge turns);
//! - `param`: a valid input and spec, command-line values mutated (zero, negative, NaN, huge,
//!   unparsable);
//! - `field`: a saved field's bytes mutated (non-finite and extreme numbers, counts), applied.
//!
//! Each case runs the binary as a child in a folder of its own, in a process group of its own,
//! under an address-space limit (`--memory`, `RLIMIT_AS`) and a timeout, and is classified:
//!
//! | class | meaning | bad |
//! |---|---|---|
//! | success | exit 0, outputs readable and finite | |
//! | clean error | a documented exit code with a message | |
//! | hang | not finished within `--timeout` (10 s: the largest legitimate requests the cases make, a millimetre `--cell-size` on a terrain tile or a `--min-cell-size` that builds half a million cells, take up to 7 s with two cases running at once; extents and motions are bounded before any work) | yes |
//! | signal | killed by a signal (an allocation abort is SIGABRT) | yes |
//! | panic | exit 101, or `panicked` in its stderr | yes |
//! | changed input | a file it was given differs afterwards | yes |
//! | leftover file | a file other than the named outputs of a success (a temporary, an output after an error) | yes |
//! | NaN output | an output our reader refuses, or a coordinate that is not finite | yes |
//! | wrong exit code | not one the case's kind allows (`file`: 0, 3, 4; `spec`: 0, 4; `param`: 0, 2, 4; `field`: 0, 3, 4), or an error without a message | yes |
//!
//! Exit status: 0 when no case is bad, 1 otherwise. `--keep DIR` copies each bad case's folder
//! there with its command line and stderr (with `--case`, whatever its class).

use std::collections::BTreeMap;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};
use std::{fs, io};

use rand::seq::IndexedRandom;
use rand::{Rng, SeedableRng, rngs::StdRng};

type Bounds = ([f64; 3], [f64; 3]);
type Failure = Box<dyn std::error::Error>;

fn main() {
    match run() {
        Ok(clean) => std::process::exit(if clean { 0 } else { 1 }),
        Err(e) => {
            eprintln!("fuzz: {e}");
            std::process::exit(2);
        }
    }
}

struct Options {
    cases: usize,
    seed: u64,
    jobs: usize,
    timeout: Duration,
    memory_mib: u64,
    bin: PathBuf,
    data: PathBuf,
    work: PathBuf,
    keep: Option<PathBuf>,
    only: Option<usize>,
    max_seed: u64,
    verbose: bool,
}

fn options() -> Result<Options, Failure> {
    let exe = std::env::current_exe()?;
    let mut o = Options {
        cases: 300,
        seed: 1,
        jobs: std::thread::available_parallelism().map_or(2, |n| n.get()),
        timeout: Duration::from_secs(10),
        memory_mib: 3072,
        bin: exe.with_file_name("rigidcells"),
        data: PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data")),
        work: std::env::temp_dir().join(format!("rigidcells-fuzz-{}", std::process::id())),
        keep: None,
        only: None,
        max_seed: 700_000,
        verbose: false,
    };
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        if flag == "-v" || flag == "--verbose" {
            o.verbose = true;
            continue;
        }
        let value = args.next().ok_or(format!("{flag} needs a value"))?;
        let number = || {
            value
                .parse::<u64>()
                .map_err(|_| format!("{flag}: not a number"))
        };
        match flag.as_str() {
            "--cases" => o.cases = number()? as usize,
            "--seed" => o.seed = number()?,
            "--jobs" => o.jobs = number()?.max(1) as usize,
            "--timeout" => o.timeout = Duration::from_secs(number()?),
            "--memory" => o.memory_mib = number()?,
            "--bin" => o.bin = value.into(),
            "--data" => o.data = value.into(),
            "--work" => o.work = value.into(),
            "--keep" => o.keep = Some(value.into()),
            "--case" => o.only = Some(number()? as usize),
            "--max-seed" => o.max_seed = number()?,
            _ => return Err(format!("unknown flag {flag}").into()),
        }
    }
    if !o.bin.is_file() {
        return Err(format!(
            "no binary at {} (run `cargo build --release --bin rigidcells`, or give --bin)",
            o.bin.display()
        )
        .into());
    }
    Ok(o)
}

fn run() -> Result<bool, Failure> {
    let o = options()?;
    fs::create_dir_all(&o.work)?;
    let started = Instant::now();
    let seeds = seeds(&o)?;
    eprintln!(
        "fuzz: {} seeds ({} with specs, {} fields) in {:.1} s; binary {}; {} jobs, timeout {} s, \
         address space {} MiB",
        seeds.len(),
        seeds.iter().filter(|s| s.bounds.is_some()).count(),
        seeds.iter().filter(|s| s.format == Format::Field).count(),
        started.elapsed().as_secs_f64(),
        o.bin.display(),
        o.jobs,
        o.timeout.as_secs(),
        o.memory_mib
    );
    let indices: Vec<usize> = match o.only {
        Some(i) => vec![i],
        None => (0..o.cases).collect(),
    };
    let next = AtomicUsize::new(0);
    let results = Mutex::new(Vec::new());
    let started = Instant::now();
    std::thread::scope(|scope| {
        for _ in 0..o.jobs.min(indices.len()) {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&index) = indices.get(k) else { break };
                    let mut rng = StdRng::seed_from_u64(
                        o.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ index as u64,
                    );
                    let case = make_case(&seeds, &mut rng);
                    let outcome = run_case(&o, index, &case).unwrap_or_else(|e| Outcome {
                        class: Class::Harness,
                        detail: e.to_string(),
                        code: None,
                        seconds: 0.0,
                    });
                    if o.verbose || outcome.class.bad() {
                        eprintln!(
                            "case {index}: {} ({:.2} s, exit {:?}) {} | {} | {}",
                            outcome.class.name(),
                            outcome.seconds,
                            outcome.code,
                            case.op,
                            case.what,
                            outcome.detail
                        );
                    }
                    let mut all = results.lock().expect("no job panics");
                    all.push((index, case, outcome));
                    if all.len() % 1000 == 0 {
                        eprintln!(
                            "fuzz: {} cases, {:.0} s",
                            all.len(),
                            started.elapsed().as_secs_f64()
                        );
                    }
                }
            });
        }
    });
    let mut results = results.into_inner().expect("no job panics");
    results.sort_by_key(|r| r.0);
    Ok(summarize(&o, &results, started.elapsed()))
}

fn summarize(o: &Options, results: &[(usize, Case, Outcome)], took: Duration) -> bool {
    let mut table: BTreeMap<(&str, &str), usize> = BTreeMap::new();
    for (_, case, outcome) in results {
        *table.entry((outcome.class.name(), case.op)).or_default() += 1;
        *table.entry((outcome.class.name(), "all")).or_default() += 1;
    }
    let ops = ["file", "spec", "param", "field", "all"];
    println!(
        "{} cases, seed {}, in {:.0} s ({:.1} cases/s)\n",
        results.len(),
        o.seed,
        took.as_secs_f64(),
        results.len() as f64 / took.as_secs_f64()
    );
    println!("| class | {} |", ops.join(" | "));
    println!("|---|{}", "---|".repeat(ops.len()));
    for class in Class::ALL {
        let counts: Vec<String> = ops
            .iter()
            .map(|op| {
                table
                    .get(&(class.name(), *op))
                    .copied()
                    .unwrap_or(0)
                    .to_string()
            })
            .collect();
        println!("| {} | {} |", class.name(), counts.join(" | "));
    }
    let mut slow: Vec<_> = results.iter().collect();
    slow.sort_by(|a, b| b.2.seconds.total_cmp(&a.2.seconds));
    println!("\nslowest:");
    for (index, case, outcome) in slow.iter().take(3) {
        println!(
            "  case {index}: {:.2} s, {} | {}",
            outcome.seconds, case.op, case.what
        );
    }
    let bad: Vec<_> = results.iter().filter(|r| r.2.class.bad()).collect();
    for (index, case, outcome) in &bad {
        println!(
            "\nBAD case {index}: {} — {} | {}\n  rigidcells {}\n  {}\n  again: fuzz --seed {} --case {index} --keep DIR",
            outcome.class.name(),
            case.op,
            case.what,
            case.args.join(" "),
            outcome.detail,
            o.seed
        );
    }
    let _ = fs::remove_dir_all(&o.work);
    bad.is_empty()
}

// ---------------------------------------------------------------------------------------------
// Seeds

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Format {
    Las,
    Laz,
    Ply,
    Obj,
    Xyz,
    Xy,
    Png,
    Field,
}

impl Format {
    fn of(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "las" => Format::Las,
            "laz" => Format::Laz,
            "ply" => Format::Ply,
            "obj" => Format::Obj,
            "xyz" => Format::Xyz,
            "xy" => Format::Xy,
            "png" => Format::Png,
            "field" => Format::Field,
            _ => return None,
        })
    }

    fn ext(self) -> &'static str {
        match self {
            Format::Las => "las",
            Format::Laz => "laz",
            Format::Ply => "ply",
            Format::Obj => "obj",
            Format::Xyz => "xyz",
            Format::Xy => "xy",
            Format::Png => "png",
            Format::Field => "field",
        }
    }

    fn dim(self) -> usize {
        if matches!(self, Format::Xy | Format::Png) {
            2
        } else {
            3
        }
    }
}

struct Seed {
    name: String,
    format: Format,
    bytes: Vec<u8>,
    /// The samples' bounds (pixels for a PNG), where the seed reads cleanly.
    bounds: Option<Bounds>,
    /// For a field: the seed it was solved on.
    input: Option<usize>,
}

fn seeds(o: &Options) -> Result<Vec<Seed>, Failure> {
    let mut seeds = Vec::new();
    for sub in ["las", "meshes", "malformed"] {
        let dir = o.data.join(sub);
        let mut entries: Vec<PathBuf> = fs::read_dir(&dir)
            .map_err(|e| format!("{}: {e} (give --data)", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort();
        for path in entries {
            let (Some(format), Ok(meta)) = (Format::of(&path), fs::metadata(&path)) else {
                continue;
            };
            if meta.len() <= o.max_seed {
                seeds.push(seed_from(&path, format)?);
            }
        }
    }
    let dir = o.work.join("seeds");
    fs::create_dir_all(&dir)?;
    generate_seeds(o, &dir, &mut seeds)?;
    Ok(seeds)
}

fn seed_from(path: &Path, format: Format) -> Result<Seed, Failure> {
    let bytes = fs::read(path)?;
    let bounds = bounds_of(path, format, &bytes);
    Ok(Seed {
        name: path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("seed")
            .to_string(),
        format,
        bytes,
        bounds,
        input: None,
    })
}

/// The bounds of the samples of a file, where the library reads it cleanly (a panic counts as
/// unreadable: the seeds include malformed files).
fn bounds_of(path: &Path, format: Format, bytes: &[u8]) -> Option<Bounds> {
    match format {
        Format::Png => {
            let w = u32::from_be_bytes(bytes.get(16..20)?.try_into().ok()?) as f64;
            let h = u32::from_be_bytes(bytes.get(20..24)?.try_into().ok()?) as f64;
            Some(([0.0, 0.0, 0.0], [w, h, 0.0]))
        }
        Format::Field => None,
        Format::Xy => {
            let text = std::str::from_utf8(bytes).ok()?;
            let points: Vec<[f64; 3]> = text
                .lines()
                .filter_map(|l| {
                    let mut it = l.split_whitespace().map(|t| t.parse::<f64>());
                    Some([it.next()?.ok()?, it.next()?.ok()?, 0.0])
                })
                .collect();
            bounds_of_points(&points)
        }
        _ => std::panic::catch_unwind(|| {
            let points = samples_of(path).ok()?;
            bounds_of_points(&points)
        })
        .ok()
        .flatten(),
    }
}

fn samples_of(path: &Path) -> Result<Vec<[f64; 3]>, Failure> {
    let mut source = rigidcells::internal::io::open(path)?;
    let mut chunk = rigidcells::internal::io::Chunk::default();
    let mut points = Vec::new();
    while source.read(65536, &mut chunk)? > 0 {
        points.extend(chunk.positions.iter().map(|p| [p.x, p.y, p.z]));
    }
    Ok(points)
}

fn bounds_of_points(points: &[[f64; 3]]) -> Option<Bounds> {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (points.len() >= 4 && lo.iter().chain(&hi).all(|v| v.is_finite()) && hi[0] > lo[0])
        .then_some((lo, hi))
}

/// The generated seeds: the demo's files, the bar in the text formats, a 2D set, terrains, and
/// fields saved by the binary itself.
fn generate_seeds(o: &Options, dir: &Path, seeds: &mut Vec<Seed>) -> Result<(), Failure> {
    let status = Command::new(&o.bin)
        .args(["demo", "-q", "--out"])
        .arg(dir.join("demo"))
        .status()?;
    if !status.success() {
        return Err("the demo failed".into());
    }
    for name in ["bar.ply", "soup.ply", "gingerbread.png"] {
        let from = dir.join("demo").join(name);
        seeds.push(seed_from(
            &from,
            Format::of(&from).expect("known extension"),
        )?);
    }
    let bar = data_gen::bar([4.0, 1.0, 1.0], 3.0);
    let mut obj = String::new();
    let mut xyz = String::new();
    for v in &bar.vertices {
        obj += &format!("v {} {} {}\n", v[0], v[1], v[2]);
        xyz += &format!("{} {} {}\n", v[0], v[1], v[2]);
    }
    for t in &bar.triangles {
        obj += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    let mut xy = String::new();
    for i in 0..60 {
        for j in 0..12 {
            xy += &format!("{} {}\n", i as f64 * 0.1, j as f64 * 0.1);
        }
    }
    for (name, text) in [("bar.obj", obj), ("bar.xyz", xyz), ("strip.xy", xy)] {
        fs::write(dir.join(name), text)?;
        let path = dir.join(name);
        seeds.push(seed_from(
            &path,
            Format::of(&path).expect("known extension"),
        )?);
    }
    for (name, compressed) in [("terrain.las", false), ("terrain.laz", true)] {
        data_gen::write_las_terrain(&dir.join(name), 3000, compressed)?;
        let path = dir.join(name);
        seeds.push(seed_from(
            &path,
            Format::of(&path).expect("known extension"),
        )?);
    }
    // Fields: solved by the binary on generated seeds, each with its input.
    let solved = [
        ("bar.obj", "pu"),
        ("bar.obj", "blend"),
        ("bar.obj", "rbf"),
        ("terrain.las", "pu"),
    ];
    for (k, (input, transfer)) in solved.into_iter().enumerate() {
        let at = seeds
            .iter()
            .rposition(|s| s.name == input)
            .expect("generated above");
        let spec = dir.join(format!("field{k}.toml"));
        fs::write(&spec, end_lift(&seeds[at], 0.25, 0.3, 20.0, 2))?;
        let field = dir.join(format!("{}-{transfer}.field", input.replace('.', "-")));
        let out = dir.join(format!("out{k}.{}", seeds[at].format.ext()));
        let status = Command::new(&o.bin)
            .arg("deform")
            .arg(dir.join(input))
            .arg("-o")
            .arg(&out)
            .arg("--edit")
            .arg(&spec)
            .args([
                "--cells",
                "300",
                "-q",
                "--transfer",
                transfer,
                "--save-field",
            ])
            .arg(&field)
            .status()?;
        if !status.success() {
            return Err(format!("solving the field seed on {input} failed").into());
        }
        let mut seed = seed_from(&field, Format::Field)?;
        seed.input = Some(at);
        seeds.push(seed);
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Edit specs

fn num(v: f64) -> String {
    format!("{v:?}")
}

fn vector(v: &[f64; 3], dim: usize) -> String {
    let parts: Vec<String> = v[..dim].iter().map(|x| num(*x)).collect();
    format!("[{}]", parts.join(", "))
}

fn boxed(lo: [f64; 3], hi: [f64; 3], dim: usize) -> String {
    format!(
        "box = {{ min = {}, max = {} }}",
        vector(&lo, dim),
        vector(&hi, dim)
    )
}

/// The bounds with a margin, so that the end regions hold samples at every coordinate.
fn padded(seed: &Seed) -> Bounds {
    let (mut lo, mut hi) = seed.bounds.unwrap_or(([0.0; 3], [1.0; 3]));
    let pad = (hi[0] - lo[0]).max(1e-9) * 0.05;
    for a in 0..3 {
        lo[a] -= pad;
        hi[a] += pad;
    }
    (lo, hi)
}

/// Fixes the low `end` of x and moves the high end up by `lift` of the length, turned by
/// `degrees`.
fn end_lift(seed: &Seed, end: f64, lift: f64, degrees: f64, handles: usize) -> String {
    let dim = seed.format.dim();
    let (lo, hi) = padded(seed);
    let w = hi[0] - lo[0];
    let mut fixed_hi = hi;
    fixed_hi[0] = lo[0] + end * w;
    let mut text = format!("[[fixed]]\n{}\n", boxed(lo, fixed_hi, dim));
    let up = if dim == 2 { 1 } else { 2 };
    for h in 0..handles.max(1) {
        let mut handle_lo = lo;
        let mut handle_hi = hi;
        if handles > 1 {
            // Split the high end across y.
            let step = (hi[1] - lo[1]) / handles as f64;
            handle_lo[1] = lo[1] + step * h as f64;
            handle_hi[1] = handle_lo[1] + step;
        }
        handle_lo[0] = hi[0] - end * w;
        let mut t = [0.0; 3];
        t[up] = lift * w;
        text += &format!(
            "\n[[handle]]\n{}\ntranslate = {}\n",
            boxed(handle_lo, handle_hi, dim),
            vector(&t, dim)
        );
        if degrees != 0.0 {
            text += &if dim == 2 {
                format!("rotate = {{ degrees = {} }}\n", num(degrees))
            } else {
                format!(
                    "rotate = {{ axis = [0.0, 1.0, 0.0], degrees = {} }}\n",
                    num(degrees)
                )
            };
        }
    }
    text
}

/// A valid edit spec for `seed`, with the files it names.
fn spec_for(seed: &Seed, rng: &mut StdRng) -> (String, Vec<(String, Vec<u8>)>) {
    let dim = seed.format.dim();
    let (lo, hi) = padded(seed);
    let w = hi[0] - lo[0];
    let mid = |a: usize| 0.5 * (lo[a] + hi[a]);
    let mut files = Vec::new();
    let text = match rng.random_range(0..8) {
        0..=2 => end_lift(
            seed,
            rng.random_range(0.1..0.4),
            rng.random_range(-0.5..0.5),
            *[0.0, 15.0, -90.0, 400.0].choose(rng).expect("not empty"),
            rng.random_range(1..3),
        ),
        3 => {
            // Pins at the ends.
            let mut a = [mid(0), mid(1), mid(2)];
            a[0] = lo[0] + 0.1 * w;
            let mut b = a;
            b[0] = hi[0] - 0.1 * w;
            let mut to = b;
            to[1] += 0.2 * w;
            format!(
                "[[pin]]\npoint = {}\nto = {}\n\n[[pin]]\npoint = {}\nto = {}\n",
                vector(&a, dim),
                vector(&a, dim),
                vector(&b, dim),
                vector(&to, dim)
            )
        }
        4 => {
            // Targets, inline or from a CSV.
            let rows: Vec<[f64; 6]> = (0..4)
                .map(|k| {
                    let f = 0.1 + 0.8 * k as f64 / 3.0;
                    let x = lo[0] + f * w;
                    [x, mid(1), mid(2), x, mid(1) + 0.1 * w * f, mid(2)]
                })
                .collect();
            if rng.random_bool(0.5) {
                let csv: String = rows
                    .iter()
                    .map(|r| {
                        let cols: Vec<String> =
                            (0..dim).chain(3..3 + dim).map(|c| num(r[c])).collect();
                        cols.join(",") + "\n"
                    })
                    .collect();
                files.push(("gcp.csv".to_string(), csv.into_bytes()));
                "[[target]]\nfile = \"gcp.csv\"\n".to_string()
            } else {
                rows.iter()
                    .map(|r| {
                        format!(
                            "[[target]]\nfrom = {}\nto = {}\nweight = 2.0\n\n",
                            vector(&[r[0], r[1], r[2]], dim),
                            vector(&[r[3], r[4], r[5]], dim)
                        )
                    })
                    .collect()
            }
        }
        5 => {
            // A sphere handle over a plane's half-space fixed, and a soft middle.
            let mut n = [0.0; 3];
            n[0] = -1.0;
            let mut p = [mid(0), mid(1), mid(2)];
            p[0] = lo[0] + 0.2 * w;
            let mut c = p;
            c[0] = hi[0] - 0.1 * w;
            let mut t = [0.0; 3];
            t[1] = 0.1 * w;
            let mut slo = lo;
            let mut shi = hi;
            slo[0] = lo[0] + 0.4 * w;
            shi[0] = lo[0] + 0.6 * w;
            format!(
                "[[fixed]]\nplane = {{ point = {}, normal = {} }}\n\n[[handle]]\n\
                 sphere = {{ center = {}, radius = {} }}\ntranslate = {}\n\n[[stiffness]]\n{}\nscale = 0.3\n",
                vector(&p, dim),
                vector(&n, dim),
                vector(&c, dim),
                num(0.15 * w),
                vector(&t, dim),
                boxed(slo, shi, dim)
            )
        }
        6 => {
            // Classes where LAS has them, else the ends by index.
            if matches!(seed.format, Format::Las | Format::Laz) {
                let mut hlo = lo;
                hlo[0] = hi[0] - 0.3 * w;
                format!(
                    "[[fixed]]\nclassification = [1, 2]\n\n[[handle]]\n{}\ntranslate = [0.0, 0.0, {}]\n",
                    boxed(hlo, hi, dim),
                    num(0.1 * w)
                )
            } else {
                files.push(("ends.txt".to_string(), b"0\n1\n2\n3\n".to_vec()));
                let mut hlo = lo;
                hlo[0] = hi[0] - 0.3 * w;
                let mut t = [0.0; 3];
                t[dim - 1] = 0.1 * w;
                format!(
                    "[[fixed]]\nindices = \"ends.txt\"\n\n[[handle]]\n{}\ntranslate = {}\n",
                    boxed(hlo, hi, dim),
                    vector(&t, dim)
                )
            }
        }
        _ => {
            // An affine matrix on the handle.
            let mut flo = hi;
            flo[0] = lo[0] + 0.3 * w;
            let mut hlo = lo;
            hlo[0] = hi[0] - 0.3 * w;
            let n = dim + 1;
            let rows: Vec<String> = (0..n)
                .map(|r| {
                    let row: Vec<String> = (0..n)
                        .map(|c| {
                            let v = if r == c {
                                1.0
                            } else if c == n - 1 && r == 1 {
                                0.1 * w
                            } else {
                                0.0
                            };
                            num(v)
                        })
                        .collect();
                    format!("[{}]", row.join(", "))
                })
                .collect();
            format!(
                "[[fixed]]\n{}\n\n[[handle]]\n{}\nmatrix = [{}]\n",
                boxed(lo, flo, dim),
                boxed(hlo, hi, dim),
                rows.join(", ")
            )
        }
    };
    (text, files)
}

// ---------------------------------------------------------------------------------------------
// Mutations

const INTERESTING_INTS: [u64; 20] = [
    0,
    1,
    2,
    7,
    8,
    0x7f,
    0x80,
    0xff,
    0x100,
    0x7fff,
    0x8000,
    0xffff,
    0x1_0000,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_ffff,
    1 << 32,
    i64::MAX as u64,
    1 << 63,
    u64::MAX,
];

const INTERESTING_FLOATS: [f64; 16] = [
    0.0,
    -0.0,
    1.0,
    -1.0,
    1e-9,
    1e9,
    1e-300,
    5e-324,
    1e300,
    f64::MAX,
    -f64::MAX,
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    0.001,
    1e15,
];

const INTERESTING_TEXT: [&str; 22] = [
    "0",
    "-0.0",
    "-1",
    "1",
    "2",
    "1e308",
    "-1e308",
    "1e-308",
    "1e400",
    "nan",
    "inf",
    "-inf",
    "NaN",
    "4294967295",
    "4294967296",
    "18446744073709551616",
    "-9223372036854775809",
    "99999999999999999999999999",
    "0.5",
    "1e15",
    "",
    "x",
];

/// Mutates `bytes` in one to four steps; returns what was done.
fn mutate_file(bytes: &mut Vec<u8>, format: Format, others: &[&Seed], rng: &mut StdRng) -> String {
    let mut done = Vec::new();
    for _ in 0..rng.random_range(1..=4) {
        let step = match format {
            Format::Las | Format::Laz if rng.random_bool(0.5) => las_field(bytes, rng),
            Format::Png if rng.random_bool(0.4) => png_header(bytes, rng),
            Format::Ply if rng.random_bool(0.4) => text_step(bytes, rng, true),
            Format::Obj | Format::Xyz | Format::Xy if rng.random_bool(0.6) => {
                text_step(bytes, rng, false)
            }
            Format::Field if rng.random_bool(0.6) => float_at(bytes, rng),
            _ => generic_step(bytes, format, others, rng),
        };
        done.push(step);
    }
    done.join("; ")
}

fn offset(bytes: &[u8], rng: &mut StdRng) -> usize {
    if bytes.is_empty() {
        0
    } else if rng.random_bool(0.5) {
        rng.random_range(0..bytes.len().min(512))
    } else {
        rng.random_range(0..bytes.len())
    }
}

fn put(bytes: &mut [u8], at: usize, value: &[u8]) -> bool {
    match bytes.get_mut(at..at + value.len()) {
        Some(slot) => {
            slot.copy_from_slice(value);
            true
        }
        None => false,
    }
}

fn int_value(bytes: &[u8], rng: &mut StdRng) -> u64 {
    match rng.random_range(0..6) {
        0 => bytes.len() as u64,
        1 => bytes.len() as u64 + rng.random_range(1..64),
        2 => rng.random::<u64>(),
        _ => *INTERESTING_INTS.choose(rng).expect("not empty"),
    }
}

fn put_int(bytes: &mut [u8], at: usize, width: usize, value: u64) -> bool {
    put(bytes, at, &value.to_le_bytes()[..width])
}

fn generic_step(bytes: &mut Vec<u8>, format: Format, others: &[&Seed], rng: &mut StdRng) -> String {
    let len = bytes.len();
    match rng.random_range(0..9) {
        0 | 1 => {
            let at = offset(bytes, rng);
            let bits = rng.random_range(1..=8);
            for _ in 0..bits {
                let k = (at + rng.random_range(0..8)).min(len.saturating_sub(1));
                if let Some(b) = bytes.get_mut(k) {
                    *b ^= 1 << rng.random_range(0..8);
                }
            }
            format!("{bits} bit flips near {at}")
        }
        2 => {
            let at = offset(bytes, rng);
            let v = *[0u8, 1, 0x7f, 0x80, 0xff].choose(rng).expect("not empty");
            put(bytes, at, &[v]);
            format!("byte {at} = {v:#x}")
        }
        3 => {
            let at = offset(bytes, rng);
            let width = *[2usize, 4, 8].choose(rng).expect("not empty");
            let v = int_value(bytes, rng);
            put_int(bytes, at, width, v);
            format!("u{} {at} = {v}", width * 8)
        }
        4 => float_at(bytes, rng),
        5 => {
            let to = rng.random_range(0..=len);
            bytes.truncate(to);
            format!("truncated to {to}")
        }
        6 => {
            let same: Vec<&&Seed> = others.iter().filter(|s| s.format == format).collect();
            match same.choose(rng) {
                Some(other) if !other.bytes.is_empty() => {
                    let at = rng.random_range(0..=len);
                    let from = rng.random_range(0..other.bytes.len());
                    bytes.truncate(at);
                    bytes.extend_from_slice(&other.bytes[from..]);
                    format!("spliced {} from {from} at {at}", other.name)
                }
                _ => "no splice".to_string(),
            }
        }
        7 => {
            let a = rng.random_range(0..=len);
            let b = (a + rng.random_range(0..=4096)).min(len);
            let span = bytes[a..b].to_vec();
            let at = rng.random_range(0..=len);
            bytes.splice(at..at, span);
            format!("duplicated {a}..{b} at {at}")
        }
        _ => {
            let a = rng.random_range(0..=len);
            let b = (a + rng.random_range(0..=4096)).min(len);
            bytes.drain(a..b);
            format!("deleted {a}..{b}")
        }
    }
}

fn float_at(bytes: &mut Vec<u8>, rng: &mut StdRng) -> String {
    let mut at = rng.random_range(0..bytes.len().max(1));
    if rng.random_bool(0.5) {
        at &= !7;
    } else {
        at &= !3;
    }
    let v = *INTERESTING_FLOATS.choose(rng).expect("not empty");
    if put(bytes, at, &v.to_le_bytes()) {
        format!("f64 {at} = {v:e}")
    } else {
        bytes.truncate(at);
        format!("truncated to {at}")
    }
}

/// Interesting values in the fields of a LAS public header, its first VLR, the LASzip VLR and
/// a LAZ chunk table's offset.
fn las_field(bytes: &mut [u8], rng: &mut StdRng) -> String {
    let read = |at: usize, w: usize| -> u64 {
        let mut b = [0u8; 8];
        if let Some(s) = bytes.get(at..at + w) {
            b[..w].copy_from_slice(s);
        }
        u64::from_le_bytes(b)
    };
    let header = read(94, 2) as usize;
    let points = read(96, 4) as usize;
    let laszip = bytes
        .windows(14)
        .position(|w| w == b"laszip encoded")
        .map(|p| p - 2 + 54);
    // (name, offset, width; width 0 marks an f64)
    let mut fields: Vec<(&str, usize, usize)> = vec![
        ("header size", 94, 2),
        ("offset to points", 96, 4),
        ("vlr count", 100, 4),
        ("point format", 104, 1),
        ("record length", 105, 2),
        ("legacy count", 107, 4),
        ("scale x", 131, 0),
        ("scale z", 147, 0),
        ("offset x", 155, 0),
        ("max x", 179, 0),
        ("min z", 219, 0),
        ("waveform start", 227, 8),
        ("evlr start", 235, 8),
        ("evlr count", 243, 4),
        ("count", 247, 8),
        ("first vlr length", header + 20, 2),
        ("chunk table offset", points, 8),
    ];
    if let Some(z) = laszip {
        fields.extend([
            ("laszip compressor", z, 2),
            ("laszip chunk size", z + 12, 4),
            ("laszip item count", z + 32, 2),
            ("laszip item size", z + 36, 2),
            ("laszip item version", z + 38, 2),
        ]);
    }
    let &(name, at, width) = fields.choose(rng).expect("not empty");
    if width == 0 {
        let v = *INTERESTING_FLOATS.choose(rng).expect("not empty");
        put(bytes, at, &v.to_le_bytes());
        format!("{name} = {v:e}")
    } else {
        let v = if rng.random_bool(0.3) {
            read(at, width).wrapping_add(rng.random_range(-3i64..=3) as u64)
        } else {
            int_value(bytes, rng)
        };
        put_int(bytes, at, width, v);
        format!("{name} = {v}")
    }
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// A PNG's IHDR width, height, depth or color type set to an interesting value, its CRC fixed.
fn png_header(bytes: &mut [u8], rng: &mut StdRng) -> String {
    if bytes.len() < 33 {
        return "png too short".to_string();
    }
    let (name, at, width) = *[
        ("width", 16, 4),
        ("height", 20, 4),
        ("depth", 24, 1),
        ("color type", 25, 1),
    ]
    .choose(rng)
    .expect("not empty");
    let v = *INTERESTING_INTS.choose(rng).expect("not empty");
    bytes[at..at + width].copy_from_slice(&v.to_be_bytes()[8 - width..]);
    let crc = crc32(&bytes[12..29]);
    bytes[29..33].copy_from_slice(&crc.to_be_bytes());
    format!("IHDR {name} = {v}")
}

/// A text mutation: a number replaced by an interesting one, a line deleted or doubled, or (in
/// a PLY header) a word replaced.
fn text_step(bytes: &mut Vec<u8>, rng: &mut StdRng, ply: bool) -> String {
    let end = if ply {
        bytes
            .windows(10)
            .position(|w| w == b"end_header")
            .map_or(bytes.len(), |p| p + 10)
    } else {
        bytes.len()
    };
    let head = String::from_utf8_lossy(&bytes[..end]).into_owned();
    let mut lines: Vec<String> = head.split('\n').map(str::to_string).collect();
    let k = rng.random_range(0..lines.len());
    let what = match rng.random_range(0..5) {
        0 => {
            lines.remove(k);
            format!("line {} deleted", k + 1)
        }
        1 => {
            let line = lines[k].clone();
            lines.insert(k, line);
            format!("line {} doubled", k + 1)
        }
        2 if ply => {
            let words = [
                "float",
                "double",
                "uchar",
                "int",
                "uint",
                "list",
                "vertex",
                "face",
                "binary_little_endian",
                "ascii",
                "property",
                "element",
                "char",
                "int64",
            ];
            let mut parts: Vec<String> = lines[k].split(' ').map(str::to_string).collect();
            let w = rng.random_range(0..parts.len());
            let to = words.choose(rng).expect("not empty").to_string();
            parts[w] = to.clone();
            lines[k] = parts.join(" ");
            format!("line {} word {w} = {to}", k + 1)
        }
        _ => {
            let mut parts: Vec<String> = lines[k].split(' ').map(str::to_string).collect();
            let numeric: Vec<usize> = (0..parts.len())
                .filter(|&i| parts[i].parse::<f64>().is_ok())
                .collect();
            match numeric.choose(rng) {
                Some(&i) => {
                    let to = INTERESTING_TEXT.choose(rng).expect("not empty").to_string();
                    parts[i] = to.clone();
                    lines[k] = parts.join(" ");
                    format!("line {} number {i} = {to:?}", k + 1)
                }
                None => "no number".to_string(),
            }
        }
    };
    let mut out = lines.join("\n").into_bytes();
    out.extend_from_slice(&bytes[end..]);
    *bytes = out;
    what
}

/// Turns at and past the spec's bound of ten whole turns, and far past it.
const HUGE_TURNS: [&str; 7] = ["3600", "3600.5", "-3601", "7200", "1e5", "-1e308", "1e12"];

const SPEC_KEYS: [&str; 32] = [
    "box",
    "sphere",
    "plane",
    "min",
    "max",
    "center",
    "radius",
    "point",
    "normal",
    "translate",
    "rotate",
    "axis",
    "degrees",
    "pivot",
    "matrix",
    "to",
    "from",
    "weight",
    "scale",
    "classification",
    "indices",
    "file",
    "polygon",
    "polygon_file",
    "invert",
    "snap",
    "z",
    "[[fixed]]",
    "[[handle]]",
    "[[pin]]",
    "[[target]]",
    "[[stiffness]]",
];

/// Mutates an edit spec's text (and adds the files its mutations name).
fn mutate_spec(
    text: &str,
    dim: usize,
    files: &mut Vec<(String, Vec<u8>)>,
    rng: &mut StdRng,
) -> (Vec<u8>, String) {
    let mut text = text.to_string();
    let mut done = Vec::new();
    let mut raw_tail: Vec<u8> = Vec::new();
    for _ in 0..rng.random_range(1..=3) {
        let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
        if lines.is_empty() {
            lines.push(String::new());
        }
        let k = rng.random_range(0..lines.len());
        let step = match rng.random_range(0..12) {
            0..=2 => {
                // A number replaced.
                let line = lines[k].clone();
                let spans: Vec<(usize, usize)> = number_spans(&line);
                match spans.choose(rng) {
                    Some(&(a, b)) => {
                        let to = INTERESTING_TEXT.choose(rng).expect("not empty");
                        lines[k] = format!("{}{to}{}", &line[..a], &line[b..]);
                        format!("line {} {:?} -> {to:?}", k + 1, &line[a..b])
                    }
                    None => "no number".to_string(),
                }
            }
            3 => {
                lines.remove(k);
                format!("line {} deleted", k + 1)
            }
            4 => {
                let line = lines[k].clone();
                lines.insert(k, line);
                format!("line {} doubled", k + 1)
            }
            5 => {
                let from = *SPEC_KEYS.choose(rng).expect("not empty");
                let to = *SPEC_KEYS.choose(rng).expect("not empty");
                lines[k] = lines[k].replace(from, to);
                format!("{from} -> {to}")
            }
            6 => {
                let cut = rng.random_range(0..=text.len());
                let cut = (0..=cut)
                    .rev()
                    .find(|&c| text.is_char_boundary(c))
                    .unwrap_or(0);
                text.truncate(cut);
                lines = text.lines().map(str::to_string).collect();
                format!("truncated to {cut}")
            }
            7 => {
                raw_tail = vec![0xff, 0xfe, b'\n', 0xc3];
                "bytes that are not UTF-8".to_string()
            }
            8 => named_file(
                rng,
                files,
                &mut lines,
                "[[target]]\nfile",
                &[
                    ("gcp.csv", Some(&b"1,2\n"[..])),
                    ("gcp.csv", Some(&b"a,b,c,d,e,f\n"[..])),
                    ("gcp.csv", Some(&b"nan,0,0,0,0,0\n"[..])),
                    ("gcp.csv", Some(&b"0;0;0;1;1;1\n"[..])),
                    ("gcp.csv", Some(&b"id;x;y;z;X;Y;Z\nP1;0,5;0;0;1;1;1\n"[..])),
                    ("gcp.csv", Some(&b"id,x,y,X,Y\nP1,0.5,0.5,0.6,0.5\nP2,1e300,0,0,0\n"[..])),
                    ("gcp.csv", Some(&b"P1 0.5 0.5 0.6 0.5\nP2 9 0.5 9 0.7\n"[..])),
                    ("gcp.csv", Some(&b"x,x,y,Y,z,Z,weight\n1,1,1,1,1,1,-1\n"[..])),
                    ("gcp.csv", Some(&b"\"id\"\t\"x\"\n\"\n"[..])),
                    ("gcp.csv", Some(&b"\xff\xfe\n"[..])),
                    (
                        "gcp.csv",
                        Some(&b"1e308,1e308,1e308,-1e308,-1e308,-1e308\n"[..]),
                    ),
                    ("missing.csv", None),
                ],
            ),
            9 if rng.random_bool(0.4) => named_file(
                rng,
                files,
                &mut lines,
                "[[fixed]]\ninvert = true\npolygon_file",
                &[
                    (
                        "area.geojson",
                        Some(&br#"{"type":"Polygon","coordinates":[[[0,0],[5,0],[5,1],[0,1],[0,0]]]}"#[..]),
                    ),
                    (
                        "area.geojson",
                        Some(&br#"{"type":"FeatureCollection","features":[{"type":"Feature","geometry":{"type":"MultiPolygon","coordinates":[[[[0,0],[1e308,0],[0,-1e308]]],[[[1,1],[2,2]]]]}}]}"#[..]),
                    ),
                    ("area.geojson", Some(&br#"{"type":"Feature","geometry":null}"#[..])),
                    ("area.geojson", Some(&br#"{"type":"Polygon","coordinates":[[["a",0]]]}"#[..])),
                    ("area.geojson", Some(&b"[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[["[..])),
                    ("missing.geojson", None),
                ],
            ),
            9 => named_file(
                rng,
                files,
                &mut lines,
                "[[fixed]]\nindices",
                &[
                    ("idx.txt", Some(&b"0\n18446744073709551615\n"[..])),
                    ("idx.txt", Some(&b"-1\n"[..])),
                    ("idx.txt", Some(&b"1.5\nx\n"[..])),
                    ("idx.txt", Some(&b"99999999999\n"[..])),
                    ("idx.txt", Some(&b""[..])),
                    ("missing.txt", None),
                ],
            ),
            10 => {
                // A handle turned by a huge angle: the spec's bound on the solver's work.
                let degrees = *HUGE_TURNS.choose(rng).expect("not empty");
                let axis = if dim == 2 { "" } else { "axis = [0.0, 1.0, 0.0], " };
                let rotate = format!("rotate = {{ {axis}degrees = {degrees} }}");
                match lines.iter().position(|l| l.trim_start().starts_with("rotate")) {
                    Some(r) => lines[r] = rotate.clone(),
                    None => match lines.iter().position(|l| l.trim() == "[[handle]]") {
                        Some(h) => lines.insert(h + 1, rotate.clone()),
                        None => lines.push(format!(
                            "[[handle]]\nsphere = {{ center = [{}], radius = 1.0 }}\n{rotate}",
                            vec!["0.0"; dim].join(", ")
                        )),
                    },
                }
                format!("huge turn: {rotate}")
            }
            _ => {
                // A region or motion of extreme or wrong shape.
                let zero = vec!["0.0"; dim].join(", ");
                let blocks = [
                    format!("[[handle]]\nsphere = {{ center = [{zero}], radius = 1e308 }}\nrotate = {{ axis = [0.0, 0.0, 1.0], degrees = 1e12 }}"),
                    format!("[[handle]]\nbox = {{ min = [{zero}], max = [{zero}] }}\ntranslate = [1e308, 1e308, 1e308]"),
                    "[[fixed]]\nbox = { min = [1.0], max = [2.0, 3.0, 4.0, 5.0] }".to_string(),
                    format!("[[pin]]\npoint = [{zero}]\nto = [nan, 0.0, 0.0]"),
                    "[[handle]]\nplane = { point = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 0.0] }\ntranslate = [1.0, 0.0, 0.0]".to_string(),
                    format!("[[handle]]\nbox = {{ min = [{zero}], max = [{zero}] }}\nmatrix = [[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]"),
                    format!("[[stiffness]]\nsphere = {{ center = [{zero}], radius = 1e300 }}\nscale = 1e-300"),
                    "[[handle]]\npolygon = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]\ntranslate = [0.0, 0.0, 1.0]".to_string(),
                    "[[fixed]]\nclassification = [256, -1]".to_string(),
                    "[[fixed]]\nclassification = [2]\npolygon = [[0.0, 0.0], [1e308, 0.0], [0.0, 1e308]]\nz = [1.0, 0.0]".to_string(),
                    "[[fixed]]\nsphere = { center = [0.0, 0.0, 0.0], radius = 1.0 }\ninvert = true".to_string(),
                    "[[target]]\nfrom = [0.0, 0.0, 1e9]\nto = [0.0, 0.0, 0.0]\nsnap = 1e300".to_string(),
                ];
                let block = blocks.choose(rng).expect("not empty").clone();
                let first = block.lines().nth(1).unwrap_or_default().to_string();
                lines.push(block);
                format!("added {first}")
            }
        };
        text = lines.join("\n") + "\n";
        done.push(step);
    }
    let mut bytes = text.into_bytes();
    bytes.extend(raw_tail);
    (bytes, done.join("; "))
}

/// An entry `entry = "NAME"` (`[[target]]\nfile`, `[[fixed]]\nindices`) naming one of
/// `choices`, whose body (if any: `None` leaves it missing) joins the case's files; says which.
fn named_file(
    rng: &mut StdRng,
    files: &mut Vec<(String, Vec<u8>)>,
    lines: &mut Vec<String>,
    entry: &str,
    choices: &[(&str, Option<&[u8]>)],
) -> String {
    let (name, body) = *choices.choose(rng).expect("not empty");
    if let Some(body) = body {
        add_file(files, name, body);
    }
    lines.push(format!("{entry} = \"{name}\""));
    let what = entry.rsplit('\n').next().unwrap_or(entry);
    format!("{what} {name}: {:?}", body.map(String::from_utf8_lossy))
}

/// Adds a file to a case, replacing one of the same name.
fn add_file(files: &mut Vec<(String, Vec<u8>)>, name: &str, body: &[u8]) {
    files.retain(|(n, _)| n != name);
    files.push((name.to_string(), body.to_vec()));
}

fn number_spans(line: &str) -> Vec<(usize, usize)> {
    let b = line.as_bytes();
    let mut spans = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit() || (b[i] == b'-' && b.get(i + 1).is_some_and(u8::is_ascii_digit)) {
            let start = i;
            i += 1;
            while i < b.len()
                && (b[i].is_ascii_alphanumeric() || b[i] == b'.' || b[i] == b'-' || b[i] == b'+')
            {
                i += 1;
            }
            spans.push((start, i));
        } else {
            i += 1;
        }
    }
    spans
}

const NUMBERS: [&str; 19] = [
    "0",
    "-1",
    "1e-300",
    "1e300",
    "nan",
    "inf",
    "-inf",
    "abc",
    "",
    "1",
    "2",
    "7",
    "1000000",
    "18446744073709551615",
    "4294967297",
    "0.001",
    "1e9",
    "99999999999999999999999",
    "0.5",
];

/// One mutated command-line value for `command`: (flags, what).
fn mutate_param(command: &str, rng: &mut StdRng) -> Vec<String> {
    let pick = |rng: &mut StdRng, pool: &[&str]| pool.choose(rng).expect("not empty").to_string();
    let mut flags: Vec<&str> = match command {
        "deform" | "cells" | "image" => vec![
            "--cell-size",
            "--cells",
            "--min-cell-size",
            "--max-level",
            "--memory-limit",
            "--inside",
            "--interior-stiffness",
            "--solver",
        ],
        _ => vec![],
    };
    if command == "deform" || command == "image" {
        flags.extend(["--transfer", "--refine-strain"]);
    }
    if command == "deform" {
        flags.extend([
            "--rbf-tolerance",
            "--chunk",
            "--size",
            "--azimuth",
            "--elevation",
            "--strain",
        ]);
    }
    if command == "render" {
        flags.extend(["--size", "--azimuth", "--elevation"]);
    }
    if command == "image" {
        flags.push("--background");
    }
    if command == "apply" {
        flags.extend(["--transfer", "--rbf-tolerance", "--outside"]);
    }
    let Some(&flag) = flags.choose(rng) else {
        return vec![];
    };
    let value = match flag {
        "--memory-limit" => pick(
            rng,
            &[
                "0",
                "1",
                "1K",
                "1M",
                "64M",
                "1P",
                "1E",
                "abc",
                "99999999999999999999Z",
                "-5M",
                "1.5G",
            ],
        ),
        "--size" => pick(
            rng,
            &[
                "0x0",
                "1x1",
                "100000x100000",
                "64x48",
                "-1x5",
                "axb",
                "65536x1",
                "4294967296x1",
                "x",
            ],
        ),
        "--inside" => pick(rng, &["auto", "winding", "flood", "none", "bogus"]),
        "--solver" => pick(rng, &["auto", "direct", "multilevel", "bogus"]),
        "--transfer" => pick(rng, &["blend", "blend-idw", "rbf", "pu", "bogus"]),
        "--outside" => pick(rng, &["refuse", "keep", "extend", "bogus"]),
        "--background" => pick(
            rng,
            &[
                "0,0,0",
                "255,255,255",
                "256,0,0",
                "-1,0,0",
                "a,b,c",
                "1,2",
                "",
            ],
        ),
        "--strain" => return vec!["--strain".into(), "--preview".into(), "p.png".into()],
        _ => pick(rng, &NUMBERS),
    };
    vec![flag.to_string(), value]
}

// ---------------------------------------------------------------------------------------------
// Cases

struct Case {
    op: &'static str,
    what: String,
    files: Vec<(String, Vec<u8>)>,
    args: Vec<String>,
    /// Files a success writes.
    outputs: Vec<String>,
    allowed: &'static [i32],
}

fn make_case(seeds: &[Seed], rng: &mut StdRng) -> Case {
    let readable: Vec<&Seed> = seeds.iter().filter(|s| s.bounds.is_some()).collect();
    let fields: Vec<&Seed> = seeds.iter().filter(|s| s.format == Format::Field).collect();
    let inputs: Vec<&Seed> = seeds.iter().filter(|s| s.format != Format::Field).collect();
    let op = *[
        "file", "file", "file", "file", "spec", "spec", "param", "param", "field", "field",
    ]
    .choose(rng)
    .expect("not empty");
    if op == "field" {
        return field_case(seeds, &fields, rng);
    }
    let seed = if op == "file" {
        *inputs.choose(rng).expect("seeds")
    } else {
        *readable.choose(rng).expect("readable seeds")
    };
    let input = format!("in.{}", seed.format.ext());
    let mut files = Vec::new();
    let mut what = seed.name.clone();
    let mut bytes = seed.bytes.clone();
    if op == "file" {
        what += &format!(": {}", mutate_file(&mut bytes, seed.format, &inputs, rng));
    }
    files.push((input.clone(), bytes));
    let (spec, named) = spec_for(seed, rng);
    files.extend(named);
    let spec = if op == "spec" {
        let (mutated, how) = mutate_spec(&spec, seed.format.dim(), &mut files, rng);
        what += &format!(": {how}");
        mutated
    } else {
        spec.into_bytes()
    };
    files.push(("edit.toml".to_string(), spec));

    let commands: &[&str] = if op == "file" {
        &[
            "deform", "deform", "deform", "deform", "cells", "cells", "info", "render",
        ]
    } else {
        &["deform", "deform", "deform", "cells"]
    };
    let command = match seed.format {
        Format::Png => "image",
        Format::Xy => "deform",
        _ => *commands.choose(rng).expect("not empty"),
    };
    let mut args = vec![command.to_string(), input.clone(), "-q".to_string()];
    let mut outputs = Vec::new();
    let out_ext = match (seed.format, rng.random_bool(0.2)) {
        (Format::Las, true) => "laz",
        (Format::Laz, true) => "las",
        (f, _) => f.ext(),
    };
    let params = if op == "param" {
        mutate_param(command, rng)
    } else {
        vec![]
    };
    if params.is_empty() && op == "param" {
        what += ": no parameter to mutate";
    } else if !params.is_empty() {
        what += &format!(": {}", params.join(" "));
    }
    match command {
        "info" => args.retain(|a| a != "-q"),
        "render" => {
            args.retain(|a| a != "-q");
            args.extend(["-o".into(), "r.png".into()]);
            outputs.push("r.png".into());
        }
        _ => {
            let out = match command {
                "cells" => "cells.ply".to_string(),
                _ => format!("out.{out_ext}"),
            };
            args.extend(["-o".into(), out.clone()]);
            outputs.push(out);
            if command != "cells" || op == "spec" || rng.random_bool(0.5) {
                args.extend(["--edit".into(), "edit.toml".into()]);
            }
            if !params
                .iter()
                .any(|p| p == "--cells" || p == "--cell-size" || p == "--min-cell-size")
            {
                args.extend(["--cells".into(), pick_cells(rng).to_string()]);
            }
            if command == "deform" {
                for (flag, name) in [
                    ("--report", "r.json"),
                    ("--save-field", "s.field"),
                    ("--preview", "p.png"),
                ] {
                    if rng.random_bool(0.15) && !(flag == "--preview" && seed.format == Format::Xy)
                    {
                        args.extend([flag.to_string(), name.to_string()]);
                        outputs.push(name.to_string());
                    }
                }
            }
        }
    }
    if params.iter().any(|p| p == "--preview") {
        outputs.push("p.png".into());
    }
    args.extend(params);
    let allowed: &[i32] = match op {
        "file" => &[0, 3, 4],
        "spec" => &[0, 4],
        _ => &[0, 2, 4],
    };
    Case {
        op,
        what,
        files,
        args,
        outputs,
        allowed,
    }
}

fn pick_cells(rng: &mut StdRng) -> usize {
    *[150usize, 400, 1000].choose(rng).expect("not empty")
}

fn field_case(seeds: &[Seed], fields: &[&Seed], rng: &mut StdRng) -> Case {
    let field = *fields.choose(rng).expect("field seeds");
    let input = &seeds[field.input.expect("fields have inputs")];
    let mut bytes = field.bytes.clone();
    let mut what = format!(
        "{}: {}",
        field.name,
        mutate_file(&mut bytes, Format::Field, &[], rng)
    );
    let name = format!("in.{}", input.format.ext());
    let out = format!("out.{}", input.format.ext());
    let mut args = vec![
        "apply".to_string(),
        "f.field".into(),
        name.clone(),
        "-o".into(),
        out.clone(),
        "-q".into(),
    ];
    if rng.random_bool(0.3) {
        let p = mutate_param("apply", rng);
        what += &format!(": {}", p.join(" "));
        args.extend(p);
    }
    Case {
        op: "field",
        what,
        files: vec![("f.field".into(), bytes), (name, input.bytes.clone())],
        args,
        outputs: vec![out],
        allowed: &[0, 2, 3, 4],
    }
}

// ---------------------------------------------------------------------------------------------
// Running and classifying

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Class {
    Success,
    CleanError,
    Hang,
    Signal,
    Panic,
    ChangedInput,
    Leftover,
    NanOutput,
    WrongExit,
    Harness,
}

impl Class {
    const ALL: [Class; 10] = [
        Class::Success,
        Class::CleanError,
        Class::Hang,
        Class::Signal,
        Class::Panic,
        Class::ChangedInput,
        Class::Leftover,
        Class::NanOutput,
        Class::WrongExit,
        Class::Harness,
    ];

    fn name(self) -> &'static str {
        match self {
            Class::Success => "success",
            Class::CleanError => "clean error",
            Class::Hang => "hang",
            Class::Signal => "signal",
            Class::Panic => "panic",
            Class::ChangedInput => "changed input",
            Class::Leftover => "leftover file",
            Class::NanOutput => "NaN output",
            Class::WrongExit => "wrong exit code",
            Class::Harness => "harness error",
        }
    }

    fn bad(self) -> bool {
        !matches!(self, Class::Success | Class::CleanError)
    }
}

struct Outcome {
    class: Class,
    detail: String,
    code: Option<i32>,
    seconds: f64,
}

fn digest(bytes: &[u8]) -> u64 {
    let mut h = DefaultHasher::new();
    bytes.hash(&mut h);
    h.finish()
}

fn run_case(o: &Options, index: usize, case: &Case) -> Result<Outcome, Failure> {
    let dir = o.work.join(format!("case-{index}"));
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(&dir)?;
    for (name, bytes) in &case.files {
        fs::write(dir.join(name), bytes)?;
    }
    let err_path = o.work.join(format!("case-{index}.stderr"));
    let memory = o.memory_mib << 20;
    let mut command = Command::new(&o.bin);
    command
        .args(&case.args)
        .current_dir(&dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(fs::File::create(&err_path)?)
        .process_group(0);
    // SAFETY: only async-signal-safe setrlimit calls between fork and exec.
    unsafe {
        command.pre_exec(move || {
            let limit = |resource, value| {
                let l = libc::rlimit {
                    rlim_cur: value,
                    rlim_max: value,
                };
                if libc::setrlimit(resource, &l) == 0 {
                    Ok(())
                } else {
                    Err(io::Error::last_os_error())
                }
            };
            limit(libc::RLIMIT_AS, memory)?;
            limit(libc::RLIMIT_CORE, 0)
        });
    }
    let started = Instant::now();
    let mut child = command.spawn()?;
    let mut timed_out = false;
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        if started.elapsed() > o.timeout {
            timed_out = true;
            // SAFETY: kill of the child's own process group.
            unsafe { libc::kill(-(child.id() as i32), libc::SIGKILL) };
            break child.wait()?;
        }
        std::thread::sleep(Duration::from_millis(
            if started.elapsed().as_millis() < 100 {
                2
            } else {
                15
            },
        ));
    };
    let seconds = started.elapsed().as_secs_f64();
    let stderr = fs::read_to_string(&err_path).unwrap_or_default();
    let _ = fs::remove_file(&err_path);
    let first = stderr
        .lines()
        .next()
        .unwrap_or("")
        .chars()
        .take(300)
        .collect::<String>();
    let code = status.code();
    let (class, detail) = classify(case, &dir, timed_out, status, &stderr);
    let outcome = Outcome {
        class,
        detail: if class.bad() { detail } else { first },
        code,
        seconds,
    };
    if (class.bad() || o.only.is_some())
        && let Some(keep) = &o.keep
    {
        let to = keep.join(format!("case-{index}"));
        let _ = fs::remove_dir_all(&to);
        fs::create_dir_all(&to)?;
        for (name, bytes) in &case.files {
            fs::write(to.join(name), bytes)?;
        }
        fs::write(
            to.join("command.txt"),
            format!("rigidcells {}\n", case.args.join(" ")),
        )?;
        fs::write(to.join("stderr.txt"), &stderr)?;
    }
    let _ = fs::remove_dir_all(&dir);
    Ok(outcome)
}

fn classify(
    case: &Case,
    dir: &Path,
    timed_out: bool,
    status: std::process::ExitStatus,
    stderr: &str,
) -> (Class, String) {
    let first = stderr
        .lines()
        .next()
        .unwrap_or("")
        .chars()
        .take(300)
        .collect::<String>();
    if timed_out {
        return (Class::Hang, "killed at the timeout".into());
    }
    if let Some(signal) = status.signal() {
        return (Class::Signal, format!("signal {signal}: {first}"));
    }
    let code = status.code().unwrap_or(-1);
    if code == 101 || stderr.contains("panicked") {
        let line = stderr
            .lines()
            .find(|l| l.contains("panicked"))
            .unwrap_or(&first);
        return (Class::Panic, line.to_string());
    }
    for (name, bytes) in &case.files {
        match fs::read(dir.join(name)) {
            Ok(now) if digest(&now) == digest(bytes) => {}
            _ => return (Class::ChangedInput, format!("{name} changed or removed")),
        }
    }
    let mut extra = Vec::new();
    if let Ok(entries) = fs::read_dir(dir) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let given = case.files.iter().any(|(n, _)| *n == name);
            let written = code == 0 && case.outputs.contains(&name);
            if !given && !written {
                extra.push(name);
            }
        }
    }
    if !extra.is_empty() {
        return (
            Class::Leftover,
            format!("exit {code}, left {}: {first}", extra.join(", ")),
        );
    }
    if code == 0 {
        for name in &case.outputs {
            if let Err(e) = check_output(&dir.join(name)) {
                return (Class::NanOutput, format!("{name}: {e}"));
            }
        }
    }
    if !case.allowed.contains(&code) {
        return (Class::WrongExit, format!("exit {code}: {first}"));
    }
    if code != 0 && !first.starts_with("error") {
        return (
            Class::WrongExit,
            format!("exit {code} without an error message: {first:?}"),
        );
    }
    if code != 0 && stderr.contains(".tmp") {
        return (
            Class::WrongExit,
            format!("the message names a temporary: {first}"),
        );
    }
    (
        if code == 0 {
            Class::Success
        } else {
            Class::CleanError
        },
        String::new(),
    )
}

/// An output must be there, readable by the library, with finite coordinates.
fn check_output(path: &Path) -> Result<(), Failure> {
    let bytes = fs::read(path)?;
    match Format::of(path) {
        Some(Format::Png) => {
            if !bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
                return Err("not a PNG".into());
            }
        }
        Some(Format::Xy) => {
            let text = String::from_utf8(bytes)?;
            for t in text.split_whitespace() {
                if t.parse::<f64>().is_ok_and(|v| !v.is_finite()) {
                    return Err(format!("a coordinate {t}").into());
                }
            }
        }
        Some(Format::Field) | None => {
            if path.extension().is_some_and(|e| e == "json") {
                serde_json::from_slice::<serde_json::Value>(&bytes)?;
            }
        }
        Some(_) => {
            let points = std::panic::catch_unwind(|| samples_of(path).map_err(|e| e.to_string()))
                .map_err(|_| "the reader panicked")??;
            if let Some(p) = points.iter().find(|p| p.iter().any(|v| !v.is_finite())) {
                return Err(format!("a sample at {p:?}").into());
            }
        }
    }
    Ok(())
}
