//! Several files read as one [`Source`]: their samples one file after another, numbered across
//! them, so that pass 1 over a set of tiles builds the cells the merged file would give
//! (`rigidcells solve TILE…`; each tile is then deformed on its own by `apply`).

use std::path::{Path, PathBuf};

use super::stream::{Bounds, Chunk, Sink, Source};
use crate::error::{Error, Result};
use crate::said::{Opt, Said};

/// The files of a set of tiles as one source.
pub struct Tiles {
    sources: Vec<Box<dyn Source>>,
    /// The index of each file's first sample.
    offsets: Vec<u64>,
    len: u64,
    current: usize,
}

impl Tiles {
    /// Opens every file of `paths` (at least one). Meshes are refused: a triangle cannot span
    /// two files.
    pub fn open(paths: &[PathBuf]) -> Result<Self> {
        if paths.is_empty() {
            return Err(Error::param("no input files"));
        }
        let mut sources = Vec::with_capacity(paths.len());
        let (mut offsets, mut len) = (Vec::with_capacity(paths.len()), 0u64);
        for p in paths {
            let s = super::open(p)?;
            if !s.triangles().is_empty() && paths.len() > 1 {
                return Err(Error::param(format!(
                    "{}: a mesh cannot be one of several tiles (its triangles would span \
                     them); give it alone",
                    p.display()
                )));
            }
            offsets.push(len);
            len = len.saturating_add(s.len());
            sources.push(s);
        }
        Ok(Self {
            sources,
            offsets,
            len,
            current: 0,
        })
    }

    /// Refuses, unless `same` (`--same-crs`), tiles whose coordinate systems differ
    /// ([`crate::crs::check`]), each compared with the first that declares one; returns the
    /// warnings of tiles that declare none beside one that does.
    pub fn check_crs(&self, same: bool) -> Result<Vec<Said>> {
        let systems: Vec<_> = self.sources.iter().map(|s| (s.crs(), s.path())).collect();
        let Some((first, first_path)) = systems.iter().find(|(c, _)| c.is_some()) else {
            return Ok(Vec::new());
        };
        let mut warnings = Vec::new();
        for (crs, path) in &systems {
            if path == first_path {
                continue;
            }
            warnings.extend(crate::crs::check(
                "the tiles' coordinate systems differ",
                (first.as_ref(), first_path),
                (crs.as_ref(), path),
                same,
                Said::from("reproject the tiles into one system, or pass ")
                    .opt(Opt::SameCrs)
                    .text(" if both describe the same one"),
            )?);
        }
        Ok(warnings)
    }

    fn next(&mut self, max: usize, chunk: &mut Chunk, samples: bool) -> Result<usize> {
        while self.current < self.sources.len() {
            let s = &mut self.sources[self.current];
            let n = if samples {
                s.read_samples(max, chunk)?
            } else {
                s.read(max, chunk)?
            };
            if n > 0 {
                chunk.first += self.offsets[self.current];
                return Ok(n);
            }
            self.current += 1;
        }
        Ok(0)
    }
}

impl Source for Tiles {
    fn path(&self) -> &Path {
        self.sources[self.current.min(self.sources.len() - 1)].path()
    }

    fn len(&self) -> u64 {
        self.len
    }

    /// The union of the files' header bounds, when every file declares them.
    fn bounds_hint(&self) -> Option<Bounds> {
        self.sources
            .iter()
            .try_fold(None, |acc: Option<Bounds>, s| {
                let (lo, hi) = s.bounds_hint()?;
                Some(Some(match acc {
                    None => (lo, hi),
                    Some((a, b)) => (a.inf(&lo), b.sup(&hi)),
                }))
            })?
    }

    fn has_classes(&self) -> bool {
        self.sources.iter().all(|s| s.has_classes())
    }

    /// The first file's that declares one ([`Tiles::check_crs`] checks that the others agree).
    fn crs(&self) -> Option<crate::crs::Crs> {
        self.sources.iter().find_map(|s| s.crs())
    }

    fn triangles(&self) -> &[[u32; 3]] {
        match self.sources.as_slice() {
            [one] => one.triangles(),
            _ => &[],
        }
    }

    fn rewind(&mut self) -> Result<()> {
        for s in &mut self.sources {
            s.rewind()?;
        }
        self.current = 0;
        Ok(())
    }

    fn read(&mut self, max: usize, chunk: &mut Chunk) -> Result<usize> {
        self.next(max, chunk, false)
    }

    fn read_samples(&mut self, max: usize, chunk: &mut Chunk) -> Result<usize> {
        self.next(max, chunk, true)
    }

    fn sink(&self, output: &Path, _bounds: Option<Bounds>) -> Result<Box<dyn Sink>> {
        Err(Error::param(format!(
            "{}: a set of tiles is solved, not written: `apply` the field to each tile",
            output.display()
        )))
    }
}
