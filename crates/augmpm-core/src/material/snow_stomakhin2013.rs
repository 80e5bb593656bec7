//! Snow plasticity of Stomakhin et al. 2013 ("A material point method for snow
//! simulation") on the fixed-corotated model.

use super::fixed_corotated::kirchhoff;
use super::{advance_f, elastic_dt, lame, ConstitutiveModel, MaterialPoint};
use crate::math::{Dim, DimOps, Matrix, Real};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Singular values of the elastic F are clamped to `[1 − θc, 1 + θs]` each step;
/// the excess goes to the plastic volume ratio J_p, which hardens the Lamé
/// parameters by `exp(ξ(1 − J_p))`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SnowStomakhin2013 {
    /// Rest density ρ0 (per unit area in 2D).
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "kg/m²"))]
    pub density: Real,
    /// Young's modulus E (a stress: N/m in 2D, Pa in 3D).
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "N/m"))]
    pub youngs_modulus: Real,
    /// Poisson's ratio ν.
    #[schemars(extend("exclusiveMinimum" = -1.0, "exclusiveMaximum" = 0.5, "unit" = "1"))]
    pub poisson_ratio: Real,
    /// Critical compression θc: singular values of the elastic F below 1 − θc become plastic.
    #[serde(default = "default_compression")]
    #[schemars(extend("exclusiveMinimum" = 0.0, "exclusiveMaximum" = 1.0, "unit" = "1"))]
    pub critical_compression: Real,
    /// Critical stretch θs: singular values above 1 + θs become plastic.
    #[serde(default = "default_stretch")]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "1"))]
    pub critical_stretch: Real,
    /// Hardening coefficient ξ: the Lamé parameters scale by exp(ξ(1 − J_p)).
    #[serde(default = "default_hardening")]
    #[schemars(extend("minimum" = 0.0, "unit" = "1"))]
    pub hardening: Real,
    /// Lower clamp of the plastic volume ratio J_p.
    #[serde(default = "default_jp_min")]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "1"))]
    pub jp_min: Real,
    /// Upper clamp of the plastic volume ratio J_p (greater than `jp_min`).
    #[serde(default = "default_jp_max")]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "1"))]
    pub jp_max: Real,
}

fn default_compression() -> Real {
    2.5e-2
}
fn default_stretch() -> Real {
    7.5e-3
}
fn default_hardening() -> Real {
    10.0
}
fn default_jp_min() -> Real {
    0.6
}
fn default_jp_max() -> Real {
    20.0
}

impl SnowStomakhin2013 {
    /// The rule between keys: J_p's clamps in order.
    pub(super) fn validate(&self) -> Result<(), (&'static str, String)> {
        if self.jp_max <= self.jp_min {
            return Err(("jp_max", format!("must be greater than jp_min ({}), got {}", self.jp_min, self.jp_max)));
        }
        Ok(())
    }

    /// Lamé parameters (Pa) hardened for plastic volume ratio `jp`.
    pub fn hardened_lame(&self, jp: Real) -> (Real, Real) {
        let (mu, lambda) = lame(self.youngs_modulus, self.poisson_ratio);
        let e = (self.hardening * (1.0 - jp)).exp();
        (mu * e, lambda * e)
    }
}

