//! The order in which the transfers visit particles: particles binned by grid block, and blocks
//! grouped in colours so that P2G can scatter in parallel without atomics.
//!
//! A particle whose stencil starts at node `o` (per axis, ghost-shifted coordinates) writes to
//! the nodes `o ..= o + 2` and to the boundary points of the cells `o − 1 ..= o + 2`. Particles
//! are binned by the block `o / B` of their stencil origin, and re-binned only when they may
//! have moved more than [`SLACK`] cells since: until then block `k` writes only within
//! `k·B − 1 − S ..= k·B + B + 1 + S`. Blocks are coloured by the parity of their coordinate
//! along each axis (2^D colours): two blocks of one colour lie 2B apart along some axis, and
//! with B > 2 + 2S they never write the same grid point. P2G scatters the colours one after
//! another, the blocks of a colour in parallel, and the particles of a block in index order.
//! Every grid point therefore receives its sums in one fixed order, whatever the number of
//! threads: results are bitwise identical for 1 or N threads.
//!
//! The schedule also knows which node blocks the particles can touch (the active blocks), so
//! the grid is cleared and updated only there.

use crate::grid::{GridLayout, OutOfGrid};
use crate::math::{floor_i64, Real, Vector};
use crate::parallel::{task_len, worth_splitting, Disjoint, MIN_BLOCKS};
use rayon::prelude::*;

/// Nodes per block edge (> 2 + 2·SLACK, see the module documentation).
pub const BLOCK: usize = 8;
/// Cells a particle may move from where it was binned before the particles are binned again.
pub const SLACK: Real = 2.0;
const _: () = assert!(BLOCK > 2 + 2 * SLACK as usize);
/// Fixed number of particle chunks of the parallel counting sort (independent of the thread count).
const CHUNKS: usize = 8;
/// Key of a particle whose stencil is not inside the grid.
const OUT_OF_GRID: u32 = u32::MAX;

/// The stencil origins (grid coordinates, per axis `lo ..= hi`) a block's particles may have while
/// the binning holds: the block's own nodes widened by [`SLACK`]. Scattering a particle outside it
/// could race with another block of the same colour, so the scatter checks it.
#[derive(Clone, Copy, Debug)]
pub struct Reach<const D: usize> {
    pub lo: [i64; D],
    pub hi: [i64; D],
}

impl<const D: usize> Reach<D> {
    /// Panics unless the stencil origin `base` is within reach: only a caller that moved particles
    /// between steps without re-binning them can get here, and continuing would be a data race.
    #[inline(always)]
    pub fn check(&self, base: &[i64; D]) {
        for k in 0..D {
            assert!(
                self.lo[k] <= base[k] && base[k] <= self.hi[k],
                "particle moved out of its block since it was binned; after moving particles, set the state's drift to infinity (or restore a state)"
            );
        }
    }
}

/// The block each particle was binned in, and how far (cells, per axis) the particles may have moved
/// since: part of a simulation's state, as it fixes the order of the grid sums.
#[derive(Clone, Debug, PartialEq)]
pub struct Binning {
    pub bins: Vec<u32>,
    /// Infinite before the first binning, or when the binning is not to be trusted: bin again.
    pub drift: Real,
}

impl Default for Binning {
    fn default() -> Self {
        Self { bins: Vec::new(), drift: Real::INFINITY }
    }
}

/// Particles sorted by block, the non-empty blocks by colour, and the active node blocks.
#[derive(Clone, Debug)]
pub struct Schedule<const D: usize> {
    /// Blocks along each axis.
    block_dims: [usize; D],
    /// Particle indices sorted by block, in index order within a block.
    order: Vec<u32>,
    /// `order[start[b]..start[b + 1]]` are the particles of block `b`.
    start: Vec<u32>,
    /// Per chunk and block: particle counts, then write offsets (chunk-major).
    hist: Vec<u32>,
    /// Non-empty blocks grouped by colour: `coloured[colour_start[c]..colour_start[c + 1]]`.
    coloured: Vec<u32>,
    colour_start: Vec<usize>,
    /// Node blocks some particle's stencil reaches, ascending, and those of the previous sort.
    active: Vec<u32>,
    stale: Vec<u32>,
    mark: Vec<bool>,
    parallel: bool,
    /// Whether the last [`Schedule::prepare`] binned the particles again.
    rebinned: bool,
}

