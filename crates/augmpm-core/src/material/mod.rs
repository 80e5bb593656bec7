//! Constitutive models. Each model is its own type implementing
//! [`ConstitutiveModel`]; [`Material`] dispatches between them with a `match`
//! in the hot loop and is what scenes name (`type = "fluid"`, ...).

mod fixed_corotated;
mod fluid_weakly_compressible;
mod sand_klar2016;
mod snow_stomakhin2013;
mod stvk;

pub use fixed_corotated::FixedCorotated;
pub use fluid_weakly_compressible::{DensityEstimate, WeaklyCompressibleFluid};
pub use sand_klar2016::SandKlar2016;
pub use snow_stomakhin2013::SnowStomakhin2013;
pub use stvk::StVenantKirchhoff;

use crate::math::{Dim, DimOps, Matrix, Real};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// What a constitutive model may read of one particle.
#[derive(Clone, Copy, Debug)]
pub struct MaterialPoint<const D: usize> {
    /// Elastic deformation gradient F.
    pub f: Matrix<D>,
    /// Plastic volume ratio J_p (1 without plasticity).
    pub jp: Real,
    /// Velocity gradient ∇v (1/s), the APIC/MLS affine matrix the particle keeps (next to a wall of the
    /// stable augmented grid only its symmetric part, the strain rate, is the fit's: see `Particles::c`).
    pub grad_v: Matrix<D>,
    /// Particle mass (kg, or kg/m in 2D).
    pub mass: Real,
    /// Initial particle volume (m³, or m² in 2D).
    pub vol0: Real,
    /// Density estimated from the regular grid (kg/m³ or kg/m²); only for models that ask for it.
    pub density: Real,
}

impl<const D: usize> MaterialPoint<D> {
    /// A point of a solid with deformation gradient `f` and initial volume `vol0`, at rest.
    pub fn solid(f: Matrix<D>, jp: Real, vol0: Real) -> Self {
        Self { f, jp, grad_v: Matrix::<D>::zeros(), mass: 1.0, vol0, density: 0.0 }
    }
}

/// A constitutive model of the explicit MLS-MPM step.
pub trait ConstitutiveModel<const D: usize> {
    /// `V_p σ_p`: current particle volume times Cauchy stress (Pa·m³, or Pa·m² in 2D).
    /// For hyperelastic models this is `V⁰_p τ_p` with τ the Kirchhoff stress.
    fn volume_stress(&self, p: &MaterialPoint<D>) -> Matrix<D>;

    /// Cauchy stress σ (Pa, or N/m in 2D) at this point: for the hyperelastic models the Kirchhoff stress
    /// over J = det F, `volume_stress / (V⁰ det F)`.
    fn cauchy_stress(&self, p: &MaterialPoint<D>) -> Matrix<D>
    where
        Dim<D>: DimOps<D>,
    {
        self.volume_stress(p) / (p.vol0 * Dim::<D>::det(&p.f))
    }

    /// Advances F (and J_p) over one step with velocity gradient `grad_v`.
    fn update_deformation(&self, f: &mut Matrix<D>, jp: &mut Real, grad_v: &Matrix<D>, dt: Real);

    /// Whether the model reads and advances the deformation gradient F. A scene none of whose models
    /// does keeps no F: every particle reads F = I (`Particles::f`).
    fn keeps_deformation_gradient(&self) -> bool {
        true
    }

    /// Whether [`MaterialPoint::density`] must be estimated on the grid before the stress.
    fn needs_grid_density(&self) -> bool {
        false
    }

    /// Whether the model keeps its density in `jp` = J, smoothed over the grid each step (J-bar: the
    /// step scatters V⁰ and V⁰J to the nodes and gathers their ratio back).
    fn smooths_volume_ratio(&self) -> bool {
        false
    }

    /// Whether the model's density is ρ0/J from the J it keeps in `jp` (smoothed or not).
    fn keeps_volume_ratio(&self) -> bool {
        false
    }

    /// τ (s), where the model relaxes its J toward the particles' packing on the grid
    /// ([`crate::step::packing`]).
    fn packing_relaxation_time(&self) -> Option<Real> {
        None
    }

    /// The volume (m³, or m² in 2D) the point takes up in the packing sums ([`crate::step::packing`]), at the
    /// density `density` its stress sees: V⁰ det F J_p for a solid (J_p its plastic volume ratio).
    fn occupied_volume(&self, p: &MaterialPoint<D>, _density: Real) -> Real
    where
        Dim<D>: DimOps<D>,
    {
        p.vol0 * Dim::<D>::det(&p.f) * p.jp
    }

    /// The density (kg/m³, or kg/m² in 2D) the model's stress sees at this point: the grid
    /// estimate it is handed, unless the model keeps its own.
    fn current_density(&self, p: &MaterialPoint<D>) -> Real {
        p.density
    }

    /// Rest density (kg/m³, or kg/m² in 2D).
    fn density(&self) -> Real;

    /// The largest stable time step (s) on a grid of spacing `h` (m), ignoring advection:
    /// one cell per step at the material's wave speed, and explicit viscous diffusion.
    fn stable_dt(&self, h: Real) -> Real;
}

