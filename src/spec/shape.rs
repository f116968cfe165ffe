//! The regions of space a field keeps exact to their own border ([`Shape`]): the spec's boxes,
//! spheres, half-spaces and polygons, and what `All`, `Not` and several entries make of them.
//!
//! **Why a field carries them.** A region's cells are prescribed by their centers (the cells
//! whose center lies in it; [`crate::solve::constraints`]), so the cells that straddle its
//! border are free and the turn between two regions starts where the regions end, not up to a
//! cell past them. The exact layer ([`crate::field::FieldMap`]) then takes a sample inside the region
//! to the region's map as it came, and blends the map into the transfer over the band of four
//! of the smallest cells measured from the region itself — by [`Shape::signed_distance`] —
//! instead of from the staircase of its cells.
//!
//! [`Shape::contains`] answers as [`Region::contains_point`] does, bit for bit, so every sample
//! the spec selects is exact. [`Shape::signed_distance`] is negative inside and positive
//! outside, and 1-Lipschitz (a voxel whose center is farther than its half-diagonal from the
//! border lies wholly on one side): the Euclidean distance to the border for a box, a sphere,
//! a half-space and a polygon's prism; for several regions together, the largest (`All`) or
//! the least (several entries) of theirs, and for `Not` its negative, which bound it.
//! Coordinates are the input's (world), as the spec's.

use super::{Polygon, Region};
use crate::rigid::Vect;

/// A region of space with a border, in the input's coordinates.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape<const D: usize> {
    /// A box, ball, half-space or polygon's prism of the spec ([`Region::Box`],
    /// [`Region::Sphere`], [`Region::Plane`], [`Region::Polygon`]; no other).
    Part(Box<Region<D>>),
    /// The points every part holds.
    All(Vec<Shape<D>>),
    /// The points the part does not hold.
    Not(Box<Shape<D>>),
    /// The points some part holds (the entries of one role).
    Any(Vec<Shape<D>>),
}

/// How deep a shape read from a file may nest, and how many parts and ring vertices it may
/// have: a damaged file is refused, not followed.
const DEEPEST: usize = 16;
const MOST: usize = 1 << 24;

impl<const D: usize> Shape<D> {
    /// The shape of `region`, when it is a region of space with a border: not a selection of
    /// samples (indices, classes, what a camera sees) nor a polygon on a screen.
    pub fn of(region: &Region<D>) -> Option<Self> {
        // Only what a field file takes back (`Shape::read` refuses what the spec could not
        // have made: corners out of order, a zero normal, a ring of two points, non-finite
        // numbers): a field that `deform` saves, `apply` reads.
        let shape = Self::part_of(region)?;
        let mut bytes = Vec::new();
        shape.write(&mut bytes);
        Self::read(&bytes, &mut 0).filter(|back| *back == shape)
    }

    fn part_of(region: &Region<D>) -> Option<Self> {
        Some(match region {
            Region::Box { .. } | Region::Sphere { .. } | Region::Plane { .. } => {
                Self::Part(Box::new(region.clone()))
            }
            // The rings and heights alone: where they were read from is the spec's to say.
            Region::Polygon(p) => Self::Part(Box::new(Region::Polygon(Polygon::new(
                p.rings.clone(),
                p.z,
            )))),
            Region::All(parts) => {
                Self::All(parts.iter().map(Self::part_of).collect::<Option<_>>()?)
            }
            Region::Not(part) => Self::Not(Box::new(Self::part_of(part)?)),
            _ => return None,
        })
    }

    /// Whether `x` lies in the shape: [`Region::contains_point`]'s answer.
    pub fn contains(&self, x: &Vect<D>) -> bool {
        match self {
            Self::Part(r) => r.contains_point(x),
            Self::All(parts) => parts.iter().all(|s| s.contains(x)),
            Self::Not(s) => !s.contains(x),
            Self::Any(parts) => parts.iter().any(|s| s.contains(x)),
        }
    }

