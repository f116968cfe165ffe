//! Generators of synthetic shapes for rigidcells' demo, tests and benchmarks.
//!
//! Shapes are plain vertex and triangle lists; [`write_ply`] writes them as binary
//! little-endian or ASCII PLY. Nothing here depends on rigidcells, so tests can check the
//! library against shapes it did not make.

#![deny(missing_docs)]

use std::io::Write;
use std::path::Path;

/// A triangle mesh (or soup: vertices need not be shared).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub vertices: Vec<[f64; 3]>,
    /// Triangles, counter-clockwise seen from outside for closed shapes.
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// The signed volume enclosed by a closed, outward-oriented mesh (divergence theorem).
    pub fn volume(&self) -> f64 {
        signed_volume(&self.vertices, &self.triangles)
    }
}

/// The signed volume enclosed by triangles over `vertices` (divergence theorem).
pub fn signed_volume(vertices: &[[f64; 3]], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| vertices[i as usize]);
            (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]))
                / 6.0
        })
        .sum()
}

/// A closed, welded box surface `[0, size]` with `per_unit` grid divisions per unit length on
/// every face, triangulated, oriented outwards.
pub fn bar(size: [f64; 3], per_unit: f64) -> Mesh {
    let mut mesh = Mesh::default();
    let mut index = std::collections::HashMap::new();
    let n: [usize; 3] = size.map(|s| ((s * per_unit).round() as usize).max(1));
    let mut vertex = |p: [usize; 3], mesh: &mut Mesh| -> u32 {
        *index.entry(p).or_insert_with(|| {
            mesh.vertices
                .push(std::array::from_fn(|a| size[a] * p[a] as f64 / n[a] as f64));
            (mesh.vertices.len() - 1) as u32
        })
    };
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in [0, 1] {
            for i in 0..n[u] {
                for j in 0..n[v] {
                    let corner = |di: usize, dj: usize| {
                        let mut p = [0usize; 3];
                        p[axis] = side * n[axis];
                        p[u] = i + di;
                        p[v] = j + dj;
                        p
                    };
                    let q = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)]
                        .map(|p| vertex(p, &mut mesh));
                    // (u, v, axis) is right-handed: u × v = +axis, so counter-clockwise in
                    // (u, v) faces +axis; flip on the lower side.
                    if side == 1 {
                        mesh.triangles.push([q[0], q[1], q[2]]);
                        mesh.triangles.push([q[0], q[2], q[3]]);
                    } else {
                        mesh.triangles.push([q[0], q[2], q[1]]);
                        mesh.triangles.push([q[0], q[3], q[2]]);
                    }
                }
            }
        }
    }
    mesh
}

/// A non-manifold triangle soup: the bar of [`bar`] with every triangle unwelded (three
/// vertices of its own), plus two internal fins — a lengthwise one and a crosswise one — that
/// meet the walls and each other along non-manifold edges, plus a few loose triangles floating
/// near the bar as disconnected parts.
pub fn soup(size: [f64; 3], per_unit: f64) -> Mesh {
    let welded = bar(size, per_unit);
    let mut mesh = Mesh::default();
    let push = |tri: [[f64; 3]; 3], mesh: &mut Mesh| {
        let base = mesh.vertices.len() as u32;
        mesh.vertices.extend(tri);
        mesh.triangles.push([base, base + 1, base + 2]);
    };
    for t in &welded.triangles {
        push(t.map(|i| welded.vertices[i as usize]), &mut mesh);
    }
    let fin = |mesh: &mut Mesh, a: [f64; 3], du: [f64; 3], dv: [f64; 3], nu: usize, nv: usize| {
        for i in 0..nu {
            for j in 0..nv {
                let p = |di: f64, dj: f64| -> [f64; 3] {
                    std::array::from_fn(|k| {
                        a[k] + du[k] * (i as f64 + di) / nu as f64
                            + dv[k] * (j as f64 + dj) / nv as f64
                    })
                };
                let base = mesh.vertices.len() as u32;
                mesh.vertices
                    .extend([p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)]);
                mesh.triangles.push([base, base + 1, base + 2]);
                mesh.triangles.push([base, base + 2, base + 3]);
            }
        }
    };
    let nx = (size[0] * per_unit).round().max(1.0) as usize;
    let ny = (size[1] * per_unit).round().max(1.0) as usize;
    let nz = (size[2] * per_unit).round().max(1.0) as usize;
    fin(
        &mut mesh,
        [0.0, 0.5 * size[1], 0.0],
        [size[0], 0.0, 0.0],
        [0.0, 0.0, size[2]],
        nx,
        nz,
    );
    fin(
        &mut mesh,
        [0.5 * size[0], 0.0, 0.0],
        [0.0, size[1], 0.0],
        [0.0, 0.0, size[2]],
        ny,
        nz,
    );
    for k in 0..8 {
        let x = size[0] * (k as f64 + 0.5) / 8.0;
        let z = size[2] + 0.3 + 0.05 * k as f64;
        push(
            [[x, 0.2, z], [x + 0.2, 0.2, z], [x, 0.4, z + 0.1]],
            &mut mesh,
        );
    }
    mesh
}

