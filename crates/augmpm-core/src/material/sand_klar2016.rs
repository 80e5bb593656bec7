//! Sand: Drucker–Prager elastoplasticity of Klár et al. 2016 ("Drucker–Prager elastoplasticity for
//! sand animation", SIGGRAPH 2016), with its volume correction and an optional cohesion.
//!
//! The elastic part is St. Venant–Kirchhoff in the Hencky (logarithmic) strain ε = ln Σ of the elastic
//! deformation gradient F_E = U Σ Vᵀ: Kirchhoff stress τ = U (2μ ε + λ tr(ε) I) Uᵀ. Each step the
//! trial strain is returned to the yield cone ‖τ̂‖ + α (tr τ − D c cot φ) ≤ 0 (τ̂ the deviatoric part,
//! φ the friction angle, c the cohesion) along the deviatoric direction, which keeps the volume. A state
//! past the cone's apex (the sand pulled apart) comes apart: stress-free, and the volume it gained is
//! kept in J_p, the sand's loose volume, which a later compression takes back before the sand pushes
//! (the volume correction: sand that falls apart and lands again does not swell). Loose sand has no
//! cohesion until it is packed again.

use super::{advance_f, elastic_dt, lame, ConstitutiveModel, MaterialPoint};
use crate::math::{Dim, DimOps, Matrix, Real, Vector};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Granular material: Drucker–Prager plasticity on Hencky-strain elasticity (Klár et al. 2016).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SandKlar2016 {
    /// Rest density ρ0 of the packed sand (per unit area in 2D).
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "kg/m²"))]
    pub density: Real,
    /// Young's modulus E of the packing (a stress: N/m in 2D, Pa in 3D).
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "N/m"))]
    pub youngs_modulus: Real,
    /// Poisson's ratio ν.
    #[schemars(extend("exclusiveMinimum" = -1.0, "exclusiveMaximum" = 0.5, "unit" = "1"))]
    pub poisson_ratio: Real,
    /// Internal friction angle φ (degrees). In 2D the cone is Mohr–Coulomb's (α = sin φ / √2): a cohesionless
    /// slope stands up to φ. In 3D it passes through Mohr–Coulomb's compression corners (α = √(2/3) · 2 sin φ /
    /// (3 − sin φ), Klár et al. 2016) and is stronger than Mohr–Coulomb between them.
    #[schemars(extend("exclusiveMinimum" = 0.0, "exclusiveMaximum" = 90.0, "unit" = "deg"))]
    pub friction_angle: Real,
    /// Cohesion c (a stress: N/m in 2D, Pa in 3D): the shear strength at zero pressure. With c > 0 the sand
    /// bears a mean tension up to c cot φ; pulled past it, it comes apart (stress-free, and without cohesion
    /// until it is packed again).
    #[serde(default)]
    #[schemars(extend("minimum" = 0.0, "unit" = "N/m"))]
    pub cohesion: Real,
}

/// Singular values of F_E are floored here before their logarithm: one step may compress the sand at most
/// a thousandfold along an axis (ε ≥ −6.9), so that a step far beyond the stable one gives a large finite
/// stress, never an infinite one.
const MIN_STRETCH: Real = 1e-3;

/// ln of a singular value, floored at [`MIN_STRETCH`]; NaN stays NaN (the step reports it).
#[inline]
fn ln_stretch(x: Real) -> Real {
    if x.is_nan() {
        x
    } else {
        x.max(MIN_STRETCH).ln()
    }
}

impl SandKlar2016 {
    /// The cone's slope α in ‖τ̂‖ + α tr τ ≤ const, for D dimensions.
    ///
    /// In 2D, with principal stresses σ1, σ2 (tension positive), ‖τ̂‖ = |σ1 − σ2| / √2 and tr τ = σ1 + σ2,
    /// so Mohr–Coulomb's |σ1 − σ2| / 2 ≤ c cos φ − (σ1 + σ2) / 2 · sin φ is exactly
    /// ‖τ̂‖ + (sin φ / √2)(tr τ − 2 c cot φ) ≤ 0.
    pub fn cone_slope(&self, dim: usize) -> Real {
        let s = self.friction_angle.to_radians().sin();
        if dim == 2 {
            s / std::f64::consts::SQRT_2 as Real
        } else {
            (2.0 / 3.0 as Real).sqrt() * 2.0 * s / (3.0 - s)
        }
    }

