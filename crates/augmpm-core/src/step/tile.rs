//! P2G's 3D scatter of the particles away from walls into a tile: the grid around one block, held per
//! thread, with a node's mass and momentum side by side, `(m, (mv)ₓ, (mv)_y, (mv)_z)`, and added to the grid
//! once the block is done.
//!
//! A node's four sums are then one short vector (one SSE register in f32, two in f64), and a stencil's row
//! of three nodes is contiguous with constant strides. Against the scatter straight into the grid's mass and
//! momentum arrays (64³ dam break, one thread, `benches/compare_builds.py`, medians of round ratios): f32
//! P2G 0.82–0.88× its time in two runs (95% intervals of the median 0.813–0.826 and 0.866–0.885), the step
//! 0.905–0.947×; callgrind, 32³: P2G 1,519 → 1,373 instructions a particle-step. Used in 3D f32 only, and
//! not with the paper's transfer (whose B-spline mass it does not hold): in f64 (a node's four numbers in two
//! registers) P2G took 1.16× (1.03–1.31), and in 2D 1.19× (a block's nodes are few and already in the
//! first-level cache there).
//!
//! The grid sums are not bitwise those of the direct scatter: a node adds the block's sum at once. They are
//! the same on any number of threads: one thread scatters a block, its particles in their order, and adds
//! its tile in node order.

use std::cell::RefCell;

use crate::grid::{GridLayout, GHOST};
use crate::kernel::Stencil;
use crate::math::{Matrix, Real, Vector};
use crate::parallel::Disjoint;
use crate::step::schedule::{Reach, BLOCK, SLACK};

/// Nodes of a tile along each axis: a block's particles have stencil origins in `BLOCK + 2 SLACK` cells
/// along each axis ([`Reach`]), and a stencil spans three nodes from its origin.
pub const TILE: usize = BLOCK + 2 * SLACK as usize + 2;

/// One thread's tile: the sums of a block's particles, and the box of the stencil origins they had.
pub struct Tile {
    /// `(m, mv)` per node, the first axis fastest; zero outside the box while a block is scattered.
    nodes: Vec<[Real; 4]>,
    /// Lowest and highest stencil origin scattered since [`Tile::begin`], in tile coordinates.
    lo: [usize; 3],
    hi: [usize; 3],
    /// Between [`Tile::begin`] and [`Tile::add_to_grid`]: if a block was left unfinished (a panic in the
    /// scatter), the next `begin` zeroes the whole tile.
    open: bool,
}

thread_local! {
    static TILE_OF_THREAD: RefCell<Tile> =
        const { RefCell::new(Tile { nodes: Vec::new(), lo: [0; 3], hi: [0; 3], open: false }) };
}

/// Calls `f` with this thread's tile (2,744 nodes of four numbers: 43 KiB in f32, allocated at the first
/// use).
pub fn with_tile<R>(f: impl FnOnce(&mut Tile) -> R) -> R {
    TILE_OF_THREAD.with(|t| f(&mut t.borrow_mut()))
}

impl Tile {
    /// Starts a block: the tile is zero.
    pub fn begin(&mut self) {
        if self.nodes.is_empty() {
            self.nodes = vec![[0.0; 4]; TILE * TILE * TILE];
        } else if self.open {
            self.nodes.fill([0.0; 4]);
        }
        (self.lo, self.hi, self.open) = ([usize::MAX; 3], [0; 3], true);
    }

    /// Adds to the tile what a particle away from walls gives its stencil `s` (3D): mass `w m_p` and
    /// momentum `w (m_p v_p + A_p d)` with `d = x_i − x_p`, as [`super::transfer`]'s direct scatter, in
    /// rows of three nodes: `(m_p, m_p v_p + A_p (0, d₁, d₂)) + d₀ (0, A_p e₀)`, times `w₀ (w₁ w₂)`.
    /// `reach` is the block's, which the stencil origin has been checked against.
    #[inline(always)]
    pub fn scatter<const D: usize>(
        &mut self,
        reach: &Reach<D>,
        s: &Stencil<D>,
        h: Real,
        mp: Real,
        mv: &Vector<D>,
        a: &Matrix<D>,
    ) {
        debug_assert_eq!(D, 3, "tiles are 3D");
        let mut at = 0;
        for k in (0..3).rev() {
            // Within the tile: the reach check has made sure of it, and this keeps the writes below in
            // bounds whatever the caller did.
            let l = s.base[k] - reach.lo[k];
            assert!((0..(TILE - 2) as i64).contains(&l), "stencil origin outside the block's tile");
            let l = l as usize;
            self.lo[k] = self.lo[k].min(l);
            self.hi[k] = self.hi[k].max(l);
            at = at * TILE + l;
        }
        let dk = s.axis_offsets(h);
        let along0 = [0.0, a[(0, 0)], a[(1, 0)], a[(2, 0)]];
        for c in 0..3 {
            for b in 0..3 {
                let w_rest = s.w[1][b] * s.w[2][c];
                let (d1, d2) = (dk[1][b], dk[2][c]);
                let row_sum: [Real; 4] = [
                    mp,
                    mv[0] + (a[(0, 1)] * d1 + a[(0, 2)] * d2),
                    mv[1] + (a[(1, 1)] * d1 + a[(1, 2)] * d2),
                    mv[2] + (a[(2, 1)] * d1 + a[(2, 2)] * d2),
                ];
                let row = at + (b + c * TILE) * TILE;
                // The row's three nodes, within the tile by the assert above.
                let nodes = &mut self.nodes[row..row + 3];
                for (x, node) in nodes.iter_mut().enumerate() {
                    let (w, d0) = (s.w[0][x] * w_rest, dk[0][x]);
                    for j in 0..4 {
                        node[j] += (row_sum[j] + along0[j] * d0) * w;
                    }
                }
            }
        }
    }

    /// Adds the tile's nodes in the box of the origins scattered to the grid's `mass` and `momentum`, in
    /// node order, and zeroes them: the block is done.
    ///
    /// # Safety
    /// No other thread writes the grid nodes of the block's stencils meanwhile (the schedule's colours).
    pub(crate) unsafe fn add_to_grid<const D: usize>(
        &mut self,
        layout: &GridLayout<D>,
        reach: &Reach<D>,
        mass: Disjoint<'_, Real>,
        momentum: Disjoint<'_, Vector<D>>,
    ) {
        debug_assert_eq!(D, 3, "tiles are 3D");
        if self.lo[0] == usize::MAX {
            self.open = false;
            return;
        }
        let strides = layout.strides();
        // The grid index of the tile's node 0 (it may lie outside the grid; the nodes added never do).
        let origin: i64 = (0..3).map(|k| (reach.lo[k] + GHOST) * strides[k] as i64).sum();
        for z in self.lo[2]..self.hi[2] + 3 {
            for y in self.lo[1]..self.hi[1] + 3 {
                for x in self.lo[0]..self.hi[0] + 3 {
                    let node = std::mem::take(&mut self.nodes[x + (y + z * TILE) * TILE]);
                    let i = (origin + (x * strides[0] + y * strides[1] + z * strides[2]) as i64) as usize;
                    // SAFETY: exclusive by the caller; `update` checks the bounds.
                    unsafe {
                        mass.update(i, |m| *m += node[0]);
                        momentum.update(i, |mv| {
                            for k in 0..3 {
                                mv[k] += node[1 + k];
                            }
                        });
                    }
                }
            }
        }
        // Only now: a panic above leaves the tile to be zeroed whole by the next `begin`.
        self.open = false;
    }
}