    /// A signed distance of `x` from the border: negative inside, positive outside,
    /// 1-Lipschitz (see the module docs).
    pub fn signed_distance(&self, x: &Vect<D>) -> f64 {
        let part = match self {
            Self::Part(r) => Some(r.as_ref()),
            _ => None,
        };
        match (self, part) {
            (_, Some(Region::Box { min, max })) => {
                let mut outside = 0.0f64;
                let mut inside = f64::NEG_INFINITY;
                for a in 0..D {
                    let d = (min[a] - x[a]).max(x[a] - max[a]);
                    outside += d.max(0.0).powi(2);
                    inside = inside.max(d);
                }
                if outside > 0.0 {
                    outside.sqrt()
                } else {
                    inside
                }
            }
            (_, Some(Region::Sphere { center, radius })) => (x - center).norm() - radius,
            (_, Some(Region::Plane { point, normal })) => (x - point).dot(normal) / normal.norm(),
            (_, Some(Region::Polygon(p))) => {
                let plane = ring_distance(p, x[0], x[1]);
                let flat = if p.contains(x[0], x[1], None) {
                    -plane
                } else {
                    plane
                };
                match (p.z, D > 2) {
                    (Some([z0, z1]), true) => {
                        let z = x[D - 1];
                        let height = (z0 - z).max(z - z1);
                        if flat > 0.0 || height > 0.0 {
                            (flat.max(0.0).powi(2) + height.max(0.0).powi(2)).sqrt()
                        } else {
                            flat.max(height)
                        }
                    }
                    _ => flat,
                }
            }
            // `Shape::of` and `Shape::read` make no other part.
            (Self::Part(_), _) => f64::INFINITY,
            (Self::All(parts), _) => parts
                .iter()
                .map(|s| s.signed_distance(x))
                .fold(f64::NEG_INFINITY, f64::max),
            (Self::Not(s), _) => -s.signed_distance(x),
            (Self::Any(parts), _) => parts
                .iter()
                .map(|s| s.signed_distance(x))
                .fold(f64::INFINITY, f64::min),
        }
    }

    /// Appends the shape to `out` (the field file's encoding: a tag, then its numbers).
    pub fn write(&self, out: &mut Vec<u8>) {
        let put = |out: &mut Vec<u8>, v: f64| out.extend_from_slice(&v.to_le_bytes());
        let part = match self {
            Self::Part(r) => Some(r.as_ref()),
            _ => None,
        };
        match (self, part) {
            (_, Some(Region::Box { min, max })) => {
                out.push(0);
                min.iter().chain(max.iter()).for_each(|&v| put(out, v));
            }
            (_, Some(Region::Sphere { center, radius })) => {
                out.push(1);
                center.iter().for_each(|&v| put(out, v));
                put(out, *radius);
            }
            (_, Some(Region::Plane { point, normal })) => {
                out.push(2);
                point.iter().chain(normal.iter()).for_each(|&v| put(out, v));
            }
            (_, Some(Region::Polygon(p))) => {
                out.push(3);
                match p.z {
                    None => out.push(0),
                    Some([z0, z1]) => {
                        out.push(1);
                        put(out, z0);
                        put(out, z1);
                    }
                }
                out.extend_from_slice(&(p.rings.len() as u32).to_le_bytes());
                for ring in &p.rings {
                    out.extend_from_slice(&(ring.len() as u32).to_le_bytes());
                    ring.iter().flatten().for_each(|&v| put(out, v));
                }
            }
            // No other part is made; it would hold no point, as no part of `Any` does.
            (Self::Part(_), _) => {
                out.push(6);
                out.extend_from_slice(&0u32.to_le_bytes());
            }
            (Self::All(parts) | Self::Any(parts), _) => {
                out.push(if matches!(self, Self::All(_)) { 4 } else { 6 });
                out.extend_from_slice(&(parts.len() as u32).to_le_bytes());
                parts.iter().for_each(|s| s.write(out));
            }
            (Self::Not(s), _) => {
                out.push(5);
                s.write(out);
            }
        }
    }

