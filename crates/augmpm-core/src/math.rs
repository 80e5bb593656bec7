//! Scalar, vector and matrix types, generic over the spatial dimension `D`.
//!
//! The whole engine is written once over `const D: usize`; 2D is `D = 2` and 3D
//! is a second instantiation of the same code. The few operations whose
//! nalgebra implementation needs per-dimension trait bounds (the SVD) live
//! behind [`DimOps`], implemented for `Dim<2>` and `Dim<3>`.

use nalgebra::{SMatrix, SVector};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Floating-point type of the core: `f64`, or `f32` with the feature `f32` (the crate
/// `augmpm-core-f32` compiles these same sources that way).
#[cfg(not(feature = "f32"))]
pub type Real = f64;
/// Floating-point type of the core: `f64`, or `f32` with the feature `f32` (the crate
/// `augmpm-core-f32` compiles these same sources that way).
#[cfg(feature = "f32")]
pub type Real = f32;
/// π in the core's precision.
pub const PI: Real = std::f64::consts::PI as Real;
/// A point or vector in `D` dimensions (m, m/s, ...).
pub type Vector<const D: usize> = SVector<Real, D>;
/// A `D`×`D` tensor (deformation gradient, stress, velocity gradient).
pub type Matrix<const D: usize> = SMatrix<Real, D, D>;

/// Marker type naming a supported dimension.
pub struct Dim<const D: usize>;

/// Operations whose implementation depends on the dimension.
pub trait DimOps<const D: usize> {
    /// Rotation-variant SVD `m = U diag(s) Vᵀ` with `det U = det V = +1`
    /// (a negative determinant of `m` shows up as a negative last singular value).
    fn svd(m: &Matrix<D>) -> (Matrix<D>, Vector<D>, Matrix<D>);
    /// Determinant of `m`.
    fn det(m: &Matrix<D>) -> Real;
    /// Smallest eigenvalue of the symmetric matrix `m`.
    fn min_sym_eigenvalue(m: &Matrix<D>) -> Real;
    /// Inverse of `m`, if it is invertible.
    fn inverse(m: &Matrix<D>) -> Option<Matrix<D>>;
    /// Whether the smallest eigenvalue of the symmetric matrix `m` is at least `floor`: in 2D
    /// `min_sym_eigenvalue(m) >= floor`; in 3D whether `m − floor·I` has positive pivots (a Cholesky
    /// factorisation without its square roots; the same answer but where the two are within rounding).
    fn at_least(m: &Matrix<D>, floor: Real) -> bool;
}

macro_rules! impl_dim_ops {
    ($d:literal) => {
        impl DimOps<$d> for Dim<$d> {
            fn svd(m: &Matrix<$d>) -> (Matrix<$d>, Vector<$d>, Matrix<$d>) {
                let svd = m.svd(true, true);
                let mut u = svd.u.expect("SVD computed with U");
                let mut v = svd.v_t.expect("SVD computed with Vt").transpose();
                let mut s = svd.singular_values;
                if u.determinant() < 0.0 {
                    u.column_mut($d - 1).neg_mut();
                    s[$d - 1] = -s[$d - 1];
                }
                if v.determinant() < 0.0 {
                    v.column_mut($d - 1).neg_mut();
                    s[$d - 1] = -s[$d - 1];
                }
                (u, s, v)
            }
            #[inline]
            fn det(m: &Matrix<$d>) -> Real {
                m.determinant()
            }
            fn min_sym_eigenvalue(m: &Matrix<$d>) -> Real {
                if $d == 2 {
                    // Closed form for 2×2: λ_min = t − √(t² − det), t = tr/2 (the hot path in 2D).
                    let t = 0.5 * (m[(0, 0)] + m[(1, 1)]);
                    let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
                    t - (t * t - det).max(0.0).sqrt()
                } else {
                    // Closed form for 3×3 (the hot path in 3D): an iterative decomposition per
                    // particle and Newton step costs more than the rest of the fit.
                    let a: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| wide(m[(i, j)])));
                    let closed = min_sym3_eigenvalue(&a) as Real;
                    // Where the spread underflows (off-diagonal entries near the smallest normal), iterate.
                    if closed.is_finite() {
                        closed
                    } else {
                        m.symmetric_eigenvalues().min()
                    }
                }
            }
            #[inline]
            fn inverse(m: &Matrix<$d>) -> Option<Matrix<$d>> {
                m.try_inverse()
            }
            #[inline]
            fn at_least(m: &Matrix<$d>, floor: Real) -> bool {
                if $d == 2 {
                    Self::min_sym_eigenvalue(m) >= floor
                } else {
                    let a = |i: usize, j: usize| m[(i, j)] - if i == j { floor } else { 0.0 };
                    // Pivots d0, d1, d2 of m − floor·I = L diag(d) Lᵀ; a NaN pivot fails too.
                    let d0 = a(0, 0);
                    if d0 > 0.0 {
                        let (l10, l20) = (a(1, 0) / d0, a(2, 0) / d0);
                        let d1 = a(1, 1) - l10 * a(1, 0);
                        if d1 > 0.0 {
                            let l21 = (a(2, 1) - l20 * a(1, 0)) / d1;
                            return a(2, 2) - l20 * a(2, 0) - l21 * l21 * d1 > 0.0;
                        }
                    }
                    false
                }
            }
        }
    };
}
impl_dim_ops!(2);
impl_dim_ops!(3);