/// `mesh` with every triangle split into 4 at its edge midpoints (shared edges share their
/// midpoint, so a welded mesh stays welded).
pub fn subdivide(mesh: &Mesh) -> Mesh {
    let mut out = Mesh {
        vertices: mesh.vertices.clone(),
        triangles: Vec::with_capacity(4 * mesh.triangles.len()),
    };
    let mut midpoints = std::collections::HashMap::new();
    let mut mid = |a: u32, b: u32, out: &mut Mesh| -> u32 {
        *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
            let (p, q) = (out.vertices[a as usize], out.vertices[b as usize]);
            out.vertices
                .push(std::array::from_fn(|k| 0.5 * (p[k] + q[k])));
            out.vertices.len() as u32 - 1
        })
    };
    for &[a, b, c] in &mesh.triangles {
        let (ab, bc, ca) = (
            mid(a, b, &mut out),
            mid(b, c, &mut out),
            mid(c, a, &mut out),
        );
        out.triangles
            .extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    out
}

/// `mesh` grown to exactly `vertices` vertices by splitting its first triangles into 3 at their
/// centroids (one new vertex each); unchanged if it already has as many.
pub fn split_to(mesh: &Mesh, vertices: usize) -> Mesh {
    let mut out = mesh.clone();
    let extra = vertices
        .saturating_sub(mesh.vertices.len())
        .min(mesh.triangles.len());
    out.triangles.clear();
    for (k, &[a, b, c]) in mesh.triangles.iter().enumerate() {
        if k < extra {
            let [p, q, r] = [a, b, c].map(|i| mesh.vertices[i as usize]);
            out.vertices
                .push(std::array::from_fn(|j| (p[j] + q[j] + r[j]) / 3.0));
            let m = out.vertices.len() as u32 - 1;
            out.triangles.extend([[a, b, m], [b, c, m], [c, a, m]]);
        } else {
            out.triangles.push([a, b, c]);
        }
    }
    out
}

/// `mesh` decimated by vertex clustering to about `vertices` vertices: vertices in one cell of
/// a regular grid merge into their mean, triangles that collapse are dropped. The grid is
/// bisected to the count.
pub fn decimate(mesh: &Mesh, vertices: usize) -> Mesh {
    let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
    for v in &mesh.vertices {
        for k in 0..3 {
            lo[k] = lo[k].min(v[k]);
            hi[k] = hi[k].max(v[k]);
        }
    }
    let longest = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    let cluster = |cell: f64| -> Mesh {
        let mut index = std::collections::HashMap::new();
        let mut sums: Vec<([f64; 3], f64)> = Vec::new();
        let map: Vec<u32> = mesh
            .vertices
            .iter()
            .map(|v| {
                let key: [i64; 3] = std::array::from_fn(|k| ((v[k] - lo[k]) / cell) as i64);
                let i = *index.entry(key).or_insert_with(|| {
                    sums.push(([0.0; 3], 0.0));
                    sums.len() as u32 - 1
                });
                let s = &mut sums[i as usize];
                for (sum, x) in s.0.iter_mut().zip(v) {
                    *sum += x;
                }
                s.1 += 1.0;
                i
            })
            .collect();
        let triangles = mesh
            .triangles
            .iter()
            .map(|t| t.map(|i| map[i as usize]))
            .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
            .collect();
        Mesh {
            vertices: sums.iter().map(|(s, n)| s.map(|v| v / n)).collect(),
            triangles,
        }
    };
    let (mut small, mut large) = (longest / 1e5, longest);
    for _ in 0..30 {
        let mid = (small * large).sqrt();
        if cluster(mid).vertices.len() > vertices {
            small = mid
        } else {
            large = mid
        }
    }
    cluster(large)
}