impl<const D: usize> Schedule<D> {
    pub fn new(layout: &GridLayout<D>) -> Self {
        let block_dims: [usize; D] = std::array::from_fn(|k| layout.dims[k].div_ceil(BLOCK));
        let n: usize = block_dims.iter().product();
        Self {
            block_dims,
            order: Vec::new(),
            start: vec![0; n + 1],
            hist: vec![0; CHUNKS * n],
            coloured: Vec::with_capacity(n),
            colour_start: vec![0; (1 << D) + 1],
            active: Vec::with_capacity(n),
            stale: Vec::with_capacity(n),
            mark: vec![false; n],
            parallel: false,
            rebinned: false,
        }
    }

    fn num_blocks(&self) -> usize {
        self.mark.len()
    }

    /// Heap bytes of the per-particle array (`order`; the bins are part of the state).
    pub fn particle_bytes(&self) -> usize {
        crate::math::heap_bytes(&self.order)
    }

    /// Heap bytes of the per-block arrays.
    pub fn block_bytes(&self) -> usize {
        use crate::math::heap_bytes as b;
        b(&self.start) + b(&self.hist) + b(&self.coloured) + b(&self.active) + b(&self.stale) + b(&self.mark)
    }

    /// Block coordinates of block `b`.
    fn block_coord(&self, mut b: usize) -> [usize; D] {
        std::array::from_fn(|k| {
            let c = b % self.block_dims[k];
            b /= self.block_dims[k];
            c
        })
    }

    /// Whether the transfers of this step run in parallel: enough particles, and a pool of more than one
    /// thread when they were last binned ([`worth_splitting`]; a pool changed since counts from the next
    /// binning, which changes how fast, not what, the step computes).
    pub fn parallel(&self) -> bool {
        self.parallel
    }

    /// The smallest piece a parallel loop may hand to one thread: `piece`, or everything in one
    /// piece (no other thread woken) when the step runs serially.
    pub fn min_len(&self, piece: usize) -> usize {
        if self.parallel {
            piece
        } else {
            usize::MAX
        }
    }

    /// Makes the schedule valid for particles at `x` binned as `binning` says (part of the
    /// simulation's state): bins them again if they may have moved more than [`SLACK`] cells since
    /// (its drift; infinite before the first binning), or their number changed.
    pub fn prepare(&mut self, layout: &GridLayout<D>, x: &[Vector<D>], binning: &mut Binning) -> Result<(), OutOfGrid> {
        // A NaN drift (never produced: G2P stops on non-finite velocities) would also rebin.
        self.rebinned = binning.drift.is_nan() || binning.drift > SLACK || x.len() != self.order.len();
        if self.rebinned {
            self.sort(layout, x, binning)?;
        }
        Ok(())
    }

    /// Bins the particles at `x` by block into `binning`, its drift 0. Fails with the
    /// lowest-numbered particle whose stencil is not inside the grid (the drift is then infinite).
    /// Allocates only when the particle count grows.
    pub fn sort(&mut self, layout: &GridLayout<D>, x: &[Vector<D>], binning: &mut Binning) -> Result<(), OutOfGrid> {
        let n = x.len();
        assert!(n < u32::MAX as usize, "particle indices are stored as u32");
        let Binning { bins, drift } = binning;
        *drift = Real::INFINITY;
        self.parallel = worth_splitting(n);
        bins.resize(n, 0);
        let inv_h = 1.0 / layout.h;
        let block_dims = self.block_dims;
        let key_of = |(key, xp): (&mut u32, &Vector<D>)| *key = block_of(layout, &block_dims, xp, inv_h);
        if self.parallel {
            bins.par_iter_mut().zip(x.par_iter()).with_min_len(task_len(n)).for_each(key_of);
        } else {
            bins.iter_mut().zip(x).for_each(key_of);
        }
        self.sort_keys(bins)?;
        *drift = 0.0;
        Ok(())
    }

