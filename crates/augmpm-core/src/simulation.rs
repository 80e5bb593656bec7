//! A simulation: the model (what does not change during a run), the state (everything that evolves;
//! a checkpoint) and the scratch of a step; the step itself, which calls the stages of
//! [`crate::step`] and the wall treatment ([`crate::treatment`]) in order.

use crate::contact::Contacts;
use crate::geometry::Region;
use crate::grid::{GridLayout, GridState, OutOfGrid};
use crate::material::{ConstitutiveModel, Material, MaterialPoint};
use crate::math::{Dim, DimOps, Matrix, Real, Vector};
use crate::motion::WallPose;
use crate::parallel::Disjoint;
use crate::particles::{Column, ColumnMut, Field, FieldKind, Particles};
use crate::rigid::{drift, RigidBody};
use crate::step::packing::Packing;
use crate::step::schedule::{Binning, Schedule};
use crate::step::transfer::{self, G2pOutcome, GridDensity, Transfer, VolumeRatio};
use crate::treatment::augmented::WallParticles;
use crate::treatment::wall_fit::WallPush;
use crate::treatment::{Boundary, WallTreatment};
use crate::wall::WallImpulses;
use std::time::Instant;

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
    /// corrected next to walls (see [`transfer::density_at`]).
    pub wall_fraction: Option<Vec<Real>>,
    /// Time step (s).
    pub dt: Real,
    /// The rigid bodies, each moving one of the region's walls.
    pub bodies: Vec<RigidBody<D>>,
    /// What the bodies meet besides the material (each other, the walls, their hinges); without it they
    /// move freely between the material's impulses.
    pub contacts: Option<Box<dyn Contacts<D>>>,
}

impl<const D: usize> Model<D>
where
    Dim<D>: DimOps<D>,
{
    fn needs_grid_density(&self) -> bool {
        self.materials.iter().any(ConstitutiveModel::<D>::needs_grid_density)
    }

    fn smooths_volume_ratio(&self) -> bool {
        self.materials.iter().any(ConstitutiveModel::<D>::smooths_volume_ratio)
    }

    /// Whether a material relaxes its J toward the particles' packing ([`crate::step::packing`]).
    fn relaxes_to_packing(&self) -> bool {
        self.materials.iter().any(|m| ConstitutiveModel::<D>::packing_relaxation_time(m).is_some())
    }

    /// Whether a material of the model keeps a deformation gradient; without one the particles keep
    /// no F (`Particles::f`).
    pub fn keeps_deformation_gradient(&self) -> bool {
        self.materials.iter().any(ConstitutiveModel::<D>::keeps_deformation_gradient)
    }

    /// Puts moving walls where they are at time `t` (s), moving over the step that starts there (the
    /// walls `poses` names as set there, the others as their scene says), and has the wall treatment
    /// follow them.
    pub fn follow_walls(&mut self, t: Real, poses: &[(usize, WallPose<D>)]) {
        self.region.set_poses(poses);
        self.region.set_time(t, self.dt);
        for wall in 0..self.region.num_walls() {
            self.boundary.set_moving(wall, self.region.is_moving(wall));
        }
        self.boundary.follow(&self.layout, self.region.as_ref());
    }

    /// The smallest stable time step (s) of the model's materials on its grid.
    pub fn stable_dt(&self) -> Real {
        self.materials
            .iter()
            .map(|m| ConstitutiveModel::<D>::stable_dt(m, self.layout.h))
            .fold(Real::INFINITY, Real::min)
    }
}

/// A particle may move at most this many cell widths in one step. An explicit MPM step is stable
/// only well below one cell per step (CFL); a particle jumping further means the state is blowing up.
pub const MAX_CELLS_PER_STEP: Real = 1.0;

/// Why a step failed, and the likely cause. The state is left as it was after the failing stage.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StepError {
    #[error(
        "step {step}: particle {particle} left the grid (its stencil is outside the domain plus ghost layers); {cause}"
    )]
    LeftGrid { step: u64, particle: usize, cause: String },
    #[error("step {step}: particle {particle} became non-finite (NaN or infinity, or a kinetic energy beyond the floating-point range); {cause}")]
    NonFinite { step: u64, particle: usize, cause: String },
    #[error("step {step}: particle {particle} moved {cells:.3} cell widths in one step (at most {MAX_CELLS_PER_STEP} is allowed): the explicit step is unstable; {cause}")]
    Unstable { step: u64, particle: usize, cells: Real, cause: String },
    #[error("step {step}: rigid_bodies[{body}] would move {cells:.3} cell widths in one step (at most one): the material or gravity sped it up beyond what time.dt follows; lower time.dt or time.cfl")]
    BodyTooFast { step: u64, body: usize, cells: Real },
}

impl StepError {
    /// The step and the particle the error names (none for a body).
    pub fn location(&self) -> (u64, Option<usize>) {
        match *self {
            StepError::LeftGrid { step, particle, .. }
            | StepError::NonFinite { step, particle, .. }
            | StepError::Unstable { step, particle, .. } => (step, Some(particle)),
            StepError::BodyTooFast { step, .. } => (step, None),
        }
    }
}

/// The likely cause of a failed step, from the time step against the materials' stable bound
/// (computed only for a failing step).
fn likely_cause<const D: usize>(model: &Model<D>) -> String
where
    Dim<D>: DimOps<D>,
{
    let (dt, stable_dt) = (model.dt, model.stable_dt());
    let cause = if dt > stable_dt {
        format!(
            "likely cause: time.dt = {dt:e} s exceeds the materials' stable step {stable_dt:e} s (stiffness or \
             viscosity too high for it); lower time.dt or give time.cfl"
        )
    } else {
        format!(
            "likely cause: the flow outran the grid (time.dt = {dt:e} s is within the materials' stable step \
             {stable_dt:e} s, but a velocity v needs dt < h / v); lower time.dt"
        )
    };
    if crate::math::Precision::NATIVE == crate::math::Precision::F32 {
        cause + "; or the f32 rounding near walls: precision = \"f64\" is the robust choice"
    } else {
        cause
    }
}