/// The next of xorshift64* `state`'s numbers, uniform in [0, 1): every generator here draws
/// from it, so that a scene is the same on every machine.
fn uniform(state: &mut u64) -> f64 {
    *state ^= *state >> 12;
    *state ^= *state << 25;
    *state ^= *state >> 27;
    (state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
}

/// A tree as in the paper's Fig. 9: a closed trunk (a welded bar of 0.4 × 0.4 × 4 along z,
/// from the origin) and `leaves` disconnected triangles of edge about 0.15, every one with its
/// own vertices, scattered in a ball of radius 1.5 around the trunk's top (reproducible).
pub fn leafy_tree(leaves: usize) -> Mesh {
    let mut mesh = bar([0.4, 0.4, 4.0], 8.0);
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut rand = move || uniform(&mut state) * 2.0 - 1.0;
    let top = [0.2, 0.2, 4.5];
    let trunk = mesh.triangles.len();
    while mesh.triangles.len() < trunk + leaves {
        let c = [rand(), rand(), rand()];
        if c.iter().map(|v| v * v).sum::<f64>() > 1.0 {
            continue;
        }
        let at: [f64; 3] = std::array::from_fn(|k| top[k] + 1.5 * c[k]);
        let base = mesh.vertices.len() as u32;
        for _ in 0..3 {
            let v = [rand(), rand(), rand()];
            mesh.vertices
                .push(std::array::from_fn(|k| at[k] + 0.1 * v[k]));
        }
        mesh.triangles.push([base, base + 1, base + 2]);
    }
    mesh
}

/// Writes `mesh` as PLY (`float x y z` vertices, `uchar int` face lists), binary
/// little-endian or ASCII.
pub fn write_ply(path: &Path, mesh: &Mesh, binary: bool) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    write!(
        out,
        "ply\nformat {} 1.0\ncomment generated by rigidcells data_gen\ncomment up z\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        if binary {
            "binary_little_endian"
        } else {
            "ascii"
        },
        mesh.vertices.len(),
        mesh.triangles.len()
    )?;
    for v in &mesh.vertices {
        if binary {
            for c in v {
                out.write_all(&(*c as f32).to_le_bytes())?;
            }
        } else {
            writeln!(out, "{} {} {}", v[0] as f32, v[1] as f32, v[2] as f32)?;
        }
    }
    for t in &mesh.triangles {
        if binary {
            out.write_all(&[3u8])?;
            for i in t {
                out.write_all(&(*i as i32).to_le_bytes())?;
            }
        } else {
            writeln!(out, "3 {} {} {}", t[0], t[1], t[2])?;
        }
    }
    out.flush()
}

/// An edit spec (TOML) over the box `lo..hi` that fixes the western `end` fraction along x and
/// lifts the eastern `end` fraction by `lift`, turned by `degrees` about y: the bend of the
/// streaming benchmarks and tests.
pub fn end_lift_spec(lo: [f64; 3], hi: [f64; 3], end: f64, lift: f64, degrees: f64) -> String {
    let w = hi[0] - lo[0];
    format!(
        "[[fixed]]\nbox = {{ min = [{}, {}, {}], max = [{}, {}, {}] }}\n\
         [[handle]]\nbox = {{ min = [{}, {}, {}], max = [{}, {}, {}] }}\n\
         translate = [0, 0, {lift}]\nrotate = {{ axis = [0, 1, 0], degrees = {degrees} }}\n",
        lo[0] - 1.0,
        lo[1] - 1.0,
        lo[2] - 1.0,
        lo[0] + end * w,
        hi[1] + 1.0,
        hi[2] + 1.0,
        hi[0] - end * w,
        lo[1] - 1.0,
        lo[2] - 1.0,
        hi[0] + 1.0,
        hi[1] + 1.0,
        hi[2] + 1.0,
    )
}

