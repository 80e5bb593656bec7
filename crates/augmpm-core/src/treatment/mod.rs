//! The wall treatments: how the walls act on the grid, behind one trait with the same calls for
//! both — prepare for this step, apply the wall conditions at the grid points — and what the
//! transfers see of them. [`naive`] is the classic node projection (the paper's baseline);
//! [`augmented`] is the augmented grid of Toyota & Umetani 2024, with [`wall_fit`], its G2P at walls.
//! [`Boundary`] holds the one a simulation runs, chosen by [`Method`].

pub mod augmented;
pub mod naive;
pub mod wall_fit;

use crate::geometry::Region;
use crate::grid::{GridLayout, OutOfGrid};
use crate::kernel::{MlsInverse, MlsKind, Stencil};
use crate::math::{DimOps, Real, Vector};
use crate::wall::{BoundaryPoint, WallContact, WallImpulses};
use augmented::{AugmentedGrid, AugmentedTransfer, WallParticles};
use naive::NaiveBoundary;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// How walls act on the grid, chosen by name (`method` in scenes, the API and the CLI).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Grid-node projection on the regular grid (the baseline of the paper).
    Naive,
    /// Augmented grid points on the walls (Toyota & Umetani 2024): the default.
    #[default]
    Augmented,
}

/// What a step asks of a wall treatment. `table` is the treatment's per-step scratch (the particles
/// whose MLS system sees a wall, for the augmented grid; unused by the naive treatment).
pub trait WallTreatment<const D: usize> {
    /// The treatment's name in scenes.
    fn method(&self) -> Method;

    /// Grid points the transfers scatter to: the regular nodes, then any boundary points.
    fn num_points(&self, layout: &GridLayout<D>) -> usize;

    /// Prepares for a step of particles at `x`, in `table`. Returns how many particles' MLS systems
    /// were ill-conditioned or isolated.
    fn prepare<Ops: DimOps<D>>(
        &self,
        layout: &GridLayout<D>,
        x: &[Vector<D>],
        table: &mut WallParticles<D>,
    ) -> Result<u64, OutOfGrid>;

    /// Applies the walls' conditions at the grid points they act on (velocities, after the grid update),
    /// adding the impulse each wall gives the grid's material there, `m_i (v_i' − v_i)` (N·s, per metre
    /// in 2D), and its moment to `impulse` (one per wall, the domain box last). P2G and the grid update conserve
    /// momentum, so these are the walls' impulses on the material (with the augmented grid's G2P wall
    /// fit, counted in G2P).
    fn apply(
        &self,
        layout: &GridLayout<D>,
        region: &dyn Region<D>,
        mass: &[Real],
        velocity: &mut [Vector<D>],
        impulse: &mut WallImpulses<D>,
    );

    /// How each wall acts (condition, friction, whether it moves), the domain box last.
    fn contacts(&self) -> &[WallContact];

    /// Says whether wall `wall` moves (its whole velocity then counts in its condition).
    fn set_moving(&mut self, wall: usize, moving: bool);

    /// Follows walls that moved: what the treatment keeps of them is brought to where `region`'s walls
    /// are now (naive: from then on the nodes are classified at each step where there is material;
    /// augmented: the boundary points, and the node flags and point index where the walls swept).
    fn follow(&mut self, layout: &GridLayout<D>, region: &dyn Region<D>);

    /// What P2G and G2P see of the walls this step: the augmented grid and its table, or `None`
    /// (the transfers then run on the regular grid alone).
    fn transfer_view<'a>(&'a self, table: &'a WallParticles<D>)
        -> Option<(&'a AugmentedGrid<D>, &'a WallParticles<D>)>;

    /// The points sampled on the walls that join the grid (none for the naive treatment).
    fn boundary_points(&self) -> &[BoundaryPoint<D>];

    /// Whether regular node `node` takes part in the interpolation.
    fn includes(&self, node: usize) -> bool;

