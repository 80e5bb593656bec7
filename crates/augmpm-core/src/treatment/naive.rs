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
    nodes: Vec<WallNode<D>>,
    /// The node of each entry of `nodes`, apart: each step scans these for the few wall nodes that hold
    /// mass, and reads a 48-byte record only for those (on the 256² bench dam break 0.11 ms a step was spent
    /// scanning the records, about 25,000 outside the tilted tank, nearly all without mass).
    ids: Vec<u32>,
    /// Condition and friction of each wall.
    pub walls: Vec<WallContact>,
    /// Whether the walls move: the nodes are then classified where the material is, at each step.
    moving: bool,
    /// Moving walls: which nodes are surely inside the material region, kept across steps (see
    /// [`NaiveBoundary::follow`]); `None` before the first follow and after walls jumped.
    follow: Option<Follow>,
}

/// What [`NaiveBoundary::follow`] keeps between steps of moving walls. A node's signed distance to the walls
/// changes by at most what they swept (`Region::sweep`), so a node found inside by d stays inside until
/// the walls have swept d since: the step classifies only the nodes with mass that may be on the wall
/// side, and a follow looks again only at the nodes whose classification may have changed. The wall nodes
/// are the same as classifying every node with mass at every step (on the shaken tank 0.3 of its step): by
/// the bound, up to a rounding slack that covers the distances' own (in f32 ~1e-7 of the domain's size). It
/// holds as long as a follow comes after every `Region::set_time`, as in `Model::follow_walls`: a sweep
/// bounds the last move only.
#[derive(Clone, Debug)]
struct Follow {
    /// How far (m) the walls may have moved in all since the nodes were first looked at: the sum of every
    /// follow's `Region::sweep`, each taken 0.1% larger (a sweep is computed in `Real`, and may round below
    /// the true one), summed in f64 (so that a long run's sum does not lose its small terms in f32).
    swept: f64,
    /// Per node, the `swept` at which it must be looked at again: its distance may have changed sign.
    due: Vec<f64>,
    /// Per node, whether it was inside the material region (and is until its `due`) when last looked at.
    inside: Vec<bool>,
}

impl Follow {
    /// The nodes of `layout` looked at where the walls of `region` are now.
    fn new<const D: usize>(layout: &GridLayout<D>, region: &dyn Region<D>) -> Self {
        let n = layout.num_nodes();
        let mut follow = Self { swept: 0.0, due: vec![0.0; n], inside: vec![false; n] };
        for node in 0..n {
            follow.look(layout, region, node);
        }
        follow
    }

    /// Classifies `node` where the walls are now, and says when to look again: once the walls have swept
    /// its distance, less a rounding slack (distances round, in f32 by ~1e-7 of the domain's size; the
    /// slack is 256 ulp of it, at least 1e-6 h, so that nodes within it of a wall are looked at every step).
    fn look<const D: usize>(&mut self, layout: &GridLayout<D>, region: &dyn Region<D>, node: usize) {
        let slack = (1e-6 * layout.h).max(256.0 * Real::EPSILON * layout.extent().max());
        let d = region.distance(&layout.position(node)).distance;
        self.inside[node] = d < 0.0;
        self.due[node] = self.swept + crate::math::wide(d.abs() - slack);
    }

    /// Whether `node` is surely inside the material region where the walls are now (no wall node).
    #[inline]
    fn surely_inside(&self, node: usize) -> bool {
        self.inside[node] && self.due[node] > self.swept
    }
}

impl<const D: usize> NaiveBoundary<D> {
    /// Classifies every node of `layout` against `region`, each wall node with its wall's surface
    /// velocity there.
    pub fn new(layout: &GridLayout<D>, region: &dyn Region<D>, walls: Vec<WallContact>) -> Self {
        let mut naive = Self { nodes: Vec::new(), ids: Vec::new(), walls, moving: false, follow: None };
        naive.classify(layout, region);
        naive
    }

    /// Classifies the nodes where the walls are now.
    pub fn classify(&mut self, layout: &GridLayout<D>, region: &dyn Region<D>) {
        self.nodes = (0..layout.num_nodes()).filter_map(|node| wall_node(layout, region, node)).collect();
        self.ids = self.nodes.iter().map(|w| u32::try_from(w.node).expect("grid nodes are counted in u32")).collect();
    }