/// A closed thick-walled tube along x: length `length`, outer radius `outer`, inner radius
/// `inner`, `around` vertices per ring and `along` segments, outward oriented (the
/// benchmark's 480k-vertex tube is `tube(10.0, 1.0, 0.8, 400, 599)`).
pub fn tube(length: f64, outer: f64, inner: f64, around: usize, along: usize) -> Mesh {
    let (n, m) = (around.max(3), along.max(1));
    let mut mesh = Mesh::default();
    for radius in [outer, inner] {
        for i in 0..=m {
            let x = length * i as f64 / m as f64;
            for j in 0..n {
                let t = std::f64::consts::TAU * j as f64 / n as f64;
                mesh.vertices.push([x, radius * t.cos(), radius * t.sin()]);
            }
        }
    }
    let at = |surface: usize, i: usize, j: usize| ((surface * (m + 1) + i) * n + j % n) as u32;
    for i in 0..m {
        for j in 0..n {
            let q = |s| {
                [
                    at(s, i, j),
                    at(s, i, j + 1),
                    at(s, i + 1, j + 1),
                    at(s, i + 1, j),
                ]
            };
            // Around, then along, is outward on the outer wall; the inner wall faces the axis.
            let [a, b, c, d] = q(0);
            mesh.triangles.extend([[a, b, c], [a, c, d]]);
            let [a, b, c, d] = q(1);
            mesh.triangles.extend([[a, c, b], [a, d, c]]);
        }
    }
    for j in 0..n {
        // The annular ends: −x at x = 0, +x at x = length.
        let (o0, o1, i0, i1) = (at(0, 0, j), at(0, 0, j + 1), at(1, 0, j), at(1, 0, j + 1));
        mesh.triangles.extend([[o0, i0, o1], [o1, i0, i1]]);
        let (o0, o1, i0, i1) = (at(0, m, j), at(0, m, j + 1), at(1, m, j), at(1, m, j + 1));
        mesh.triangles.extend([[o0, o1, i0], [o1, i1, i0]]);
    }
    mesh
}

/// A closed solid cylinder along y: radius `radius`, from y = 0 to y = `height`, `around`
/// vertices per ring and `along` segments, with flat caps (rings shrinking to the axis in
/// `around / 4` steps), outward oriented. Short ones (height = diameter) are the twist tests'
/// bulky part.
pub fn cylinder(radius: f64, height: f64, around: usize, along: usize) -> Mesh {
    let (n, m) = (around.max(3), along.max(1));
    let mut mesh = Mesh::default();
    let ring = |mesh: &mut Mesh, r: f64, y: f64| {
        let first = mesh.vertices.len() as u32;
        for j in 0..n {
            let t = std::f64::consts::TAU * j as f64 / n as f64;
            mesh.vertices.push([r * t.cos(), y, r * t.sin()]);
        }
        first
    };
    let rings: Vec<u32> = (0..=m)
        .map(|i| ring(&mut mesh, radius, height * i as f64 / m as f64))
        .collect();
    // Quads between rings `a` and `b`, split in two; `up` says which way they face.
    let band = |mesh: &mut Mesh, a: u32, b: u32, out: bool| {
        for j in 0..n as u32 {
            let k = (j + 1) % n as u32;
            let (p, q, r, s) = (a + j, a + k, b + k, b + j);
            if out {
                mesh.triangles.extend([[p, r, q], [p, s, r]]);
            } else {
                mesh.triangles.extend([[p, q, r], [p, r, s]]);
            }
        }
    };
    for i in 0..m {
        band(&mut mesh, rings[i], rings[i + 1], true);
    }
    let steps = (n / 4).max(1);
    for (edge, y, down) in [(rings[0], 0.0, true), (rings[m], height, false)] {
        let mut outer = edge;
        for k in 1..steps {
            let inner = ring(&mut mesh, radius * (1.0 - k as f64 / steps as f64), y);
            band(&mut mesh, outer, inner, !down);
            outer = inner;
        }
        let center = mesh.vertices.len() as u32;
        mesh.vertices.push([0.0, y, 0.0]);
        for j in 0..n as u32 {
            let (p, q) = (outer + j, outer + (j + 1) % n as u32);
            mesh.triangles
                .push(if down { [p, q, center] } else { [p, center, q] });
        }
    }
    mesh
}

/// Height of the synthetic terrain at `(x, y)` (metres; a 2 km square): rolling hills, a river
/// valley along y = 1000, flat-roofed buildings on a grid, and a bridge deck across the valley.
pub fn terrain_height(x: f64, y: f64) -> (f64, u8) {
    let hills = 20.0 * (x / 170.0).sin() * (y / 230.0).cos() + 8.0 * (x / 53.0 + y / 71.0).sin();
    let valley = -25.0 * (-((y - 1000.0) / 60.0).powi(2)).exp();
    let ground = 100.0 + hills + valley;
    // Bridge: a deck 12 m wide at x in [990, 1002], y in [850, 1150].
    if (990.0..1002.0).contains(&x) && (850.0..1150.0).contains(&y) {
        return (112.0, 17);
    }
    // Buildings: 40 m blocks every 150 m, away from the valley.
    let (bx, by) = (x.rem_euclid(150.0), y.rem_euclid(150.0));
    if bx < 40.0 && by < 40.0 && (y - 1000.0).abs() > 150.0 {
        let storeys = 3.0 + ((x / 150.0).floor() + (y / 150.0).floor()).rem_euclid(5.0) * 3.0;
        return (ground + storeys * 3.0, 6);
    }
    (ground, 2)
}

