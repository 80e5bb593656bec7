//! Particle storage, structure of arrays.

use crate::math::{Matrix, Real, Vector};

/// Material points. Every array has one entry per particle.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Particles<const D: usize> {
    /// Position (m).
    pub x: Vec<Vector<D>>,
    /// Velocity (m/s).
    pub v: Vec<Vector<D>>,
    /// Affine velocity field, the velocity gradient ∇v (1/s) of APIC/MLS.
    pub c: Vec<Matrix<D>>,
    /// Elastic deformation gradient F.
    pub f: Vec<Matrix<D>>,
    /// Plastic volume ratio J_p.
    pub jp: Vec<Real>,
    /// Mass (kg, or kg/m in 2D).
    pub mass: Vec<Real>,
    /// Initial volume (m³, or m² in 2D).
    pub vol0: Vec<Real>,
    /// Index of the body the particle was seeded in.
    pub body: Vec<u32>,
    /// Index of the particle's material in the model.
    pub material: Vec<u32>,
}

impl<const D: usize> Particles<D> {
    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Adds a particle at rest state (F = I, J_p = 1, ∇v = 0).
    pub fn push(&mut self, x: Vector<D>, v: Vector<D>, mass: Real, vol0: Real, body: u32, material: u32) {
        self.x.push(x);
        self.v.push(v);
        self.c.push(Matrix::<D>::zeros());
        self.f.push(Matrix::<D>::identity());
        self.jp.push(1.0);
        self.mass.push(mass);
        self.vol0.push(vol0);
        self.body.push(body);
        self.material.push(material);
    }

    /// Heap bytes of the particle arrays.
    pub fn heap_bytes(&self) -> usize {
        use crate::math::heap_bytes as b;
        b(&self.x)
            + b(&self.v)
            + b(&self.c)
            + b(&self.f)
            + b(&self.jp)
            + b(&self.mass)
            + b(&self.vol0)
            + b(&self.body)
            + b(&self.material)
    }

    /// Total kinetic energy ½ Σ m v² (J, or J/m in 2D), summed in particle order in f64 as
    /// ½ Σ (√m |v|)², which overflows only when the energy itself is beyond the f64 range.
    pub fn kinetic_energy(&self) -> f64 {
        0.5 * self.mass.iter().zip(&self.v).map(|(&m, v)| energy_root(m, v).powi(2)).sum::<f64>()
    }

    /// Total momentum Σ m v.
    pub fn momentum(&self) -> Vector<D> {
        self.mass.iter().zip(&self.v).fold(Vector::<D>::zeros(), |acc, (m, v)| acc + v * *m)
    }
}

/// √(m) |v| in f64: its square is twice a particle's kinetic energy, finite exactly when that
/// energy is within the f64 range (m |v|² itself can overflow first).
#[inline]
#[allow(clippy::useless_conversion)] // `Real` is f64 here, f32 in augmpm-core-f32
pub fn energy_root<const D: usize>(m: Real, v: &Vector<D>) -> f64 {
    f64::from(m).sqrt() * v.iter().map(|&a| f64::from(a).powi(2)).sum::<f64>().sqrt()
}
