//! Quadratic B-spline weights of MLS-MPM (Hu et al. 2018) and the moving
//! least-squares shape functions built on them (eq. (3)–(6) of Toyota &
//! Umetani 2024).

use crate::math::{stencil_len, stencil_offset, Matrix, Real, Vector};

/// The 3^D nodes around a particle and their quadratic B-spline weights.
#[derive(Clone, Copy, Debug)]
pub struct Stencil<const D: usize> {
    /// Integer grid coordinate of the stencil's lowest node.
    pub base: [i64; D],
    /// Per-axis weights of the three nodes `base + 0, 1, 2`.
    pub w: [[Real; 3]; D],
    /// Particle position in cell units relative to `base`, in [0.5, 1.5).
    pub fx: Vector<D>,
}

impl<const D: usize> Stencil<D> {
    /// Stencil of a particle at `x` (m) on a grid of spacing `1 / inv_h` with nodes at `i·h`.
    #[inline]
    pub fn new(x: &Vector<D>, inv_h: Real) -> Self {
        let mut base = [0i64; D];
        let mut w = [[0.0; 3]; D];
        let mut fx = Vector::<D>::zeros();
        for k in 0..D {
            let xk = x[k] * inv_h;
            let b = crate::math::floor_i64(xk - 0.5);
            let f = xk - b as Real;
            base[k] = b;
            fx[k] = f;
            w[k] = [0.5 * (1.5 - f).powi(2), 0.75 - (f - 1.0).powi(2), 0.5 * (f - 0.5).powi(2)];
        }
        Self { base, w, fx }
    }

    /// The integer grid coordinate of the lowest node of the stencil at `x` ([`Stencil::base`]), without
    /// the weights.
    #[inline]
    pub fn base_of(x: &Vector<D>, inv_h: Real) -> [i64; D] {
        std::array::from_fn(|k| crate::math::floor_i64(x[k] * inv_h - 0.5))
    }

    /// Calls `f(offset, weight, x_i − x_p)` for every node of the stencil, the first axis fastest; the
    /// distance is in metres (`h` is the grid spacing).
    #[inline]
    pub fn for_each(&self, h: Real, mut f: impl FnMut([usize; D], Real, Vector<D>)) {
        self.visit(h, &[0; D], |o, _, w, d| f(o, w, d));
    }

    /// Calls `f(i, weight, x_i − x_p)` for every node of the stencil, in the order of
    /// [`Stencil::for_each`], with `i = origin + Σ_k o_k strides_k` the node's index in a grid of those
    /// strides whose stencil origin is `origin` (at most `origin + Σ_k 2 strides_k`, see [`Stencil::visit`]).
    #[inline]
    pub fn for_each_index(
        &self,
        h: Real,
        origin: usize,
        strides: &[usize; D],
        mut f: impl FnMut(usize, Real, Vector<D>),
    ) {
        self.visit(h, strides, |_, i, w, d| f(origin + i, w, d));
    }

    /// The components of `x_i − x_p` (m) along each axis: `[k][j] = (j − fx_k) h` for the nodes whose
    /// offset along axis k is j.
    #[inline(always)]
    pub fn axis_offsets(&self, h: Real) -> [[Real; 3]; D] {
        std::array::from_fn(|k| std::array::from_fn(|j| (j as Real - self.fx[k]) * h))
    }

    /// Calls `f(offset, i − origin, w_rest)` for every row of three nodes along the first axis, in the order
    /// of [`Stencil::visit`]: `offset` is the row's first node (`offset[0] = 0`), and `w_rest` the product of
    /// the other axes' weights, `w₁` in 2D and `w₁·w₂` in 3D. The row's node `a` has the index
    /// `i + a·strides[0]` and the weight `w₀[a]·w_rest`, as [`Stencil::visit`] forms it; as there,
    /// `i + a·strides[0] ≤ Σ_k 2 strides_k`, the stencil's last node.
    ///
    /// G2P gathers a 3D particle away from walls by rows: a row's sum is formed once, and what depends only
    /// on the other axes' offsets is taken once a row instead of once a node.
    #[inline(always)]
    pub fn for_each_row(&self, strides: &[usize; D], mut f: impl FnMut([usize; D], usize, Real)) {
        match D {
            2 => {
                for b in 0..3 {
                    let mut o = [0; D];
                    o[1] = b;
                    f(o, b * strides[1], self.w[1][b]);
                }
            }
            3 => {
                for c in 0..3 {
                    for b in 0..3 {
                        let mut o = [0; D];
                        (o[1], o[2]) = (b, c);
                        f(o, b * strides[1] + c * strides[2], self.w[1][b] * self.w[2][c]);
                    }
                }
            }
            _ => unreachable!("the transfers run in 2D and 3D"),
        }
    }