    /// Reads a shape [`Shape::write`] wrote from `bytes` at `*at`, moving `*at` past it; `None`
    /// for bytes that are not one (truncated, an unknown tag, numbers that are not finite,
    /// nesting or counts past what a spec can make).
    pub fn read(bytes: &[u8], at: &mut usize) -> Option<Self> {
        Self::read_nested(bytes, at, 0)
    }

    fn read_nested(bytes: &[u8], at: &mut usize, depth: usize) -> Option<Self> {
        if depth > DEEPEST {
            return None;
        }
        let take = |at: &mut usize, n: usize| -> Option<&[u8]> {
            let s = bytes.get(*at..at.checked_add(n)?)?;
            *at += n;
            Some(s)
        };
        let f64_at = |at: &mut usize| -> Option<f64> {
            let v = f64::from_le_bytes(take(at, 8)?.try_into().ok()?);
            v.is_finite().then_some(v)
        };
        let u32_at = |at: &mut usize| -> Option<usize> {
            let n = u32::from_le_bytes(take(at, 4)?.try_into().ok()?) as usize;
            (n <= MOST).then_some(n)
        };
        let vect = |at: &mut usize| -> Option<Vect<D>> {
            let mut v = Vect::<D>::zeros();
            for a in 0..D {
                v[a] = f64_at(at)?;
            }
            Some(v)
        };
        let parts = |at: &mut usize| -> Option<Vec<Self>> {
            let n = u32_at(at)?;
            (0..n)
                .map(|_| Self::read_nested(bytes, at, depth + 1))
                .collect()
        };
        Some(match *take(at, 1)?.first()? {
            // What the spec accepts and no more: a box with its corners in order, a radius not
            // negative, a normal not zero, a polygon's heights in order and rings of three
            // points or more.
            0 => {
                let (min, max) = (vect(at)?, vect(at)?);
                (0..D).all(|a| min[a] <= max[a]).then_some(())?;
                Self::Part(Box::new(Region::Box { min, max }))
            }
            1 => {
                let (center, radius) = (vect(at)?, f64_at(at)?);
                (radius >= 0.0).then_some(())?;
                Self::Part(Box::new(Region::Sphere { center, radius }))
            }
            2 => {
                let (point, normal) = (vect(at)?, vect(at)?);
                (normal.norm() > 0.0).then_some(())?;
                Self::Part(Box::new(Region::Plane { point, normal }))
            }
            3 => {
                let z = match *take(at, 1)?.first()? {
                    0 => None,
                    1 => Some([f64_at(at)?, f64_at(at)?]),
                    _ => return None,
                };
                let rings = (0..u32_at(at)?)
                    .map(|_| {
                        (0..u32_at(at)?)
                            .map(|_| Some([f64_at(at)?, f64_at(at)?]))
                            .collect::<Option<Vec<_>>>()
                    })
                    .collect::<Option<Vec<_>>>()?;
                if rings.is_empty()
                    || rings.iter().any(|r| r.len() < 3)
                    || z.is_some_and(|[z0, z1]| z0 > z1)
                {
                    return None;
                }
                Self::Part(Box::new(Region::Polygon(Polygon::new(rings, z))))
            }
            4 => Self::All(parts(at)?),
            5 => Self::Not(Box::new(Self::read_nested(bytes, at, depth + 1)?)),
            6 => Self::Any(parts(at)?),
            _ => return None,
        })
    }
}

