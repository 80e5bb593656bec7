//! The naive wall treatment: grid nodes on the wall side of the material region take the wall's
//! condition ([`crate::wall::WallCondition`]), the classic MLS-MPM boundary and the paper's baseline.

use crate::geometry::Region;
use crate::grid::GridLayout;
use crate::math::{Real, Vector};
use crate::wall::{WallContact, WallImpulses};

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
    /// The wall nodes, classified once (still walls; empty when the walls move).
    pub nodes: Vec<WallNode<D>>,
    /// The node of each entry of `nodes`, apart: each step scans these for the few wall nodes that hold
    /// mass, and reads a 48-byte record only for those (on the 256² bench dam break 0.11 ms a step was spent
    /// scanning the records, about 25,000 outside the tilted tank, nearly all without mass).
    ids: Vec<u32>,
    /// Condition and friction of each wall.
    pub walls: Vec<WallContact>,
    /// Whether the walls move: the nodes are then classified where the material is, at each step.
    moving: bool,
}

impl<const D: usize> NaiveBoundary<D> {
    /// Classifies every node of `layout` against `region`, each wall node with its wall's surface
    /// velocity there.
    pub fn new(layout: &GridLayout<D>, region: &dyn Region<D>, walls: Vec<WallContact>) -> Self {
        let mut naive = Self { nodes: Vec::new(), ids: Vec::new(), walls, moving: false };
        naive.classify(layout, region);
        naive
    }

    /// Classifies the nodes where the walls are now.
    pub fn classify(&mut self, layout: &GridLayout<D>, region: &dyn Region<D>) {
        self.nodes = (0..layout.num_nodes()).filter_map(|node| wall_node(layout, region, node)).collect();
        self.ids = self.nodes.iter().map(|w| u32::try_from(w.node).expect("grid nodes are counted in u32")).collect();
    }

    /// Follows walls that moved: from now on the nodes are classified at each step, and only those that
    /// hold material (the others need no condition), so that the cost follows the material, not the grid.
    pub fn follow(&mut self) {
        self.moving = true;
        self.nodes = Vec::new();
        self.ids = Vec::new();
    }

    /// Heap bytes of the wall-node list.
    pub fn heap_bytes(&self) -> usize {
        crate::math::heap_bytes(&self.nodes) + crate::math::heap_bytes(&self.ids) + crate::math::heap_bytes(&self.walls)
    }

    /// Projects the grid velocities of wall nodes (after momentum → velocity), adding each wall's
    /// impulse on the material, `m_i (v_i' − v_i)` (N·s), at the node to `impulse`. Moving walls: the nodes
    /// that hold material are classified against `region` where its walls are now (in node order, as
    /// the list of still walls).
    pub fn apply(
        &self,
        layout: &GridLayout<D>,
        region: &dyn Region<D>,
        mass: &[Real],
        velocity: &mut [Vector<D>],
        impulse: &mut WallImpulses<D>,
    ) {
        let mut project = |w: &WallNode<D>| {
            let m = mass[w.node];
            if m > 0.0 {
                let before = velocity[w.node];
                velocity[w.node] = self.walls[w.wall].apply(before, &w.normal, &w.velocity);
                impulse.add(w.wall, &layout.position(w.node), (velocity[w.node] - before) * m);
            }
        };
        if self.moving {
            (0..layout.num_nodes())
                .filter(|&node| mass[node] > 0.0)
                .filter_map(|node| wall_node(layout, region, node))
                .for_each(|w| project(&w));
        } else {
            // In node order, as before (the impulses are summed in it).
            for (k, &node) in self.ids.iter().enumerate() {
                if mass[node as usize] > 0.0 {
                    project(&self.nodes[k]);
                }
            }
        }
    }
}

/// Node `node` as a wall node, with its wall's normal and surface velocity there, if it lies on the
/// wall side of `region` (or on a wall).
fn wall_node<const D: usize>(layout: &GridLayout<D>, region: &dyn Region<D>, node: usize) -> Option<WallNode<D>> {
    let x = layout.position(node);
    let d = region.distance(&x);
    (d.distance >= 0.0).then(|| WallNode {
        node,
        normal: d.normal,
        wall: d.wall,
        velocity: region.surface_velocity(d.wall, &x, &d.normal),
    })
}