/// A road corridor 1 km × 200 m at `(x, y)`: a road 12 m wide along the middle (y = 100) at a
/// grade rolling ±15 m; banks rising from it at 15 % with hummocks; stands of trees up to 18 m
/// on the banks (a sample there lies at a height `u` ∈ [0, 1) of the canopy: returns through
/// it); and a row of 20 m buildings 8 m high every 100 m on the north side, with their walls
/// sampled. z spans about 50 m. Returns the height and the LAS class.
pub fn corridor_height(x: f64, y: f64, u: f64) -> (f64, u8) {
    let grade = 100.0 + 15.0 * (x / 200.0).sin();
    let off = (y - 100.0).abs();
    if off < 6.0 {
        return (grade, 11);
    }
    let bank = grade + 0.15 * (off - 6.0) + 5.0 * (x / 53.0 + y / 71.0).sin() * (off / 100.0);
    let (bx, by) = (x.rem_euclid(100.0), y - 160.0);
    if (0.0..20.0).contains(&bx) && (0.0..20.0).contains(&by) {
        let wall = bx.min(20.0 - bx).min(by).min(20.0 - by) < 1.0;
        return (bank + if wall { 8.0 * u } else { 8.0 }, 6);
    }
    if off > 15.0 && (x / 37.0).sin() * (y / 23.0).cos() > 0.3 {
        return (bank + 18.0 * u, 5);
    }
    (bank, 2)
}

/// Rolling ground under low vegetation: hills of tens of metres and every point raised by up
/// to 3 m (LAS class 3), so that the cells of a metre or two fill columns two or three cells
/// deep and every cell is a boundary cell (the solver benchmark's scene).
pub fn vegetation_height(x: f64, y: f64, u: f64) -> (f64, u8) {
    let ground = 100.0 + 20.0 * (x / 170.0).sin() + 8.0 * (y / 60.0 + x / 310.0).cos();
    (ground + 3.0 * u, 3)
}

/// Seeded smooth relief: a sum of plane waves in random directions, their wavelengths spread
/// by an octave either side of `wavelength` and their amplitudes falling with it, scaled so
/// that the heights span about `span` metres (a hilly scan's ground: 50 m over hills 100 m
/// apart makes slopes near 45°, cells of a few metres filling columns two or three deep).
#[derive(Debug, Clone)]
pub struct Relief {
    /// Per wave: the wave vector (radians a metre, x and y), its phase and its amplitude.
    waves: Vec<([f64; 2], f64, f64)>,
}

impl Relief {
    /// `span`: the heights' range, metres; `wavelength`: the hills' spacing, metres.
    pub fn new(span: f64, wavelength: f64, seed: u64) -> Self {
        let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut rand = move || uniform(&mut state);
        const WAVES: usize = 24;
        let mut waves: Vec<([f64; 2], f64, f64)> = (0..WAVES)
            .map(|_| {
                let angle = std::f64::consts::TAU * rand();
                let length = wavelength * 2f64.powf(2.0 * rand() - 1.0);
                let k = std::f64::consts::TAU / length;
                let phase = std::f64::consts::TAU * rand();
                (
                    [k * angle.cos(), k * angle.sin()],
                    phase,
                    length / wavelength,
                )
            })
            .collect();
        // Sum of WAVES unit-amplitude waves: a standard deviation of sqrt(WAVES / 2) times the
        // mean amplitude; ±2 standard deviations span `span`.
        let rms = (waves.iter().map(|w| w.2 * w.2).sum::<f64>() / 2.0).sqrt();
        for w in &mut waves {
            w.2 *= span / (4.0 * rms);
        }
        Self { waves }
    }

    /// The height at `(x, y)`, metres about zero.
    pub fn height(&self, x: f64, y: f64) -> f64 {
        self.waves
            .iter()
            .map(|([kx, ky], phase, a)| a * (kx * x + ky * y + phase).sin())
            .sum()
    }
}

/// A synthetic scan's samples: points on a jittered grid over a rectangle at georeferenced
/// coordinates (x from 500 000, y from 5 000 000), z from a height function with 2 cm of
/// noise. Reproducible (xorshift64*).
pub struct Terrain {
    columns: u64,
    step: [f64; 2],
    height: Box<dyn Fn(f64, f64, f64) -> (f64, u8) + Send>,
    state: u64,
}

impl Terrain {
    /// The 2 km × 2 km terrain of [`terrain_height`], `n` samples.
    pub fn new(n: u64) -> Self {
        Self::over(n, [2000.0, 2000.0], |x, y, _| terrain_height(x, y))
    }

