//! The naive wall treatment: grid nodes on the wall side of the material region take the wall's
//! condition ([`crate::wall::WallCondition`]), the classic MLS-MPM boundary and the paper's baseline.

use crate::geometry::Region;
use crate::grid::GridLayout;
use crate::math::{Real, Vector};
use crate::wall::WallContact;

/// A grid node on the wall side of the region, with the condition it gets.
#[derive(Clone, Copy, Debug)]
pub struct WallNode<const D: usize> {
    pub node: usize,
    pub normal: Vector<D>,
    pub wall: usize,
    /// Velocity of the wall surface there (m/s): of a still wall only its tangential part acts, of a
    /// moving one all of it.
    pub velocity: Vector<D>,
}

/// The classic MLS-MPM boundary: every grid node outside the material region
/// (or exactly on its wall) gets its wall's condition after the grid update.
#[derive(Clone, Debug)]
pub struct NaiveBoundary<const D: usize> {
    pub nodes: Vec<WallNode<D>>,
    /// Condition and friction of each wall.
    pub walls: Vec<WallContact>,
}

impl<const D: usize> NaiveBoundary<D> {
    /// Classifies every node of `layout` against `region`, each wall node with its wall's surface
    /// velocity there.
    pub fn new(layout: &GridLayout<D>, region: &dyn Region<D>, walls: Vec<WallContact>) -> Self {
        let mut naive = Self { nodes: Vec::new(), walls };
        naive.classify(layout, region);
        naive
    }

    /// Classifies the nodes again, where the walls are now.
    pub fn classify(&mut self, layout: &GridLayout<D>, region: &dyn Region<D>) {
        self.nodes = (0..layout.num_nodes())
            .filter_map(|node| {
                let x = layout.position(node);
                let d = region.distance(&x);
                (d.distance >= 0.0).then(|| WallNode {
                    node,
                    normal: d.normal,
                    wall: d.wall,
                    velocity: region.surface_velocity(d.wall, &x, &d.normal),
                })
            })
            .collect();
    }

    /// Heap bytes of the wall-node list.
    pub fn heap_bytes(&self) -> usize {
        crate::math::heap_bytes(&self.nodes) + crate::math::heap_bytes(&self.walls)
    }

    /// Projects the grid velocities of wall nodes (after momentum → velocity), adding each wall's
    /// impulse on the material, `m_i (v_i' − v_i)` (N·s), to `impulse[wall]`.
    pub fn apply(&self, mass: &[Real], velocity: &mut [Vector<D>], impulse: &mut [Vector<D>]) {
        for w in &self.nodes {
            let m = mass[w.node];
            if m > 0.0 {
                let before = velocity[w.node];
                velocity[w.node] = self.walls[w.wall].apply(before, &w.normal, &w.velocity);
                impulse[w.wall] += (velocity[w.node] - before) * m;
            }
        }
    }
}