/// Twice the axial vector of `a`'s antisymmetric part, `(a_zy − a_yz, a_xz − a_zx, a_yx − a_xy)` (in 2D
/// only z): with `D = Σ w d dᵀ`, `Σ w d × (A d) = axial(A D)`. So a particle's APIC spin, the angular
/// momentum of its affine velocity over its grid points, is `m axial(C D)`.
#[inline]
pub fn axial<const D: usize>(a: &Matrix<D>) -> Vector<3> {
    let z = a[(1, 0)] - a[(0, 1)];
    if D == 3 {
        Vector::<3>::new(a[(2, 1)] - a[(1, 2)], a[(0, 2)] - a[(2, 0)], z)
    } else {
        Vector::<3>::new(0.0, 0.0, z)
    }
}

/// The rotation rate `W` with `W d = w × d` (rad/s), for `w` given as a 3-vector (in 2D only its z counts).
#[inline]
pub fn rotation_rate<const D: usize>(w: &Vector<3>) -> Matrix<D> {
    let mut m = Matrix::<D>::zeros();
    m[(0, 1)] = -w.z;
    m[(1, 0)] = w.z;
    if D == 3 {
        m[(0, 2)] = w.y;
        m[(2, 0)] = -w.y;
        m[(1, 2)] = -w.x;
        m[(2, 1)] = w.x;
    }
    m
}

/// The affine velocity `C + W` that has over second moment `to` (m²) the spin `c` has over `from`:
/// `axial((C + W) to) = axial(C from)` ([`axial`]), with `W` a rotation rate alone, so its symmetric part
/// (the strain rate) is `C`'s. `axial(W to) = (tr(to) I − to) w` for `W d = w × d`, which is positive
/// definite for a positive definite `to`; where it is singular, `C` is returned as it is.
pub fn keep_spin<const D: usize>(c: &Matrix<D>, from: &Matrix<D>, to: &Matrix<D>) -> Matrix<D> {
    let missing = axial(&(c * from)) - axial(&(c * to));
    let trace = to.trace();
    let w = if D == 3 {
        let m = nalgebra::Matrix3::<Real>::from_fn(|i, j| if i == j { trace } else { 0.0 } - to[(i, j)]);
        m.try_inverse().map(|inv| inv * missing)
    } else {
        (trace != 0.0).then(|| missing / trace)
    };
    match w {
        Some(w) if w.iter().all(|a| a.is_finite()) => c + rotation_rate::<D>(&w),
        _ => *c,
    }
}