    /// The 1 km × 200 m road corridor of [`corridor_height`], `n` samples (the scale
    /// benchmark's scan).
    pub fn corridor(n: u64) -> Self {
        Self::over(n, [1000.0, 200.0], corridor_height)
    }

    /// A 1 km × 200 m strip of [`vegetation_height`], `n` samples.
    pub fn vegetation(n: u64) -> Self {
        Self::over(n, [1000.0, 200.0], vegetation_height)
    }

    /// A 1 km × 200 m strip of [`Relief`] ground under up to 3 m of low vegetation, `n`
    /// samples: the vegetation scene with the hills of a chosen height, steepness and seed.
    pub fn rough(n: u64, relief: Relief) -> Self {
        Self::over(n, [1000.0, 200.0], move |x, y, u| {
            (100.0 + relief.height(x, y) + 3.0 * u, 3)
        })
    }

    fn over(
        n: u64,
        extent: [f64; 2],
        height: impl Fn(f64, f64, f64) -> (f64, u8) + Send + 'static,
    ) -> Self {
        // Square cells of the jittered grid: columns / rows = width / depth.
        let aspect = extent[0] / extent[1];
        let columns = ((n as f64) * aspect).sqrt().ceil().max(1.0) as u64;
        let rows = ((n as f64) / aspect).sqrt().ceil().max(1.0) as u64;
        Self {
            columns,
            step: [extent[0] / columns as f64, extent[1] / rows as f64],
            height: Box::new(height),
            state: 0x9E37_79B9_7F4A_7C15,
        }
    }

    fn rand(&mut self) -> f64 {
        uniform(&mut self.state)
    }

    /// Sample `k` (call in order): local x, y, z and its LAS class.
    pub fn sample(&mut self, k: u64) -> (f64, f64, f64, u8) {
        let x = (k % self.columns) as f64 * self.step[0] + self.rand() * self.step[0];
        let y = (k / self.columns) as f64 * self.step[1] + self.rand() * self.step[1];
        // The height within a column (a canopy's, a wall's): golden-ratio steps over k, so the
        // jitter's stream stays that of the plain terrain.
        let u = (k as f64 * 0.618_033_988_749_894_9).fract();
        let (z, class) = (self.height)(x, y, u);
        (x, y, z + 0.02 * (self.rand() - 0.5), class)
    }
}

/// Writes the terrain of `n` samples as a binary little-endian PLY point cloud as scanners
/// export it: double `x y z` (georeferenced), `uchar red green blue`, `uchar class`,
/// `float intensity`.
pub fn write_ply_terrain(path: &Path, n: u64) -> std::io::Result<()> {
    use std::io::Write;
    let mut out = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(path)?);
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment rigidcells data_gen terrain\ncomment up z\n\
         element vertex {n}\nproperty double x\nproperty double y\nproperty double z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         property uchar class\nproperty float intensity\nend_header\n"
    )?;
    let mut terrain = Terrain::new(n);
    for k in 0..n {
        let (x, y, z, class) = terrain.sample(k);
        for v in [x + 500_000.0, y + 5_000_000.0, z] {
            out.write_all(&v.to_le_bytes())?;
        }
        let c = (class % 6) * 40;
        out.write_all(&[c, (z * 3.0) as u8, 255 - c, class])?;
        out.write_all(&((z * 100.0) as f32).to_le_bytes())?;
    }
    out.flush()
}

/// Writes a LAS 1.2 (or LAZ) scan of `n` points of [`terrain_height`] (point format 3: GPS time
/// and RGB; UTM-like offsets around 500 000 / 5 000 000, scale 1 mm), streaming in chunks.
pub fn write_las_terrain(path: &Path, n: u64, compressed: bool) -> Result<(), las::Error> {
    write_las(path, Terrain::new(n), n, compressed)
}

/// The order of a generated scan's records.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Order {
    /// As scanned: row after row of the jittered grid.
    Scan,
    /// A random permutation of the records (merged flight lines, time order, other tools'
    /// output: no spatial order at all).
    Shuffled,
    /// Sorted into strips 1 m wide along y, by x within a strip (what a tiling tool writes).
    Strips,
}

impl std::str::FromStr for Order {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "scan" => Ok(Self::Scan),
            "shuffled" => Ok(Self::Shuffled),
            "strips" => Ok(Self::Strips),
            _ => Err(format!("`{s}`: the order is scan, shuffled or strips")),
        }
    }
}