    /// The trace of the Hencky strain at the cone's apex: tr τ = D c cot φ over the bulk stiffness Dλ + 2μ.
    fn apex_trace(&self, dim: usize, mu: Real, lambda: Real) -> Real {
        if self.cohesion == 0.0 {
            return 0.0;
        }
        let d = dim as Real;
        d * self.cohesion / self.friction_angle.to_radians().tan() / (d * lambda + 2.0 * mu)
    }

    /// The return mapping of Klár et al. 2016 on the principal Hencky strains `eps` of a trial F_E whose
    /// loose volume is `ln_jp` = ln J_p ≥ 0: the strains after plasticity and the new ln J_p.
    pub fn project<const D: usize>(&self, eps: &Vector<D>, ln_jp: Real) -> (Vector<D>, Real) {
        let (mu, lambda) = lame(self.youngs_modulus, self.poisson_ratio);
        let d = D as Real;
        // Loose sand has come apart: no cohesion until it is packed again.
        let apex = if ln_jp > 0.0 { 0.0 } else { self.apex_trace(D, mu, lambda) };
        // The loose volume counts first: compression takes it back before the sand is strained.
        let trace = eps.sum() + ln_jp;
        if trace >= apex {
            // Pulled apart past the apex: stress-free, the whole volume gained is loose.
            return (Vector::<D>::zeros(), trace);
        }
        let eps = eps.add_scalar(ln_jp / d);
        let dev = eps.add_scalar(-trace / d);
        let dev_norm = dev.norm();
        // How far outside the cone the trial state lies, as a deviatoric strain (≤ 0: inside; then
        // dev_norm = 0 never reaches the division).
        let excess = dev_norm + (d * lambda + 2.0 * mu) / (2.0 * mu) * (trace - apex) * self.cone_slope(D);
        if excess <= 0.0 {
            (eps, 0.0)
        } else {
            (eps - dev * (excess / dev_norm), 0.0)
        }
    }
}