/// Everything that evolves during a run: with the scene it was built from, a [`State`] continues
/// the run bitwise identically (the binning is part of it: it fixes the order of the grid sums).
/// A checkpoint is a [`State`]: its per-particle arrays are listed by [`State::fields`] and
/// [`State::columns`], its numbers by [`State::scalars`].
#[derive(Clone, Debug, PartialEq)]
pub struct State<const D: usize> {
    pub step: u64,
    /// Time (s).
    pub time: Real,
    pub ill_conditioned: u64,
    pub low_mass_nodes: u64,
    pub held_at_wall: u64,
    /// Largest move of a particle in the last step (cell widths).
    pub max_cfl: Real,
    pub particles: Particles<D>,
    /// Density of each particle in the last step (ρ0/J with the particle's J, or the grid's; see
    /// [`Simulation::grid_density`]).
    pub density: Vec<Real>,
    /// The block each particle was binned in, and how far the particles may have moved since.
    pub binning: Binning,
    /// The impulse each wall has given the material since the start (N·s, per metre in 2D; the
    /// domain box last): what the wall conditions took from or gave to the grid points and, at walls,
    /// to the particles. Empty before a simulation sizes it.
    pub wall_impulse: Vec<Vector<D>>,
    /// The moment of those impulses about the origin, `Σ x × Δp` (N·m·s, per metre in 2D; 3 components,
    /// in 2D only z), by wall as `wall_impulse`. Empty before a simulation sizes it.
    pub wall_angular_impulse: Vec<Vector<3>>,
    /// The poses set by [`Simulation::set_wall_pose`], by wall (sorted); the other walls move as their
    /// scene says.
    pub wall_poses: Vec<(usize, WallPose<D>)>,
    /// Per rigid body (in `Model::bodies` order), a velocity change (m/s) and angular velocity change
    /// (rad/s; in 2D only z) the material sees its wall take ahead over the next step
    /// ([`State::seen_poses`]): the part of its change over the last step that gravity, contacts and
    /// joints gave it. Empty before a simulation sizes it.
    pub body_kicks: Vec<(Vector<D>, Vector<3>)>,
}

/// The per-particle arrays of a [`State`] beyond its [`Particles`].
const STEP_FIELDS: [Field; 2] = [
    Field {
        name: "density",
        kind: FieldKind::Real,
        unit: "kg/m³",
        doc: "Density in the last step, as the particle's material saw it (per unit area in 2D).",
        optional: false,
    },
    Field { name: "bins", kind: FieldKind::Index, unit: "", doc: "Block the particle was binned in.", optional: false },
];

/// A number of a [`State`], to read or to replace.
#[derive(Debug)]
pub enum Scalar<'a> {
    Count(&'a mut u64),
    Real(&'a mut Real),
}

impl<const D: usize> State<D> {
    /// The state of `particles` at rest before the first step: time 0, not binned.
    pub fn new(particles: Particles<D>) -> Self {
        let n = particles.len();
        // Seeding grew the columns by doubling: keep what the particles take.
        let mut particles = particles;
        particles.columns_mut().iter_mut().for_each(ColumnMut::shrink_to_fit);
        Self {
            step: 0,
            time: 0.0,
            ill_conditioned: 0,
            low_mass_nodes: 0,
            held_at_wall: 0,
            max_cfl: 0.0,
            particles,
            density: vec![0.0; n],
            binning: Binning { bins: vec![0; n], drift: Real::INFINITY },
            wall_impulse: Vec::new(),
            wall_angular_impulse: Vec::new(),
            wall_poses: Vec::new(),
            body_kicks: Vec::new(),
        }
    }

    /// The per-particle fields: the particles', then the density and the binning.
    pub fn fields() -> impl Iterator<Item = &'static Field> {
        Particles::<D>::FIELDS.iter().chain(STEP_FIELDS.iter())
    }

    /// Each per-particle array, in the order of [`State::fields`].
    pub fn columns(&self) -> Vec<Column<'_, D>> {
        let mut columns = self.particles.columns();
        columns.extend([Column::Real(&self.density), Column::Index(&self.binning.bins)]);
        columns
    }

    /// Each per-particle array, to replace, in the order of [`State::fields`].
    pub fn columns_mut(&mut self) -> Vec<ColumnMut<'_, D>> {
        let mut columns = self.particles.columns_mut();
        columns.extend([ColumnMut::Real(&mut self.density), ColumnMut::Index(&mut self.binning.bins)]);
        columns
    }

    /// The numbers of the state by name: the clock, the counters, the last move and the drift.
    pub fn scalars(&mut self) -> [(&'static str, Scalar<'_>); 7] {
        [
            ("step", Scalar::Count(&mut self.step)),
            ("time", Scalar::Real(&mut self.time)),
            ("ill_conditioned", Scalar::Count(&mut self.ill_conditioned)),
            ("low_mass_nodes", Scalar::Count(&mut self.low_mass_nodes)),
            ("held_at_wall", Scalar::Count(&mut self.held_at_wall)),
            ("max_cfl", Scalar::Real(&mut self.max_cfl)),
            ("drift", Scalar::Real(&mut self.binning.drift)),
        ]
    }

    /// The walls' poses as the material sees them over the next step: [`State::wall_poses`], with each of
    /// the model's rigid `bodies` moving on at its velocities plus the change `body_kicks` shows ahead.
    /// A body's velocities change at the step's end, after the material moved against its wall; seen at
    /// the old ones, a body that speeds up into the material (pushed, or falling) would gain on it by
    /// Δv Δt each step, and the particles at its surface would end the step inside it. A body at rest, or
    /// moving steadily, is seen as it moves. Its state keeps its own velocities.
    pub fn seen_poses(&self, bodies: &[RigidBody<D>]) -> std::borrow::Cow<'_, [(usize, WallPose<D>)]> {
        if self.body_kicks.iter().all(|(v, w)| v.iter().chain(w.iter()).all(|&a| a == 0.0)) {
            return std::borrow::Cow::Borrowed(&self.wall_poses);
        }
        let mut poses = self.wall_poses.clone();
        for (body, (dv, dw)) in bodies.iter().zip(&self.body_kicks) {
            let i = poses.binary_search_by_key(&body.wall, |&(w, _)| w).expect("a body's wall is posed");
            let pose = &mut poses[i].1;
            pose.velocity = (Vector::<D>::from(pose.velocity) + dv).into();
            pose.angular_velocity = (Vector::<3>::from(pose.angular_velocity) + dw).into();
        }
        std::borrow::Cow::Owned(poses)
    }

    /// Ends step `step` of `dt` (s) in which the particles moved at most `cells` cell widths and
    /// `held` were held at a wall.
    fn advance_clock(&mut self, step: u64, dt: Real, cells: Real, held: u64) {
        self.binning.drift += cells;
        self.held_at_wall += held;
        self.step = step;
        self.time += dt;
        self.max_cfl = cells;
    }

    /// Bytes per particle of the state in D dimensions, with every optional column kept (at most).
    pub fn bytes_per_particle() -> usize {
        Self::fields().map(|f| f.kind.bytes(D)).sum()
    }

    /// Heap bytes of the state's arrays.
    pub fn heap_bytes(&self) -> usize {
        crate::particles::heap_bytes(&self.columns())
    }

    /// Checks that every array has one entry per particle and every real is finite; names the field.
    fn check(&self) -> Result<(), String> {
        let n = self.particles.len();
        let fields: Vec<Field> = Self::fields().copied().collect();
        let columns = self.columns();
        crate::particles::check_lengths(&columns, &fields, n)?;
        if let Some((f, p)) = fields.iter().zip(&columns).find_map(|(f, c)| c.first_non_finite().map(|p| (f, p))) {
            return Err(format!("{} of particle {p} is not finite", f.name));
        }
        if !(self.time.is_finite() && self.max_cfl.is_finite()) {
            return Err("the state holds non-finite values".to_string());
        }
        if self.wall_impulse.iter().any(|i| !i.iter().all(|a| a.is_finite())) {
            return Err("wall_impulse holds non-finite values".to_string());
        }
        if self.wall_angular_impulse.iter().any(|i| !i.iter().all(|a| a.is_finite())) {
            return Err("wall_angular_impulse holds non-finite values".to_string());
        }
        if let Some((w, _)) = self.wall_poses.iter().find(|(_, p)| !p.to_row().iter().all(|a| a.is_finite())) {
            return Err(format!("wall_pose of wall {w} holds non-finite values"));
        }
        if self.body_kicks.iter().any(|(v, w)| !(v.iter().chain(w.iter()).all(|a| a.is_finite()))) {
            return Err("body_kick holds non-finite values".to_string());
        }
        if self.wall_poses.windows(2).any(|p| p[0].0 >= p[1].0) {
            return Err("wall_pose rows must name each wall once, in increasing order".to_string());
        }
        Ok(())
    }
}

