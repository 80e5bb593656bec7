//! Weakly compressible Newtonian fluid (Tait-like equation of state), the
//! fluid of Toyota & Umetani 2024 after the MPM guide they cite.

use super::{ConstitutiveModel, MaterialPoint};
use crate::math::{Matrix, Real};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Where a fluid particle's density comes from (`density_estimate` in scene files).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum DensityEstimate {
    /// From the particle's own volume change: ρ = ρ0 / J with J̇ = J tr(∇v), J kept in the
    /// particle's `jp` (Hu et al. 2018's fluid) and smoothed over the grid each step (J-bar). Smooth,
    /// so a column at rest is not rectified by the p ≥ 0 clamp, and unbiased next to walls and free
    /// surfaces.
    #[schemars(
        description = "ρ = ρ0/J from the particle's own volume change, smoothed over the grid each step (J-bar)"
    )]
    #[default]
    Deformation,
    /// Gathered from the particle masses scattered to the regular grid (the paper's choice):
    /// ρ_p = Σ w_ip m_i / h^D.
    #[schemars(description = "ρ gathered from the particle masses scattered to the regular grid (the paper's)")]
    Grid,
    /// From the particle's own volume change, smoothed and relaxed toward how closely the particles pack:
    /// ρ = ρ0 / J with J̇ = J tr(∇v) and, each step, J ← J̄ + min(dt/τ, 1)(J* − J̄). J̄ is a J-bar average
    /// that keeps a linearly varying J (fitted on the grid as a value and a gradient per node), and
    /// J* = 1/ψ_p within 10% of 1 (where ψ_p is thinner, a free surface, J* keeps J within [1, 1/ψ_p]).
    /// ψ_p is the particles' occupied volume per volume of material gathered at the particle from the
    /// regular grid (corrected for the part of each node's support inside the walls;
    /// [`crate::step::packing`]). J then follows the packing that the grid's forces act on, so a column
    /// at rest keeps both uniform.
    #[schemars(
        description = "ρ = ρ0/J from the particle's own volume change, smoothed by a J-bar that keeps a linear J \
                       and relaxed toward the particles' packing on the grid over `relaxation_time`"
    )]
    Packing,
}

/// `p = k((ρ/ρ0)^γ − 1)`, clamped below at `min_pressure`, and
/// `σ = −p I + μ(∇v + ∇vᵀ)`; ρ as `density_estimate` says.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WeaklyCompressibleFluid {
    /// Rest density ρ0 (per unit area in 2D).
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "kg/m²"))]
    pub density: Real,
    /// Stiffness k of the equation of state (a stress: N/m in 2D, Pa in 3D).
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "N/m"))]
    pub stiffness: Real,
    /// Exponent γ of the equation of state.
    #[serde(default = "default_gamma")]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "1"))]
    pub gamma: Real,
    /// Dynamic viscosity μ (N·s/m in 2D, Pa·s in 3D).
    #[serde(default)]
    #[schemars(extend("minimum" = 0.0, "unit" = "N·s/m"))]
    pub viscosity: Real,
    /// Lowest pressure; a small negative value allows mild tension.
    #[serde(default)]
    #[schemars(extend("maximum" = 0.0, "unit" = "N/m"))]
    pub min_pressure: Real,
    /// Where the density comes from.
    #[serde(default)]
    pub density_estimate: DensityEstimate,
    /// Time τ over which J relaxes toward the particles' packing (`density_estimate = "packing"` only; 0.05 s
    /// when not given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "s"))]
    pub relaxation_time: Option<Real>,
}

fn default_gamma() -> Real {
    7.0
}

/// τ (s) of `density_estimate = "packing"` when the scene gives none: about the time water 0.3–1 m deep takes
/// to settle under its viscosity in the validation's tanks, so that the relaxation follows the flow's packing
/// rather than each step's sampling noise.
pub const DEFAULT_RELAXATION_TIME: Real = 0.05;

/// With the deformation and packing densities, the stress volume of a particle follows its dilation up to this
/// factor of its rest volume; a packing fluid's J itself goes no higher.
pub const MAX_DILATION: Real = 1.25;

impl WeaklyCompressibleFluid {
    /// Dust: a fluid of rest density `density` (kg/m²) with no pressure and no viscosity, so that the
    /// transfers alone move its momentum (what conservation tests of the transfers run on).
    pub fn dust(density: Real) -> Self {
        Self {
            density,
            stiffness: 0.0,
            gamma: 1.0,
            viscosity: 0.0,
            min_pressure: 0.0,
            density_estimate: DensityEstimate::Grid,
            relaxation_time: None,
        }
    }