/// Lamé parameters (Pa) from Young's modulus (Pa) and Poisson's ratio.
pub fn lame(youngs_modulus: Real, poisson_ratio: Real) -> (Real, Real) {
    let mu = youngs_modulus / (2.0 * (1.0 + poisson_ratio));
    let lambda = youngs_modulus * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio));
    (mu, lambda)
}

/// Time step (s) at which the P-wave of a solid crosses one cell of width `h` (m).
fn elastic_dt(h: Real, density: Real, youngs_modulus: Real, poisson_ratio: Real) -> Real {
    let (mu, lambda) = lame(youngs_modulus, poisson_ratio);
    h / ((lambda + 2.0 * mu) / density).sqrt()
}

/// Checks the density and elastic moduli every solid model has.
/// `F ← (I + dt ∇v) F`, the MLS-MPM deformation update.
#[inline]
pub(crate) fn advance_f<const D: usize>(f: &mut Matrix<D>, grad_v: &Matrix<D>, dt: Real) {
    *f = (Matrix::<D>::identity() + grad_v * dt) * *f;
}

/// The materials a scene can name, chosen by the tag `type`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum Material {
    /// Weakly compressible Newtonian fluid: p = k((ρ/ρ0)^γ − 1) clamped below at `min_pressure`,
    /// σ = −pI + μ(∇v + ∇vᵀ).
    #[schemars(title = "Fluid")]
    Fluid(WeaklyCompressibleFluid),
    /// Fixed-corotated hyperelastic solid (Stomakhin et al. 2012).
    #[schemars(title = "Elastic")]
    Elastic(FixedCorotated),
    /// St. Venant–Kirchhoff hyperelastic solid.
    #[schemars(title = "Stvk")]
    Stvk(StVenantKirchhoff),
    /// Snow: fixed-corotated with clamped singular values and hardening (Stomakhin et al. 2013).
    #[schemars(title = "Snow")]
    Snow(SnowStomakhin2013),
    /// Sand: Drucker–Prager plasticity with a friction angle and optional cohesion (Klár et al. 2016).
    #[schemars(title = "Sand")]
    Sand(SandKlar2016),
}

impl Material {
    /// Scene name of the model.
    pub fn name(&self) -> &'static str {
        match self {
            Material::Fluid(_) => "fluid",
            Material::Elastic(_) => "elastic",
            Material::Stvk(_) => "stvk",
            Material::Snow(_) => "snow",
            Material::Sand(_) => "sand",
        }
    }

    /// Checks the rules that tie a model's keys together (each key's own range is in the scene schema);
    /// returns the offending key and the reason.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        match self {
            Material::Snow(m) => m.validate(),
            _ => Ok(()),
        }
    }
}

macro_rules! dispatch {
    ($self:ident, $m:ident => $e:expr) => {
        match $self {
            Material::Fluid($m) => $e,
            Material::Elastic($m) => $e,
            Material::Stvk($m) => $e,
            Material::Snow($m) => $e,
            Material::Sand($m) => $e,
        }
    };
}

impl<const D: usize> ConstitutiveModel<D> for Material
where
    Dim<D>: DimOps<D>,
{
    #[inline]
    fn volume_stress(&self, p: &MaterialPoint<D>) -> Matrix<D> {
        dispatch!(self, m => m.volume_stress(p))
    }
    fn cauchy_stress(&self, p: &MaterialPoint<D>) -> Matrix<D> {
        dispatch!(self, m => ConstitutiveModel::<D>::cauchy_stress(m, p))
    }
    #[inline]
    fn update_deformation(&self, f: &mut Matrix<D>, jp: &mut Real, grad_v: &Matrix<D>, dt: Real) {
        dispatch!(self, m => m.update_deformation(f, jp, grad_v, dt))
    }
    fn keeps_deformation_gradient(&self) -> bool {
        dispatch!(self, m => ConstitutiveModel::<D>::keeps_deformation_gradient(m))
    }
    fn needs_grid_density(&self) -> bool {
        dispatch!(self, m => ConstitutiveModel::<D>::needs_grid_density(m))
    }
    #[inline]
    fn current_density(&self, p: &MaterialPoint<D>) -> Real {
        dispatch!(self, m => ConstitutiveModel::<D>::current_density(m, p))
    }
    fn smooths_volume_ratio(&self) -> bool {
        dispatch!(self, m => ConstitutiveModel::<D>::smooths_volume_ratio(m))
    }
    fn keeps_volume_ratio(&self) -> bool {
        dispatch!(self, m => ConstitutiveModel::<D>::keeps_volume_ratio(m))
    }
    fn packing_relaxation_time(&self) -> Option<Real> {
        dispatch!(self, m => ConstitutiveModel::<D>::packing_relaxation_time(m))
    }
    fn occupied_volume(&self, p: &MaterialPoint<D>, density: Real) -> Real
    where
        Dim<D>: DimOps<D>,
    {
        dispatch!(self, m => ConstitutiveModel::<D>::occupied_volume(m, p, density))
    }
    fn density(&self) -> Real {
        dispatch!(self, m => ConstitutiveModel::<D>::density(m))
    }
    fn stable_dt(&self, h: Real) -> Real {
        dispatch!(self, m => ConstitutiveModel::<D>::stable_dt(m, h))
    }
}