    /// Follows walls that moved (`region` where they are now): from now on the nodes are classified at each
    /// step, and only those that hold material (the others need no condition), so that the cost follows the
    /// material, not the grid; of those, only the ones the walls may have reached since they were found
    /// inside ([`Follow`]).
    pub fn follow(&mut self, layout: &GridLayout<D>, region: &dyn Region<D>) {
        self.moving = true;
        self.nodes = Vec::new();
        self.ids = Vec::new();
        let sweep = region.sweep();
        match self.follow.as_mut().filter(|f| sweep.is_finite() && f.due.len() == layout.num_nodes()) {
            Some(follow) => {
                follow.swept += crate::math::wide(sweep) * 1.001;
                for node in 0..follow.due.len() {
                    if follow.due[node] <= follow.swept {
                        follow.look(layout, region, node);
                    }
                }
            }
            None => self.follow = Some(Follow::new(layout, region)),
        }
    }

    /// Heap bytes of the wall-node list.
    pub fn heap_bytes(&self) -> usize {
        let follow =
            self.follow.as_ref().map_or(0, |f| crate::math::heap_bytes(&f.due) + crate::math::heap_bytes(&f.inside));
        crate::math::heap_bytes(&self.nodes)
            + crate::math::heap_bytes(&self.ids)
            + crate::math::heap_bytes(&self.walls)
            + follow
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
            let follow = self.follow.as_ref();
            let inside = |node: usize| follow.is_some_and(|f| f.surely_inside(node));
            (0..layout.num_nodes())
                .filter(|&node| mass[node] > 0.0 && !inside(node))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Point, Polygon, WallShape, Walls2};
    use crate::motion::Motion;
    use crate::wall::WallCondition;

    /// Property: with moving walls, the wall nodes found through the follow's record of nodes surely inside
    /// are exactly those of classifying every node with mass at every step. A square container carried at
    /// (0.05, 0.02) m/s and turning at 0.5 rad/s about its centre sweeps ~2.5 cells of a 64² grid in 300
    /// steps; every node holds mass, and the velocities and impulses after `apply` are bitwise those of the
    /// same boundary with no record.
    #[test]
    fn following_moving_walls_finds_the_wall_nodes_of_a_full_classification() {
        let layout = GridLayout::new(1.0 / 64.0, [64, 64]);
        let square =
            Polygon::new(vec![Point::new(0.2, 0.2), Point::new(0.8, 0.2), Point::new(0.8, 0.8), Point::new(0.2, 0.8)]);
        let motion = Motion::Constant { velocity: [0.05, 0.02], angular_velocity: 0.5, pivot: None };
        let mut walls =
            Walls2::new(vec![WallShape::Polygon(square)], Point::new(1.0, 1.0)).with_moves(vec![Some(motion)]);
        let contacts = vec![WallContact { moving: true, ..WallCondition::Slip.into() }, WallCondition::Slip.into()];
        let (mut followed, mut full) = (
            NaiveBoundary::new(&layout, &walls, contacts.clone()),
            NaiveBoundary::new(&layout, &walls, contacts.clone()),
        );
        let n = layout.num_nodes();
        let mass = vec![1.0; n];
        let start: Vec<Point> = (0..n).map(|i| Point::new((i as Real).sin(), (i as Real * 0.7).cos())).collect();
        let (dt, mut skipped) = (1e-3, 0);
        for step in 0..300 {
            walls.set_time(step as Real * dt, dt);
            followed.follow(&layout, &walls);
            full.follow(&layout, &walls);
            full.follow = None;
            let follow = followed.follow.as_ref().expect("the record of a moving boundary");
            skipped += (0..n).filter(|&i| follow.surely_inside(i)).count();
            let (mut a, mut b) = (start.clone(), start.clone());
            let (mut ia, mut ib) = (WallImpulses::zeros(2), WallImpulses::zeros(2));
            followed.apply(&layout, &walls, &mass, &mut a, &mut ia);
            full.apply(&layout, &walls, &mass, &mut b, &mut ib);
            assert!(a == b, "step {step}: the velocities differ");
            assert!(ia.linear == ib.linear && ia.angular == ib.angular, "step {step}: the impulses differ");
        }
        // Not vacuous: most nodes inside the square were skipped at most steps.
        assert!(skipped > 300 * n / 4, "{skipped} node-steps skipped");
    }
}