    /// The warning for a `relaxation_time` given to a fluid that does not relax toward the packing (`key`: the
    /// material's dotted key), if it was given so.
    pub fn unused_keys(&self, key: &str) -> Option<String> {
        (self.relaxation_time.is_some() && self.density_estimate != DensityEstimate::Packing)
            .then(|| format!("{key}.relaxation_time has no effect: it applies to density_estimate = \"packing\""))
    }

    /// Whether the density is ρ0/J from the J the particle keeps (`deformation`, `packing`).
    pub fn keeps_volume_ratio(&self) -> bool {
        self.density_estimate != DensityEstimate::Grid
    }

    /// Pressure (Pa) at density `rho`.
    pub fn pressure(&self, rho: Real) -> Real {
        let ratio = rho / self.density;
        // Integer exponents (the usual 1, 4, 7) by multiplication: powf is a libm call. (`fract()` would
        // be one too on x86-64's baseline, which has no rounding instruction.)
        let power = if self.gamma <= 16.0 && self.gamma == (self.gamma as u32) as Real {
            crate::math::powu(ratio, self.gamma as u32)
        } else {
            ratio.powf(self.gamma)
        };
        (self.stiffness * (power - 1.0)).max(self.min_pressure)
    }

    /// Cauchy stress (Pa) at density `rho` and velocity gradient `grad_v` (1/s).
    pub fn cauchy_stress<const D: usize>(&self, rho: Real, grad_v: &Matrix<D>) -> Matrix<D> {
        Matrix::<D>::identity() * -self.pressure(rho) + (grad_v + grad_v.transpose()) * self.viscosity
    }

    /// The density the stress sees at `p` ([`ConstitutiveModel::current_density`]) and `V_p σ_p`
    /// ([`ConstitutiveModel::volume_stress`]) together, the density computed once.
    #[inline(always)]
    pub fn density_and_volume_stress<const D: usize>(&self, p: &MaterialPoint<D>) -> (Real, Matrix<D>) {
        let density = ConstitutiveModel::<D>::current_density(self, p);
        (density, self.stress_at(density, p))
    }

    /// `V_p σ_p` of the point `p` at its density `density` (kg/m³, or kg/m² in 2D).
    #[inline(always)]
    fn stress_at<const D: usize>(&self, density: Real, p: &MaterialPoint<D>) -> Matrix<D> {
        // The stress acts over the particle's volume V = m/ρ, bounded: the grid estimate of ρ falls
        // far below ρ0 where neighbours are missing (free surface, spray), and V = m/ρ there would
        // inflate an isolated particle's volume ~10×, and with it the explicit viscous coefficient
        // μV/(m h²), which then blows up; so V ≤ m/ρ0 with it. J is the particle's own volume
        // change, so with it V follows a dilated fluid (which otherwise feels too little viscous
        // stress) up to `MAX_DILATION` V0, which `stable_dt` accounts for.
        let floor = if self.keeps_volume_ratio() { self.density / MAX_DILATION } else { self.density };
        let volume = p.mass / density.max(floor);
        self.cauchy_stress(density, &p.grad_v) * volume
    }
}

impl<const D: usize> ConstitutiveModel<D> for WeaklyCompressibleFluid {
    fn volume_stress(&self, p: &MaterialPoint<D>) -> Matrix<D> {
        self.stress_at(ConstitutiveModel::<D>::current_density(self, p), p)
    }

    fn cauchy_stress(&self, p: &MaterialPoint<D>) -> Matrix<D>
    where
        crate::math::Dim<D>: crate::math::DimOps<D>,
    {
        self.cauchy_stress(ConstitutiveModel::<D>::current_density(self, p), &p.grad_v)
    }

    fn update_deformation(&self, _f: &mut Matrix<D>, jp: &mut Real, grad_v: &Matrix<D>, dt: Real) {
        // F is not needed; with the deformation and packing estimates `jp` holds J, J̇ = J tr(∇v), integrated
        // exactly for the step's constant ∇v (J stays positive however large the step's divergence).
        if self.keeps_volume_ratio() {
            *jp *= crate::math::exp_near_zero(dt * grad_v.trace());
            // A packing fluid's J goes no higher than `MAX_DILATION`, where its stress volume stops following
            // it (`stress_at`): a film stretched thin along a moving wall, which no pressure pulls back, grows J
            // faster than the relaxation brings it back, and carried it to 10 and more into its neighbours'
            // J-bar and the water's volume Σ m/ρ.
            if self.density_estimate == DensityEstimate::Packing {
                *jp = jp.min(MAX_DILATION);
            }
        }
    }

    fn keeps_deformation_gradient(&self) -> bool {
        false
    }

    fn needs_grid_density(&self) -> bool {
        self.density_estimate == DensityEstimate::Grid
    }

    fn smooths_volume_ratio(&self) -> bool {
        self.density_estimate == DensityEstimate::Deformation
    }

    fn keeps_volume_ratio(&self) -> bool {
        WeaklyCompressibleFluid::keeps_volume_ratio(self)
    }

