//! The model (what does not change during a run), the simulation state and
//! the time step, which only calls the stages of [`crate::transfer`] in order.

use crate::augmented::{AugmentedGrid, NearPoints};
use crate::boundary::NaiveBoundary;
use crate::geometry::Region;
use crate::grid::{GridLayout, GridState};
use crate::kernel::{MlsInverse, MlsKind};
use crate::material::{ConstitutiveModel, Material};
use crate::math::{Dim, DimOps, Matrix, Real, Vector};
use crate::particles::Particles;
use crate::transfer::{self, AugmentedStencil, Neighbourhood, OutOfGrid, RegularStencil};
use rayon::prelude::*;

/// How the walls act on the grid: one of the two methods of [`crate::boundary::Method`].
pub enum Boundary<const D: usize> {
    /// Grid nodes on the wall side are projected after the grid update.
    Naive(NaiveBoundary<D>),
    /// Boundary points join the grid; particles solve their own MLS systems.
    Augmented(AugmentedGrid<D>),
}

impl<const D: usize> Boundary<D> {
    /// Grid points: regular nodes, plus boundary points on an augmented grid.
    fn num_points(&self, layout: &GridLayout<D>) -> usize {
        match self {
            Boundary::Naive(_) => layout.num_nodes(),
            Boundary::Augmented(g) => layout.num_nodes() + g.points.len(),
        }
    }
}

/// Everything fixed during a run: grid, materials, gravity, walls.
pub struct Model<const D: usize> {
    pub layout: GridLayout<D>,
    pub materials: Vec<Material>,
    /// Gravity (m/s²), added on the grid as `dt·g`.
    pub gravity: Vector<D>,
    /// The material region and its walls.
    pub region: Box<dyn Region<D>>,
    pub boundary: Boundary<D>,
    /// Per node, the part of its support inside the material, when the fluid density is
    /// corrected next to walls (see [`transfer::gather_density`]).
    pub wall_fraction: Option<Vec<Real>>,
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
    /// Per-particle MLS inverse and how it was obtained (augmented grid only).
    minv: Vec<MlsInverse<D>>,
    kind: Vec<MlsKind>,
    near: Vec<NearPoints>,
    /// Whether each particle's MLS system saw a wall this step (not the closed form).
    at_wall: Vec<bool>,
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
    /// Particle-steps so far whose MLS moment matrix was near-singular or empty (augmented grid).
    pub ill_conditioned: u64,
    /// Node-steps so far whose MLS mass was below [`transfer::LOW_MASS_FRACTION`] of its B-spline mass.
    pub low_mass_nodes: u64,
    /// Particle-steps so far in which a particle past a wall was kept from moving deeper (augmented grid).
    pub held_at_wall: u64,
}

/// A running simulation: the model, the particles and the clock.
pub struct Simulation<const D: usize> {
    pub model: Model<D>,
    pub particles: Particles<D>,
    /// Steps taken.
    pub step: u64,
    /// Time (s).
    pub time: Real,
    ill_conditioned: u64,
    low_mass_nodes: u64,
    held_at_wall: u64,
    scratch: Scratch<D>,
}

