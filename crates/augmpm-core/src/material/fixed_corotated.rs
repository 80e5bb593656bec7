//! Fixed-corotated hyperelasticity (Stomakhin et al. 2012).

use super::{advance_f, elastic_dt, lame, ConstitutiveModel, MaterialPoint};
use crate::math::{Dim, DimOps, Matrix, Real};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Elastic solid with Kirchhoff stress `τ = 2μ(F − R)Fᵀ + λ(J − 1)J I`, R the rotation of F.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FixedCorotated {
    /// Rest density ρ0 (per unit area in 2D).
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "kg/m²"))]
    pub density: Real,
    /// Young's modulus E (a stress: N/m in 2D, Pa in 3D).
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "N/m"))]
    pub youngs_modulus: Real,
    /// Poisson's ratio ν.
    #[schemars(extend("exclusiveMinimum" = -1.0, "exclusiveMaximum" = 0.5, "unit" = "1"))]
    pub poisson_ratio: Real,
}

/// Kirchhoff stress of the fixed-corotated model with Lamé parameters `mu`, `lambda` (Pa).
pub(super) fn kirchhoff<const D: usize>(f: &Matrix<D>, mu: Real, lambda: Real) -> Matrix<D>
where
    Dim<D>: DimOps<D>,
{
    let (u, _, v) = Dim::<D>::svd(f);
    let r = u * v.transpose();
    let j = Dim::<D>::det(f);
    (f - r) * f.transpose() * (2.0 * mu) + Matrix::<D>::identity() * (lambda * (j - 1.0) * j)
}

impl<const D: usize> ConstitutiveModel<D> for FixedCorotated
where
    Dim<D>: DimOps<D>,
{
    fn volume_stress(&self, p: &MaterialPoint<D>) -> Matrix<D> {
        let (mu, lambda) = lame(self.youngs_modulus, self.poisson_ratio);
        kirchhoff(&p.f, mu, lambda) * p.vol0
    }

    fn update_deformation(&self, f: &mut Matrix<D>, _jp: &mut Real, grad_v: &Matrix<D>, dt: Real) {
        advance_f(f, grad_v, dt);
    }

    fn density(&self) -> Real {
        self.density
    }

    fn stable_dt(&self, h: Real) -> Real {
        elastic_dt(h, self.density, self.youngs_modulus, self.poisson_ratio)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix2;

    /// Uniaxial stretch F = diag(s, 1) (R = I, J = s): τ_xx = 2μ(s − 1)s + λ(s − 1)s, τ_yy = λ(s − 1)s.
    #[test]
    fn uniaxial_stretch_gives_analytic_stress() {
        let m = FixedCorotated { density: 1000.0, youngs_modulus: 1e6, poisson_ratio: 0.3 };
        let (mu, lambda) = lame(1e6, 0.3);
        let s = 1.2;
        let p = MaterialPoint::<2>::solid(Matrix2::new(s, 0.0, 0.0, 1.0), 1.0, 0.5);
        let tau = m.volume_stress(&p) / 0.5;
        let txx = 2.0 * mu * (s - 1.0) * s + lambda * (s - 1.0) * s;
        let tyy = lambda * (s - 1.0) * s;
        assert!((tau - Matrix2::new(txx, 0.0, 0.0, tyy)).norm() < 1e-6 * txx.abs());
    }

    /// The Cauchy stress is the Kirchhoff stress over J = det F: for a uniaxial stretch s, σ = τ/s; and a
    /// small stretch ε gives linear elasticity's σ_xx = (λ + 2μ)ε, σ_yy = λε to O(ε²) (relative 3ε).
    #[test]
    fn cauchy_stress_is_kirchhoff_over_j() {
        let m = FixedCorotated { density: 1000.0, youngs_modulus: 1e6, poisson_ratio: 0.3 };
        let (mu, lambda) = lame(1e6, 0.3);
        for s in [1.2, 1.0 + 1e-4] {
            let p = MaterialPoint::<2>::solid(Matrix2::new(s, 0.0, 0.0, 1.0), 1.0, 0.5);
            let sigma = ConstitutiveModel::<2>::cauchy_stress(&m, &p);
            assert!((sigma * s - m.volume_stress(&p) / 0.5).norm() < 1e-9 * sigma.norm());
            if s < 1.01 {
                let eps = s - 1.0;
                assert!((sigma[(0, 0)] - (lambda + 2.0 * mu) * eps).abs() < 3.0 * eps * (lambda + 2.0 * mu) * eps);
                assert!((sigma[(1, 1)] - lambda * eps).abs() < 3.0 * eps * (lambda + 2.0 * mu) * eps);
            }
        }
    }

    /// A pure rotation carries no stress.
    #[test]
    fn rotation_is_stress_free() {
        let m = FixedCorotated { density: 1000.0, youngs_modulus: 1e6, poisson_ratio: 0.3 };
        let (c, s) = (0.8f64.cos(), 0.8f64.sin());
        let p = MaterialPoint::<2>::solid(Matrix2::new(c, -s, s, c), 1.0, 1.0);
        assert!(m.volume_stress(&p).norm() < 1e-6);
    }
}