    /// MLS reconstruction (eq. (4)) at `x` of a scalar field given at the grid points (one value per
    /// node, then one per boundary point): the value, its gradient, and how the system was solved.
    fn interpolate<Ops: DimOps<D>>(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        values: &[Real],
    ) -> Result<(Real, Vector<D>, MlsKind), OutOfGrid>;

    /// Heap bytes of what the treatment keeps (node lists, boundary points, indices).
    fn heap_bytes(&self) -> usize;
}

impl<const D: usize> WallTreatment<D> for NaiveBoundary<D> {
    fn method(&self) -> Method {
        Method::Naive
    }
    fn num_points(&self, layout: &GridLayout<D>) -> usize {
        layout.num_nodes()
    }
    fn prepare<Ops: DimOps<D>>(
        &self,
        _: &GridLayout<D>,
        _: &[Vector<D>],
        _: &mut WallParticles<D>,
    ) -> Result<u64, OutOfGrid> {
        Ok(0)
    }
    fn apply(
        &self,
        layout: &GridLayout<D>,
        region: &dyn Region<D>,
        mass: &[Real],
        velocity: &mut [Vector<D>],
        impulse: &mut WallImpulses<D>,
    ) {
        NaiveBoundary::apply(self, layout, region, mass, velocity, impulse)
    }
    fn contacts(&self) -> &[WallContact] {
        &self.walls
    }
    fn set_moving(&mut self, wall: usize, moving: bool) {
        self.walls[wall].moving = moving;
    }
    fn follow(&mut self, layout: &GridLayout<D>, region: &dyn Region<D>) {
        NaiveBoundary::follow(self, layout, region)
    }
    fn transfer_view<'a>(&'a self, _: &'a WallParticles<D>) -> Option<(&'a AugmentedGrid<D>, &'a WallParticles<D>)> {
        None
    }
    fn boundary_points(&self) -> &[BoundaryPoint<D>] {
        &[]
    }
    fn includes(&self, _: usize) -> bool {
        true
    }
    /// The regular grid's closed form (APIC MLS) over the whole stencil.
    fn interpolate<Ops: DimOps<D>>(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        values: &[Real],
    ) -> Result<(Real, Vector<D>, MlsKind), OutOfGrid> {
        let h = layout.h;
        let s = Stencil::new(x, 1.0 / h);
        let origin = layout.stencil_origin(&s.base).ok_or(OutOfGrid(0))?;
        let minv = MlsInverse::<D>::regular(h);
        let (mut u, mut grad) = (0.0, Vector::<D>::zeros());
        s.for_each(h, |o, w, d| {
            let (phi, g) = minv.shape(w, &d);
            let vi = values[origin + layout.offset(&o)];
            u += phi * vi;
            grad += g * vi;
        });
        Ok((u, grad, MlsKind::Regular))
    }
    fn heap_bytes(&self) -> usize {
        NaiveBoundary::heap_bytes(self)
    }
}

impl<const D: usize> WallTreatment<D> for AugmentedGrid<D> {
    fn method(&self) -> Method {
        Method::Augmented
    }
    fn num_points(&self, layout: &GridLayout<D>) -> usize {
        layout.num_nodes() + self.points.len()
    }
    /// eq. (5), once per particle near a wall and step, reused by P2G, the force and G2P.
    fn prepare<Ops: DimOps<D>>(
        &self,
        layout: &GridLayout<D>,
        x: &[Vector<D>],
        table: &mut WallParticles<D>,
    ) -> Result<u64, OutOfGrid> {
        table.update::<Ops>(self, layout, x)
    }
    fn apply(
        &self,
        _: &GridLayout<D>,
        _: &dyn Region<D>,
        mass: &[Real],
        velocity: &mut [Vector<D>],
        impulse: &mut WallImpulses<D>,
    ) {
        AugmentedGrid::apply(self, mass, velocity, impulse)
    }
    fn contacts(&self) -> &[WallContact] {
        &self.walls
    }
    fn set_moving(&mut self, wall: usize, moving: bool) {
        self.walls[wall].moving = moving;
    }
    fn follow(&mut self, layout: &GridLayout<D>, region: &dyn Region<D>) {
        AugmentedGrid::follow(self, layout, region)
    }
    fn transfer_view<'a>(
        &'a self,
        table: &'a WallParticles<D>,
    ) -> Option<(&'a AugmentedGrid<D>, &'a WallParticles<D>)> {
        Some((self, table))
    }
    fn boundary_points(&self) -> &[BoundaryPoint<D>] {
        &self.points
    }
    fn includes(&self, node: usize) -> bool {
        self.included[node]
    }
    fn interpolate<Ops: DimOps<D>>(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        values: &[Real],
    ) -> Result<(Real, Vector<D>, MlsKind), OutOfGrid> {
        AugmentedGrid::interpolate::<Ops>(self, layout, x, values)
    }
    fn heap_bytes(&self) -> usize {
        AugmentedGrid::heap_bytes(self)
    }
}