impl<const D: usize> ConstitutiveModel<D> for SandKlar2016
where
    Dim<D>: DimOps<D>,
{
    /// `V⁰ τ`, τ = U (2μ ε + λ tr(ε) I) Uᵀ with ε = ln Σ.
    fn volume_stress(&self, p: &MaterialPoint<D>) -> Matrix<D> {
        let (mu, lambda) = lame(self.youngs_modulus, self.poisson_ratio);
        let (u, s, _) = Dim::<D>::svd(&p.f);
        let eps = s.map(ln_stretch);
        let principal = eps * (2.0 * mu) + Vector::<D>::repeat(lambda * eps.sum());
        u * Matrix::<D>::from_diagonal(&principal) * u.transpose() * p.vol0
    }

    /// The Kirchhoff stress over the whole volume ratio J = det F_E · J_p (J_p the loose volume).
    fn cauchy_stress(&self, p: &MaterialPoint<D>) -> Matrix<D> {
        self.volume_stress(p) / (p.vol0 * Dim::<D>::det(&p.f) * p.jp)
    }

    /// A trial F_E turned inside out (det ≤ 0: one step far beyond the stable one) has no strain to return:
    /// it is reset to F_E = I, stress-free, and the step's change of volume is lost. A non-finite F is left
    /// as it is, for the step to report.
    fn update_deformation(&self, f: &mut Matrix<D>, jp: &mut Real, grad_v: &Matrix<D>, dt: Real) {
        advance_f(f, grad_v, dt);
        if !f.iter().all(|x| x.is_finite()) {
            return;
        }
        let (u, s, v) = Dim::<D>::svd(f);
        if s[D - 1] <= 0.0 {
            *f = Matrix::<D>::identity();
            return;
        }
        let eps = s.map(ln_stretch);
        let (eps, ln_jp) = self.project(&eps, jp.ln());
        *jp = ln_jp.exp();
        *f = u * Matrix::<D>::from_diagonal(&eps.map(Real::exp)) * v.transpose();
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
    use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

    fn sand(friction_angle: Real, cohesion: Real) -> SandKlar2016 {
        SandKlar2016 { density: 2200.0, youngs_modulus: 3.537e5, poisson_ratio: 0.3, friction_angle, cohesion }
    }

    fn kirchhoff_principal<const D: usize>(m: &SandKlar2016, eps: &Vector<D>) -> Vector<D> {
        let (mu, lambda) = lame(m.youngs_modulus, m.poisson_ratio);
        eps * (2.0 * mu) + Vector::<D>::repeat(lambda * eps.sum())
    }

    /// In 2D the cone is Mohr–Coulomb's: a state returned to it has (σ1 − σ2)/2 = −(σ1 + σ2)/2 · sin φ
    /// (its Mohr circle touches the line of slope tan φ), to round-off (1e-9 relative).
    #[test]
    fn plane_return_lands_on_the_mohr_coulomb_line() {
        let m = sand(30.0, 0.0);
        let (eps, ln_jp) = m.project(&Vector2::new(-0.02, 0.01), 0.0);
        assert_eq!(ln_jp, 0.0);
        let t = kirchhoff_principal(&m, &eps);
        let radius = (t[0] - t[1]).abs() / 2.0;
        let centre = -(t[0] + t[1]) / 2.0;
        assert!((radius - centre * 0.5).abs() < 1e-9 * centre, "{radius} {centre}");
    }

    /// The return keeps the volume (it moves along the deviatoric direction), and a state inside the cone
    /// (a near-isotropic compression) is left as it is.
    #[test]
    fn return_is_deviatoric_and_inside_is_elastic() {
        let m = sand(35.0, 0.0);
        let trial = Vector3::new(-0.03, 0.004, 0.01);
        let (eps, _) = m.project(&trial, 0.0);
        assert!((eps.sum() - trial.sum()).abs() < 1e-15);
        assert!((eps - trial).norm() > 1e-3);
        let inside = Vector3::new(-0.010, -0.011, -0.012);
        assert_eq!(m.project(&inside, 0.0), (inside, 0.0));
    }

    /// In 3D, a triaxial compression state returned to the cone has the Mohr–Coulomb ratio
    /// σ1/σ3 = (1 + sin φ)/(1 − sin φ) (the cone passes through the compression corners), to 1e-9.
    #[test]
    fn triaxial_return_meets_the_compression_corner() {
        let m = sand(30.0, 0.0);
        // σ1 (most compressive) along x, σ2 = σ3: a trial well outside the cone (uniaxial strain alone,
        // σ1/σ3 = (λ + 2μ)/λ = 2.33 at ν = 0.3, would be inside it).
        let trial = Vector3::new(-0.05, 0.01, 0.01);
        let t_trial = -kirchhoff_principal(&m, &trial);
        assert!(t_trial[0] / t_trial[1] > 3.5, "{t_trial:?}");
        let (eps, _) = m.project(&trial, 0.0);
        let t = -kirchhoff_principal(&m, &eps);
        assert!((t[1] - t[2]).abs() < 1e-9 * t[0]);
        assert!((t[0] / t[1] - 3.0).abs() < 1e-9, "{t:?}"); // (1 + 1/2) / (1 − 1/2) at 30°
    }

    /// Pulled apart, cohesionless sand is stress-free and keeps the gained volume loose (J_p = e^{tr ε});
    /// compressed back by the same amount it is stress-free again and J_p = 1 (the volume correction).
    #[test]
    fn loose_volume_is_taken_back_before_the_sand_pushes() {
        let m = sand(30.0, 0.0);
        let (mut f, mut jp) = (Matrix2::identity(), 1.0);
        let stretch = Matrix2::new(0.05, 0.0, 0.0, 0.05);
        <SandKlar2016 as ConstitutiveModel<2>>::update_deformation(&m, &mut f, &mut jp, &stretch, 1.0);
        assert!((f - Matrix2::identity()).norm() < 1e-12);
        assert!((jp - 1.05f64 * 1.05).abs() < 1e-12);
        let squeeze = Matrix2::new(1.0 / 1.05 - 1.0, 0.0, 0.0, 1.0 / 1.05 - 1.0);
        <SandKlar2016 as ConstitutiveModel<2>>::update_deformation(&m, &mut f, &mut jp, &squeeze, 1.0);
        assert!((f - Matrix2::identity()).norm() < 1e-12 && (jp - 1.0).abs() < 1e-12, "{f} {jp}");
        let p = MaterialPoint::<2>::solid(f, jp, 1.0);
        assert!(m.volume_stress(&p).norm() < 1e-6);
    }

    /// With cohesion c the sand bears an isotropic tension up to the apex, mean stress c cot φ (to 1e-9
    /// relative just inside it); pulled past it, it comes apart: stress-free, the whole volume gain loose
    /// (J_p = e^{tr ε}), and while loose it bears no tension at all.
    #[test]
    fn cohesion_bears_tension_up_to_the_apex_then_the_sand_comes_apart() {
        let c = 100.0;
        let m = sand(30.0, c);
        let (mu, lambda) = lame(m.youngs_modulus, m.poisson_ratio);
        let apex = m.apex_trace(2, mu, lambda);
        let inside = Vector2::repeat(0.5 * apex * (1.0 - 1e-12));
        assert_eq!(m.project(&inside, 0.0), (inside, 0.0));
        let t = kirchhoff_principal(&m, &inside);
        let tension = c / 30f64.to_radians().tan();
        assert!((t[0] - tension).abs() < 1e-9 * tension && (t[1] - tension).abs() < 1e-9 * tension, "{t:?}");
        let (eps, ln_jp) = m.project(&Vector2::new(0.01, 0.01), 0.0);
        assert_eq!((eps, ln_jp), (Vector2::zeros(), 0.02));
        let (eps, ln_jp) = m.project(&Vector2::repeat(0.1 * apex), 1e-3);
        assert_eq!(eps, Vector2::zeros());
        assert!((ln_jp - (0.2 * apex + 1e-3)).abs() < 1e-15);
    }

    /// With cohesion, a state returned to the 2D cone lies on Mohr–Coulomb's line with its intercept:
    /// (σ1 − σ2)/2 = c cos φ − (σ1 + σ2)/2 · sin φ (tension positive), to 1e-9 relative.
    #[test]
    fn plane_return_with_cohesion_lands_on_the_mohr_coulomb_line() {
        let (c, phi) = (2000.0, 35f64.to_radians());
        let m = sand(35.0, c);
        let (eps, _) = m.project(&Vector2::new(-0.03, 0.012), 0.0);
        let t = kirchhoff_principal(&m, &eps);
        let radius = (t[0] - t[1]).abs() / 2.0;
        let line = c * phi.cos() - (t[0] + t[1]) / 2.0 * phi.sin();
        assert!((radius - line).abs() < 1e-9 * radius, "{radius} {line}");
    }

    /// A step that turns the particle inside out (det F < 0) leaves it stress-free at F_E = I with its loose
    /// volume; a non-finite velocity gradient leaves F non-finite (nothing hides it).
    #[test]
    fn inverted_and_non_finite_steps() {
        let m = sand(30.0, 0.0);
        let (mut f, mut jp) = (Matrix2::identity(), 1.2);
        let flip = Matrix2::new(0.0, 0.0, 0.0, -2.0);
        <SandKlar2016 as ConstitutiveModel<2>>::update_deformation(&m, &mut f, &mut jp, &flip, 1.0);
        assert_eq!((f, jp), (Matrix2::identity(), 1.2));
        let nan = Matrix2::new(f64::NAN, 0.0, 0.0, 0.0);
        <SandKlar2016 as ConstitutiveModel<2>>::update_deformation(&m, &mut f, &mut jp, &nan, 1.0);
        assert!(f[(0, 0)].is_nan());
    }

    /// The stress of a rotated state is the rotated stress (frame indifference), and the Cauchy stress
    /// times the current volume V⁰ det F_E J_p is the stress the step applies.
    #[test]
    fn stress_is_objective_and_cauchy_integrates_over_the_volume() {
        let m = sand(30.0, 0.0);
        let f = Matrix3::new(0.99, 0.002, 0.0, 0.001, 0.995, 0.003, 0.0, 0.0, 0.998);
        let (c, s) = (0.7f64.cos(), 0.7f64.sin());
        let r = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
        let tau = m.volume_stress(&MaterialPoint::<3>::solid(f, 1.0, 1.0));
        let turned = m.volume_stress(&MaterialPoint::<3>::solid(r * f, 1.0, 1.0));
        assert!((turned - r * tau * r.transpose()).norm() < 1e-9 * tau.norm());
        let p = MaterialPoint::<3>::solid(f, 1.1, 0.3);
        let volume = 0.3 * f.determinant() * 1.1;
        assert!((ConstitutiveModel::<3>::cauchy_stress(&m, &p) * volume - m.volume_stress(&p)).norm() < 1e-9);
    }
}