impl<const D: usize> ConstitutiveModel<D> for SnowStomakhin2013
where
    Dim<D>: DimOps<D>,
{
    fn volume_stress(&self, p: &MaterialPoint<D>) -> Matrix<D> {
        let (mu, lambda) = self.hardened_lame(p.jp);
        kirchhoff(&p.f, mu, lambda) * p.vol0
    }

    /// The Kirchhoff stress over the whole volume ratio J = det F_E · J_p (F is the elastic part).
    fn cauchy_stress(&self, p: &MaterialPoint<D>) -> Matrix<D> {
        self.volume_stress(p) / (p.vol0 * Dim::<D>::det(&p.f) * p.jp)
    }

    fn update_deformation(&self, f: &mut Matrix<D>, jp: &mut Real, grad_v: &Matrix<D>, dt: Real) {
        advance_f(f, grad_v, dt);
        let (u, s, v) = Dim::<D>::svd(f);
        let lo = 1.0 - self.critical_compression;
        let hi = 1.0 + self.critical_stretch;
        let clamped = s.map(|x| x.clamp(lo, hi));
        // The volume change removed from the elastic part becomes plastic.
        let ratio = s.iter().product::<Real>() / clamped.iter().product::<Real>();
        *jp = (*jp * ratio).clamp(self.jp_min, self.jp_max);
        *f = u * Matrix::<D>::from_diagonal(&clamped) * v.transpose();
    }

    fn density(&self) -> Real {
        self.density
    }

    /// At the initial state (J_p = 1). Compression hardens the snow by up to
    /// exp(ξ(1 − jp_min)) (e⁴ ≈ 55 with the defaults), which would shorten this bound by
    /// up to √55 ≈ 7.4×; bounding by that worst case would flag every usual snow scene.
    fn stable_dt(&self, h: Real) -> Real {
        elastic_dt(h, self.density, self.youngs_modulus, self.poisson_ratio)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix2;

    fn snow() -> SnowStomakhin2013 {
        SnowStomakhin2013 {
            density: 400.0,
            youngs_modulus: 1.4e5,
            poisson_ratio: 0.2,
            critical_compression: 2.5e-2,
            critical_stretch: 7.5e-3,
            hardening: 10.0,
            jp_min: 0.6,
            jp_max: 20.0,
        }
    }

    /// The Cauchy stress times the particle's current volume V⁰ det F_E J_p is the stress the step applies,
    /// `volume_stress` (V⁰ τ), also once snow has lost volume plastically (J_p = 0.8).
    #[test]
    fn cauchy_stress_integrates_over_the_current_volume() {
        let m = snow();
        let p = MaterialPoint::<2>::solid(Matrix2::new(1.01, 0.002, 0.0, 0.995), 0.8, 0.3);
        let volume = 0.3 * Dim::<2>::det(&p.f) * 0.8;
        let sigma = ConstitutiveModel::<2>::cauchy_stress(&m, &p);
        assert!((sigma * volume - m.volume_stress(&p)).norm() < 1e-12 * m.volume_stress(&p).norm());
    }

    /// Stretching past 1 + θs and compressing past 1 − θc leaves the elastic singular values at the clamps,
    /// and J_p takes the removed volume: J_p = (1.1 · 0.9) / ((1 + θs)(1 − θc)).
    #[test]
    fn plasticity_clamps_singular_values() {
        let m = snow();
        let mut f = Matrix2::identity();
        let mut jp = 1.0;
        let grad_v = Matrix2::new(0.1, 0.0, 0.0, -0.1); // dt = 1: F_trial = diag(1.1, 0.9)
        <SnowStomakhin2013 as ConstitutiveModel<2>>::update_deformation(&m, &mut f, &mut jp, &grad_v, 1.0);
        let (_, s, _) = Dim::<2>::svd(&f);
        let mut s = [s[0], s[1]];
        s.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert!((s[0] - 0.975).abs() < 1e-12 && (s[1] - 1.0075).abs() < 1e-12, "{s:?}");
        assert!((jp - 0.99 / (1.0075 * 0.975)).abs() < 1e-12);
    }

    /// Under a uniaxial stretch within the elastic range, snow at J_p = 1 has the fixed-corotated stress,
    /// and hardening scales it by exp(ξ(1 − J_p)).
    #[test]
    fn hardening_scales_stress() {
        let m = snow();
        let mut p = MaterialPoint::<2>::solid(Matrix2::new(1.005, 0.0, 0.0, 1.0), 1.0, 1.0);
        let s1 = m.volume_stress(&p);
        let (mu, lambda) = lame(1.4e5, 0.2);
        let s = 1.005;
        let txx = 2.0 * mu * (s - 1.0) * s + lambda * (s - 1.0) * s;
        assert!((s1[(0, 0)] - txx).abs() < 1e-6 * txx);
        p.jp = 0.9;
        let s2 = m.volume_stress(&p);
        assert!((s2[(0, 0)] / s1[(0, 0)] - 1.0f64.exp()).abs() < 1e-9);
    }
}