/// Writes `n` samples of `terrain` as [`write_las_terrain`] does.
pub fn write_las(
    path: &Path,
    terrain: Terrain,
    n: u64,
    compressed: bool,
) -> Result<(), las::Error> {
    write_las_ordered(path, terrain, n, compressed, Order::Scan)
}

/// Bytes of a point format 3 record.
const RECORD: usize = 34;

/// The format 3 record of sample `k` at local `x y z` with `class`.
fn record(bytes: &mut Vec<u8>, k: u64, (x, y, z, class): (f64, f64, f64, u8)) {
    let raw = |v: f64| (v / 0.001).round() as i32;
    bytes.extend_from_slice(&raw(x).to_le_bytes());
    bytes.extend_from_slice(&raw(y).to_le_bytes());
    bytes.extend_from_slice(&raw(z).to_le_bytes());
    bytes.extend_from_slice(&((z * 100.0) as u16).to_le_bytes()); // intensity
    bytes.push(0b0000_1001); // return 1 of 1
    bytes.push(class);
    bytes.push(0); // scan angle
    bytes.push((k % 251) as u8); // user data
    bytes.extend_from_slice(&((k / 100_000) as u16).to_le_bytes()); // point source
    bytes.extend_from_slice(&(k as f64 * 1e-5).to_le_bytes()); // GPS time
    let c = (class as u16 % 16) * 4000;
    for v in [c, (z * 300.0) as u16, 65535 - c] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
}

/// Writes `n` samples of `terrain` as [`write_las_terrain`] does, the records in `order`
/// (other than [`Order::Scan`], every record is held in memory first: 34 bytes a sample).
pub fn write_las_ordered(
    path: &Path,
    mut terrain: Terrain,
    n: u64,
    compressed: bool,
    order: Order,
) -> Result<(), las::Error> {
    use las::{Builder, LazParallelism, PointDataBuilder, Transform, Vector, WriterOptions};
    let mut b = Builder::from((1, 2));
    b.point_format = las::point::Format::new(3)?;
    b.point_format.is_compressed = compressed;
    let t = |o: f64| Transform {
        scale: 0.001,
        offset: o,
    };
    b.transforms = Vector {
        x: t(500_000.0),
        y: t(5_000_000.0),
        z: t(0.0),
    };
    b.generating_software = "rigidcells data_gen".into();
    let header = b.into_header()?;
    let transforms = *header.transforms();
    let format = *header.point_format();
    let file = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(path)?);
    let mut w = las::Writer::with_options(
        file,
        header,
        WriterOptions::default().with_laz_parallelism(LazParallelism::Yes),
    )?;
    let chunk = 1u64 << 20;
    let mut write = |bytes: Vec<u8>| -> Result<(), las::Error> {
        let pd = PointDataBuilder::new()
            .with_format(format)
            .with_transforms(transforms)
            .build_from_bytes(bytes)?;
        w.write_points(&pd)
    };
    if order == Order::Scan {
        let mut i = 0u64;
        while i < n {
            let m = chunk.min(n - i);
            let mut bytes = Vec::with_capacity(m as usize * RECORD);
            for k in i..i + m {
                record(&mut bytes, k, terrain.sample(k));
            }
            write(bytes)?;
            i += m;
        }
    } else {
        let mut all = Vec::with_capacity(n as usize * RECORD);
        let mut keys = Vec::with_capacity(n as usize);
        for k in 0..n {
            let sample = terrain.sample(k);
            keys.push((sample.1.floor() as i64, sample.0, k));
            record(&mut all, k, sample);
        }
        let mut by: Vec<u64> = match order {
            Order::Strips => {
                keys.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
                keys.iter().map(|k| k.2).collect()
            }
            _ => {
                let mut by: Vec<u64> = (0..n).collect();
                for i in (1..by.len()).rev() {
                    let j = (terrain.rand() * (i + 1) as f64) as usize;
                    by.swap(i, j.min(i));
                }
                by
            }
        };
        drop(keys);
        for run in by.chunks_mut(chunk as usize) {
            let mut bytes = Vec::with_capacity(run.len() * RECORD);
            for &mut k in run {
                let k = k as usize * RECORD;
                bytes.extend_from_slice(&all[k..k + RECORD]);
            }
            write(bytes)?;
        }
    }
    w.close()
}