/// Scratch arrays of a step, allocated once (they grow only with the particle count or the
/// number of particles next to walls).
struct Scratch<const D: usize> {
    schedule: Schedule<D>,
    grid: GridState<D>,
    /// B-spline grid mass of the density estimate (fluids only; empty otherwise).
    density_mass: Vec<Real>,
    /// Per node, rest volume and rest volume·J of the particles whose J is smoothed (empty when none is);
    /// after the grid update, their ratio J in the second place.
    volume_ratio: VolumeRatio,
    /// Per node, the volume the particles occupy and the part of the support inside the material, when a
    /// material relaxes its J toward the packing (empty otherwise); after the grid update, the packing.
    packing: Packing,
    /// Particles whose MLS system sees a wall, with their inverses (augmented grid only).
    walls: WallParticles<D>,
    /// The impulse each wall gave each particle of `walls` in G2P.
    pushes: Vec<WallPush<D>>,
    /// What the walls gave the material in this step.
    step_impulse: WallImpulses<D>,
}

impl<const D: usize> Scratch<D> {
    /// Bins the particles at `x` again if due (`binning`, part of the state), and clears the grid
    /// values the last step left: on the node blocks it touched, and at every boundary point.
    fn prepare_grid(
        &mut self,
        layout: &GridLayout<D>,
        x: &[Vector<D>],
        binning: &mut Binning,
    ) -> Result<(), OutOfGrid> {
        let Self { schedule, grid, .. } = self;
        schedule.prepare(layout, x, binning)?;
        let nodes = layout.num_nodes();
        {
            let (mass, momentum) = (Disjoint::new(&mut grid.mass[..nodes]), Disjoint::new(&mut grid.momentum[..nodes]));
            // SAFETY: node blocks do not overlap, and each is listed once.
            schedule.for_each_node_of(layout, schedule.stale(), |i| unsafe {
                mass.update(i, |m| *m = 0.0);
                momentum.update(i, |m| *m = Vector::<D>::zeros());
            });
        }
        if grid.keeps_spline_mass() {
            schedule.clear(layout, schedule.stale(), &mut grid.spline_mass[..nodes], 0.0);
            grid.spline_mass[nodes..].fill(0.0);
        }
        grid.mass[nodes..].fill(0.0);
        grid.momentum[nodes..].fill(Vector::<D>::zeros());
        Ok(())
    }

    /// The grid mass of the fluids' `grid` density estimate, where a material needs it; and the volume
    /// ratio and packing sums, which P2G scatters, cleared (with moving walls, the nodes' support fractions
    /// where the walls of `region` are now).
    fn scatter_density(&mut self, layout: &GridLayout<D>, particles: &Particles<D>, region: &dyn Region<D>) {
        let Self { schedule, volume_ratio, packing, density_mass, .. } = self;
        if !volume_ratio.is_empty() {
            volume_ratio.clear(layout, schedule, schedule.stale());
        }
        if !packing.is_empty() {
            packing.clear(layout, schedule, schedule.stale());
            if region.moves() {
                packing.follow_walls(layout, schedule, region);
            }
        }
        if !density_mass.is_empty() {
            schedule.clear(layout, schedule.stale(), density_mass, 0.0);
            transfer::scatter_mass(layout, schedule, &particles.x, &particles.mass, density_mass);
        }
    }
}

/// Adds the time since the last lap to a stage's total.
struct Lap(Instant);

impl Lap {
    fn start() -> Self {
        Self(Instant::now())
    }

