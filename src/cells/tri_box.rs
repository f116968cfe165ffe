//! Exact triangle–box overlap by the separating axis theorem (Akenine-Möller, "Fast 3D
//! triangle-box overlap testing", JGT 2001): a triangle and an axis-aligned box are disjoint iff
//! their projections are disjoint on one of 13 axes — the 3 box normals, the triangle normal and
//! the 9 cross products of triangle edges with box axes. Boxes are closed: a triangle touching a
//! face overlaps the box, so a surface on a cell face marks the cells on both sides.

/// Whether the triangle `tri` overlaps the closed box with the given center and half size.
pub fn triangle_box_overlap(tri: &[[f64; 3]; 3], center: [f64; 3], half: f64) -> bool {
    let v: [[f64; 3]; 3] = tri.map(|p| [p[0] - center[0], p[1] - center[1], p[2] - center[2]]);
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let separated = |axis: [f64; 3]| {
        let r = half * (axis[0].abs() + axis[1].abs() + axis[2].abs());
        let p = v.map(|q| dot(q, axis));
        let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        lo > r || hi < -r
    };
    let units = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    if units.iter().any(|&u| separated(u)) {
        return false;
    }
    let edges = [sub(v[1], v[0]), sub(v[2], v[1]), sub(v[0], v[2])];
    if separated(cross(edges[0], edges[1])) {
        return false;
    }
    !edges
        .iter()
        .any(|&e| units.iter().any(|&u| separated(cross(e, u))))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn large_triangle_through_box_overlaps_without_vertices_inside() {
        let tri = [[-10.0, -10.0, 0.1], [10.0, -10.0, 0.1], [0.0, 10.0, 0.1]];
        assert!(triangle_box_overlap(&tri, [0.0; 3], 0.5));
        assert!(!triangle_box_overlap(&tri, [0.0, 0.0, 2.0], 0.5));
    }

    #[test]
    fn diagonal_miss_is_found_by_edge_axes() {
        // The triangle's bounding box overlaps the box, but the triangle passes the corner.
        let tri = [[1.2, 0.0, 0.0], [0.0, 1.2, 0.0], [1.2, 1.2, 0.0]];
        assert!(!triangle_box_overlap(&tri, [0.0; 3], 0.5));
        let tri_hit = [[0.9, 0.0, 0.0], [0.0, 0.9, 0.0], [0.9, 0.9, 0.0]];
        assert!(triangle_box_overlap(&tri_hit, [0.0; 3], 0.5));
    }

    #[test]
    fn agrees_with_dense_sampling() {
        // Points sampled on the triangle inside the box imply overlap (one direction of the test).
        let tri = [[0.3, -0.8, 0.2], [-0.9, 0.7, 0.65], [0.8, 0.9, -0.9]];
        for k in 0..200 {
            let c = [
                (k as f64 * 0.37).sin(),
                (k as f64 * 0.73).cos(),
                (k as f64 * 0.11).sin(),
            ];
            let h = 0.1 + 0.2 * ((k % 7) as f64 / 7.0);
            let mut hit = false;
            for a in 0..=40 {
                for b in 0..=(40 - a) {
                    let (u, w) = (a as f64 / 40.0, b as f64 / 40.0);
                    let p: [f64; 3] = std::array::from_fn(|i| {
                        tri[0][i] * (1.0 - u - w) + tri[1][i] * u + tri[2][i] * w
                    });
                    hit |= (0..3).all(|i| (p[i] - c[i]).abs() <= h);
                }
            }
            if hit {
                assert!(triangle_box_overlap(&tri, c, h), "case {k}");
            }
        }
    }
}