/// The distance from `(x, y)` to the nearest edge of `p`'s rings.
fn ring_distance(p: &Polygon, x: f64, y: f64) -> f64 {
    let mut best = f64::INFINITY;
    for ring in &p.rings {
        let mut j = ring.len() - 1;
        for i in 0..ring.len() {
            let ([ax, ay], [bx, by]) = (ring[j], ring[i]);
            let (ex, ey) = (bx - ax, by - ay);
            let length = ex * ex + ey * ey;
            let t = if length > 0.0 {
                (((x - ax) * ex + (y - ay) * ey) / length).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let (dx, dy) = (x - ax - t * ex, y - ay - t * ey);
            best = best.min(dx * dx + dy * dy);
            j = i;
        }
    }
    best.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rigid::Vect;

    fn v(x: f64, y: f64, z: f64) -> Vect<3> {
        Vect::<3>::new(x, y, z)
    }

    #[test]
    fn a_box_measures_the_distance_to_its_faces_and_corners() {
        let s = Shape::Part(Box::new(Region::Box {
            min: v(0.0, 0.0, 0.0),
            max: v(2.0, 1.0, 1.0),
        }));
        assert_eq!(s.signed_distance(&v(1.0, 0.5, 0.5)), -0.5);
        assert_eq!(s.signed_distance(&v(3.0, 0.5, 0.5)), 1.0);
        assert!((s.signed_distance(&v(3.0, 2.0, 0.5)) - 2f64.sqrt()).abs() < 1e-15);
        assert!(s.contains(&v(2.0, 1.0, 1.0)) && !s.contains(&v(2.0 + 1e-12, 1.0, 1.0)));
    }

    #[test]
    fn a_prism_measures_its_rings_and_heights() {
        let square = vec![vec![[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]];
        let s = Shape::<3>::Part(Box::new(Region::Polygon(Polygon::new(
            square,
            Some([0.0, 1.0]),
        ))));
        assert_eq!(s.signed_distance(&v(1.0, 2.0, 0.5)), -0.5);
        assert_eq!(s.signed_distance(&v(2.0, 2.0, 3.0)), 2.0);
        assert_eq!(s.signed_distance(&v(-1.0, 2.0, 0.5)), 1.0);
        assert!((s.signed_distance(&v(-3.0, 2.0, 5.0)) - 5.0).abs() < 1e-15);
    }

    #[test]
    fn every_region_of_space_answers_as_the_spec_does_and_comes_back_from_its_bytes() {
        let ball = Region::Sphere {
            center: v(1.0, 1.0, 1.0),
            radius: 0.75,
        };
        let plane = Region::Plane {
            point: v(0.0, 0.0, 0.4),
            normal: v(0.0, 0.3, 1.0),
        };
        let lasso = Region::Polygon(Polygon::new(
            vec![
                vec![[0.0, 0.0], [2.0, 0.2], [1.0, 2.0]],
                vec![[0.5, 0.5], [1.0, 0.6], [0.9, 1.0]],
            ],
            None,
        ));
        let region = Region::All(vec![ball, Region::Not(Box::new(plane)), lasso]);
        let shape = Shape::of(&region).expect("a region of space");
        let mut bytes = Vec::new();
        Shape::Any(vec![shape.clone()]).write(&mut bytes);
        let mut at = 0;
        let back = Shape::read(&bytes, &mut at).expect("read back");
        assert_eq!(at, bytes.len());
        assert_eq!(back, Shape::Any(vec![shape.clone()]));
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 3.0 - 0.5
        };
        for _ in 0..2000 {
            let (x, y) = (v(next(), next(), next()), v(next(), next(), next()));
            assert_eq!(shape.contains(&x), region.contains_point(&x));
            assert_eq!(shape.contains(&x), shape.signed_distance(&x) <= 0.0);
            let (dx, dy) = (shape.signed_distance(&x), shape.signed_distance(&y));
            assert!(
                (dx - dy).abs() <= (x - y).norm() * (1.0 + 1e-12),
                "1-Lipschitz"
            );
        }
        assert!(Shape::<3>::read(&bytes[..bytes.len() - 1], &mut 0).is_none());
        assert_eq!(
            Shape::<3>::of(&Region::Classification([2u8].into_iter().collect())),
            None
        );
    }
}