    /// Restores the schedule of a saved binning for particles now at `x`, so that
    /// the steps that follow sum in the same order as they would have without the interruption.
    /// Fails, changing nothing, unless every particle is within reach of its block. A drift
    /// beyond [`SLACK`] (not binned, or due) leaves it to the next [`Schedule::prepare`] to bin.
    pub fn restore(&mut self, layout: &GridLayout<D>, x: &[Vector<D>], binning: &Binning) -> Result<(), String> {
        let (bins, drift) = (&binning.bins, binning.drift);
        if bins.len() != x.len() {
            return Err(format!("{} bins for {} particles", bins.len(), x.len()));
        }
        if drift.is_nan() || drift < 0.0 {
            return Err(format!("drift must be non-negative, got {drift}"));
        }
        if drift > SLACK {
            // Not binned, binning forgotten, or due: the next step bins afresh, as the saved run's did.
            return Ok(());
        }
        // Each particle must lie within `drift` cells of its block (its binning plus the motion
        // since), or the scatter's reach check could fail before the next binning. A few roundings
        // of tolerance absorb those of the saved drift and positions (a state crafted within them of
        // the edge could still trip the reach check: a panic, caught by the bindings, never a race).
        let inv_h = 1.0 / layout.h;
        for (p, (xp, &b)) in x.iter().zip(bins).enumerate() {
            if b as usize >= self.num_blocks() {
                return Err(format!("particle {p}: block {b} is not one of the grid's {} blocks", self.num_blocks()));
            }
            let c = self.block_coord(b as usize);
            let within = (0..D).all(|k| {
                // Ghost-shifted coordinate whose floor is the stencil origin.
                let u = xp[k] * inv_h - 0.5 + crate::grid::GHOST as Real;
                let lo = (c[k] * BLOCK) as Real;
                let reach = drift + 8.0 * Real::EPSILON * (u.abs() + 1.0);
                u.is_finite() && lo - reach <= u && u < lo + BLOCK as Real + reach
            });
            if !within || !stencil_in_grid(layout, xp, inv_h) {
                return Err(format!("particle {p} is not within reach of its block {b}"));
            }
        }
        self.parallel = worth_splitting(x.len());
        self.sort_keys(bins).map_err(|OutOfGrid(p)| format!("particle {p} is outside the grid"))?;
        Ok(())
    }

    /// Counting sort of the particles by their keys, then the coloured block lists and the
    /// active node blocks.
    fn sort_keys(&mut self, key: &[u32]) -> Result<(), OutOfGrid> {
        self.rebinned = true;
        let n = key.len();
        self.order.resize(n, 0);
        let block_dims = self.block_dims;

        // Counting sort in fixed chunks (CHUNKS, or one when serial): histogram, offsets
        // (block-major), scatter.
        let nb = self.num_blocks();
        let chunks = if self.parallel { CHUNKS } else { 1 };
        let chunk = n.div_ceil(chunks).max(1);
        let min_chunks = self.min_len(1);
        let hist = &mut self.hist[..chunks * nb];
        hist.fill(0);
        let outside = hist
            .par_chunks_mut(nb)
            .zip(key.par_chunks(chunk))
            .enumerate()
            .with_min_len(min_chunks)
            .filter_map(|(c, (hist, keys))| {
                for (j, &k) in keys.iter().enumerate() {
                    if k == OUT_OF_GRID {
                        return Some(c * chunk + j);
                    }
                    hist[k as usize] += 1;
                }
                None
            })
            .min();
        if let Some(p) = outside {
            return Err(OutOfGrid(p));
        }
        let mut running = 0u32;
        for b in 0..nb {
            self.start[b] = running;
            for c in 0..chunks {
                let h = &mut hist[c * nb + b];
                let count = *h;
                *h = running;
                running += count;
            }
        }
        self.start[nb] = running;
        let order = Disjoint::new(&mut self.order);
        hist.par_chunks_mut(nb).zip(key.par_chunks(chunk)).enumerate().with_min_len(min_chunks).for_each(
            |(c, (offset, keys))| {
                for (j, &k) in keys.iter().enumerate() {
                    let slot = offset[k as usize] as usize;
                    offset[k as usize] += 1;
                    // SAFETY: the offsets of distinct (chunk, particle) pairs are distinct slots.
                    unsafe { order.update(slot, |o| *o = (c * chunk + j) as u32) };
                }
            },
        );

        // Non-empty blocks by colour, and the node blocks their stencils reach (blocks k − 1 ..= k + 1
        // per axis, the slack included). Blocks are visited in index order with their coordinates counted along.
        let colours = 1usize << D;
        const { assert!(D <= 3, "at most 8 colours") };
        let colour_of = |c: &[usize; D]| (0..D).map(|k| (c[k] & 1) << k).sum::<usize>();
        let next = |c: &mut [usize; D]| {
            for k in 0..D {
                c[k] += 1;
                if c[k] < block_dims[k] {
                    return;
                }
                c[k] = 0;
            }
        };
        self.colour_start.fill(0);
        let mut c = [0usize; D];
        for b in 0..nb {
            if self.start[b + 1] > self.start[b] {
                self.colour_start[colour_of(&c) + 1] += 1;
            }
            next(&mut c);
        }
        for k in 0..colours {
            self.colour_start[k + 1] += self.colour_start[k];
        }
        self.coloured.resize(self.colour_start[colours], 0);
        let mut fill: [usize; 8] = [0; 8];
        fill[..colours].copy_from_slice(&self.colour_start[..colours]);
        let strides: [usize; D] = std::array::from_fn(|k| block_dims[..k].iter().product());
        let mut c = [0usize; D];
        for b in 0..nb {
            if self.start[b + 1] > self.start[b] {
                let colour = colour_of(&c);
                self.coloured[fill[colour]] = b as u32;
                fill[colour] += 1;
                // Node blocks k − 1 ..= k + 1 along each axis (SLACK < BLOCK − 1 cells of drift).
                for k in 0..3usize.pow(D as u32) {
                    let o = crate::math::stencil_offset::<D>(k);
                    if (0..D).all(|a| c[a] + o[a] >= 1 && c[a] + o[a] - 1 < block_dims[a]) {
                        let at: usize = (0..D).map(|a| (c[a] + o[a] - 1) * strides[a]).sum();
                        self.mark[at] = true;
                    }
                }
            }
            next(&mut c);
        }
        std::mem::swap(&mut self.active, &mut self.stale);
        self.active.clear();
        for (b, m) in self.mark.iter_mut().enumerate() {
            if *m {
                self.active.push(b as u32);
                *m = false;
            }
        }
        Ok(())
    }