    /// Calls `f(offset, i − origin, weight, x_i − x_p)` for every node of the stencil, in the order of
    /// [`Stencil::for_each`]: nested per axis in 2D and 3D, a row of three nodes along the first axis
    /// innermost, with the other axes' weights, offsets and index read once a row. The weight is
    /// `w₀·(w₁·w₂)`, the other axes' product formed once a row (`w₀·w₁` in 2D; in any other dimension the
    /// product in axis order, `1·w₀ = w₀` exactly).
    ///
    /// Every offset component is 0, 1 or 2, so `i − origin ≤ Σ_k 2 strides_k`: the transfers check that
    /// last node once and index the others unchecked, relying on this bound.
    #[inline(always)]
    pub fn visit(&self, h: Real, strides: &[usize; D], mut f: impl FnMut([usize; D], usize, Real, Vector<D>)) {
        let dk = self.axis_offsets(h);
        match D {
            2 => {
                for b in 0..3 {
                    let (wb, row) = (self.w[1][b], b * strides[1]);
                    let mut dpos = Vector::<D>::zeros();
                    dpos[1] = dk[1][b];
                    for a in 0..3 {
                        let mut o = [0; D];
                        (o[0], o[1]) = (a, b);
                        dpos[0] = dk[0][a];
                        f(o, row + a * strides[0], self.w[0][a] * wb, dpos);
                    }
                }
            }
            3 => {
                for c in 0..3 {
                    let (wc, plane) = (self.w[2][c], c * strides[2]);
                    for b in 0..3 {
                        let (wbc, row) = (self.w[1][b] * wc, b * strides[1] + plane);
                        let mut dpos = Vector::<D>::zeros();
                        (dpos[1], dpos[2]) = (dk[1][b], dk[2][c]);
                        for a in 0..3 {
                            let mut o = [0; D];
                            (o[0], o[1], o[2]) = (a, b, c);
                            dpos[0] = dk[0][a];
                            f(o, row + a * strides[0], self.w[0][a] * wbc, dpos);
                        }
                    }
                }
            }
            _ => {
                for k in 0..stencil_len(D) {
                    let o = stencil_offset::<D>(k);
                    let mut weight = 1.0;
                    let mut dpos = Vector::<D>::zeros();
                    let mut i = 0;
                    for a in 0..D {
                        weight *= self.w[a][o[a]];
                        dpos[a] = dk[a][o[a]];
                        i += o[a] * strides[a];
                    }
                    f(o, i, weight, dpos);
                }
            }
        }
    }
}

/// Quadratic B-spline N(r) of a distance `r` in cell widths (support |r| < 1.5).
#[inline]
pub fn bspline(r: Real) -> Real {
    let r = r.abs();
    if r < 0.5 {
        0.75 - r * r
    } else if r < 1.5 {
        0.5 * (1.5 - r) * (1.5 - r)
    } else {
        0.0
    }
}

/// `∫_{−∞}^{s} N(u) du` for the quadratic B-spline N ([`bspline`]), `s` in cell widths: the part of a node's
/// support that lies behind a plane `s` cells past the node, measured along a grid axis.
pub fn bspline_integral(s: Real) -> Real {
    let a = s.abs();
    let below = if a >= 1.5 {
        0.0
    } else if a >= 0.5 {
        (1.5 - a).powi(3) / 6.0
    } else {
        0.5 - 0.75 * a + a * a * a / 3.0
    };
    if s < 0.0 {
        below
    } else {
        1.0 - below
    }
}

/// Tensor-product weight w(d) = Π N(d_k / h) of a point at offset `d` (m).
#[inline]
pub fn weight<const D: usize>(d: &Vector<D>, inv_h: Real) -> Real {
    d.iter().map(|&x| bspline(x * inv_h)).product()
}

/// How a particle's MLS system was solved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum MlsKind {
    /// Whole regular stencil and no boundary point: the closed form.
    Regular,
    /// General inverse of eq. (5).
    General,
    /// The moment matrix was near-singular (points almost collinear): regularized.
    Regularized,
    /// No grid point at all in the particle's support (it is deep inside a wall).
    Isolated,
}