/// A gingerbread figure for the 2D image deformation (paper Fig. 7): a `240 × 240` RGBA picture,
/// transparent around a head, a body, two arms held out sideways and two legs, textured with a
/// fine pattern (so that moved pixels can be recognized). Returns `(width, height, rgba)`.
pub fn gingerbread() -> (u32, u32, Vec<u8>) {
    let (w, h) = (240u32, 240u32);
    let inside = |x: f64, y: f64| {
        let disc = |cx: f64, cy: f64, r: f64| (x - cx).powi(2) + (y - cy).powi(2) <= r * r;
        let rect = |x0: f64, y0: f64, x1: f64, y1: f64| x >= x0 && x <= x1 && y >= y0 && y <= y1;
        disc(120.0, 45.0, 27.0)
            || rect(92.0, 60.0, 148.0, 160.0)
            || rect(20.0, 85.0, 220.0, 125.0)
            || disc(20.0, 105.0, 20.0)
            || disc(220.0, 105.0, 20.0)
            || rect(94.0, 150.0, 116.0, 228.0)
            || rect(124.0, 150.0, 146.0, 228.0)
    };
    let mut rgba = Vec::with_capacity((4 * w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            if inside(x as f64 + 0.5, y as f64 + 0.5) {
                let icing = (x / 6 + y / 6) % 5 == 0;
                rgba.extend_from_slice(&if icing {
                    [250, 245, 235, 255]
                } else {
                    [
                        (140 + (x * 7 + y * 3) % 50) as u8,
                        (80 + (x * 3 + y * 11) % 40) as u8,
                        (40 + (x + y * 5) % 25) as u8,
                        255,
                    ]
                });
            } else {
                rgba.extend_from_slice(&[0, 0, 0, 0]);
            }
        }
    }
    (w, h, rgba)
}

/// An edit of [`gingerbread`] in pixel coordinates: the legs fixed, the left hand raised by
/// 30 pixels and the right hand lowered by 25.
pub const GINGERBREAD_SPEC: &str = "\
# The gingerbread figure: legs fixed, left hand up, right hand down (pixel coordinates, y down).
[[fixed]]
box = { min = [90.0, 185.0], max = [150.0, 240.0] }

[[handle]]
box = { min = [0.0, 80.0], max = [40.0, 130.0] }
translate = [0.0, -30.0]

[[handle]]
box = { min = [200.0, 80.0], max = [240.0, 130.0] }
translate = [0.0, 25.0]
";

#[cfg(test)]
mod tests {

    /// The tube is closed and outward oriented: its signed volume is the polygonal annulus's
    /// area times its length.
    #[test]
    fn tube_encloses_its_wall() {
        let (n, length, r_out, r_in) = (64usize, 3.0, 1.0, 0.7);
        let mesh = tube(length, r_out, r_in, n, 10);
        let polygon = |r: f64| 0.5 * n as f64 * r * r * (std::f64::consts::TAU / n as f64).sin();
        let expected = (polygon(r_out) - polygon(r_in)) * length;
        assert!(
            (mesh.volume() - expected).abs() < 1e-9 * expected,
            "{}",
            mesh.volume()
        );
        assert_eq!(mesh.vertices.len(), 2 * 11 * n);
    }

    use super::*;

    /// Every edge of `m` is shared by exactly two triangles, in opposite directions.
    fn assert_welded_and_closed(m: &Mesh) {
        let mut edges = std::collections::HashMap::new();
        for t in &m.triangles {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        assert!(
            edges
                .iter()
                .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
        );
    }

    #[test]
    fn bar_is_closed_and_outward() {
        let m = bar([10.0, 1.0, 1.0], 4.0);
        assert!((m.volume() - 10.0).abs() < 1e-9);
        assert_welded_and_closed(&m);
    }

    /// The cylinder is closed, welded and outward oriented: its signed volume is the polygonal
    /// disk's area times its height, and every edge has two triangles in opposite directions.
    #[test]
    fn cylinder_is_closed_and_outward() {
        let (n, r, h) = (48usize, 0.5, 1.0);
        let m = cylinder(r, h, n, 24);
        let disk = 0.5 * n as f64 * r * r * (std::f64::consts::TAU / n as f64).sin();
        assert!((m.volume() - disk * h).abs() < 1e-9, "{}", m.volume());
        assert_welded_and_closed(&m);
    }

    #[test]
    fn soup_keeps_the_volume_of_its_walls() {
        let m = soup([10.0, 1.0, 1.0], 4.0);
        let walls = bar([10.0, 1.0, 1.0], 4.0).triangles.len();
        assert!((signed_volume(&m.vertices, &m.triangles[..walls]) - 10.0).abs() < 1e-9);
        // Unwelded: no two wall triangles share a vertex index.
        let mut seen = std::collections::HashSet::new();
        assert!(
            m.triangles[..walls]
                .iter()
                .flatten()
                .all(|i| seen.insert(*i))
        );
        assert!(m.triangles.len() > walls);
    }
}
