//! The regular background grid: layout (node indexing) and per-node state.

use crate::math::{Real, Vector};

/// Ghost node layers outside the domain box on every side. Nodes beyond the
/// box are wall nodes; they let a particle that strays up to 1.5 cells past
/// the box still have a whole stencil, so it can be counted and reported.
pub const GHOST: i64 = 2;

/// Node layout of a regular grid with nodes at `i·h`, `i = −GHOST ..= cells + GHOST`.
#[derive(Clone, Debug)]
pub struct GridLayout<const D: usize> {
    /// Cell width h (m).
    pub h: Real,
    /// Number of cells of the domain box along each axis.
    pub cells: [usize; D],
    /// Nodes along each axis, ghosts included.
    pub dims: [usize; D],
    strides: [usize; D],
}

impl<const D: usize> GridLayout<D> {
    pub fn new(h: Real, cells: [usize; D]) -> Self {
        let mut dims = [0; D];
        let mut strides = [0; D];
        let mut stride = 1;
        for k in 0..D {
            dims[k] = cells[k] + 1 + 2 * GHOST as usize;
            strides[k] = stride;
            stride *= dims[k];
        }
        Self { h, cells, dims, strides }
    }

    /// Index stride of each axis.
    #[inline]
    pub fn strides(&self) -> &[usize; D] {
        &self.strides
    }

    /// Total number of nodes, ghosts included.
    pub fn num_nodes(&self) -> usize {
        self.dims.iter().product()
    }

    /// Size of the domain box (m).
    pub fn extent(&self) -> Vector<D> {
        Vector::<D>::from_fn(|k, _| self.cells[k] as Real * self.h)
    }

    /// Linear index of the node at integer coordinate `base + offset`, or
    /// `None` when the whole 3^D stencil at `base` does not fit in the grid.
    #[inline]
    pub fn stencil_origin(&self, base: &[i64; D]) -> Option<usize> {
        let mut idx = 0;
        for k in 0..D {
            let i = base[k] + GHOST;
            if i < 0 || i as usize + 2 >= self.dims[k] {
                return None;
            }
            idx += i as usize * self.strides[k];
        }
        Some(idx)
    }

    /// Linear index of the node at integer coordinate `c`, if it is in the grid.
    #[inline]
    pub fn node_index(&self, c: &[i64; D]) -> Option<usize> {
        let mut idx = 0;
        for k in 0..D {
            let i = c[k] + GHOST;
            if i < 0 || i as usize >= self.dims[k] {
                return None;
            }
            idx += i as usize * self.strides[k];
        }
        Some(idx)
    }

    /// Linear offset of a stencil offset (each component 0..3) from its origin.
    #[inline]
    pub fn offset(&self, o: &[usize; D]) -> usize {
        (0..D).map(|k| o[k] * self.strides[k]).sum()
    }

    /// Integer coordinate of node `idx`.
    pub fn coord(&self, mut idx: usize) -> [i64; D] {
        let mut c = [0i64; D];
        for k in 0..D {
            c[k] = (idx % self.dims[k]) as i64 - GHOST;
            idx /= self.dims[k];
        }
        c
    }

    /// Position of node `idx` (m).
    pub fn position(&self, idx: usize) -> Vector<D> {
        let c = self.coord(idx);
        Vector::<D>::from_fn(|k, _| c[k] as Real * self.h)
    }
}

/// Per-node state of one time step: mass, momentum then velocity.
#[derive(Clone, Debug)]
pub struct GridState<const D: usize> {
    /// Node mass (kg in 3D, kg/m in 2D).
    pub mass: Vec<Real>,
    /// Σ w m_p with the plain B-spline weights, where a step reads it (the paper's augmented transfer, whose
    /// low-mass floor compares the MLS mass with it); empty otherwise (it would equal `mass`).
    pub spline_mass: Vec<Real>,
    /// Momentum after particle→grid, velocity (m/s) after the grid update.
    pub momentum: Vec<Vector<D>>,
}

impl<const D: usize> GridState<D> {
    /// Zero state on `n` grid points, with the B-spline mass if `spline` (see [`GridState::spline_mass`]).
    pub fn new(n: usize, spline: bool) -> Self {
        let spline_mass = if spline { vec![0.0; n] } else { Vec::new() };
        Self { mass: vec![0.0; n], spline_mass, momentum: vec![Vector::<D>::zeros(); n] }
    }

    /// Whether the B-spline mass is kept.
    pub fn keeps_spline_mass(&self) -> bool {
        !self.spline_mass.is_empty()
    }

    /// Heap bytes of the arrays.
    pub fn heap_bytes(&self) -> usize {
        use crate::math::heap_bytes as b;
        b(&self.mass) + b(&self.spline_mass) + b(&self.momentum)
    }

    /// `n` grid points (after moving walls changed the number of boundary points), new ones zero.
    pub fn resize(&mut self, n: usize) {
        if self.keeps_spline_mass() {
            self.spline_mass.resize(n, 0.0);
        }
        self.mass.resize(n, 0.0);
        self.momentum.resize(n, Vector::<D>::zeros());
    }
}

/// Particle index whose stencil left the grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutOfGrid(pub usize);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coordinates_round_trip() {
        let g = GridLayout::<2>::new(0.1, [4, 3]);
        assert_eq!(g.dims, [9, 8]);
        for idx in 0..g.num_nodes() {
            let c = g.coord(idx);
            assert_eq!(g.stencil_origin(&c).map(|_| ()), if c[0] + 2 <= 6 && c[1] + 2 <= 5 { Some(()) } else { None });
        }
        assert_eq!(g.stencil_origin(&[-2, -2]), Some(0));
        assert_eq!(g.stencil_origin(&[-3, 0]), None);
        assert!((g.position(g.stencil_origin(&[1, 2]).unwrap()) - Vector::<2>::new(0.1, 0.2)).norm() < 1e-15);
    }
}