impl<const D: usize> Simulation<D>
where
    Dim<D>: DimOps<D>,
{
    pub fn new(model: Model<D>, particles: Particles<D>) -> Self {
        let n = particles.len();
        let scratch = Scratch {
            grid: GridState::new(model.boundary.num_points(&model.layout)),
            density: vec![0.0; n],
            stress: vec![Matrix::<D>::zeros(); n],
            minv: vec![MlsInverse::regular(model.layout.h); n],
            kind: vec![MlsKind::Regular; n],
            near: vec![NearPoints::NONE; n],
            at_wall: vec![false; n],
        };
        Self { model, particles, step: 0, time: 0.0, ill_conditioned: 0, low_mass_nodes: 0, held_at_wall: 0, scratch }
    }

    /// One explicit MLS-MPM step: (density) → stress → (MLS inverses) → P2G →
    /// grid update and walls → G2P → advection and deformation update.
    pub fn step(&mut self) -> Result<(), StepError> {
        let step = self.step + 1;
        let left = |OutOfGrid(particle)| StepError::LeftGrid { step, particle };
        let Self { model, particles, scratch, .. } = self;
        let layout = &model.layout;
        let dt = model.dt;

        if model.needs_grid_density() {
            transfer::scatter_mass(layout, &particles.x, &particles.mass, &mut scratch.grid.mass).map_err(left)?;
            let fractions = model.wall_fraction.as_deref();
            transfer::gather_density(layout, &particles.x, &scratch.grid.mass, fractions, &mut scratch.density);
        }
        transfer::compute_stress(&model.materials, particles, &scratch.density, &mut scratch.stress);
        let low_mass = match &model.boundary {
            Boundary::Naive(walls) => {
                let nbh = RegularStencil { layout, minv: MlsInverse::regular(layout.h) };
                transfer_momentum(&nbh, model, particles, &scratch.stress, &mut scratch.grid, |m, v| walls.apply(m, v))
                    .map_err(left)?
            }
            Boundary::Augmented(grid) => {
                // eq. (5), once per particle and step, reused by P2G, the force and G2P.
                scratch
                    .minv
                    .par_iter_mut()
                    .zip(scratch.kind.par_iter_mut())
                    .zip(scratch.near.par_iter_mut())
                    .zip(particles.x.par_iter())
                    .enumerate()
                    .try_for_each(|(p, (((minv, kind), near), x))| {
                        (*minv, *kind, *near) = grid.particle_inverse::<Dim<D>>(layout, x, p)?;
                        Ok(())
                    })
                    .map_err(left)?;
                self.ill_conditioned +=
                    scratch.kind.iter().filter(|k| matches!(k, MlsKind::Regularized | MlsKind::Isolated)).count()
                        as u64;
                let nbh = AugmentedStencil { layout, grid, minv: &scratch.minv, near: &scratch.near };
                let low = transfer_momentum(&nbh, model, particles, &scratch.stress, &mut scratch.grid, |m, v| {
                    grid.apply(m, v)
                })
                .map_err(left)?;
                for (at_wall, kind) in scratch.at_wall.iter_mut().zip(&scratch.kind) {
                    *at_wall = *kind != MlsKind::Regular;
                }
                self.held_at_wall +=
                    transfer::hold_at_walls(model.region.as_ref(), &scratch.at_wall, &particles.x, &mut particles.v)
                        as u64;
                low
            }
        };
        self.low_mass_nodes += low_mass as u64;
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

    /// Density (kg/m³, or kg/m² in 2D) of each particle as gathered from the regular grid in
    /// the last step; only for models that use it (fluids), zero before the first step.
    pub fn grid_density(&self) -> &[Real] {
        &self.scratch.density
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
            ill_conditioned: self.ill_conditioned,
            low_mass_nodes: self.low_mass_nodes,
            held_at_wall: self.held_at_wall,
        }
    }
}

/// P2G, grid velocity with gravity, the walls' conditions, G2P. Returns the low-mass node count.
fn transfer_momentum<const D: usize, N: Neighbourhood<D>>(
    nbh: &N,
    model: &Model<D>,
    particles: &mut Particles<D>,
    stress: &[Matrix<D>],
    grid: &mut GridState<D>,
    walls: impl Fn(&[Real], &mut [Vector<D>]),
) -> Result<usize, OutOfGrid> {
    transfer::p2g(nbh, particles, stress, model.dt, grid)?;
    let low_mass = transfer::grid_velocity(grid, &model.gravity, model.dt);
    walls(&grid.mass, &mut grid.momentum);
    transfer::g2p(nbh, &grid.momentum, &particles.x, &mut particles.v, &mut particles.c);
    Ok(low_mass)
}
