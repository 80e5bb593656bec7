//! The model (what does not change during a run), the simulation state and
//! the time step, which only calls the stages of [`crate::transfer`] in order.

use crate::boundary::NaiveBoundary;
use crate::geometry::Region;
use crate::grid::{GridLayout, GridState};
use crate::kernel::MlsInverse;
use crate::material::{ConstitutiveModel, Material};
use crate::math::{Dim, DimOps, Matrix, Real, Vector};
use crate::particles::Particles;
use crate::transfer::{self, OutOfGrid};

/// Everything fixed during a run: grid, materials, gravity, walls.
pub struct Model<const D: usize> {
    pub layout: GridLayout<D>,
    pub materials: Vec<Material>,
    /// Gravity (m/s²), added on the grid as `dt·g`.
    pub gravity: Vector<D>,
    /// The material region and its walls.
    pub region: Box<dyn Region<D>>,
    pub boundary: NaiveBoundary<D>,
    /// Time step (s).
    pub dt: Real,
}

impl<const D: usize> Model<D>
where
    Dim<D>: DimOps<D>,
{
    fn needs_grid_density(&self) -> bool {
        self.materials.iter().any(ConstitutiveModel::<D>::needs_grid_density)
    }

    /// The smallest stable time step (s) of the model's materials on its grid.
    pub fn stable_dt(&self) -> Real {
        self.materials
            .iter()
            .map(|m| ConstitutiveModel::<D>::stable_dt(m, self.layout.h))
            .fold(Real::INFINITY, Real::min)
    }
}

/// Why a step failed. The state is left as it was after the failing stage.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StepError {
    #[error("step {step}: particle {particle} left the grid (its stencil is outside the domain plus ghost layers)")]
    LeftGrid { step: u64, particle: usize },
    #[error("step {step}: particle {particle} became non-finite (NaN or infinity); the time step is likely too large for the material's stiffness or viscosity")]
    NonFinite { step: u64, particle: usize },
}

/// Scratch arrays of a step, allocated once.
struct Scratch<const D: usize> {
    grid: GridState<D>,
    density: Vec<Real>,
    stress: Vec<Matrix<D>>,
}

/// Diagnostics of the current state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metrics {
    pub step: u64,
    /// Time (s).
    pub time: Real,
    /// ½ Σ m v² (J, or J/m in 2D).
    pub kinetic_energy: Real,
    /// Particles on the wall side of the material region.
    pub n_outside: usize,
    /// Deepest particle beyond a wall, in cell widths h (0 when none is outside).
    pub max_penetration: Real,
}

/// A running simulation: the model, the particles and the clock.
pub struct Simulation<const D: usize> {
    pub model: Model<D>,
    pub particles: Particles<D>,
    /// Steps taken.
    pub step: u64,
    /// Time (s).
    pub time: Real,
    scratch: Scratch<D>,
}

impl<const D: usize> Simulation<D>
where
    Dim<D>: DimOps<D>,
{
    pub fn new(model: Model<D>, particles: Particles<D>) -> Self {
        let n = particles.len();
        let scratch = Scratch {
            grid: GridState::new(model.layout.num_nodes()),
            density: vec![0.0; n],
            stress: vec![Matrix::<D>::zeros(); n],
        };
        Self { model, particles, step: 0, time: 0.0, scratch }
    }

    /// One explicit MLS-MPM step: (density) → stress → P2G → grid update and
    /// walls → G2P → advection and deformation update.
    pub fn step(&mut self) -> Result<(), StepError> {
        let step = self.step + 1;
        let left = |OutOfGrid(particle)| StepError::LeftGrid { step, particle };
        let Self { model, particles, scratch, .. } = self;
        let layout = &model.layout;
        let dt = model.dt;
        let minv = MlsInverse::regular(layout.h);

        if model.needs_grid_density() {
            transfer::scatter_mass(layout, &particles.x, &particles.mass, &mut scratch.grid.mass).map_err(left)?;
            transfer::gather_density(layout, &particles.x, &scratch.grid.mass, &mut scratch.density);
        }
        transfer::compute_stress(&model.materials, particles, &scratch.density, &mut scratch.stress);
        transfer::p2g(layout, particles, &scratch.stress, &minv, dt, &mut scratch.grid).map_err(left)?;
        transfer::grid_velocity(&mut scratch.grid, &model.gravity, dt);
        model.boundary.apply(&scratch.grid.mass, &mut scratch.grid.momentum);
        transfer::g2p(layout, &scratch.grid.momentum, &minv, &particles.x, &mut particles.v, &mut particles.c);
        transfer::advect(&model.materials, particles, dt);

        self.step = step;
        self.time += dt;
        if let Some(particle) = transfer::first_non_finite(&self.particles) {
            return Err(StepError::NonFinite { step, particle });
        }
        Ok(())
    }

    /// Takes `n` steps, stopping at the first failure.
    pub fn advance(&mut self, n: u64) -> Result<(), StepError> {
        (0..n).try_for_each(|_| self.step())
    }

    /// Kinetic energy and wall penetration of the current state.
    pub fn metrics(&self) -> Metrics {
        let region = self.model.region.as_ref();
        let (mut n_outside, mut deepest) = (0usize, 0.0 as Real);
        for x in &self.particles.x {
            let d = region.distance(x).distance;
            if d > 0.0 {
                n_outside += 1;
                deepest = deepest.max(d);
            }
        }
        Metrics {
            step: self.step,
            time: self.time,
            kinetic_energy: self.particles.kinetic_energy(),
            n_outside,
            max_penetration: deepest / self.model.layout.h,
        }
    }
}