    /// Never inlined: the step calls it once at the end of each stage, so that a tool can cut the step
    /// into the same stages as these times (`augmpm bench --ops` counts each stage's operations with
    /// callgrind, dumping before each call here; the timer's own work falls in the next stage).
    #[inline(never)]
    fn add_to(&mut self, total: &mut f64) {
        let now = Instant::now();
        *total += (now - self.0).as_secs_f64();
        self.0 = now;
    }
}

/// The error of step `step` if its G2P found a non-finite particle, one whose stencil left the grid,
/// or a move of more than [`MAX_CELLS_PER_STEP`] cells (`cells`), with its likely `cause`.
fn failure(step: u64, outcome: &G2pOutcome, cells: Real, cause: impl FnOnce() -> String) -> Option<StepError> {
    match (outcome.non_finite, outcome.left_grid) {
        (Some(particle), _) => Some(StepError::NonFinite { step, particle, cause: cause() }),
        (None, Some(particle)) => Some(StepError::LeftGrid { step, particle, cause: cause() }),
        (None, None) if cells > MAX_CELLS_PER_STEP => {
            Some(StepError::Unstable { step, particle: outcome.fastest, cells, cause: cause() })
        }
        (None, None) => None,
    }
}

/// Wall-clock time spent in each stage since the simulation was created (s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimes {
    /// Binning particles by block, clearing the grid.
    pub sort: f64,
    /// The grid density's mass scatter (fluids with `density_estimate = "grid"`), and clearing the J-bar
    /// sums.
    pub density: f64,
    /// Boundary-point lookups and per-particle MLS inverses (augmented grid).
    pub boundary: f64,
    /// Particle→grid transfer, stress and the J-bar sums included.
    pub p2g: f64,
    /// Grid velocity update, the nodes' J (J-bar) and wall conditions.
    pub grid: f64,
    /// Grid→particle transfer, the J-bar gather, advection and deformation update.
    pub g2p: f64,
}

/// Heap bytes held by a simulation, by what they scale with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MemoryUse {
    /// Particle state.
    pub particles: usize,
    /// Per-particle scratch of a step: density, binning, the wall table of the augmented grid.
    pub particle_scratch: usize,
    /// Grid: node state, density mass, blocks, wall fractions, walls' node lists and boundary points.
    pub grid: usize,
}

/// Per-particle fields of a state for output ([`Simulation::particle_fields`]), in particle order.
#[derive(Clone, Debug, Default)]
pub struct ParticleFields<const D: usize> {
    /// Cauchy stress σ (Pa, or N/m in 2D).
    pub stress: Vec<Matrix<D>>,
    /// Volume ratio J = V/V⁰.
    pub volume_ratio: Vec<Real>,
    /// Plastic volume ratio J_p (1 without plasticity).
    pub plastic: Vec<Real>,
}

/// Diagnostics of the current state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metrics {
    pub step: u64,
    /// Time (s).
    pub time: Real,
    /// ½ Σ m v² (J, or J/m in 2D), in f64 whatever the precision.
    pub kinetic_energy: f64,
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
    /// Largest distance a particle moved in the last step, in cell widths (the step's CFL number).
    pub max_cfl: Real,
}

/// A running simulation: the model (fixed during the run), the state (everything that evolves) and
/// the scratch of a step.
pub struct Simulation<const D: usize> {
    pub model: Model<D>,
    pub state: State<D>,
    scratch: Scratch<D>,
    times: StageTimes,
    /// The threads steps run on; `None` runs them in the caller's rayon context.
    pool: Option<rayon::ThreadPool>,
    /// The error of the step that failed; later steps return it until a [`State`] is restored.
    failed: Option<StepError>,
}

/// How much a body's velocities (m/s, rad/s) changed from `before` to `after`.
fn velocity_change<const D: usize>(before: &WallPose<D>, after: &WallPose<D>) -> (Vector<D>, Vector<3>) {
    (
        Vector::<D>::from(after.velocity) - Vector::<D>::from(before.velocity),
        Vector::<3>::from(after.angular_velocity) - Vector::<3>::from(before.angular_velocity),
    )
}

/// The velocity change a body's wall is shown ahead of in the next step ([`State::body_kicks`]), from its
/// change over the last step, `total`, and the part of it that the material did not give, `other`
/// (gravity, contacts, joints): `total` scaled by `other`'s share of it, between 0 and 1. A body driven
/// into the material from outside (falling freely, pushed by a piston) is shown at its whole change; one
/// the material alone moves, or holds up against gravity, at none (predicting the material's own push on
/// it would feed it back a step early, which a light body does not survive); one the material slows,
/// at none.
fn ahead<const N: usize>(total: &Vector<N>, other: &Vector<N>) -> Vector<N> {
    let norm = total.norm_squared();
    if norm > 0.0 {
        total * (total.dot(other) / norm).clamp(0.0, 1.0)
    } else {
        Vector::<N>::zeros()
    }
}