    /// Calls `f` with the particles of every non-empty block and the block's [`Reach`], colour
    /// after colour; the blocks of one colour run in parallel when the step is parallel.
    pub fn for_each_block(&self, f: impl Fn(&Reach<D>, &[u32]) + Sync) {
        for c in 0..(1usize << D) {
            let blocks = &self.coloured[self.colour_start[c]..self.colour_start[c + 1]];
            let run = |&b: &u32| {
                let coord = self.block_coord(b as usize);
                let slack = SLACK as i64;
                let reach = Reach {
                    lo: std::array::from_fn(|k| (coord[k] * BLOCK) as i64 - slack - crate::grid::GHOST),
                    hi: std::array::from_fn(|k| (coord[k] * BLOCK + BLOCK - 1) as i64 + slack - crate::grid::GHOST),
                };
                f(&reach, &self.order[self.start[b as usize] as usize..self.start[b as usize + 1] as usize])
            };
            if self.parallel {
                blocks.par_iter().for_each(run);
            } else {
                blocks.iter().for_each(run);
            }
        }
    }

    /// Node blocks the particles' stencils can reach until they are binned again.
    pub fn active(&self) -> &[u32] {
        &self.active
    }

    /// Node blocks the grid may hold values in from the previous step (to be cleared).
    pub fn stale(&self) -> &[u32] {
        if self.rebinned {
            &self.stale
        } else {
            &self.active
        }
    }

    /// Calls `f(node)` for every node of node block `b`.
    #[inline]
    pub fn for_each_node(&self, layout: &GridLayout<D>, b: u32, mut f: impl FnMut(usize)) {
        self.for_each_node_at(layout, b, |i, _| f(i));
    }

    /// Calls `f(node, coordinates)` for every node of node block `b`: its index and its place on the grid's
    /// axes.
    #[inline]
    pub fn for_each_node_at(&self, layout: &GridLayout<D>, b: u32, mut f: impl FnMut(usize, &[usize; D])) {
        let c = self.block_coord(b as usize);
        let lo: [usize; D] = std::array::from_fn(|k| c[k] * BLOCK);
        let span: [usize; D] = std::array::from_fn(|k| BLOCK.min(layout.dims[k] - lo[k]));
        let strides = layout.strides();
        // Rows along axis 0 (contiguous), the other axes counted like an odometer.
        let mut at = [0usize; D];
        loop {
            let row: usize = (0..D).map(|k| (lo[k] + at[k]) * strides[k]).sum();
            let mut coord: [usize; D] = std::array::from_fn(|k| lo[k] + at[k]);
            for i in 0..span[0] {
                coord[0] = lo[0] + i;
                f(row + i * strides[0], &coord);
            }
            let mut k = 1;
            loop {
                if k >= D {
                    return;
                }
                at[k] += 1;
                if at[k] < span[k] {
                    break;
                }
                at[k] = 0;
                k += 1;
            }
        }
    }

