//! Particle storage, structure of arrays, declared once as a table of fields: the table drives the
//! storage, the checkpoint's keys and shapes, the restore checks and the memory accounting, for any
//! dimension D.

use crate::math::{Matrix, Real, Vector};

/// What a per-particle field holds for each particle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldKind {
    /// A vector of D reals.
    Vector,
    /// A D × D matrix of reals (stored row by row in checkpoints).
    Matrix,
    /// One real.
    Real,
    /// One unsigned 32-bit index.
    Index,
}

impl FieldKind {
    /// The shape of one particle's value in D dimensions: `[D]`, `[D, D]` or `[]`.
    pub fn shape(self, d: usize) -> Vec<usize> {
        match self {
            FieldKind::Vector => vec![d],
            FieldKind::Matrix => vec![d, d],
            FieldKind::Real | FieldKind::Index => vec![],
        }
    }

    /// Bytes of one particle's value in D dimensions.
    pub fn bytes(self, d: usize) -> usize {
        match self {
            FieldKind::Index => std::mem::size_of::<u32>(),
            kind => kind.shape(d).iter().product::<usize>() * std::mem::size_of::<Real>(),
        }
    }
}

/// One per-particle field: its name (the checkpoint's key), what it holds, its unit and doc line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    pub name: &'static str,
    pub kind: FieldKind,
    /// SI unit, "1" when dimensionless, "" for an index.
    pub unit: &'static str,
    pub doc: &'static str,
    /// Whether the column may be empty, standing for every particle at its kind's rest value
    /// ([`Column::to_f64_rows`]): kept only where a material reads it.
    pub optional: bool,
}