/// Weighted moments Σw, Σw d, Σw d dᵀ of a particle's points (the blocks of eq. (5)).
#[derive(Clone, Copy, Debug)]
pub struct Moments<const D: usize> {
    pub a: Real,
    pub b: Vector<D>,
    pub c: Matrix<D>,
}

impl<const D: usize> Moments<D> {
    pub fn new() -> Self {
        Self { a: 0.0, b: Vector::<D>::zeros(), c: Matrix::<D>::zeros() }
    }

    #[inline]
    pub fn add(&mut self, w: Real, d: &Vector<D>) {
        self.a += w;
        self.b += d * w;
        if D == 3 {
            // The six distinct entries of w d dᵀ, from w d (in 2D the sums stay as they were).
            let dw = d * w;
            for i in 0..D {
                for j in i..D {
                    let v = dw[i] * d[j];
                    self.c[(i, j)] += v;
                    if j != i {
                        self.c[(j, i)] += v;
                    }
                }
            }
        } else {
            self.c += d * d.transpose() * w;
        }
    }
}

impl<const D: usize> Default for Moments<D> {
    fn default() -> Self {
        Self::new()
    }
}

/// Below this ratio of the smallest eigenvalue of the centred second moment
/// to `Σw·h²` (1/4 on a whole regular stencil) the MLS system counts as
/// ill-conditioned: its points are almost collinear.
pub const ILL_CONDITIONED: Real = 1e-3;

/// Inverse of the MLS moment matrix `M_p` (eq. (5)) with the linear basis
/// `P(x) = [1, x]`, stored in block form
/// `M_p⁻¹ = [[alpha, betaᵀ], [beta, gamma]]` so that it is generic over `D`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MlsInverse<const D: usize> {
    pub alpha: Real,
    pub beta: Vector<D>,
    pub gamma: Matrix<D>,
}

impl<const D: usize> MlsInverse<D> {
    /// Closed form on a whole regular stencil: `M_p = diag(1, h²/4 I)`, so
    /// `M_p⁻¹ = diag(1, 4/h² I)` and MLS-MPM reduces to APIC.
    pub fn regular(h: Real) -> Self {
        Self { alpha: 1.0, beta: Vector::<D>::zeros(), gamma: Matrix::<D>::identity() * (4.0 / (h * h)) }
    }

    /// Inverse of `M = [[a, bᵀ], [b, C]]` by the Schur complement `S = C − b bᵀ/a`:
    /// `Γ = S⁻¹`, `β = −Γ b/a`, `α = 1/a + bᵀΓb/a²`. A near-singular S (points almost
    /// collinear, e.g. a particle beyond a wall that sees only boundary points) is
    /// regularized by adding `ILL_CONDITIONED·a·h²` to its spectrum, which damps the
    /// gradient along the missing direction; with no point at all (`a = 0`) the
    /// particle is isolated and every shape function is zero.
    pub fn from_moments<Ops: crate::math::DimOps<D>>(m: &Moments<D>, h: Real) -> (Self, MlsKind) {
        if m.a <= 1e-12 {
            return (Self { alpha: 0.0, beta: Vector::<D>::zeros(), gamma: Matrix::<D>::zeros() }, MlsKind::Isolated);
        }
        let mean = m.b / m.a;
        let mut s = m.c - m.b * mean.transpose();
        let floor = ILL_CONDITIONED * m.a * h * h;
        let mut kind = MlsKind::General;
        if !Ops::at_least(&s, floor) {
            s += Matrix::<D>::identity() * floor;
            kind = MlsKind::Regularized;
        }
        let gamma = Ops::inverse(&s).unwrap_or_else(|| Matrix::<D>::identity() / floor);
        let beta = -(gamma * mean);
        let alpha = 1.0 / m.a + mean.dot(&(gamma * mean));
        (Self { alpha, beta, gamma }, kind)
    }

    /// The second moment `Σ ŵ d dᵀ` (m²) of the normalised weights `ŵ = w / Σw` this inverse was built from,
    /// `Σw = total`: `S / Σw + d̄ d̄ᵀ`, with `S = Γ⁻¹` the Schur complement and the mean offset `d̄ = −S β`
    /// (a regularised system's S includes its floor). `h²/4 I` on a whole regular stencil.
    pub fn second_moment<Ops: crate::math::DimOps<D>>(&self, total: Real) -> Option<Matrix<D>> {
        let s = Ops::inverse(&self.gamma)?;
        let mean = -(s * self.beta);
        Some(s / total + mean * mean.transpose())
    }