    /// Calls `f(node)` for every node of the given node blocks, in parallel.
    pub fn for_each_node_of(&self, layout: &GridLayout<D>, blocks: &[u32], f: impl Fn(usize) + Sync) {
        blocks.par_iter().with_min_len(self.min_len(MIN_BLOCKS)).for_each(|&b| self.for_each_node(layout, b, &f));
    }

    /// Calls `f(node, coordinates)` for every node of the given node blocks, in parallel.
    pub fn for_each_node_of_at(&self, layout: &GridLayout<D>, blocks: &[u32], f: impl Fn(usize, &[usize; D]) + Sync) {
        blocks.par_iter().with_min_len(self.min_len(MIN_BLOCKS)).for_each(|&b| self.for_each_node_at(layout, b, &f));
    }

    /// Sets `data` to `zero` on every node of the given node blocks (in parallel).
    pub fn clear<T: Copy + Send + Sync>(&self, layout: &GridLayout<D>, blocks: &[u32], data: &mut [T], zero: T) {
        let out = Disjoint::new(data);
        // SAFETY: node blocks do not overlap, and each is listed once.
        self.for_each_node_of(layout, blocks, |i| unsafe { out.update(i, |v| *v = zero) });
    }
}

/// Whether the whole stencil of a particle at `x` is inside the grid: its lowest node, at index
/// `floor(y) + GHOST` with `y = x/h − 1/2`, at 0 or above, and its highest, two further, below `dims`.
/// The bounds are integers, so that is `−GHOST ≤ y < dims − 2 − GHOST`, compared without the floor
/// (NaN and the infinities fail it, as they must). `inv_h` is finite and positive (scenes have h > 0).
#[inline]
pub fn stencil_in_grid<const D: usize>(layout: &GridLayout<D>, x: &Vector<D>, inv_h: Real) -> bool {
    use crate::grid::GHOST;
    (0..D).all(|k| {
        let y = x[k] * inv_h - 0.5;
        y >= -(GHOST as Real) && y < (layout.dims[k] as i64 - 2 - GHOST) as Real
    })
}