/// A field's values, read-only (the variant is the field's [`FieldKind`]).
#[derive(Clone, Copy, Debug)]
pub enum Column<'a, const D: usize> {
    Vector(&'a Vec<Vector<D>>),
    Matrix(&'a Vec<Matrix<D>>),
    Real(&'a Vec<Real>),
    Index(&'a Vec<u32>),
}

/// A field's values, to replace.
#[derive(Debug)]
pub enum ColumnMut<'a, const D: usize> {
    Vector(&'a mut Vec<Vector<D>>),
    Matrix(&'a mut Vec<Matrix<D>>),
    Real(&'a mut Vec<Real>),
    Index(&'a mut Vec<u32>),
}

impl<const D: usize> ColumnMut<'_, D> {
    /// Gives back the allocation beyond the column's length.
    pub fn shrink_to_fit(&mut self) {
        match self {
            ColumnMut::Vector(a) => a.shrink_to_fit(),
            ColumnMut::Matrix(a) => a.shrink_to_fit(),
            ColumnMut::Real(a) => a.shrink_to_fit(),
            ColumnMut::Index(a) => a.shrink_to_fit(),
        }
    }
}

impl<'a, const D: usize> Column<'a, D> {
    pub fn len(&self) -> usize {
        match self {
            Column::Vector(a) => a.len(),
            Column::Matrix(a) => a.len(),
            Column::Real(a) => a.len(),
            Column::Index(a) => a.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Heap bytes of the array (its capacity).
    pub fn heap_bytes(&self) -> usize {
        use crate::math::heap_bytes as b;
        match self {
            Column::Vector(a) => b(a),
            Column::Matrix(a) => b(a),
            Column::Real(a) => b(a),
            Column::Index(a) => b(a),
        }
    }

    /// Index of the first particle whose value is not finite (indices always are).
    pub fn first_non_finite(&self) -> Option<usize> {
        match self {
            Column::Vector(a) => a.iter().position(|v| !v.iter().all(|x| x.is_finite())),
            Column::Matrix(a) => a.iter().position(|m| !m.iter().all(|x| x.is_finite())),
            Column::Real(a) => a.iter().position(|x| !x.is_finite()),
            Column::Index(_) => None,
        }
    }

    /// The reals of the column for `n` particles, as [`Column::to_f64`] gives them; an empty column
    /// stands for every particle at its kind's rest value (a matrix I, a vector 0, a real 1).
    pub fn to_f64_rows(&self, n: usize) -> Option<Vec<f64>> {
        if !self.is_empty() || n == 0 {
            return self.to_f64();
        }
        Some(match self {
            Column::Vector(_) => vec![0.0; n * D],
            Column::Matrix(_) => {
                (0..n).flat_map(|_| (0..D * D).map(|k| if k / D == k % D { 1.0 } else { 0.0 })).collect()
            }
            Column::Real(_) => vec![1.0; n],
            Column::Index(_) => return None,
        })
    }

    /// The reals of the column, widened to f64, particle by particle (matrices row by row);
    /// `None` for an index column.
    #[allow(clippy::useless_conversion)] // `Real` is f64 here, f32 in augmpm-core-f32
    pub fn to_f64(&self) -> Option<Vec<f64>> {
        let w = |x: Real| f64::from(x);
        Some(match self {
            Column::Vector(a) => a.iter().flat_map(|v| v.iter().map(|&x| w(x)).collect::<Vec<_>>()).collect(),
            Column::Matrix(a) => {
                a.iter().flat_map(|m| (0..D).flat_map(move |i| (0..D).map(move |j| w(m[(i, j)])))).collect()
            }
            Column::Real(a) => a.iter().map(|&x| w(x)).collect(),
            Column::Index(_) => return None,
        })
    }
}

impl<const D: usize> ColumnMut<'_, D> {
    /// Replaces the values of a real column with `data` (particle by particle, matrices row by row,
    /// as [`Column::to_f64`] gives them), rounded to `Real`.
    pub fn set_f64(&mut self, data: &[f64]) {
        let r = |x: f64| x as Real;
        match self {
            ColumnMut::Vector(a) => {
                **a = data.chunks_exact(D).map(|c| Vector::<D>::from_fn(|i, _| r(c[i]))).collect();
            }
            ColumnMut::Matrix(a) => {
                **a = data.chunks_exact(D * D).map(|c| Matrix::<D>::from_fn(|i, j| r(c[i * D + j]))).collect();
            }
            ColumnMut::Real(a) => **a = data.iter().map(|&x| r(x)).collect(),
            ColumnMut::Index(_) => panic!("set_f64 on an index column"),
        }
    }

    /// Replaces the values of an index column.
    pub fn set_indices(&mut self, data: &[u32]) {
        match self {
            ColumnMut::Index(a) => **a = data.to_vec(),
            _ => panic!("set_indices on a real column"),
        }
    }
}

/// Declares a structure of per-particle arrays once: the struct (one `Vec` per field), its field
/// table `FIELDS` and its `columns`/`columns_mut` views in the same order.
#[macro_export]
macro_rules! per_particle {
    (
        $(#[$meta:meta])*
        pub struct $name:ident {
            $( $(#[doc = $doc:literal])* $field:ident : $kind:ident [$unit:literal $(, $optional:ident)?], )*
        }
    ) => {
        $(#[$meta])*
        pub struct $name<const D: usize> {
            $( $(#[doc = $doc])* pub $field: Vec<$crate::per_particle!(@type $kind)>, )*
        }

        impl<const D: usize> $name<D> {
            /// The fields, in declaration order.
            pub const FIELDS: &'static [$crate::particles::Field] = &[
                $( $crate::particles::Field {
                    name: stringify!($field),
                    kind: $crate::particles::FieldKind::$kind,
                    unit: $unit,
                    doc: concat!($($doc),*),
                    optional: $crate::per_particle!(@optional $($optional)?),
                }, )*
            ];

            /// Each field's values, in the order of [`Self::FIELDS`].
            pub fn columns(&self) -> Vec<$crate::particles::Column<'_, D>> {
                vec![$( $crate::particles::Column::$kind(&self.$field), )*]
            }

            /// Each field's values, to replace, in the order of [`Self::FIELDS`].
            pub fn columns_mut(&mut self) -> Vec<$crate::particles::ColumnMut<'_, D>> {
                vec![$( $crate::particles::ColumnMut::$kind(&mut self.$field), )*]
            }
        }
    };
    (@optional optional) => { true };
    (@optional) => { false };
    (@type Vector) => { $crate::math::Vector<D> };
    (@type Matrix) => { $crate::math::Matrix<D> };
    (@type Real) => { $crate::math::Real };
    (@type Index) => { u32 };
}

per_particle! {
    /// Material points. Every array has one entry per particle.
    #[derive(Clone, Debug, Default, PartialEq)]
    pub struct Particles {
        /// Position.
        x: Vector["m"],
        /// Velocity.
        v: Vector["m/s"],
        /// Affine velocity field, the velocity gradient ∇v of APIC/MLS. Next to a wall of the stable
        /// augmented grid, the state a particle keeps: its fitted gradient with the rotation rate that
        /// gives it APIC's regular spin m h²/4 axial(C) (`WallEntry::kept_affine`); P2G turns it back into
        /// the velocity over the particle's own grid points (`WallEntry::affine_velocity`), so the spin is
        /// kept as the particle moves. The strain rate (its symmetric part) is the fit's.
        c: Matrix["1/s"],
        /// Elastic deformation gradient F; empty when no material of the model keeps one (fluids do not),
        /// every particle then at F = I.
        f: Matrix["1", optional],
        /// Plastic volume ratio J_p (fluids: the volume ratio J).
        jp: Real["1"],
        /// Mass (per unit length in 2D).
        mass: Real["kg"],
        /// Initial volume (an area in 2D).
        vol0: Real["m³"],
        /// Index of the body the particle was seeded in, and of its material in the model (one a body).
        body: Index[""],
    }
}

/// Heap bytes of the arrays behind `columns`.
pub fn heap_bytes<const D: usize>(columns: &[Column<'_, D>]) -> usize {
    columns.iter().map(Column::heap_bytes).sum()
}

/// The first column whose length is not `n` (nor 0 for an optional field), as a message naming its field.
pub fn check_lengths<const D: usize>(columns: &[Column<'_, D>], fields: &[Field], n: usize) -> Result<(), String> {
    match columns.iter().zip(fields).find(|(c, f)| c.len() != n && !(f.optional && c.is_empty())) {
        Some((c, f)) => Err(format!("{} has {} entries for {n} particles", f.name, c.len())),
        None => Ok(()),
    }
}

impl<const D: usize> Particles<D> {
    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Adds a particle at rest state (F = I, J_p = 1, ∇v = 0). Its F is not stored: an empty `f` holds every
    /// particle at I, and a simulation whose materials keep F fills it (seeding then never holds it twice).
    pub fn push(&mut self, x: Vector<D>, v: Vector<D>, mass: Real, vol0: Real, body: u32) {
        self.x.push(x);
        self.v.push(v);
        self.c.push(Matrix::<D>::zeros());
        self.jp.push(1.0);
        self.mass.push(mass);
        self.vol0.push(vol0);
        self.body.push(body);
    }

    /// Particle `p`'s deformation gradient: I where the model keeps none.
    #[inline]
    pub fn deformation_gradient(&self, p: usize) -> Matrix<D> {
        self.f.get(p).copied().unwrap_or_else(Matrix::<D>::identity)
    }

    /// Heap bytes of the particle arrays.
    pub fn heap_bytes(&self) -> usize {
        heap_bytes(&self.columns())
    }

    /// Bytes per particle of the arrays, in D dimensions, with every optional column kept.
    pub fn bytes_per_particle() -> usize {
        Self::FIELDS.iter().map(|f| f.kind.bytes(D)).sum()
    }

    /// Total kinetic energy ½ Σ m v² (J, or J/m in 2D), summed in particle order in f64 as
    /// ½ Σ (√m |v|)² ([`energy_root`]).
    pub fn kinetic_energy(&self) -> f64 {
        0.5 * self.mass.iter().zip(&self.v).map(|(&m, v)| energy_root(m, v).powi(2)).sum::<f64>()
    }

    /// Total momentum Σ m v.
    pub fn momentum(&self) -> Vector<D> {
        self.mass.iter().zip(&self.v).fold(Vector::<D>::zeros(), |acc, (m, v)| acc + v * *m)
    }
}

/// √(m) |v| in f64: its square is twice a particle's kinetic energy. Infinite when m or |v|² is beyond the
/// f64 range (NaN if the other factor is 0), NaN for a negative or NaN mass.
#[inline]
#[allow(clippy::useless_conversion)] // `Real` is f64 here, f32 in augmpm-core-f32
pub fn energy_root<const D: usize>(m: Real, v: &Vector<D>) -> f64 {
    f64::from(m).sqrt() * v.iter().map(|&a| f64::from(a).powi(2)).sum::<f64>().sqrt()
}

/// Whether m |v|², twice a particle's kinetic energy, is within the f64 range: `energy_root(m, v) < √f64::MAX`
/// up to rounding at that boundary, without its two square roots. Both fail when |v|² alone overflows, and for
/// a negative, infinite or NaN mass.
#[inline]
#[allow(clippy::useless_conversion)] // as above
pub fn energy_in_range<const D: usize>(m: Real, v: &Vector<D>) -> bool {
    let m = f64::from(m);
    m >= 0.0 && (m * v.iter().map(|&a| f64::from(a).powi(2)).sum::<f64>()).is_finite()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table lists every array of the struct, and `push` grows each by one particle.
    #[test]
    fn the_table_covers_every_array_and_push_fills_them() {
        let mut p = Particles::<3>::default();
        p.push(Vector::<3>::zeros(), Vector::<3>::zeros(), 1.0, 1.0, 0);
        p.push(Vector::<3>::zeros(), Vector::<3>::zeros(), 1.0, 1.0, 0);
        assert_eq!(p.columns().len(), Particles::<3>::FIELDS.len());
        check_lengths(&p.columns(), Particles::<3>::FIELDS, 2).unwrap();
        let names: Vec<&str> = Particles::<3>::FIELDS.iter().map(|f| f.name).collect();
        assert_eq!(names, ["x", "v", "c", "f", "jp", "mass", "vol0", "body"]);
        // 3D: 3 + 3 + 9 + 9 + 3 reals and 1 index per particle.
        assert_eq!(Particles::<3>::bytes_per_particle(), 27 * std::mem::size_of::<Real>() + 4);
        // Every array but the optional F, which the seeding leaves empty (every particle at F = I).
        assert!(p.f.is_empty() && p.deformation_gradient(1) == Matrix::<3>::identity());
        assert!(p.heap_bytes() >= 2 * (Particles::<3>::bytes_per_particle() - 9 * std::mem::size_of::<Real>()));
    }

    /// A column written from its f64 form reads back the same (matrices row by row).
    #[test]
    fn columns_round_trip_through_f64() {
        let mut p = Particles::<2>::default();
        p.push(Vector::<2>::new(0.25, 0.5), Vector::<2>::new(1.0, -2.0), 3.0, 0.5, 1);
        p.c[0] = Matrix::<2>::new(1.0, 2.0, 3.0, 4.0);
        assert_eq!(Column::Matrix(&p.c).to_f64().unwrap(), [1.0, 2.0, 3.0, 4.0]);
        // The empty F of a seeded particle reads as the identity; a kept column as it is.
        assert_eq!(Column::Matrix(&p.f).to_f64_rows(2).unwrap(), [1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0]);
        assert_eq!(Column::Matrix(&p.c).to_f64_rows(1), Column::Matrix(&p.c).to_f64());
        let mut q = Particles::<2>::default();
        for (from, mut to) in p.columns().iter().zip(q.columns_mut()) {
            match from.to_f64() {
                Some(data) => to.set_f64(&data),
                None => match from {
                    Column::Index(a) => to.set_indices(a.as_slice()),
                    _ => unreachable!(),
                },
            }
        }
        assert_eq!(p, q);
    }

    /// `energy_in_range` agrees with `energy_root(m, v) < √f64::MAX`, the form the kinetic energy sums: for
    /// positive masses and speeds drawn over the whole f64 range, except within rounding of the boundary
    /// (m |v|² within a factor 1 ± 7·10⁻¹⁰ of f64::MAX: its logarithm within 10⁻¹² ln MAX of ln MAX), and for
    /// zero, negative, subnormal, infinite and NaN masses and velocity components, in 2D and 3D. f64 only: in
    /// f32 no particle's energy reaches the f64 range.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn energy_in_range_is_energy_root_below_the_root_of_the_largest_float() {
        use rand::{Rng, SeedableRng};
        let by_root = |m: Real, v: &[Real]| {
            if v.len() == 2 {
                energy_root(m, &Vector::<2>::from_column_slice(v)) < f64::MAX.sqrt()
            } else {
                energy_root(m, &Vector::<3>::from_column_slice(v)) < f64::MAX.sqrt()
            }
        };
        let in_range = |m: Real, v: &[Real]| {
            if v.len() == 2 {
                energy_in_range(m, &Vector::<2>::from_column_slice(v))
            } else {
                energy_in_range(m, &Vector::<3>::from_column_slice(v))
            }
        };
        let masses = [0.0, -0.0, 1.0, -1.0, 5e-324, Real::INFINITY, Real::NEG_INFINITY, Real::NAN];
        let parts = [0.0, -2.0, 1e200, Real::INFINITY, Real::NAN];
        for &m in &masses {
            for &a in &parts {
                for &b in &parts {
                    for v in [vec![a, b], vec![b, 1.0, a]] {
                        assert_eq!(in_range(m, &v), by_root(m, &v), "m = {m}, v = {v:?}");
                    }
                }
            }
        }
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let (lo, hi) = (Real::MIN_POSITIVE.log10(), Real::MAX.log10());
        let mut tried = [0; 2];
        for _ in 0..20_000 {
            let m: Real = (10.0 as Real).powf(rng.gen_range(lo..hi));
            let v = Vector::<2>::from_fn(|_, _| {
                let sign = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
                sign * (10.0 as Real).powf(rng.gen_range(lo..hi))
            });
            let two_e = m.ln() + v.iter().map(|&a| a.powi(2)).sum::<f64>().ln();
            if (two_e - f64::MAX.ln()).abs() < 1e-12 * f64::MAX.ln() {
                continue;
            }
            let by_root = energy_root(m, &v) < f64::MAX.sqrt();
            assert_eq!(energy_in_range(m, &v), by_root, "m = {m}, v = {v}");
            tried[usize::from(by_root)] += 1;
        }
        // Both sides of the boundary were seen.
        assert!(tried[0] > 1000 && tried[1] > 1000, "{tried:?}");
    }
}
