//! The decimated samples a `--cells N` search sizes the cells on: one sample per occupied voxel
//! of 1/1024 of the longest extent, the first to reach it in the samples' order. A file's first
//! pass gathers them chunk by chunk and samples in memory in one go, so a file and the same
//! samples in memory are sized alike.

use rustc_hash::FxHashSet;

use crate::rigid::Vect;

/// Voxels per longest extent of the decimated samples the cell size is searched on.
pub(crate) const PROXY_RESOLUTION: f64 = 1024.0;

/// Voxels along each axis of a block of [`Seen`].
const BLOCK: i64 = 16;

/// Blocks along each axis of the grid of [`Seen`]: they cover voxels `0..=PROXY_RESOLUTION`.
const BLOCKS: i64 = PROXY_RESOLUTION as i64 / BLOCK + 1;

/// The samples kept so far, and the voxels they reached.
pub(crate) struct Decimation<const D: usize> {
    lo: Vect<D>,
    voxel: f64,
    seen: Seen<D>,
    last: Option<[i64; D]>,
    /// One sample per occupied voxel (or every sample, when asked), in their order.
    pub kept: Vec<Vect<D>>,
}

impl<const D: usize> Decimation<D> {
    /// An empty decimation of samples in the box `lo`–`hi` (samples beyond it are kept per
    /// voxel too).
    pub fn new(lo: &Vect<D>, hi: &Vect<D>) -> Self {
        Self {
            lo: *lo,
            voxel: (hi - lo).max().max(f64::MIN_POSITIVE) / PROXY_RESOLUTION,
            seen: Seen::default(),
            last: None,
            kept: Vec::new(),
        }
    }

    /// Keeps the samples of `points` that reach a voxel first (all of them with `keep_all`:
    /// a mesh's triangles need every vertex).
    pub fn add(&mut self, points: &[Vect<D>], keep_all: bool) {
        for p in points {
            let key: [i64; D] =
                std::array::from_fn(|a| ((p[a] - self.lo[a]) / self.voxel).floor() as i64);
            // A scan's next sample is mostly in the voxel of the last: no lookup then.
            let new = self.last != Some(key) && self.seen.insert(key);
            self.last = Some(key);
            if keep_all || new {
                self.kept.push(*p);
            }
        }
    }
}

/// The grid's voxels seen so far: in 3D a bitmap of `16³` voxels per block, each block made
/// when a sample first reaches it (memory grows with the occupied blocks, 512 bytes each, not
/// with the grid), and a hash set for voxels off the grid (samples beyond the bounds used) and
/// in 2D. A scan in no spatial order reaches its voxels at random, which a hash set of a
/// million voxels pays for in cache misses.
struct Seen<const D: usize> {
    /// Block slot → 1 + its bitmap's index, or 0.
    blocks: Vec<u32>,
    bits: Vec<[u64; 64]>,
    off: FxHashSet<[i64; D]>,
}

impl<const D: usize> Default for Seen<D> {
    fn default() -> Self {
        Self {
            blocks: Vec::new(),
            bits: Vec::new(),
            off: FxHashSet::default(),
        }
    }
}

impl<const D: usize> Seen<D> {
    /// Marks `key` seen; whether it was new.
    fn insert(&mut self, key: [i64; D]) -> bool {
        if D != 3 || !key.iter().all(|&k| (0..BLOCKS * BLOCK).contains(&k)) {
            return self.off.insert(key);
        }
        if self.blocks.is_empty() {
            self.blocks = vec![0; (BLOCKS * BLOCKS * BLOCKS) as usize];
        }
        let slot = ((key[2] / BLOCK * BLOCKS + key[1] / BLOCK) * BLOCKS + key[0] / BLOCK) as usize;
        if self.blocks[slot] == 0 {
            self.bits.push([0; 64]);
            self.blocks[slot] = self.bits.len() as u32;
        }
        let bit =
            (key[0] % BLOCK + (key[1] % BLOCK) * BLOCK + (key[2] % BLOCK) * BLOCK * BLOCK) as usize;
        let word = &mut self.bits[self.blocks[slot] as usize - 1][bit / 64];
        let new = *word & (1 << (bit % 64)) == 0;
        *word |= 1 << (bit % 64);
        new
    }
}