/// Block of the stencil origin of a particle at `x`, or [`OUT_OF_GRID`].
#[inline]
fn block_of<const D: usize>(layout: &GridLayout<D>, block_dims: &[usize; D], x: &Vector<D>, inv_h: Real) -> u32 {
    let mut key = 0usize;
    for k in (0..D).rev() {
        // Ghost-shifted node coordinate of the stencil's lowest node; the stencil needs o + 2 in the grid.
        let o = floor_i64(x[k] * inv_h - 0.5).saturating_add(crate::grid::GHOST);
        if !x[k].is_finite() || o < 0 || o as usize + 2 >= layout.dims[k] {
            return OUT_OF_GRID;
        }
        key = key * block_dims[k] + o as usize / BLOCK;
    }
    key as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    /// `stencil_in_grid` is the floor-based definition (lowest node `floor(x/h − 1/2) + GHOST` at 0 or
    /// above, highest below `dims`, x finite) at every position: random ones, each node and cell centre
    /// across the grid's edges, the exact bounds, each of those with its nearest floats, huge values and
    /// the non-finite ones.
    #[test]
    fn stencil_in_grid_is_the_floor_definition() {
        let layout = GridLayout::<2>::new(0.1, [8, 5]);
        let inv_h = 1.0 / layout.h;
        let by_floor = |x: &Vector2<Real>| {
            (0..2).all(|k| {
                let o = floor_i64(x[k] * inv_h - 0.5).saturating_add(crate::grid::GHOST);
                x[k].is_finite() && o >= 0 && (o as usize) + 2 < layout.dims[k]
            })
        };
        // Bits one to three ulps to either side of `c` (`next_up` is newer than the crate's minimum Rust).
        let beside = |c: Real| {
            (1..=3).flat_map(move |k| {
                [Real::from_bits(c.to_bits().wrapping_add(k)), Real::from_bits(c.to_bits().wrapping_sub(k))]
            })
        };
        // The non-finite values, and finite ones far enough out that the floor takes its saturating cast.
        let mut coords: Vec<Real> = vec![Real::NAN, Real::INFINITY, Real::NEG_INFINITY, Real::MAX, -Real::MAX];
        coords.extend([1e18, -1e18, 1e30, -1e30, 4.6e15, -4.6e15]);
        // Nodes and cell centres every h/2 from 5 cells below the box to 15 cells past its origin, with their
        // neighbours (0's are −0 and the smallest subnormals of either sign).
        for i in -10..=30 {
            let c = i as Real * 0.5 * layout.h;
            coords.push(c);
            coords.extend(beside(c));
        }
        // The exact bounds −2 ≤ y < dims − 4 (y = x/h − 1/2; dims = 13 and 10 with the ghost nodes), and
        // their neighbours.
        for y in [-2.0, layout.dims[0] as Real - 4.0, layout.dims[1] as Real - 4.0] {
            let x = (y + 0.5) * layout.h;
            coords.push(x);
            coords.extend(beside(x));
        }
        coords.extend(scattered(500, 3).iter().map(|p| ((p.x - 0.25) * 1.5) as Real));
        let mut inside = 0;
        for &a in &coords {
            for &b in &coords {
                let x = Vector2::new(a, b);
                assert_eq!(stencil_in_grid(&layout, &x, inv_h), by_floor(&x), "at {x:?}");
                inside += usize::from(by_floor(&x));
            }
        }
        assert!(inside > 1000, "the positions reach inside the grid ({inside})");
    }

    fn scattered(n: usize, seed: u64) -> Vec<Vector2<f64>> {
        let mut s = seed;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n).map(|_| Vector2::new(rnd(), rnd())).collect()
    }

    /// The sort is a permutation, grouped by block, in index order within a block; every
    /// non-empty block has one colour; active blocks cover every particle's stencil.
    #[test]
    fn sort_groups_particles_by_block() {
        let layout = GridLayout::<2>::new(1.0 / 40.0, [40, 40]);
        let x = scattered(5000, 3);
        let mut s = Schedule::new(&layout);
        s.sort(&layout, &x, &mut Binning::default()).unwrap();
        let mut seen = vec![false; x.len()];
        let mut visited = 0;
        s.for_each_block(|_, ps| {
            for w in ps.windows(2) {
                assert!(w[0] < w[1]);
            }
            let key = block_of(&layout, &s.block_dims, &x[ps[0] as usize], 40.0);
            assert!(ps.iter().all(|&p| block_of(&layout, &s.block_dims, &x[p as usize], 40.0) == key));
        });
        for &p in &s.order {
            assert!(!std::mem::replace(&mut seen[p as usize], true));
            visited += 1;
        }
        assert_eq!(visited, x.len());
        let mut active = vec![false; layout.num_nodes()];
        for &b in s.active() {
            s.for_each_node(&layout, b, |i| active[i] = true);
        }
        for xp in &x {
            let st = crate::kernel::Stencil::new(xp, 40.0);
            let o = layout.stencil_origin(&st.base).unwrap();
            st.for_each(layout.h, |off, _, _| assert!(active[o + layout.offset(&off)]));
        }
    }

    /// Two blocks of one colour never reach a common node or boundary-point cell.
    #[test]
    fn blocks_of_one_colour_are_apart() {
        let layout = GridLayout::<2>::new(0.1, [30, 30]);
        let s = Schedule::new(&layout);
        let reach = |b: usize| {
            let c = s.block_coord(b);
            // Cells k·B − 1 − S ..= k·B + B + 1 + S along each axis.
            let slack = SLACK as i64;
            std::array::from_fn::<_, 2, _>(|k| {
                (c[k] as i64 * BLOCK as i64 - 1 - slack, (c[k] * BLOCK + BLOCK + 1) as i64 + slack)
            })
        };
        for a in 0..s.num_blocks() {
            for b in a + 1..s.num_blocks() {
                let (ca, cb) = (s.block_coord(a), s.block_coord(b));
                if (0..2).all(|k| ca[k] % 2 == cb[k] % 2) {
                    let (ra, rb) = (reach(a), reach(b));
                    let overlap = (0..2).all(|k| ra[k].0 <= rb[k].1 && rb[k].0 <= ra[k].1);
                    assert!(!overlap, "blocks {ca:?} and {cb:?}");
                }
            }
        }
    }

    /// The lowest-numbered particle outside the grid is the one reported.
    #[test]
    fn first_particle_outside_is_reported() {
        let layout = GridLayout::<2>::new(0.1, [10, 10]);
        let mut x = scattered(9000, 5);
        x[7000] = Vector2::new(5.0, 0.5);
        x[4000] = Vector2::new(0.5, -1.0);
        assert_eq!(Schedule::new(&layout).sort(&layout, &x, &mut Binning::default()), Err(OutOfGrid(4000)));
    }
}