    /// MLS shape function of a node with weight `w` at `dpos = x_i − x_p`:
    /// `phi = w·[M⁻¹P]₀` (value, eq. (4) first row) and `g = w·[M⁻¹P]₁..` (the
    /// rows of eq. (6) that turn stress into nodal force and give ∇v in eq. (4)).
    #[inline]
    pub fn shape(&self, w: Real, dpos: &Vector<D>) -> (Real, Vector<D>) {
        let phi = w * (self.alpha + self.beta.dot(dpos));
        let g = (self.beta + self.gamma * dpos) * w;
        (phi, g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    /// The stencil visits its 3^D nodes in the order of `stencil_offset` (first axis fastest), each with
    /// the weight `w₀ · Π_{k≥1} w_k` (the other axes' product in axis order), `x_i − x_p`, and its index from
    /// the strides: the transfers visit nodes in that order (3D G2P away from walls sums by rows), so it is
    /// part of the bitwise results.
    #[test]
    fn the_stencil_visits_nodes_in_offset_order() {
        fn check<const D: usize>(x: Vector<D>) {
            let (h, strides) = (0.1, std::array::from_fn::<usize, D, _>(|k| 1 + 7 * k * k));
            let s = Stencil::new(&x, 1.0 / h);
            let mut k = 0;
            s.for_each_index(h, 5, &strides, |i, w, d| {
                let o = stencil_offset::<D>(k);
                let weight = s.w[0][o[0]] * (1..D).fold(1.0, |acc, a| acc * s.w[a][o[a]]);
                assert_eq!(w.to_bits(), weight.to_bits());
                assert_eq!(i, 5 + (0..D).map(|a| o[a] * strides[a]).sum::<usize>());
                assert_eq!(d, Vector::<D>::from_fn(|a, _| (o[a] as Real - s.fx[a]) * h));
                k += 1;
            });
            assert_eq!(k, stencil_len(D));
        }
        check(Vector::<2>::new(0.337, 0.912));
        check(Vector::<3>::new(0.337, 0.912, 0.5501));
    }

    /// The rows of `for_each_row`, expanded node by node (`i + a·strides[0]`, weight `w₀[a]·w_rest`), are the
    /// nodes `visit` gives, in its order, with the same bits: the transfers that walk rows sum what the others
    /// sum node by node.
    #[test]
    fn rows_expand_to_the_visited_nodes() {
        fn check<const D: usize>(x: Vector<D>) {
            let (h, strides) = (0.1, std::array::from_fn::<usize, D, _>(|k| 1 + 7 * k * k));
            let s = Stencil::new(&x, 1.0 / h);
            let mut nodes = Vec::new();
            s.visit(h, &strides, |o, i, w, _| nodes.push((o, i, w.to_bits())));
            let mut rows = Vec::new();
            s.for_each_row(&strides, |o, i, w_rest| {
                assert_eq!(o[0], 0);
                for a in 0..3 {
                    let mut oa = o;
                    oa[0] = a;
                    rows.push((oa, i + a * strides[0], (s.w[0][a] * w_rest).to_bits()));
                }
            });
            assert_eq!(rows, nodes);
        }
        check(Vector::<2>::new(0.337, 0.912));
        check(Vector::<3>::new(0.337, 0.912, 0.5501));
    }

    fn positions() -> Vec<Vector2<Real>> {
        // Deterministic spread of positions, including cell faces and centres.
        let mut xs = vec![Vector2::new(0.5, 0.5), Vector2::new(0.25, 0.75)];
        for i in 0..50 {
            let t = i as Real * 0.618_033_988_75;
            xs.push(Vector2::new(1.0 + (t * 3.1).fract() * 5.0, 2.0 + (t * 7.3).fract() * 3.0));
        }
        xs
    }

    /// Partition of unity: the quadratic B-spline weights of a stencil sum to one.
    #[test]
    fn weights_partition_unity() {
        let h = 0.1;
        for x in positions() {
            let s = Stencil::<2>::new(&(x * h), 1.0 / h);
            let mut sum = 0.0;
            s.for_each(h, |_, w, _| sum += w);
            assert!((sum - 1.0).abs() < 1e-14, "sum {sum}");
        }
    }

    /// Linear reproduction: Σ w (x_i − x_p) = 0, so a linear field is reproduced exactly.
    #[test]
    fn weights_reproduce_linear_fields() {
        let h = 0.1;
        for x in positions() {
            let s = Stencil::<2>::new(&(x * h), 1.0 / h);
            let mut first = Vector2::zeros();
            s.for_each(h, |_, w, d| first += d * w);
            assert!(first.norm() < 1e-14, "first moment {first}");
        }
    }

    /// On a regular grid the moment matrix Σ w (x_i − x_p)(x_i − x_p)ᵀ equals h²/4·I.
    #[test]
    fn regular_moment_matrix_is_h2_over_4() {
        let h = 0.0125;
        for x in positions() {
            let s = Stencil::<2>::new(&(x * h), 1.0 / h);
            let mut m = nalgebra::Matrix2::<Real>::zeros();
            s.for_each(h, |_, w, d| m += d * d.transpose() * w);
            let expect = nalgebra::Matrix2::identity() * (h * h / 4.0);
            assert!((m - expect).norm() < 1e-12 * h * h, "{m}");
        }
    }

    /// On a whole regular stencil the general inverse of eq. (5) equals the closed form.
    #[test]
    fn general_inverse_matches_closed_form_on_regular_stencil() {
        let h = 0.0125;
        for x in positions() {
            let s = Stencil::<2>::new(&(x * h), 1.0 / h);
            let mut m = Moments::new();
            s.for_each(h, |_, w, d| m.add(w, &d));
            let (inv, kind) = MlsInverse::from_moments::<crate::math::Dim<2>>(&m, h);
            let closed = MlsInverse::<2>::regular(h);
            assert_eq!(kind, MlsKind::General);
            assert!((inv.alpha - 1.0).abs() < 1e-12);
            assert!(inv.beta.norm() * h < 1e-10);
            assert!((inv.gamma - closed.gamma).norm() / closed.gamma.norm() < 1e-10);
        }
    }

    /// Points on one line leave the moment matrix singular across it: regularized, not a panic.
    #[test]
    fn collinear_points_are_regularized() {
        let h = 0.1;
        let mut m = Moments::<2>::new();
        for k in -1..=1 {
            let d = Vector2::new(k as Real * h, 0.5 * h);
            m.add(weight(&d, 1.0 / h), &d);
        }
        let (inv, kind) = MlsInverse::from_moments::<crate::math::Dim<2>>(&m, h);
        assert_eq!(kind, MlsKind::Regularized);
        assert!(inv.gamma.iter().all(|v| v.is_finite()));
        let (_, kind) = MlsInverse::from_moments::<crate::math::Dim<2>>(&Moments::new(), h);
        assert_eq!(kind, MlsKind::Isolated);
    }

    /// The regular closed form gives phi = w and g = 4/h²·w·(x_i − x_p).
    #[test]
    fn regular_shape_is_apic() {
        let h = 0.5;
        let inv = MlsInverse::<2>::regular(h);
        let d = Vector2::new(0.3, -0.2);
        let (phi, g) = inv.shape(0.4, &d);
        assert_eq!(phi, 0.4);
        assert!((g - d * (0.4 * 4.0 / (h * h))).norm() < 1e-15);
    }

    /// The second moment of the weights an inverse was built from, `Σ ŵ d dᵀ` with `ŵ = w / Σw`, is what
    /// `second_moment` gives back (relative 1e-12), for points off centre on one side (as next to a wall),
    /// and `h²/4 I` for the closed form of a whole stencil.
    #[test]
    fn second_moment_is_that_of_the_weights() {
        let h = 0.1;
        let points = [(0.3, [0.02, -0.05]), (0.9, [0.11, 0.04]), (0.5, [-0.07, 0.09]), (0.2, [0.15, 0.12])];
        let mut m = Moments::<2>::new();
        let (mut total, mut direct) = (0.0, nalgebra::Matrix2::<Real>::zeros());
        for (w, d) in points {
            let d = Vector2::new(d[0], d[1]);
            m.add(w, &d);
            total += w;
            direct += d * d.transpose() * w;
        }
        direct /= total;
        let (inv, kind) = MlsInverse::from_moments::<crate::math::Dim<2>>(&m, h);
        assert_eq!(kind, MlsKind::General);
        let second = inv.second_moment::<crate::math::Dim<2>>(total).unwrap();
        assert!((second - direct).norm() < 1e-12 * direct.norm(), "{second} vs {direct}");
        let regular = MlsInverse::<2>::regular(h).second_moment::<crate::math::Dim<2>>(1.0).unwrap();
        assert!((regular - nalgebra::Matrix2::identity() * (h * h / 4.0)).norm() < 1e-15);
    }
}