    fn packing_relaxation_time(&self) -> Option<Real> {
        (self.density_estimate == DensityEstimate::Packing)
            .then(|| self.relaxation_time.unwrap_or(DEFAULT_RELAXATION_TIME))
    }

    fn occupied_volume(&self, p: &MaterialPoint<D>, density: Real) -> Real
    where
        crate::math::Dim<D>: crate::math::DimOps<D>,
    {
        match self.density_estimate {
            // The rest volume: ψ counts how many particles share the space, whatever their J says.
            DensityEstimate::Packing => p.vol0,
            DensityEstimate::Deformation => p.vol0 * p.jp,
            DensityEstimate::Grid if density > 0.0 => p.mass / density,
            DensityEstimate::Grid => p.vol0,
        }
    }

    fn current_density(&self, p: &MaterialPoint<D>) -> Real {
        match self.density_estimate {
            DensityEstimate::Deformation | DensityEstimate::Packing => self.density / p.jp,
            DensityEstimate::Grid => p.density,
        }
    }

    fn density(&self) -> Real {
        self.density
    }

    fn stable_dt(&self, h: Real) -> Real {
        // Sound speed c² = dp/dρ at rest = kγ/ρ0; viscous diffusion needs ν dt/h² ≤ 1/(2D), with
        // ν = μV/m as large as the stress volume V gets.
        let sound = h / (self.stiffness * self.gamma / self.density).sqrt();
        let dilation = if self.keeps_volume_ratio() { MAX_DILATION } else { 1.0 };
        let nu = self.viscosity * dilation / self.density;
        let viscous = if nu > 0.0 { h * h / (2.0 * D as Real * nu) } else { Real::INFINITY };
        sound.min(viscous)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix2;

    fn water() -> WeaklyCompressibleFluid {
        WeaklyCompressibleFluid {
            density: 1000.0,
            stiffness: 1e5,
            gamma: 4.0,
            viscosity: 2.0,
            min_pressure: -100.0,
            density_estimate: DensityEstimate::Grid,
            relaxation_time: None,
        }
    }

    /// A uniaxial stretching flow ∂u/∂x = s at rest density gives σ_xx = 2μs, σ_yy = 0 (no pressure).
    #[test]
    fn uniaxial_stretch_gives_newtonian_stress() {
        let s = 3.0;
        let grad_v = Matrix2::new(s, 0.0, 0.0, 0.0);
        let sigma = water().cauchy_stress(1000.0, &grad_v);
        assert!((sigma - Matrix2::new(2.0 * 2.0 * s, 0.0, 0.0, 0.0)).norm() < 1e-12);
    }

    /// Compressed by 1%, p = k(1.01⁴ − 1); stretched, the pressure stops at its lower clamp.
    #[test]
    fn equation_of_state_and_clamp() {
        let f = water();
        assert!((f.pressure(1010.0) - 1e5 * (1.01f64.powi(4) - 1.0)).abs() < 1e-9);
        assert_eq!(f.pressure(900.0), -100.0);
        let p = MaterialPoint::<2> {
            f: Matrix2::identity(),
            jp: 1.0,
            grad_v: Matrix2::zeros(),
            mass: 2.0,
            vol0: 0.0,
            density: 1010.0,
        };
        let vs = f.volume_stress(&p);
        let expect = -f.pressure(1010.0) * 2.0 / 1010.0;
        assert!((vs[(0, 0)] - expect).abs() < 1e-12 && (vs[(1, 1)] - expect).abs() < 1e-12);
    }

    /// A fluid's Cauchy stress is −p I + μ(∇v + ∇vᵀ) at the density its stress sees (here ρ0/J with the
    /// deformation estimate, J = 0.99), whatever its stress volume.
    #[test]
    fn cauchy_stress_is_pressure_and_viscous_stress() {
        let f = WeaklyCompressibleFluid { density_estimate: DensityEstimate::Deformation, ..water() };
        let grad_v = Matrix2::new(0.0, 2.0, 0.0, 0.0);
        let p = MaterialPoint::<2> { f: Matrix2::identity(), jp: 0.99, grad_v, mass: 2.0, vol0: 0.002, density: 0.0 };
        let sigma = ConstitutiveModel::<2>::cauchy_stress(&f, &p);
        let pressure = f.pressure(1000.0 / 0.99);
        let expect = Matrix2::new(-pressure, 2.0 * 2.0, 2.0 * 2.0, -pressure);
        assert!((sigma - expect).norm() < 1e-9 * expect.norm(), "{sigma} vs {expect}");
    }

    /// An isolated particle (grid density ≪ ρ0) integrates its stress over at most its rest
    /// volume m/ρ0, so its explicit viscous term stays as stable as in the bulk.
    #[test]
    fn spray_volume_is_capped_at_rest_volume() {
        let f = water();
        let grad_v = Matrix2::new(0.0, 1.0, 0.0, 0.0);
        let p = MaterialPoint::<2> { f: Matrix2::identity(), jp: 1.0, grad_v, mass: 2.0, vol0: 0.0, density: 100.0 };
        let vs = f.volume_stress(&p);
        let expect_shear = 2.0 / 1000.0 * f.viscosity * 1.0;
        assert!((vs[(0, 1)] - expect_shear).abs() < 1e-12);
        assert!((vs[(0, 0)] + f.min_pressure * 2.0 / 1000.0).abs() < 1e-12);
    }

    /// The density and the stress in one call are the two calls' values, bit for bit, with either
    /// estimate, compressed or dilated, in 2D and 3D (P2G takes them in one call).
    #[test]
    fn density_and_stress_together_are_the_two_calls() {
        fn check<const D: usize>(f: &WeaklyCompressibleFluid, p: &MaterialPoint<D>) {
            let (rho, vs) = f.density_and_volume_stress(p);
            assert_eq!(rho.to_bits(), ConstitutiveModel::<D>::current_density(f, p).to_bits());
            let expect = ConstitutiveModel::<D>::volume_stress(f, p);
            assert!(vs.iter().zip(expect.iter()).all(|(a, b)| a.to_bits() == b.to_bits()), "{vs} vs {expect}");
        }
        for estimate in [DensityEstimate::Grid, DensityEstimate::Deformation] {
            let f = WeaklyCompressibleFluid { density_estimate: estimate, ..water() };
            for (jp, density) in [(0.97, 1031.0), (1.0, 1000.0), (1.4, 640.0)] {
                let grad_v = Matrix2::new(0.3, -1.2, 0.7, -0.1);
                let p = MaterialPoint::<2> { f: Matrix2::identity(), jp, grad_v, mass: 2.0, vol0: 0.002, density };
                check(&f, &p);
                let grad_v = nalgebra::Matrix3::new(0.3, -1.2, 0.7, -0.1, 0.4, 0.2, 0.05, -0.6, 0.9);
                let f3 = nalgebra::Matrix3::identity();
                check(&f, &MaterialPoint::<3> { f: f3, jp, grad_v, mass: 2.0, vol0: 0.002, density });
            }
        }
    }

    /// A flow that dilates a particle (tr ∇v = 20 /s for 0.1 s: J would reach e² ≈ 7.4) leaves a packing fluid's J
    /// at `MAX_DILATION` (1.25), where its stress volume stops following J; the deformation estimate's J follows
    /// the flow all the way (within 1e-12 of e²).
    #[test]
    fn a_packing_fluids_j_stops_at_the_largest_dilation() {
        let grad_v = Matrix2::identity() * 10.0;
        for (estimate, expect) in [(DensityEstimate::Packing, MAX_DILATION), (DensityEstimate::Deformation, 2f64.exp())]
        {
            let f = WeaklyCompressibleFluid { density_estimate: estimate, ..water() };
            let (mut fm, mut jp) = (Matrix2::identity(), 1.0);
            for _ in 0..100 {
                f.update_deformation(&mut fm, &mut jp, &grad_v, 1e-3);
            }
            assert!((jp - expect).abs() < 1e-12, "{estimate:?}: J = {jp}, expected {expect}");
        }
    }

    /// With the deformation estimate, a particle compressed by a uniform flow ∇v = −s I over n
    /// steps has J = exp(−2 s n dt) in 2D (J̇ = J tr ∇v) and reads ρ = ρ0 / J; the grid density it
    /// is handed is ignored.
    #[test]
    fn deformation_density_follows_the_volume_change() {
        let f = WeaklyCompressibleFluid { density_estimate: DensityEstimate::Deformation, ..water() };
        assert!(!ConstitutiveModel::<2>::needs_grid_density(&f));
        let (s, dt, n) = (2.0, 1e-3, 10);
        let grad_v = Matrix2::identity() * -s;
        let (mut fm, mut jp) = (Matrix2::identity(), 1.0);
        for _ in 0..n {
            f.update_deformation(&mut fm, &mut jp, &grad_v, dt);
        }
        let expect = (-2.0 * s * dt * n as f64).exp();
        assert!((jp - expect).abs() < 1e-14, "{jp} vs {expect}");
        let p = MaterialPoint::<2> { f: fm, jp, grad_v: Matrix2::zeros(), mass: 2.0, vol0: 0.0, density: 1.0 };
        assert!((ConstitutiveModel::<2>::current_density(&f, &p) - 1000.0 / expect).abs() < 1e-9);
        let vs = f.volume_stress(&p);
        let rho = 1000.0 / expect;
        assert!((vs[(0, 0)] + f.pressure(rho) * 2.0 / rho).abs() < 1e-9);
    }
}