/// Smallest eigenvalue of a symmetric 3×3 matrix, in closed form (Smith 1961, "Eigenvalues of a
/// symmetric 3 × 3 matrix", Commun. ACM 4(4)): with q = tr/3 and p² = ‖A − qI‖²_F / 6, the eigenvalues are
/// q + 2p cos(φ + 2πk/3), 3φ = acos(det((A − qI)/p)/2); the smallest is k = 1. Accurate to about
/// √ε p where two eigenvalues meet, to rounding elsewhere.
pub fn min_sym3_eigenvalue(a: &[[f64; 3]; 3]) -> f64 {
    let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    if off == 0.0 {
        return a[0][0].min(a[1][1]).min(a[2][2]);
    }
    let q = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
    let (b00, b11, b22) = (a[0][0] - q, a[1][1] - q, a[2][2] - q);
    let p = ((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * off) / 6.0).sqrt();
    let det = b00 * (b11 * b22 - a[1][2] * a[1][2]) - a[0][1] * (a[0][1] * b22 - a[1][2] * a[0][2])
        + a[0][2] * (a[0][1] * a[1][2] - b11 * a[0][2]);
    let r = (det / (2.0 * p * p * p)).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos()
}

/// `x` in double precision, whatever [`Real`] is.
#[allow(clippy::unnecessary_cast, clippy::useless_conversion)]
#[inline]
pub fn wide(x: Real) -> f64 {
    x as f64
}

/// `x.floor() as i64` without a libm call (x86-64's baseline has no rounding instruction):
/// truncate, then step down for negative non-integers. NaN gives 0 and ±∞ the extreme values, as the
/// cast does (saturating, so no overflow).
#[inline(always)]
pub fn floor_i64(x: Real) -> i64 {
    // Below 2^(mantissa bits − 1), adding 1.5·2^(mantissa bits) rounds x to an integer held in the low
    // bits of the sum (no float→int conversion, whose saturation checks cost more than the rest); one
    // step down where it rounded up. NaN, the infinities and huge values take the saturating cast.
    #[cfg(not(feature = "f32"))]
    const MANTISSA: i32 = 52;
    #[cfg(feature = "f32")]
    const MANTISSA: i32 = 23;
    let magic: Real = 1.5 * (2.0 as Real).powi(MANTISSA);
    if x.abs() < (2.0 as Real).powi(MANTISSA - 1) {
        let sum = x + magic;
        #[cfg(not(feature = "f32"))]
        let rounded = sum.to_bits().wrapping_sub(magic.to_bits()) as i64;
        #[cfg(feature = "f32")]
        let rounded = i64::from(sum.to_bits().wrapping_sub(magic.to_bits()) as i32);
        rounded - i64::from(sum - magic > x)
    } else {
        let t = x as i64;
        t.saturating_sub(i64::from((t as Real) > x))
    }
}

/// `x^n` by repeated squaring, inlined: the products, in the order, of the compiler's `__powidf2`, which
/// `powi` calls when the exponent is known only at run time, so the result is bitwise the same, without
/// the call.
#[inline(always)]
pub fn powu(mut x: Real, mut n: u32) -> Real {
    let mut y = 1.0;
    loop {
        if n & 1 == 1 {
            y *= x;
        }
        n >>= 1;
        if n == 0 {
            return y;
        }
        x *= x;
    }
}

/// `exp(x)`, by its Taylor series to x⁵ where |x| < 2⁻⁸ (the remainder, below x⁶/6! < 5·10⁻¹⁸, is under
/// half an f64 ulp of the result: within an ulp of libm's), and by libm's `exp` elsewhere. A fluid's
/// volume changes by exp(dt tr ∇v) per step, whose argument is a small fraction of a cell's strain: the
/// libm call was ~6% of a fluid step. The series is summed in Estrin's order (powers of x² over pairs):
/// a chain of five operations rather than Horner's ten.
#[inline(always)]
pub fn exp_near_zero(x: Real) -> Real {
    if x.abs() < 1.0 / 256.0 {
        let x2 = x * x;
        (1.0 + x) + x2 * ((0.5 + x * (1.0 / 6.0)) + x2 * (1.0 / 24.0 + x * (1.0 / 120.0)))
    } else {
        x.exp()
    }
}