impl<const D: usize> Simulation<D>
where
    Dim<D>: DimOps<D>,
{
    pub fn new(model: Model<D>, particles: Particles<D>) -> Self {
        let density = model.needs_grid_density();
        let scratch = Scratch {
            schedule: Schedule::new(&model.layout),
            grid: GridState::new(model.boundary.num_points(&model.layout), model.boundary.reads_spline_mass()),
            density_mass: if density { vec![0.0; model.layout.num_nodes()] } else { Vec::new() },
            volume_ratio: if model.smooths_volume_ratio() {
                VolumeRatio::new(model.layout.num_nodes())
            } else {
                VolumeRatio::default()
            },
            packing: if model.relaxes_to_packing() {
                Packing::new(&model.layout, model.region.as_ref())
            } else {
                Packing::default()
            },
            walls: WallParticles::default(),
            pushes: Vec::new(),
            step_impulse: WallImpulses::zeros(model.boundary.contacts().len()),
        };
        let mut model = model;
        if model.region.moves() {
            model.follow_walls(0.0, &[]);
        }
        let mut particles = particles;
        assert!(
            particles.f.is_empty() || particles.f.len() == particles.len(),
            "F has {} entries for {} particles: it is kept for every particle or for none",
            particles.f.len(),
            particles.len()
        );
        if !model.keeps_deformation_gradient() {
            particles.f = Vec::new();
        } else if particles.f.is_empty() {
            particles.f = vec![Matrix::<D>::identity(); particles.len()];
        }
        let mut state = State::new(particles);
        state.wall_impulse = vec![Vector::<D>::zeros(); model.boundary.contacts().len()];
        state.wall_angular_impulse = vec![Vector::<3>::zeros(); model.boundary.contacts().len()];
        Self { model, state, scratch, times: StageTimes::default(), pool: None, failed: None }
    }

    /// The particles.
    pub fn particles(&self) -> &Particles<D> {
        &self.state.particles
    }

    /// Steps taken.
    pub fn steps_done(&self) -> u64 {
        self.state.step
    }

    /// Time (s).
    pub fn time(&self) -> Real {
        self.state.time
    }

    /// Runs the steps on `threads` threads of the simulation's own pool (0: one per core), with
    /// denormal floats flushed to zero on them (x86-64). Results do not depend on the count.
    pub fn set_threads(&mut self, threads: usize) -> Result<(), String> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("augmpm-{i}"))
            .start_handler(|_| crate::math::flush_denormals())
            .build()
            .map_err(|e| format!("cannot start {threads} threads: {e}"))?;
        self.pool = Some(pool);
        Ok(())
    }

    /// Number of threads steps run on.
    pub fn threads(&self) -> usize {
        self.pool.as_ref().map_or_else(rayon::current_num_threads, |p| p.current_num_threads())
    }

    /// Heap bytes of the particle, scratch and grid arrays.
    pub fn memory_use(&self) -> MemoryUse {
        use crate::math::heap_bytes as b;
        let s = &self.scratch;
        let boundary = self.model.boundary.heap_bytes();
        MemoryUse {
            particles: self.state.heap_bytes(),
            particle_scratch: s.schedule.particle_bytes() + s.walls.heap_bytes() + b(&s.pushes),
            grid: s.grid.heap_bytes()
                + b(&s.density_mass)
                + s.volume_ratio.heap_bytes()
                + s.packing.heap_bytes()
                + s.schedule.block_bytes()
                + self.model.wall_fraction.as_ref().map_or(0, b)
                + boundary,
        }
    }

    /// Time spent in each stage so far.
    pub fn stage_times(&self) -> StageTimes {
        self.times
    }

    /// One explicit MLS-MPM step: sort → (grid density) → (MLS inverses near walls) →
    /// P2G with stress → grid update and walls → G2P with advection and deformation update.
    pub fn step(&mut self) -> Result<(), StepError> {
        self.advance(1)
    }

    /// Takes `n` steps on the simulation's threads, stopping at the first failure. After a failure
    /// the state is that of the failing step, and every later call returns the same error.
    pub fn advance(&mut self, n: u64) -> Result<(), StepError> {
        if let Some(e) = &self.failed {
            return Err(e.clone());
        }
        let result = match self.pool.take() {
            Some(pool) => {
                let result = pool.install(|| (0..n).try_for_each(|_| self.step_here()));
                self.pool = Some(pool);
                result
            }
            None => (0..n).try_for_each(|_| self.step_here()),
        };
        if let Err(e) = &result {
            self.failed = Some(e.clone());
        }
        result
    }

    /// The error of the step that failed, if one did.
    pub fn failure(&self) -> Option<&StepError> {
        self.failed.as_ref()
    }

    /// A copy of everything that evolves during the run (see [`State`]).
    pub fn state(&self) -> State<D> {
        self.state.clone()
    }

    /// Continues from `state`, taken from a simulation of the same scene and method: the steps
    /// that follow are bitwise identical to those the saved simulation would have taken. Fails,
    /// changing nothing, if the state does not fit this model.
    pub fn restore(&mut self, state: State<D>) -> Result<(), String> {
        state.check()?;
        let p = &state.particles;
        // One material per body (see `Scene::build`).
        let bodies = self.model.materials.len();
        if let Some(i) = p.body.iter().position(|&b| b as usize >= bodies) {
            return Err(format!("particle {i}: body {} of {bodies}", p.body[i]));
        }
        let keeps_f = self.model.keeps_deformation_gradient();
        if keeps_f && p.f.len() != p.len() {
            return Err(format!(
                "f has {} entries for {} particles; a material of this scene keeps F",
                p.f.len(),
                p.len()
            ));
        }
        // A model without F drops the checkpoint's; every particle must then be at F = I, as it kept it.
        let sheared = if keeps_f { None } else { p.f.iter().position(|f| *f != Matrix::<D>::identity()) };
        if let Some(i) = sheared {
            return Err(format!("f of particle {i} is not the identity; no material of this scene keeps F"));
        }
        // Every check before anything changes (the schedule's restore is the first change).
        let walls = self.model.boundary.contacts().len();
        if !state.wall_impulse.is_empty() && state.wall_impulse.len() != walls {
            return Err(format!(
                "wall_impulse has {} rows; the scene has {walls} walls (the domain box counted)",
                state.wall_impulse.len()
            ));
        }
        if !state.wall_angular_impulse.is_empty() && state.wall_angular_impulse.len() != walls {
            return Err(format!(
                "wall_angular_impulse has {} rows; the scene has {walls} walls (the domain box counted)",
                state.wall_angular_impulse.len()
            ));
        }
        if let Some((w, _)) = state.wall_poses.iter().find(|(w, _)| *w + 1 >= walls) {
            return Err(format!("wall_pose names wall {w}; the scene has {} walls", walls - 1));
        }
        for (w, pose) in &state.wall_poses {
            self.pose_refused(*w, pose).map_err(|(key, reason)| format!("wall_pose of wall {w}: {key}: {reason}"))?;
        }
        if let Some(k) =
            self.model.bodies.iter().position(|b| state.wall_poses.binary_search_by_key(&b.wall, |&(w, _)| w).is_err())
        {
            return Err(format!(
                "wall_pose has no row for wall {} (rigid_bodies[{k}]): the state is not of this scene",
                self.model.bodies[k].wall
            ));
        }
        let bodies = self.model.bodies.len();
        if !state.body_kicks.is_empty() && state.body_kicks.len() != bodies {
            return Err(format!("body_kick has {} rows; the scene has {bodies} rigid bodies", state.body_kicks.len()));
        }
        let layout = &self.model.layout;
        let run = |s: &mut Schedule<D>| s.restore(layout, &p.x, &state.binning);
        match &self.pool {
            Some(pool) => pool.install(|| run(&mut self.scratch.schedule)),
            None => run(&mut self.scratch.schedule),
        }?;
        let mut state = state;
        if !keeps_f {
            state.particles.f = Vec::new();
        }
        if state.wall_impulse.is_empty() {
            // A checkpoint written before walls' impulses were kept: none counted so far.
            state.wall_impulse = vec![Vector::<D>::zeros(); walls];
        }
        if state.wall_angular_impulse.is_empty() {
            state.wall_angular_impulse = vec![Vector::<3>::zeros(); walls];
        }
        if state.body_kicks.is_empty() {
            // A checkpoint written before the bodies' kicks were kept: the next step predicts none.
            state.body_kicks = vec![(Vector::<D>::zeros(), Vector::<3>::zeros()); self.model.bodies.len()];
        }
        let was_moving = self.model.region.moves();
        self.state = state;
        self.failed = None;
        let placed = was_moving || !self.state.wall_poses.is_empty();
        if placed {
            let seen = self.state.seen_poses(&self.model.bodies);
            self.model.follow_walls(self.state.time, &seen);
            self.scratch.grid.resize(self.model.boundary.num_points(&self.model.layout));
        }
        // The grid is cleared only where the binning says particles were: start from a clean one.
        let grid = &mut self.scratch.grid;
        grid.mass.fill(0.0);
        grid.spline_mass.fill(0.0);
        grid.momentum.fill(Vector::<D>::zeros());
        self.scratch.density_mass.fill(0.0);
        self.scratch.volume_ratio.fill_zero();
        self.scratch.packing.fill_zero();
        if !self.scratch.packing.is_empty() && placed {
            // The walls may be back where a region that no longer moves keeps them, which no step places again.
            self.scratch.packing.place_walls(&self.model.layout, self.model.region.as_ref());
        }
        Ok(())
    }

    /// One step, the stages in order (the timing of each goes to `times`). Never inlined: `augmpm bench
    /// --ops` counts under callgrind only inside this function.
    #[inline(never)]
    fn step_here(&mut self) -> Result<(), StepError> {
        let Self { model, state, scratch, times, .. } = self;
        let step = state.step + 1;
        let dt = model.dt;
        // One lap a stage, in the order of `StageTimes`' fields (`augmpm bench --ops` reads them so).
        let mut lap = Lap::start();

        // Moving walls are where they are at the start of the step (the end of the last one): the grid
        // has a point for each of their boundary points.
        let moving = model.region.moves();
        if moving {
            scratch.grid.resize(model.boundary.num_points(&model.layout));
        }
        let model = &*model;
        let layout = &model.layout;
        let left = |OutOfGrid(particle)| StepError::LeftGrid { step, particle, cause: likely_cause(model) };
        // 1. Bin the particles again if due; clear the grid where the last step left values.
        scratch.prepare_grid(layout, &state.particles.x, &mut state.binning).map_err(left)?;
        lap.add_to(&mut times.sort);
        // 2. The grid density's mass (fluids with the paper's density); the J-bar sums cleared.
        scratch.scatter_density(layout, &state.particles, model.region.as_ref());
        lap.add_to(&mut times.density);
        // 3. The walls prepare for this step (augmented: the MLS systems of eq. (5) near walls).
        state.ill_conditioned +=
            model.boundary.prepare::<Dim<D>>(layout, &state.particles.x, &mut scratch.walls).map_err(left)?;
        lap.add_to(&mut times.boundary);

        let Scratch { schedule, grid, density_mass, volume_ratio, packing, walls, pushes, step_impulse, .. } = scratch;
        let t = Transfer { layout, schedule, augmented: model.boundary.transfer_view(walls) };
        let grid_density = (!density_mass.is_empty())
            .then(|| GridDensity { grid_mass: density_mass, wall_fraction: model.wall_fraction.as_deref() });
        // 4. P2G: mass, momentum and the stress force; the volume ratio sums of the J-bar average.
        transfer::p2g(
            &t,
            &model.materials,
            &state.particles,
            grid_density,
            &mut state.density,
            dt,
            grid,
            volume_ratio,
            packing,
        );
        lap.add_to(&mut times.p2g);
        // 5. Grid update (momentum → velocity, gravity), then the walls' conditions; the nodes' J.
        state.low_mass_nodes += transfer::grid_velocity(&t, grid, &model.gravity, dt) as u64;
        if !volume_ratio.is_empty() {
            volume_ratio.finish(layout, schedule);
        }
        if !packing.is_empty() {
            packing.finish(layout, schedule);
        }
        step_impulse.clear();
        model.boundary.apply(layout, model.region.as_ref(), &grid.mass, &mut grid.momentum, step_impulse);
        lap.add_to(&mut times.grid);
        // 6. G2P, advection and the deformation update (with the J-bar average of the J it advances, for
        // the materials that smooth it).
        let outcome = transfer::g2p(
            &t,
            model.region.as_ref(),
            &model.materials,
            &grid.momentum,
            volume_ratio,
            packing,
            &mut state.particles,
            dt,
            pushes,
        );
        // In the table's order (the particles'), so that the sums do not depend on the threads.
        for push in pushes.iter() {
            for (wall, impulse, moment) in push.iter() {
                step_impulse.add_with_moment(wall, impulse, moment);
            }
        }
        for (total, step) in state.wall_impulse.iter_mut().zip(&step_impulse.linear) {
            *total += step;
        }
        for (total, step) in state.wall_angular_impulse.iter_mut().zip(&step_impulse.angular) {
            *total += step;
        }
        lap.add_to(&mut times.g2p);

        state.advance_clock(step, dt, outcome.max_move / layout.h, outcome.held_at_wall as u64);
        let failed = failure(step, &outcome, state.max_cfl, || likely_cause(model));
        // 7. The rigid bodies take the opposite of what their walls gave the material, and gravity.
        let failed = failed.or_else(|| self.advance_bodies(step).err());
        // 8. Moving walls go where they are at the end of the step; the treatment follows them.
        if moving {
            let seen = self.state.seen_poses(&self.model.bodies);
            self.model.follow_walls(self.state.time, &seen);
        }
        let state = &mut self.state;
        match failed {
            Some(e) => {
                // A later call must not trust the binning of a state that went bad.
                state.binning.drift = Real::INFINITY;
                Err(e)
            }
            None => Ok(()),
        }
    }

    /// Moves each rigid body from the start of the step that ended at [`Simulation::time`] to its end: its
    /// velocities take what its wall gave the material over the step and gravity ([`RigidBody::kick`]),
    /// then the model's contacts move it ([`Contacts::drift`]; a model built without them, free flight,
    /// [`drift`]); its wall pose is replaced. Refused, changing nothing, if a body would move more than a
    /// cell in the next step.
    fn advance_bodies(&mut self, step: u64) -> Result<(), StepError> {
        if self.model.bodies.is_empty() {
            return Ok(());
        }
        let (dt, h) = (self.model.dt, self.model.layout.h);
        let t = self.state.time - dt;
        let index = |poses: &[(usize, WallPose<D>)], wall: usize| {
            poses.binary_search_by_key(&wall, |&(w, _)| w).expect("a body's wall is posed")
        };
        let impulse = &self.scratch.step_impulse;
        // Each body's velocities after the step's impulses and gravity, and what the material alone did to
        // them.
        let (kicked, by_material): (Vec<WallPose<D>>, Vec<(Vector<D>, Vector<3>)>) = (self.model.bodies.iter())
            .map(|b| {
                let pose = &self.state.wall_poses[index(&self.state.wall_poses, b.wall)].1;
                let (linear, angular) = (&impulse.linear[b.wall], &impulse.angular[b.wall]);
                let only = b.kick(pose, t, dt, &Vector::<D>::zeros(), linear, angular);
                (b.kick(pose, t, dt, &self.model.gravity, linear, angular), velocity_change(pose, &only))
            })
            .unzip();
        let moved = match &self.model.contacts {
            Some(contacts) => contacts.drift(t, dt, &self.model.bodies, &kicked, self.model.region.as_ref()),
            None => kicked.iter().map(|pose| drift(pose, dt)).collect(),
        };
        for (k, (body, pose)) in self.model.bodies.iter().zip(&moved).enumerate() {
            let (_, speed) = self.model.region.pose_change(body.wall, pose);
            if speed * dt > h || speed.is_nan() {
                return Err(StepError::BodyTooFast { step, body: k, cells: speed * dt / h });
            }
        }
        self.state.body_kicks.resize(self.model.bodies.len(), (Vector::<D>::zeros(), Vector::<3>::zeros()));
        let bodies = self.model.bodies.iter().zip(moved).zip(&by_material);
        for (((body, pose), material), kick) in bodies.zip(&mut self.state.body_kicks) {
            let i = index(&self.state.wall_poses, body.wall);
            let (dv, dw) = velocity_change(&self.state.wall_poses[i].1, &pose);
            *kick = (ahead(&dv, &(dv - material.0)), ahead(&dw, &(dw - material.1)));
            self.state.wall_poses[i].1 = pose;
        }
        Ok(())
    }

    /// Sets wall `wall` (in scene order) where it is now, at [`Simulation::time`]: its pivot displaced
    /// by `pose.position` (m) from where the scene draws it, turned by `pose.angle` (rad), moving from
    /// now on at `pose.velocity` (m/s) and `pose.angular_velocity` (rad/s) until set again (`pose.time`
    /// is taken from the clock). The pose is part of the state (checkpoints keep it). Refused, changing
    /// nothing, with the argument it names and the reason: a wall that does not exist, a non-finite
    /// number, a wall point that would jump or move more than one cell in a step, or a simulation that
    /// cannot follow moving walls (the paper's transfer, the corrected grid density).
    pub fn set_wall_pose(&mut self, wall: usize, pose: WallPose<D>) -> Result<(), (&'static str, String)> {
        let pose = WallPose { time: self.state.time, ..pose };
        self.pose_refused(wall, &pose)?;
        if let Some(k) = self.model.bodies.iter().position(|b| b.wall == wall) {
            return Err(("wall", format!("wall {wall} is rigid_bodies[{k}], which the material moves")));
        }
        let h = self.model.layout.h;
        let (jump, _) = self.model.region.pose_change(wall, &pose);
        if jump > h {
            return Err((
                "position",
                format!(
                    "moves wall {wall} by up to {:.3} cells at once (at most one); move it over several steps",
                    jump / h
                ),
            ));
        }
        let poses = &mut self.state.wall_poses;
        match poses.binary_search_by_key(&wall, |&(w, _)| w) {
            Ok(k) => poses[k].1 = pose,
            Err(k) => poses.insert(k, (wall, pose)),
        }
        let seen = self.state.seen_poses(&self.model.bodies);
        self.model.follow_walls(self.state.time, &seen);
        self.scratch.grid.resize(self.model.boundary.num_points(&self.model.layout));
        Ok(())
    }

    /// Why wall `wall` cannot take `pose` in this simulation, if it cannot (the argument and the reason):
    /// a wall that does not exist or cannot move (a 3D plane), a non-finite number, a 2D turn about
    /// another axis than z, a transfer or density estimate that assumes still walls, or a velocity of
    /// more than a cell per step. [`Simulation::set_wall_pose`] and [`Simulation::restore`] ask it.
    fn pose_refused(&self, wall: usize, pose: &WallPose<D>) -> Result<(), (&'static str, String)> {
        let walls = self.model.region.num_walls();
        if wall >= walls {
            return Err(("wall", format!("there is no wall {wall}; the scene has {walls} walls")));
        }
        if let Some(reason) = self.model.region.unposable(wall) {
            return Err(("wall", reason));
        }
        if let Some(k) = pose.to_row().iter().position(|a| !a.is_finite()) {
            let name = WallPose::<D>::names()[k];
            let argument = ["_x", "_y", "_z"].iter().find_map(|axis| name.strip_suffix(axis)).unwrap_or(name);
            return Err((argument, "must be finite".into()));
        }
        if D == 2 {
            if pose.angle[..2].iter().any(|&a| a != 0.0) {
                return Err(("angle", "a 2D wall turns about z only".into()));
            }
            if pose.angular_velocity[..2].iter().any(|&a| a != 0.0) {
                return Err(("angular_velocity", "a 2D wall turns about z only".into()));
            }
        }
        if let Boundary::Augmented(g) = &self.model.boundary {
            if g.transfer == crate::treatment::augmented::AugmentedTransfer::Paper {
                return Err(("wall", "augmented.transfer = \"paper\" holds particles against still walls only; moving walls need \"stable\"".into()));
            }
        }
        if self.model.wall_fraction.is_some() {
            return Err(("wall", "grid.density_wall_correction is computed once, for still walls".into()));
        }
        let (h, dt) = (self.model.layout.h, self.model.dt);
        let (_, speed) = self.model.region.pose_change(wall, pose);
        if speed * dt > h {
            return Err((
                "velocity",
                format!(
                    "moves wall {wall} up to {:.3} cells in a step of {dt:e} s (at most one); lower the velocity or time.dt",
                    speed * dt / h
                ),
            ));
        }
        Ok(())
    }

    /// The impulse each wall has given the material since the start (N·s, per metre in 2D, N·s in 3D),
    /// the domain box last: minus what the material gave the wall.
    pub fn wall_impulse(&self) -> &[Vector<D>] {
        &self.state.wall_impulse
    }

    /// Each rigid body's centre of mass (m) and turn from where the scene draws it (a rotation vector, rad;
    /// in 2D only z), and their rates (m/s, rad/s), now.
    pub fn rigid_bodies(&self) -> Vec<(Vector<D>, [Real; 3], Vector<D>, [Real; 3])> {
        self.model
            .bodies
            .iter()
            .map(|body| {
                let i = self.state.wall_poses.binary_search_by_key(&body.wall, |&(w, _)| w).expect("posed");
                let pose = &self.state.wall_poses[i].1;
                let t = self.state.time;
                (body.centre + pose.offset(t), pose.turn(t), Vector::<D>::from(pose.velocity), pose.angular_velocity)
            })
            .collect()
    }

    /// The moment about the origin of the impulse each wall has given the material since the start (N·m·s,
    /// per metre in 2D; 3 components, in 2D only z), the domain box last.
    pub fn wall_angular_impulse(&self) -> &[Vector<3>] {
        &self.state.wall_angular_impulse
    }

    /// Density (kg/m³, or kg/m² in 2D) of each particle in the last step, as its material saw it
    /// (fluids: ρ0/J with J the particle's volume ratio, or gathered from the regular grid), zero before
    /// the first step.
    pub fn grid_density(&self) -> &[Real] {
        &self.state.density
    }

    /// Per-particle fields of the current state, for output: each particle's Cauchy stress σ (Pa, or N/m
    /// in 2D), its volume ratio J = V/V⁰ (fluids: ρ0/ρ with the density their stress sees; solids:
    /// det F · J_p) and its plastic volume ratio J_p (snow; sand: its loose volume, ≥ 1; 1 for the other materials).
    pub fn particle_fields(&self) -> ParticleFields<D> {
        let particles = &self.state.particles;
        let n = particles.len();
        let mut fields =
            ParticleFields { stress: Vec::with_capacity(n), volume_ratio: Vec::with_capacity(n), plastic: Vec::new() };
        fields.plastic.reserve(n);
        for p in 0..n {
            let material = &self.model.materials[particles.body[p] as usize];
            let point = MaterialPoint {
                f: particles.deformation_gradient(p),
                jp: particles.jp[p],
                grad_v: particles.c[p],
                mass: particles.mass[p],
                vol0: particles.vol0[p],
                density: self.state.density.get(p).copied().unwrap_or(0.0),
            };
            fields.stress.push(material.cauchy_stress(&point));
            if ConstitutiveModel::<D>::keeps_deformation_gradient(material) {
                fields.volume_ratio.push(Dim::<D>::det(&point.f) * point.jp);
                fields.plastic.push(point.jp);
            } else {
                let rho = material.current_density(&point);
                fields.volume_ratio.push(if rho > 0.0 { ConstitutiveModel::<D>::density(material) / rho } else { 1.0 });
                fields.plastic.push(1.0);
            }
        }
        fields
    }

    /// Kinetic energy and wall penetration of the current state.
    pub fn metrics(&self) -> Metrics {
        let region = self.model.region.as_ref();
        let (mut n_outside, mut deepest) = (0usize, 0.0 as Real);
        let state = &self.state;
        for x in &state.particles.x {
            let d = region.distance(x).distance;
            if d > 0.0 {
                n_outside += 1;
                deepest = deepest.max(d);
            }
        }
        Metrics {
            step: state.step,
            time: state.time,
            kinetic_energy: state.particles.kinetic_energy(),
            n_outside,
            max_penetration: deepest / self.model.layout.h,
            ill_conditioned: state.ill_conditioned,
            low_mass_nodes: state.low_mass_nodes,
            held_at_wall: state.held_at_wall,
            max_cfl: state.max_cfl,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The velocity change shown ahead is the whole last change where gravity or contacts gave all of it
    /// or more (a body falling freely, or pushed through the material), none where the material gave all
    /// of it or held the body against them (floating at rest) or slowed it against them (an impact), and
    /// the other forces' share between.
    #[test]
    fn a_body_is_shown_ahead_what_other_forces_drove() {
        let v = |x: Real, y: Real| Vector::<2>::new(x, y);
        let g = v(0.0, -0.01);
        assert_eq!(ahead(&g, &g), g);
        assert_eq!(ahead(&v(0.0, -0.004), &v(0.0, -0.01)), v(0.0, -0.004));
        assert_eq!(ahead(&v(0.3, 0.0), &v(0.0, 0.0)), v(0.0, 0.0));
        assert_eq!(ahead(&v(0.0, 0.0), &g), v(0.0, 0.0));
        assert_eq!(ahead(&v(0.0, 0.02), &g), v(0.0, 0.0));
        let half = ahead(&v(0.0, -0.02), &v(0.0, -0.01));
        assert!((half - v(0.0, -0.01)).norm() < 1e-15);
    }
}
