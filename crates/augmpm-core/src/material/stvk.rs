//! St. Venant–Kirchhoff hyperelasticity.

use super::{advance_f, elastic_dt, lame, ConstitutiveModel, MaterialPoint};
use crate::math::{Matrix, Real};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Green strain `E = ½(FᵀF − I)`, second Piola–Kirchhoff stress `S = 2μE + λ tr(E) I`,
/// Kirchhoff stress `τ = F S Fᵀ`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct StVenantKirchhoff {
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

impl<const D: usize> ConstitutiveModel<D> for StVenantKirchhoff {
    fn volume_stress(&self, p: &MaterialPoint<D>) -> Matrix<D> {
        let (mu, lambda) = lame(self.youngs_modulus, self.poisson_ratio);
        let id = Matrix::<D>::identity();
        let e = (p.f.transpose() * p.f - id) * 0.5;
        let s = e * (2.0 * mu) + id * (lambda * e.trace());
        p.f * s * p.f.transpose() * p.vol0
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

    /// Uniaxial stretch F = diag(s, 1): E_xx = (s² − 1)/2, S_xx = (2μ + λ)E_xx, S_yy = λE_xx, τ = F S Fᵀ.
    #[test]
    fn uniaxial_stretch_gives_analytic_stress() {
        let m = StVenantKirchhoff { density: 1000.0, youngs_modulus: 1e6, poisson_ratio: 0.25 };
        let (mu, lambda) = lame(1e6, 0.25);
        let s = 1.1;
        let p = MaterialPoint::<2>::solid(Matrix2::new(s, 0.0, 0.0, 1.0), 1.0, 2.0);
        let exx = 0.5 * (s * s - 1.0);
        let expect = Matrix2::new(s * s * (2.0 * mu + lambda) * exx, 0.0, 0.0, lambda * exx) * 2.0;
        assert!((m.volume_stress(&p) - expect).norm() < 1e-9 * expect.norm());
    }
}