/// The wall treatment a simulation runs: one of the two, dispatched in one place.
pub enum Boundary<const D: usize> {
    /// Grid nodes on the wall side are projected after the grid update.
    Naive(NaiveBoundary<D>),
    /// Boundary points join the grid; particles solve their own MLS systems.
    Augmented(AugmentedGrid<D>),
}

macro_rules! dispatch {
    ($self:ident, $t:ident => $e:expr) => {
        match $self {
            Boundary::Naive($t) => $e,
            Boundary::Augmented($t) => $e,
        }
    };
}

impl<const D: usize> Boundary<D> {
    /// Whether a step reads the grid's B-spline mass (`GridState::spline_mass`): only the paper's augmented
    /// transfer does, in its low-mass floor. Elsewhere it would equal the mass, and is not kept.
    pub fn reads_spline_mass(&self) -> bool {
        matches!(self, Boundary::Augmented(g) if g.transfer == AugmentedTransfer::Paper)
    }
}

impl<const D: usize> WallTreatment<D> for Boundary<D> {
    fn method(&self) -> Method {
        dispatch!(self, t => t.method())
    }
    fn num_points(&self, layout: &GridLayout<D>) -> usize {
        dispatch!(self, t => t.num_points(layout))
    }
    fn prepare<Ops: DimOps<D>>(
        &self,
        layout: &GridLayout<D>,
        x: &[Vector<D>],
        table: &mut WallParticles<D>,
    ) -> Result<u64, OutOfGrid> {
        dispatch!(self, t => t.prepare::<Ops>(layout, x, table))
    }
    fn apply(
        &self,
        layout: &GridLayout<D>,
        region: &dyn Region<D>,
        mass: &[Real],
        velocity: &mut [Vector<D>],
        impulse: &mut WallImpulses<D>,
    ) {
        dispatch!(self, t => WallTreatment::apply(t, layout, region, mass, velocity, impulse))
    }
    fn contacts(&self) -> &[WallContact] {
        dispatch!(self, t => t.contacts())
    }
    fn set_moving(&mut self, wall: usize, moving: bool) {
        dispatch!(self, t => t.set_moving(wall, moving))
    }
    fn follow(&mut self, layout: &GridLayout<D>, region: &dyn Region<D>) {
        dispatch!(self, t => WallTreatment::follow(t, layout, region))
    }
    fn transfer_view<'a>(
        &'a self,
        table: &'a WallParticles<D>,
    ) -> Option<(&'a AugmentedGrid<D>, &'a WallParticles<D>)> {
        dispatch!(self, t => t.transfer_view(table))
    }
    fn boundary_points(&self) -> &[BoundaryPoint<D>] {
        dispatch!(self, t => t.boundary_points())
    }
    fn includes(&self, node: usize) -> bool {
        dispatch!(self, t => t.includes(node))
    }
    fn interpolate<Ops: DimOps<D>>(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        values: &[Real],
    ) -> Result<(Real, Vector<D>, MlsKind), OutOfGrid> {
        dispatch!(self, t => WallTreatment::interpolate::<Ops>(t, layout, x, values))
    }
    fn heap_bytes(&self) -> usize {
        dispatch!(self, t => WallTreatment::heap_bytes(t))
    }
}