/// Sets flush-to-zero and denormals-are-zero for the calling thread (x86-64; elsewhere a no-op).
/// Impacts produce subnormal floats whose arithmetic is many times slower; at the scales of a
/// simulation (velocities, masses, stresses far above 1e-308) flushing them changes nothing.
pub fn flush_denormals() {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: MXCSR bits 15 (FTZ) and 6 (DAZ) only change how subnormal results are rounded.
    #[allow(deprecated)]
    unsafe {
        use std::arch::x86_64::{_mm_getcsr, _mm_setcsr};
        _mm_setcsr(_mm_getcsr() | 0x8040);
    }
}

/// Heap bytes of a vector's allocation (its capacity, not its length).
pub fn heap_bytes<T>(v: &Vec<T>) -> usize {
    v.capacity() * std::mem::size_of::<T>()
}

/// Resizes `v` to `len` entries (new ones `value`), growing its allocation, when it must, to `len` and an
/// eighth more rather than doubling it: per-step tables whose length drifts keep about their size.
pub fn resize_with_margin<T: Clone>(v: &mut Vec<T>, len: usize, value: T) {
    if len > v.capacity() {
        v.reserve_exact(len + len / 8 - v.len());
    }
    v.resize(len, value);
}

/// Number of nodes in the 3^D stencil of the quadratic B-spline.
pub const fn stencil_len(d: usize) -> usize {
    3usize.pow(d as u32)
}

/// The `k`-th offset of the 3^D stencil, each component in {0, 1, 2}.
#[inline]
pub fn stencil_offset<const D: usize>(mut k: usize) -> [usize; D] {
    let mut o = [0usize; D];
    for c in o.iter_mut() {
        *c = k % 3;
        k /= 3;
    }
    o
}

/// Floating-point precision: `f64` (default) or `f32`, each an engine compiled from the same sources.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// Single precision (the `augmpm-core-f32` engine).
    F32,
    /// Double precision.
    #[default]
    F64,
}

