//! Constitutive models. Each model is its own type implementing
//! [`ConstitutiveModel`]; [`Material`] dispatches between them with a `match`
//! in the hot loop and is what scenes name (`type = "fluid"`, ...).

mod fixed_corotated;
mod fluid_weakly_compressible;
mod snow_stomakhin2013;
mod stvk;

pub use fixed_corotated::FixedCorotated;
pub use fluid_weakly_compressible::{DensityEstimate, WeaklyCompressibleFluid};
pub use snow_stomakhin2013::SnowStomakhin2013;
pub use stvk::StVenantKirchhoff;

use crate::math::{Dim, DimOps, Matrix, Real};
use serde::{Deserialize, Serialize};

/// What a constitutive model may read of one particle.
#[derive(Clone, Copy, Debug)]
pub struct MaterialPoint<const D: usize> {
    /// Elastic deformation gradient F.
    pub f: Matrix<D>,
    /// Plastic volume ratio J_p (1 without plasticity).
    pub jp: Real,
    /// Velocity gradient ∇v (1/s), the APIC/MLS affine matrix.
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

    /// Advances F (and J_p) over one step with velocity gradient `grad_v`.
    fn update_deformation(&self, f: &mut Matrix<D>, jp: &mut Real, grad_v: &Matrix<D>, dt: Real);

    /// Whether [`MaterialPoint::density`] must be estimated on the grid before the stress.
    fn needs_grid_density(&self) -> bool {
        false
    }

    /// Whether the model keeps its density in `jp` = J, smoothed over the grid each step
    /// ([`crate::transfer::smooth_volume_ratio`]).
    fn smooths_volume_ratio(&self) -> bool {
        false
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
fn validate_solid(density: Real, youngs_modulus: Real, poisson_ratio: Real) -> Result<(), (&'static str, String)> {
    positive("density", density)?;
    positive("youngs_modulus", youngs_modulus)?;
    poisson(poisson_ratio)
}

/// `F ← (I + dt ∇v) F`, the MLS-MPM deformation update.
#[inline]
pub(crate) fn advance_f<const D: usize>(f: &mut Matrix<D>, grad_v: &Matrix<D>, dt: Real) {
    *f = (Matrix::<D>::identity() + grad_v * dt) * *f;
}

/// The materials a scene can name, chosen by the tag `type`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum Material {
    Fluid(WeaklyCompressibleFluid),
    Elastic(FixedCorotated),
    Stvk(StVenantKirchhoff),
    Snow(SnowStomakhin2013),
}

impl Material {
    /// Scene name of the model.
    pub fn name(&self) -> &'static str {
        match self {
            Material::Fluid(_) => "fluid",
            Material::Elastic(_) => "elastic",
            Material::Stvk(_) => "stvk",
            Material::Snow(_) => "snow",
        }
    }

    /// Checks the parameters; returns the offending key and the reason.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        match self {
            Material::Fluid(m) => m.validate(),
            Material::Elastic(m) => m.validate(),
            Material::Stvk(m) => m.validate(),
            Material::Snow(m) => m.validate(),
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
    #[inline]
    fn update_deformation(&self, f: &mut Matrix<D>, jp: &mut Real, grad_v: &Matrix<D>, dt: Real) {
        dispatch!(self, m => m.update_deformation(f, jp, grad_v, dt))
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
    fn density(&self) -> Real {
        dispatch!(self, m => ConstitutiveModel::<D>::density(m))
    }
    fn stable_dt(&self, h: Real) -> Real {
        dispatch!(self, m => ConstitutiveModel::<D>::stable_dt(m, h))
    }
}

/// Requires `value > 0` and finite.
pub(crate) fn positive(key: &'static str, value: Real) -> Result<(), (&'static str, String)> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err((key, format!("must be a positive finite number, got {value}")))
    }
}

/// Requires `value >= 0` and finite.
pub(crate) fn non_negative(key: &'static str, value: Real) -> Result<(), (&'static str, String)> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err((key, format!("must be a non-negative finite number, got {value}")))
    }
}

/// Requires a Poisson ratio in (−1, 0.5).
pub(crate) fn poisson(value: Real) -> Result<(), (&'static str, String)> {
    if value.is_finite() && value > -1.0 && value < 0.5 {
        Ok(())
    } else {
        Err(("poisson_ratio", format!("must lie in (-1, 0.5), got {value}")))
    }
}