impl Precision {
    /// The precision this engine is compiled with.
    pub const NATIVE: Self = if std::mem::size_of::<Real>() == 4 { Precision::F32 } else { Precision::F64 };
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Matrix3};

    /// Numbers in [−0.5, 0.5) from `seed` (xorshift64).
    fn uniform(mut s: u64) -> impl FnMut() -> f64 {
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        }
    }

    /// The rotation-variant SVD reconstructs the matrix and returns proper rotations.
    #[test]
    fn svd_reconstructs_with_rotations() {
        let m = Matrix2::new(0.9, -0.3, 0.2, -1.1); // det < 0: a reflection
        let (u, s, v) = Dim::<2>::svd(&m);
        let r = u * Matrix2::from_diagonal(&s) * v.transpose();
        assert!((r - m).norm() < 1e-12);
        assert!((u.determinant() - 1.0).abs() < 1e-12);
        assert!((v.determinant() - 1.0).abs() < 1e-12);
        let m3 = Matrix3::new(1.0, 0.2, 0.0, 0.1, 0.8, 0.3, 0.0, -0.2, 1.3);
        let (u, s, v) = Dim::<3>::svd(&m3);
        assert!((u * Matrix3::from_diagonal(&s) * v.transpose() - m3).norm() < 1e-12);
    }

    #[test]
    fn floor_matches_the_standard_library() {
        for x in [-2.5, -2.0, -0.5, -1e-300, -0.0, 0.0, 0.3, 1.0, 1.5, 2.5, 3.5, -3.5, 1e15 + 0.5, -1e15 - 0.5] {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
        }
        // Each side of the rounding trick's range, and the halves where rounding to even goes either way.
        let edge = 2f64.powi(51);
        for x in [edge - 0.5, -edge + 0.5, edge, -edge, edge + 1.0, 1e300, -1e300] {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
        }
        let mut next = uniform(0x853c49e6748fea9bu64);
        for _ in 0..100_000 {
            let x = next() * 1e4;
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
            let half = (next() * 1e6).round() + 0.5;
            assert_eq!(floor_i64(half), half.floor() as i64, "{half}");
        }
        assert_eq!(floor_i64(Real::NAN), 0);
        assert_eq!(floor_i64(Real::INFINITY), i64::MAX);
        assert_eq!(floor_i64(Real::NEG_INFINITY), i64::MIN);
    }

    #[test]
    fn smallest_symmetric_eigenvalue() {
        let m = Matrix2::new(2.0, 1.0, 1.0, 2.0); // eigenvalues 1 and 3
        assert!((Dim::<2>::min_sym_eigenvalue(&m) - 1.0).abs() < 1e-14);
        let m3 = Matrix3::new(2.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 4.0);
        assert!((Dim::<3>::min_sym_eigenvalue(&m3) - 0.5).abs() < 1e-14);
    }

    /// The closed form of the smallest eigenvalue of a symmetric 3×3 matrix agrees with nalgebra's
    /// iterative decomposition to 1e-12 of the matrix's norm on random matrices, and to 1e-7 where two
    /// eigenvalues meet (diag(1, 1, 3) turned; its smallest is 1).
    #[test]
    fn closed_form_smallest_eigenvalue_in_3d() {
        let mut next = uniform(0x2545f4914f6cdd1du64);
        for _ in 0..1000 {
            let g = Matrix3::from_fn(|_, _| next());
            let m = g * g.transpose() + Matrix3::from_fn(|_, _| 0.1 * next()).symmetric_part();
            let a: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]));
            let exact = m.symmetric_eigenvalues().min();
            assert!((min_sym3_eigenvalue(&a) - exact).abs() < 1e-12 * m.norm(), "{m}");
        }
        let r = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1).into_inner();
        let m = r * Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, 3.0)) * r.transpose();
        let a: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]));
        assert!((min_sym3_eigenvalue(&a) - 1.0).abs() < 1e-7);
    }

    /// The 3D pivot test says "the smallest eigenvalue is at least the floor" exactly when the eigenvalues
    /// do, on random symmetric matrices with floors on both sides of it (but within 1e-9 of it).
    #[test]
    fn at_least_agrees_with_the_smallest_eigenvalue() {
        let mut next = uniform(0x9e3779b97f4a7c15u64);
        for _ in 0..2000 {
            let g = Matrix3::from_fn(|_, _| next());
            let m = (g * g.transpose() + Matrix3::from_fn(|_, _| 0.3 * next())).symmetric_part();
            let lowest = m.symmetric_eigenvalues().min();
            let floor = lowest + next();
            if (floor - lowest).abs() > 1e-9 {
                assert_eq!(Dim::<3>::at_least(&m, floor), lowest >= floor, "{m} against {floor}");
            }
        }
    }

    #[test]
    fn stencil_offsets_cover_the_block_once() {
        let mut seen = std::collections::HashSet::new();
        for k in 0..stencil_len(3) {
            assert!(seen.insert(stencil_offset::<3>(k)));
        }
        assert_eq!(seen.len(), 27);
    }

    /// A particle's APIC spin carried from one second moment to another (`keep_spin`) is the same, the
    /// strain rate is untouched, and carrying it back returns the matrix (relative 1e-13, a few dozen
    /// operations on O(1) numbers): in 2D and 3D, on random matrices and random positive definite moments;
    /// and `axial` is the moment of `A d` about the particle, `Σ w d × (A d)`.
    #[test]
    fn keep_spin_moves_the_spin_and_nothing_else() {
        fn check<const D: usize>(c: &Matrix<D>, from: &Matrix<D>, to: &Matrix<D>) {
            let kept = keep_spin(c, from, to);
            assert!((axial(&(kept * to)) - axial(&(c * from))).norm() < 1e-13 * (1.0 + c.norm()));
            assert!((kept.symmetric_part() - c.symmetric_part()).norm() < 1e-13);
            assert!((keep_spin(&kept, to, from) - c).norm() < 1e-12 * (1.0 + c.norm()));
        }
        let mut next = uniform(0x2545f4914f6cdd1du64);
        for _ in 0..200 {
            let c3 = Matrix3::from_fn(|_, _| next());
            let (g, k) = (Matrix3::from_fn(|_, _| next()), Matrix3::from_fn(|_, _| next()));
            let (from3, to3) = (g * g.transpose() + Matrix3::identity() * 0.01, k * k.transpose() * 0.3);
            let (c2, from2, to2) = (
                c3.fixed_view::<2, 2>(0, 0).into_owned(),
                from3.fixed_view::<2, 2>(0, 0).into_owned(),
                to3.fixed_view::<2, 2>(0, 0).into_owned(),
            );
            check(&c3, &from3, &to3);
            check(&c2, &from2, &to2);
            // Σ w d × (A d) over a few points against axial(A Σ w d dᵀ).
            let points: Vec<(f64, Vector<3>)> =
                (0..5).map(|_| (next() + 0.5, Vector::<3>::new(next(), next(), next()))).collect();
            let direct = points.iter().fold(Vector::<3>::zeros(), |a, (w, d)| a + d.cross(&(c3 * d)) * *w);
            let second = points.iter().fold(Matrix3::zeros(), |a, (w, d)| a + d * d.transpose() * *w);
            assert!((direct - axial(&(c3 * second))).norm() < 1e-13);
        }
        // Where the target moment is empty, nothing can carry the spin: C comes back as it was.
        assert_eq!(
            keep_spin(&Matrix2::new(1.0, 2.0, 3.0, 4.0), &Matrix2::identity(), &Matrix2::zeros()),
            Matrix2::new(1.0, 2.0, 3.0, 4.0)
        );
    }

    /// `powu` is `powi` bitwise (the same products in the same order), for the exponents a fluid's
    /// equation of state takes (0 to 16) and densities around and far from rest.
    #[test]
    fn powu_is_powi_bitwise() {
        let mut next = uniform(0x9e3779b97f4a7c15u64);
        for _ in 0..2000 {
            let x = 1.0 + next() * 0.2 * if next() > 0.0 { 1.0 } else { 50.0 };
            for n in 0..=16u32 {
                assert_eq!(powu(x, n).to_bits(), x.powi(n as i32).to_bits(), "{x}^{n}");
            }
        }
    }

    /// `exp_near_zero` is within one ulp of libm's `exp` (its series remainder is under half an ulp,
    /// Horner's rule adds under one): over its series' range, at the range's ends, and past them
    /// (libm's itself).
    #[test]
    fn exp_near_zero_matches_exp_within_an_ulp() {
        let mut next = uniform(0x2545f4914f6cdd1du64);
        let ulps = |x: f64| (exp_near_zero(x).to_bits() as i64 - x.exp().to_bits() as i64).abs();
        let mut worst = 0;
        for k in 0..20000 {
            let x = next() / 128.0 * 0.999_999 * [1.0, 1e-3, 1e-8][k % 3];
            worst = worst.max(ulps(x));
        }
        for x in [0.0, -0.0, 1.0 / 256.0 - 1e-18, -1.0 / 256.0 + 1e-18, 1.0 / 256.0, 0.5, -3.0, 40.0] {
            worst = worst.max(ulps(x));
        }
        assert!(worst <= 1, "{worst} ulps");
    }
}
